//! Policies: map a belief to the next container to search.

use std::sync::Arc;

use ferret_world::Place;

use crate::belief::Belief;
use crate::error::PlanError;
use crate::plan_memo::PlanMemo;
use crate::planner::{self, Solution, TourProblem};
use crate::probability::Probability;
use crate::task::{DestinationLegs, Goal};
use crate::task_table::{self, TaskProblem, TaskSolution};

/// Maps a belief to the next container to search. A policy lives for one trial and may keep state
/// between decisions (a cached plan, a conversation). Policies are `Send` so that a search in
/// progress can move between threads with its robot's driver (a Python or ROS executor thread).
pub trait Policy: Send {
    /// The next container to search: an unsearched container of `belief.house`. Called only while
    /// at least one container is unsearched.
    fn choose(&mut self, belief: &Belief<'_>) -> Result<usize, PlanError>;
}

/// The optimistic+greedy baseline: every container might hold the target, so go to the nearest
/// unsearched one (ties to the lower index).
#[derive(Clone, Copy, Debug, Default)]
pub struct Greedy;

impl Policy for Greedy {
    fn choose(&mut self, belief: &Belief<'_>) -> Result<usize, PlanError> {
        nearest(belief, belief.unsearched()).ok_or_else(|| no_container("optimistic+greedy"))
    }
}

fn no_container(policy: &str) -> PlanError {
    PlanError::BadChoice {
        policy: policy.to_string(),
        container: usize::MAX,
        why: "not in the house (nothing left to search)",
    }
}

/// The nearest of `candidates` to the robot, ties to the lower index.
pub fn nearest(belief: &Belief<'_>, candidates: impl IntoIterator<Item = usize>) -> Option<usize> {
    candidates
        .into_iter()
        .map(|c| (belief.distance_to(c), c))
        .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
        .map(|(_, c)| c)
}

/// Which containers the planner considers at each decision.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum CandidateLimit {
    /// The paper's heuristic: the 2 nearest unsearched containers plus the most likely ones, up to
    /// `k` in all, dropping containers with p = 0; replanned at every decision.
    Paper {
        /// Containers planned over (the paper uses 8).
        k: usize,
    },
    /// Every unsearched container with p > 0, exactly, while they number at most `max`; beyond
    /// that the paper heuristic with `k = max` until few enough remain.
    Exact {
        /// Largest exact problem (≤ [`planner::MAX_EXACT`]).
        max: usize,
    },
}

impl CandidateLimit {
    /// The paper's setting, K = 8.
    pub const PAPER: CandidateLimit = CandidateLimit::Paper { k: 8 };
}

/// The objective the planner minimises.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CostModel {
    /// The paper's eq. 3.
    #[default]
    Paper,
    /// The paper's reference code: eq. 3 plus `p_a · D(robot, a)` on every leg that ends at
    /// container `a`, weighted like the leg, with the robot's position at the time of the
    /// decision. (In that code a leg's success cost is measured from an unset destination, which
    /// amounts to this term.) Kept to measure how much the difference matters.
    Authors,
}

/// Planner settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlannerConfig {
    /// Search cost `R` added per container, metres (0 in the paper).
    pub search_cost: f64,
    /// Candidate selection.
    pub limit: CandidateLimit,
    /// The objective.
    pub cost: CostModel,
}

impl Default for PlannerConfig {
    fn default() -> Self {
        Self {
            search_cost: 0.0,
            limit: CandidateLimit::PAPER,
            cost: CostModel::Paper,
        }
    }
}

/// The model-based planner: chooses the first container of the ordering with least expected cost
/// (paper eq. 3) over the candidates, given each container's probability; for a task, the first
/// step of the policy with least expected cost until its goal holds and the robot stands at its
/// destination ([`task_table`]).
///
/// While one target is wanted (or any of several: one target of likelihood 1 − ∏(1 − p_t)) it
/// solves the Held–Karp problem of eq. 3, with a destination's legs added to it; while several
/// are wanted at once, the task table over (searched set, found set, position).
#[derive(Debug)]
pub struct Planner {
    /// One row of probabilities per target it plans for, index-aligned with the containers.
    p: Vec<Vec<Probability>>,
    /// The index, among the belief's task targets, of each row's target.
    rows: Vec<usize>,
    goal: Goal,
    /// Travel from each place to the destination, when there is one.
    destination: Option<DestinationLegs>,
    config: PlannerConfig,
    /// A full solution over a candidate set, reused while the robot follows it.
    cached: Option<Cached>,
    /// First steps of tables other searches of this house solved.
    memo: Option<Arc<PlanMemo>>,
}

#[derive(Debug)]
struct Cached {
    candidates: Vec<usize>,
    /// The rows wanted when it was solved.
    wanted: Vec<usize>,
    table: Table,
}

#[derive(Debug)]
enum Table {
    /// One target wanted (or `any`): the Held–Karp problem. Its solution is `None` while the
    /// decision came from the memo: solved when the robot follows it further.
    Tour(TourProblem, Option<Solution>),
    /// Several targets wanted at once.
    Task(TaskProblem, TaskSolution),
}

/// What a decision plans for: the probabilities of one target (or of any of several), or of
/// several wanted at once.
enum Wanted {
    One(Vec<Probability>),
    Several(Vec<usize>),
}

impl Planner {
    /// A planner for one target over fixed per-container probabilities (index-aligned with the
    /// house's containers): the first target of the belief's task, no destination.
    pub fn new(p: Vec<Probability>, config: PlannerConfig) -> Self {
        Self::for_targets(vec![p], vec![0], Goal::All, None, config)
    }

    /// A planner for a task: one row of probabilities per target, `rows[i]` the index of row
    /// `i`'s target among the belief's task targets; done once `goal` holds over those rows;
    /// then on to `destination`.
    pub fn for_targets(
        p: Vec<Vec<Probability>>,
        rows: Vec<usize>,
        goal: Goal,
        destination: Option<DestinationLegs>,
        config: PlannerConfig,
    ) -> Self {
        Self {
            p,
            rows,
            goal,
            destination,
            config,
            cached: None,
            memo: None,
        }
    }

    /// The same planner, taking first decisions over candidate sets already solved in this
    /// house from `memo` and keeping there those it solves (see [`PlanMemo`]); its decisions
    /// are the same bit for bit.
    pub fn with_memo(self, memo: Option<Arc<PlanMemo>>) -> Self {
        Self { memo, ..self }
    }

    /// The rows whose target the belief has not found.
    fn wanted_rows(&self, belief: &Belief<'_>) -> Vec<usize> {
        (0..self.p.len())
            .filter(|&i| self.rows.get(i).is_none_or(|&t| belief.found(t).is_none()))
            .collect()
    }

    /// What this decision plans for.
    fn wanted(&self, rows: &[usize]) -> Wanted {
        match (rows, self.goal) {
            ([one], _) => Wanted::One(self.p[*one].clone()),
            (_, Goal::Any) => {
                let n = self.p.iter().map(Vec::len).max().unwrap_or(0);
                Wanted::One(
                    (0..n)
                        .map(|c| {
                            let none = self
                                .p
                                .iter()
                                .map(|row| row.get(c).map_or(1.0, |p| 1.0 - p.get()))
                                .product::<f64>();
                            Probability::clamped(1.0 - none, 0.0, 1.0)
                        })
                        .collect(),
                )
            }
            (rows, Goal::All) => Wanted::Several(rows.to_vec()),
        }
    }

    /// The candidates for this decision under the configured limit.
    pub fn candidates(&self, belief: &Belief<'_>) -> Vec<usize> {
        let rows = self.wanted_rows(belief);
        let wanted = self.wanted(&rows);
        self.candidates_for(belief, &wanted)
    }

    /// The candidates while `wanted` is what the robot wants, ranked by the chance that a
    /// container holds something wanted (for several targets at once: any of them).
    fn candidates_for(&self, belief: &Belief<'_>, wanted: &Wanted) -> Vec<usize> {
        match wanted {
            Wanted::One(p) => {
                let score: Vec<f64> = p.iter().map(|p| p.get()).collect();
                self.candidates_by(belief, &score, planner::MAX_EXACT)
            }
            Wanted::Several(rows) => {
                let n = belief.house.containers.len();
                let score: Vec<f64> = (0..n)
                    .map(|c| {
                        let none: f64 = rows
                            .iter()
                            .map(|&r| 1.0 - self.p[r].get(c).map_or(0.0, |p| p.get()))
                            .product();
                        1.0 - none
                    })
                    .collect();
                self.candidates_by(belief, &score, task_table::max_candidates(rows.len()))
            }
        }
    }

    /// The candidates by `score` (the chance each container holds something wanted): every
    /// unsearched container with a chance, while they number at most the limit (and
    /// `largest`); beyond it the 2 nearest, then the likeliest.
    fn candidates_by(&self, belief: &Belief<'_>, score: &[f64], largest: usize) -> Vec<usize> {
        let at = |c: usize| score.get(c).copied().unwrap_or(0.0);
        let positive: Vec<usize> = belief.unsearched().filter(|&c| at(c) > 0.0).collect();
        if positive.is_empty() {
            // Every remaining container has p = 0: nothing to plan, fall back to the nearest.
            return nearest(belief, belief.unsearched()).into_iter().collect();
        }
        let k = match self.config.limit {
            CandidateLimit::Paper { k } => k.clamp(1, largest),
            CandidateLimit::Exact { max } => {
                let max = max.clamp(1, planner::MAX_EXACT.min(largest));
                if positive.len() <= max {
                    return positive;
                }
                max
            }
        };
        if positive.len() <= k {
            return positive;
        }
        let mut by_distance = positive.clone();
        by_distance.sort_by(|&a, &b| {
            belief
                .distance_to(a)
                .total_cmp(&belief.distance_to(b))
                .then(a.cmp(&b))
        });
        let mut chosen: Vec<usize> = by_distance.iter().copied().take(2.min(k)).collect();
        let mut by_score = positive;
        by_score.sort_by(|&a, &b| {
            at(b)
                .total_cmp(&at(a))
                .then(belief.distance_to(a).total_cmp(&belief.distance_to(b)))
                .then(a.cmp(&b))
        });
        for c in by_score {
            if chosen.len() >= k {
                break;
            }
            if !chosen.contains(&c) {
                chosen.push(c);
            }
        }
        chosen.sort_unstable();
        chosen
    }

    fn leg(&self, place: Place) -> f64 {
        self.destination.as_ref().map_or(0.0, |d| d.from(place))
    }

    fn problem(&self, belief: &Belief<'_>, candidates: &[usize], p: &[Probability]) -> TourProblem {
        let n = candidates.len();
        let d = belief.distances;
        let pc = |c: usize| p.get(c).copied().unwrap_or(Probability::ZERO);
        let from_robot: Vec<f64> = candidates.iter().map(|&c| belief.distance_to(c)).collect();
        let mut leg_extra = match self.config.cost {
            CostModel::Paper => Vec::new(),
            CostModel::Authors => candidates
                .iter()
                .zip(&from_robot)
                .map(|(&c, d)| pc(c).get() * d)
                .collect(),
        };
        let mut final_leg = Vec::new();
        if self.destination.is_some() {
            leg_extra.resize(n, 0.0);
            for (e, &c) in leg_extra.iter_mut().zip(candidates) {
                *e += pc(c).get() * self.leg(Place::Container(c));
            }
            final_leg = candidates
                .iter()
                .map(|&c| self.leg(Place::Container(c)))
                .collect();
        }
        TourProblem {
            from_robot,
            between: between(d, candidates),
            p: candidates.iter().map(|&c| pc(c)).collect(),
            search_cost: self.config.search_cost,
            leg_extra,
            final_leg,
        }
    }

    fn task_problem(
        &self,
        belief: &Belief<'_>,
        candidates: &[usize],
        rows: &[usize],
    ) -> TaskProblem {
        TaskProblem {
            from_robot: candidates.iter().map(|&c| belief.distance_to(c)).collect(),
            between: between(belief.distances, candidates),
            p: rows
                .iter()
                .map(|&r| {
                    candidates
                        .iter()
                        .map(|&c| self.p[r].get(c).copied().unwrap_or(Probability::ZERO))
                        .collect()
                })
                .collect(),
            search_cost: self.config.search_cost,
            to_destination: match self.destination {
                Some(_) => candidates
                    .iter()
                    .map(|&c| self.leg(Place::Container(c)))
                    .collect(),
                None => Vec::new(),
            },
        }
    }

    /// Reuses the cached solution when the same targets are wanted, the candidate set is
    /// unchanged except for containers searched since, and the robot stands at one of them
    /// (Bellman's principle: the best continuation of an optimal plan is a table lookup).
    fn cached_next(
        &mut self,
        belief: &Belief<'_>,
        candidates: &[usize],
        wanted: &[usize],
    ) -> Option<usize> {
        let cached = self.cached.as_mut()?;
        if cached.wanted != wanted {
            return None;
        }
        let mut searched = 0usize;
        for (i, &c) in cached.candidates.iter().enumerate() {
            if belief.is_searched(c) {
                searched |= 1 << i;
            } else if !candidates.contains(&c) {
                return None;
            }
        }
        if candidates.iter().any(|c| !cached.candidates.contains(c)) {
            return None;
        }
        let at = match belief.position() {
            Place::Container(c) => Some(cached.candidates.iter().position(|&x| x == c)?),
            Place::Start if searched == 0 => None,
            Place::Start => return None,
        };
        if at.is_some_and(|a| searched & (1 << a) == 0) {
            return None;
        }
        let next = match &mut cached.table {
            Table::Tour(problem, solution) => {
                // A first step taken from the memo: the table it came from, solved again (bit
                // for bit the same) now that the robot follows it.
                if solution.is_none() {
                    *solution = planner::solve_exact(problem).map(|(_, solution)| solution);
                }
                solution.as_ref()?.next(problem, searched, at)
            }
            // The same targets wanted: none was found since it was solved.
            Table::Task(problem, solution) => solution.next(problem, searched, 0, at),
        };
        next.map(|i| cached.candidates[i])
    }

    /// The first step over `candidates` while one target (or any of several) is wanted.
    fn choose_tour(
        &mut self,
        belief: &Belief<'_>,
        candidates: Vec<usize>,
        wanted: Vec<usize>,
        p: &[Probability],
    ) -> Result<usize, PlanError> {
        let problem = self.problem(belief, &candidates, p);
        // The authors' extra term and a destination's make the table depend on more than the
        // candidates' probabilities and the travel between them.
        let memo = self
            .memo
            .as_ref()
            .filter(|_| self.config.cost == CostModel::Paper && problem.final_leg.is_empty());
        if let Some(memo) = memo
            && let Some(steps) = memo.first_steps(&candidates, &problem)
            && let Some(first) = planner::first_from_steps(&problem, &steps)
        {
            let chosen = candidates[first];
            self.cached = Some(Cached {
                candidates,
                wanted,
                table: Table::Tour(problem, None),
            });
            return Ok(chosen);
        }
        let (plan, solution) = planner::solve_exact(&problem)
            .ok_or_else(|| too_many(candidates.len(), planner::MAX_EXACT))?;
        let first = plan
            .order
            .first()
            .map(|&i| candidates[i])
            .ok_or_else(|| no_container("model"))?;
        if let Some(memo) = memo {
            memo.keep(&candidates, &problem, &solution);
        }
        self.cached = Some(Cached {
            candidates,
            wanted,
            table: Table::Tour(problem, Some(solution)),
        });
        Ok(first)
    }

    /// The first step over `candidates` while the targets of `wanted` are all wanted.
    fn choose_task(
        &mut self,
        belief: &Belief<'_>,
        candidates: Vec<usize>,
        wanted: Vec<usize>,
    ) -> Result<usize, PlanError> {
        let problem = self.task_problem(belief, &candidates, &wanted);
        let solution = task_table::solve_task(&problem)
            .ok_or_else(|| too_many(candidates.len(), task_table::max_candidates(wanted.len())))?;
        let first = solution
            .next(&problem, 0, 0, None)
            .map(|i| candidates[i])
            .ok_or_else(|| no_container("model"))?;
        self.cached = Some(Cached {
            candidates,
            wanted,
            table: Table::Task(problem, solution),
        });
        Ok(first)
    }
}

fn too_many(candidates: usize, limit: usize) -> PlanError {
    PlanError::Policy {
        policy: "model".into(),
        error: format!("{candidates} candidates exceed the exact planner's limit of {limit}")
            .into(),
    }
}

/// Travel between `candidates`, row-major.
fn between(d: &ferret_world::Distances, candidates: &[usize]) -> Vec<f64> {
    let n = candidates.len();
    (0..n * n)
        .map(|k| {
            d.between(
                Place::Container(candidates[k / n]),
                Place::Container(candidates[k % n]),
            )
        })
        .collect()
}

impl Policy for Planner {
    fn choose(&mut self, belief: &Belief<'_>) -> Result<usize, PlanError> {
        let rows = self.wanted_rows(belief);
        let wanted = self.wanted(&rows);
        let candidates = self.candidates_for(belief, &wanted);
        if candidates.len() <= 1 {
            return candidates
                .first()
                .copied()
                .ok_or_else(|| no_container("model"));
        }
        // The authors' extra term is measured from where the robot stands now, so a plan made
        // elsewhere is not their continuation: replan at every decision.
        if self.config.cost == CostModel::Paper
            && let Some(c) = self.cached_next(belief, &candidates, &rows)
        {
            return Ok(c);
        }
        // The old table is no longer of use; dropped first, its memory serves the new solve.
        self.cached = None;
        match wanted {
            Wanted::One(p) => self.choose_tour(belief, candidates, rows, &p),
            Wanted::Several(several) => self.choose_task(belief, candidates, several),
        }
    }
}

/// The oracle: knows which containers hold the targets. For one target and no destination it
/// goes to the nearest container holding it; for a task it follows the cheapest route through
/// containers that make the goal hold, then to the destination ([`oracle_route`]). A lower
/// bound on cost, never a selectable strategy.
#[derive(Clone, Debug)]
pub struct Oracle {
    goals: Vec<usize>,
    /// The route to follow, for a task.
    route: Option<Vec<usize>>,
}

impl Oracle {
    /// An oracle for a trial whose goal containers are `goals`.
    pub fn new(goals: Vec<usize>) -> Self {
        Self { goals, route: None }
    }

    /// An oracle that follows `route` (see [`oracle_route`]).
    pub fn along(route: Vec<usize>) -> Self {
        Self {
            goals: Vec::new(),
            route: Some(route),
        }
    }
}

impl Policy for Oracle {
    fn choose(&mut self, belief: &Belief<'_>) -> Result<usize, PlanError> {
        if let Some(route) = &self.route
            && let Some(&c) = route.iter().find(|&&c| !belief.is_searched(c))
        {
            return Ok(c);
        }
        let open = self
            .goals
            .iter()
            .copied()
            .filter(|&g| !belief.is_searched(g));
        nearest(belief, open)
            .or_else(|| nearest(belief, belief.unsearched()))
            .ok_or_else(|| no_container("oracle"))
    }
}

/// The cheapest route from the robot's position through containers until the goal holds, then
/// to the destination: `holds[c]` is the bit set of the targets container `c` holds (task
/// order, at most [`MAX_TARGETS`](crate::MAX_TARGETS)), `goal` says which sets of found
/// targets end it. Exact: a shortest path over (targets found, last container), visiting only
/// containers that hold something new. Empty when no route makes the goal hold.
pub fn oracle_route(
    belief: &Belief<'_>,
    holds: &[u8],
    goal: Goal,
    destination: Option<&DestinationLegs>,
) -> Vec<usize> {
    let m = belief.task.targets().len();
    let done = |mask: u8| match goal {
        Goal::All => usize::from(mask) == (1 << m) - 1,
        Goal::Any => mask != 0,
    };
    let table = OracleTable::build(belief, holds, m, &done);
    let end = |s: usize| {
        table.cost[s] + destination.map_or(0.0, |g| g.from(Place::Container(table.container(s))))
    };
    let best = (0..table.cost.len())
        .filter(|&s| done(table.mask(s)) && table.cost[s].is_finite())
        .min_by(|&a, &b| end(a).total_cmp(&end(b)).then(a.cmp(&b)));
    best.map_or_else(Vec::new, |s| table.route(s))
}

/// The least travel from the robot's position to every state of a route through containers
/// holding targets: (targets found, the container it stands at), growing from those found by
/// a first container. What the oracle's routes are read from.
pub(crate) struct OracleTable {
    /// The unsearched containers holding some target.
    useful: Vec<usize>,
    /// Per state `mask·k + i`: least travel to stand at `useful[i]` having found `mask`.
    pub(crate) cost: Vec<f64>,
    parent: Vec<usize>,
}

impl OracleTable {
    /// The table of routes from the belief's position; `holds[c]` the bit set of the targets
    /// (of `m`) container `c` holds. Routes end at a mask `stop` accepts (they grow no further).
    pub(crate) fn build(
        belief: &Belief<'_>,
        holds: &[u8],
        m: usize,
        stop: &dyn Fn(u8) -> bool,
    ) -> Self {
        let useful: Vec<usize> = belief
            .unsearched()
            .filter(|&c| holds.get(c).is_some_and(|&h| h != 0))
            .collect();
        let k = useful.len();
        let states = (1usize << m) * k;
        let mut cost = vec![f64::INFINITY; states];
        let mut parent = vec![usize::MAX; states];
        let at = |mask: u8, i: usize| usize::from(mask) * k + i;
        for (i, &c) in useful.iter().enumerate() {
            let s = at(holds[c], i);
            let d = belief.distance_to(c);
            if d < cost[s] {
                cost[s] = d;
            }
        }
        // Masks only grow along a route, so increasing masks are settled in order.
        for mask in 1..(1u8 << m) {
            if stop(mask) {
                continue;
            }
            for (i, &c) in useful.iter().enumerate() {
                let here = cost[at(mask, i)];
                if !here.is_finite() {
                    continue;
                }
                for (j, &d) in useful.iter().enumerate() {
                    let next = mask | holds[d];
                    if next == mask {
                        continue;
                    }
                    let v = here
                        + belief
                            .distances
                            .between(Place::Container(c), Place::Container(d));
                    if v < cost[at(next, j)] {
                        cost[at(next, j)] = v;
                        parent[at(next, j)] = at(mask, i);
                    }
                }
            }
        }
        Self {
            useful,
            cost,
            parent,
        }
    }

    /// The targets found in state `s`.
    pub(crate) fn mask(&self, s: usize) -> u8 {
        // At most MAX_TARGETS bits: the quotient fits.
        (s / self.useful.len().max(1)) as u8
    }

    /// The container the robot stands at in state `s`.
    pub(crate) fn container(&self, s: usize) -> usize {
        self.useful[s % self.useful.len()]
    }

    /// The containers of the route that ends in state `s`, in order.
    pub(crate) fn route(&self, s: usize) -> Vec<usize> {
        let mut route = Vec::new();
        let mut s = s;
        while s != usize::MAX {
            route.push(self.container(s));
            s = self.parent[s];
        }
        route.reverse();
        route
    }
}

/// One search after another: the single-target planner looks for the task's first target not
/// yet found, without a thought for the others or the destination, remembering what was
/// searched and seen (a target seen meanwhile is found). The baseline a task planner must beat.
#[derive(Debug)]
pub struct Sequential {
    /// One single-target planner per target of the task, in task order.
    planners: Vec<Planner>,
}

impl Sequential {
    /// Looks for target `t` of the task with probabilities `p[t]`, one after another.
    pub fn new(p: Vec<Vec<Probability>>, config: PlannerConfig) -> Self {
        Self {
            planners: p
                .into_iter()
                .enumerate()
                .map(|(t, row)| Planner::for_targets(vec![row], vec![t], Goal::All, None, config))
                .collect(),
        }
    }

    /// The same, the planners sharing `memo`.
    pub fn with_memo(self, memo: Option<Arc<PlanMemo>>) -> Self {
        Self {
            planners: self
                .planners
                .into_iter()
                .map(|p| p.with_memo(memo.clone()))
                .collect(),
        }
    }
}

impl Policy for Sequential {
    fn choose(&mut self, belief: &Belief<'_>) -> Result<usize, PlanError> {
        let t = (0..self.planners.len())
            .find(|&t| belief.found(t).is_none())
            .unwrap_or(0);
        self.planners
            .get_mut(t)
            .ok_or_else(|| no_container("sequential"))?
            .choose(belief)
    }
}
