//! Policies: map a belief to the next container to search.

use std::sync::Arc;

use ferret_world::Place;

use crate::belief::Belief;
use crate::error::PlanError;
use crate::plan_memo::PlanMemo;
use crate::planner::{self, Solution, TourProblem};
use crate::probability::Probability;

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
/// (paper eq. 3) over the candidates, given each container's probability.
#[derive(Debug)]
pub struct Planner {
    p: Vec<Probability>,
    config: PlannerConfig,
    /// A full solution over a candidate set, reused while the robot follows it.
    cached: Option<Cached>,
    /// First steps of tables other searches of this house solved.
    memo: Option<Arc<PlanMemo>>,
}

#[derive(Debug)]
struct Cached {
    candidates: Vec<usize>,
    problem: TourProblem,
    /// `None` while the decision came from the memo: solved when the robot follows it further.
    solution: Option<Solution>,
}

impl Planner {
    /// A planner over fixed per-container probabilities (index-aligned with the house's containers).
    pub fn new(p: Vec<Probability>, config: PlannerConfig) -> Self {
        Self {
            p,
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

    /// The candidates for this decision under the configured limit.
    pub fn candidates(&self, belief: &Belief<'_>) -> Vec<usize> {
        let positive: Vec<usize> = belief.unsearched().filter(|&c| self.p(c) > 0.0).collect();
        if positive.is_empty() {
            // Every remaining container has p = 0: nothing to plan, fall back to the nearest.
            return nearest(belief, belief.unsearched()).into_iter().collect();
        }
        let k = match self.config.limit {
            CandidateLimit::Paper { k } => k.max(1),
            CandidateLimit::Exact { max } => {
                let max = max.clamp(1, planner::MAX_EXACT);
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
        let mut by_p = positive;
        by_p.sort_by(|&a, &b| {
            self.p(b)
                .total_cmp(&self.p(a))
                .then(belief.distance_to(a).total_cmp(&belief.distance_to(b)))
                .then(a.cmp(&b))
        });
        for c in by_p {
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

    fn p(&self, c: usize) -> f64 {
        self.p.get(c).map_or(0.0, |p| p.get())
    }

    fn problem(&self, belief: &Belief<'_>, candidates: &[usize]) -> TourProblem {
        let n = candidates.len();
        let d = belief.distances;
        let from_robot: Vec<f64> = candidates.iter().map(|&c| belief.distance_to(c)).collect();
        let leg_extra = match self.config.cost {
            CostModel::Paper => Vec::new(),
            CostModel::Authors => candidates
                .iter()
                .zip(&from_robot)
                .map(|(&c, d)| self.p(c) * d)
                .collect(),
        };
        TourProblem {
            from_robot,
            between: (0..n * n)
                .map(|k| {
                    d.between(
                        Place::Container(candidates[k / n]),
                        Place::Container(candidates[k % n]),
                    )
                })
                .collect(),
            p: candidates
                .iter()
                .map(|&c| self.p.get(c).copied().unwrap_or(Probability::ZERO))
                .collect(),
            search_cost: self.config.search_cost,
            leg_extra,
        }
    }

    /// Reuses the cached solution when the candidate set is unchanged except for containers
    /// searched since, and the robot stands at one of them (Bellman's principle: the best
    /// continuation of an optimal plan is a table lookup).
    fn cached_next(&mut self, belief: &Belief<'_>, candidates: &[usize]) -> Option<usize> {
        let cached = self.cached.as_mut()?;
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
        // A first step taken from the memo: the table it came from, solved again (bit for bit
        // the same) now that the robot follows it.
        if cached.solution.is_none() {
            cached.solution = planner::solve_exact(&cached.problem).map(|(_, solution)| solution);
        }
        cached
            .solution
            .as_ref()?
            .next(&cached.problem, searched, at)
            .map(|i| cached.candidates[i])
    }
}

impl Policy for Planner {
    fn choose(&mut self, belief: &Belief<'_>) -> Result<usize, PlanError> {
        let candidates = self.candidates(belief);
        if candidates.len() <= 1 {
            return candidates
                .first()
                .copied()
                .ok_or_else(|| no_container("model"));
        }
        // The authors' extra term is measured from where the robot stands now, so a plan made
        // elsewhere is not their continuation: replan at every decision.
        if self.config.cost == CostModel::Paper
            && let Some(c) = self.cached_next(belief, &candidates)
        {
            return Ok(c);
        }
        // The old table is no longer of use; dropped first, its memory serves the new solve.
        self.cached = None;
        let problem = self.problem(belief, &candidates);
        // The authors' extra term makes the table depend on where the robot stands.
        let memo = self
            .memo
            .as_ref()
            .filter(|_| self.config.cost == CostModel::Paper);
        if let Some(memo) = memo
            && let Some(steps) = memo.first_steps(&candidates, &problem)
            && let Some(first) = planner::first_from_steps(&problem, &steps)
        {
            let chosen = candidates[first];
            self.cached = Some(Cached {
                candidates,
                problem,
                solution: None,
            });
            return Ok(chosen);
        }
        let (plan, solution) = planner::solve_exact(&problem).ok_or_else(|| PlanError::Policy {
            policy: "model".into(),
            error: format!(
                "{} candidates exceed the exact planner's limit of {}",
                candidates.len(),
                planner::MAX_EXACT
            )
            .into(),
        })?;
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
            problem,
            solution: Some(solution),
        });
        Ok(first)
    }
}

/// The oracle: knows which containers hold the target and goes to the nearest of them. A lower
/// bound on cost, never a selectable strategy.
#[derive(Clone, Debug)]
pub struct Oracle {
    goals: Vec<usize>,
}

impl Oracle {
    /// An oracle for a trial whose goal containers are `goals`.
    pub fn new(goals: Vec<usize>) -> Self {
        Self { goals }
    }
}

impl Policy for Oracle {
    fn choose(&mut self, belief: &Belief<'_>) -> Result<usize, PlanError> {
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
