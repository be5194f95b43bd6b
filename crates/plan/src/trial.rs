//! Trials: drawing a target (or a task of several) for a house, and the simulator that runs a
//! strategy until the task's goal holds (on a [`SearchProblem`]).

use ferret_world::{Distances, GroundTruth, House, ObjectType, Place, Point, TravelCost};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::belief::Belief;
use crate::error::PlanError;
use crate::policy::Policy;
use crate::problem::{SearchProblem, TrialSpec};
use crate::protocol::{InitialBelief, Protocol, TargetSet, TrialRng};
use crate::pyrandom::PyRandom;
use crate::strategy::{Strategy, TrialContext};
use crate::task::{DestinationLegs, Goal, Task};

/// A deterministic RNG for house `index` under `seed`, independent of thread scheduling.
fn house_rng(seed: u64, index: usize, stream: u64) -> ChaCha8Rng {
    let mut rng =
        ChaCha8Rng::seed_from_u64(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.set_stream(stream);
    rng
}

/// Draws a trial for a house: the target uniformly among the small-object types present in its
/// containers; with `reveal_fraction > 0`, that fraction of the containers that do not hold the
/// target start out searched (some variants of the experiment do this).
pub fn draw_trial(
    house: &House,
    truth: &GroundTruth,
    seed: u64,
    reveal_fraction: f64,
) -> Result<TrialSpec, PlanError> {
    let types: Vec<ObjectType> = truth.target_types().into_iter().collect();
    if types.is_empty() {
        return Err(PlanError::NoTarget {
            house: house.name.clone(),
        });
    }
    let mut rng = house_rng(seed, house.index, 1);
    let target = types[rng.random_range(0..types.len())].clone();
    let revealed = reveal(
        house,
        truth,
        std::slice::from_ref(&target),
        reveal_fraction,
        &mut rng,
    );
    Ok(TrialSpec {
        task: Task::single(target),
        revealed,
    })
}

/// The containers that start out searched: `reveal_fraction` of those holding none of
/// `targets`.
fn reveal(
    house: &House,
    truth: &GroundTruth,
    targets: &[ObjectType],
    reveal_fraction: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<usize> {
    let mut revealed = Vec::new();
    if reveal_fraction > 0.0 {
        let empty: Vec<usize> = (0..house.containers.len())
            .filter(|&c| !targets.iter().any(|t| truth.holds(c, t)))
            .collect();
        let k = ((empty.len() as f64) * reveal_fraction.clamp(0.0, 1.0)).round() as usize;
        let mut pool = empty;
        for _ in 0..k.min(pool.len()) {
            let i = rng.random_range(0..pool.len());
            revealed.push(pool.swap_remove(i));
        }
        revealed.sort_unstable();
    }
    revealed
}

/// How many trials (distinct targets) to run per house.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrialsPerHouse {
    /// One target drawn per house: [`draw_trial`], the paper's protocol and ferret's default.
    #[default]
    One,
    /// Up to this many distinct targets per house (every target type when the house has fewer).
    Count(usize),
    /// Every target type present in the house, once each.
    All,
}

impl std::str::FromStr for TrialsPerHouse {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "all" => Ok(Self::All),
            n => match n.parse::<usize>() {
                Ok(0) => Err("must be at least 1, or `all`".into()),
                Ok(1) => Ok(Self::One),
                Ok(n) => Ok(Self::Count(n)),
                Err(_) => Err(format!("`{s}`: expected a number ≥ 1 or `all`")),
            },
        }
    }
}

impl std::fmt::Display for TrialsPerHouse {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::One => write!(f, "1"),
            Self::Count(n) => write!(f, "{n}"),
            Self::All => write!(f, "all"),
        }
    }
}

/// Draws the trials of a house, each with a distinct target. [`TrialsPerHouse::One`] is exactly
/// [`draw_trial`]. Otherwise the target types are shuffled by a generator of the house and
/// `seed` (a stream of its own, so the single-trial draw is untouched) and the first `n` kept —
/// the first of them is not necessarily [`draw_trial`]'s target; `All` keeps every type in name
/// order. Each trial's revealed containers are drawn as in [`draw_trial`].
pub fn draw_trials(
    house: &House,
    truth: &GroundTruth,
    seed: u64,
    reveal_fraction: f64,
    per_house: TrialsPerHouse,
) -> Result<Vec<TrialSpec>, PlanError> {
    draw_trials_with(
        house,
        truth,
        seed,
        reveal_fraction,
        per_house,
        &Protocol::FERRET,
    )
}

/// [`draw_trials`] under a protocol's target set, initial belief and random draws. Under
/// ferret's protocol it is exactly [`draw_trials`].
///
/// The paper's target set leaves out types that are also top-level objects of the house
/// (containers or other furniture). The paper's initial belief keeps unsearched `m` containers
/// drawn from all `n` of the house, `m` uniform in `⌊n/2⌋ … n − 1` (at least `min(n, 2)`), plus
/// every goal container; the rest start out searched (besides any `reveal_fraction`).
///
/// With [`TrialRng::Python`] the draws are the reference code's: CPython's `random` seeded with
/// [`python_seed`], afresh for the target (`sample` of the distinct target types in the order
/// the house lists its objects) and afresh for the unsearched containers (`randint` for `m`,
/// then `sample`). Several trials per house draw their targets from ferret's stream and all
/// share the house's one unsearched draw, which does not depend on the target.
pub fn draw_trials_with(
    house: &House,
    truth: &GroundTruth,
    seed: u64,
    reveal_fraction: f64,
    per_house: TrialsPerHouse,
    protocol: &Protocol,
) -> Result<Vec<TrialSpec>, PlanError> {
    let furniture: std::collections::BTreeSet<&ObjectType> = house
        .containers
        .iter()
        .map(|c| &c.object_type)
        .chain(house.obstacles.iter().map(|o| &o.object_type))
        .collect();
    let allowed =
        |t: &ObjectType| protocol.targets == TargetSet::Pickupable || !furniture.contains(t);
    let mut trials = if protocol.rng == TrialRng::Python && per_house == TrialsPerHouse::One {
        let types = types_in_house_order(truth, &allowed);
        if types.is_empty() {
            return Err(PlanError::NoTarget {
                house: house.name.clone(),
            });
        }
        let mut py = PyRandom::new(python_seed(house.index, seed));
        let target = types[py.sample(types.len(), 1)[0]].clone();
        let revealed = reveal(
            house,
            truth,
            std::slice::from_ref(&target),
            reveal_fraction,
            &mut house_rng(seed, house.index, 1),
        );
        vec![TrialSpec {
            task: Task::single(target),
            revealed,
        }]
    } else {
        let types = allowed_types(house, truth, protocol);
        draw_targets(house, types, truth, seed, reveal_fraction, per_house)?
    };
    paper_initial_belief(house, truth, seed, protocol, &mut trials);
    Ok(trials)
}

/// The target types a trial of `house` may ask for under `protocol`, in name order.
fn allowed_types(house: &House, truth: &GroundTruth, protocol: &Protocol) -> Vec<ObjectType> {
    let furniture: std::collections::BTreeSet<&ObjectType> = house
        .containers
        .iter()
        .map(|c| &c.object_type)
        .chain(house.obstacles.iter().map(|o| &o.object_type))
        .collect();
    truth
        .target_types()
        .into_iter()
        .filter(|t| protocol.targets == TargetSet::Pickupable || !furniture.contains(t))
        .collect()
}

/// Under the paper's initial belief, reveals the containers each trial starts with searched
/// (see [`draw_trials_with`]); nothing under ferret's.
fn paper_initial_belief(
    house: &House,
    truth: &GroundTruth,
    seed: u64,
    protocol: &Protocol,
    trials: &mut [TrialSpec],
) {
    if protocol.initial_belief == InitialBelief::Paper {
        let n = house.containers.len();
        let mut rng = house_rng(seed, house.index, 4);
        for t in trials.iter_mut() {
            let unsearched = match protocol.rng {
                TrialRng::Python => {
                    let mut py = PyRandom::new(python_seed(house.index, seed));
                    let m = (py.randint((n / 2) as u64, n.saturating_sub(1) as u64) as usize)
                        .max(n.min(2));
                    py.sample(n, m)
                }
                TrialRng::Ferret => {
                    let m = if n == 0 {
                        0
                    } else {
                        rng.random_range(n / 2..n).max(n.min(2))
                    };
                    rand::seq::index::sample(&mut rng, n, m).into_vec()
                }
            };
            let mut keep = vec![false; n];
            let goals = t
                .task
                .targets()
                .iter()
                .flat_map(|target| truth.goal_containers(target));
            for c in unsearched.into_iter().chain(goals) {
                if let Some(k) = keep.get_mut(c) {
                    *k = true;
                }
            }
            t.revealed.extend((0..n).filter(|&c| !keep[c]));
            t.revealed.sort_unstable();
            t.revealed.dedup();
        }
    }
}

/// The shape of the tasks a run draws: how many targets each asks for, and whether all of them
/// or any one.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct TaskShape {
    /// All of the targets, or any one.
    pub goal: Goal,
    /// Targets per task, 1 to [`MAX_TARGETS`](crate::MAX_TARGETS).
    pub targets: usize,
}

impl std::str::FromStr for TaskShape {
    type Err = crate::task::TaskError;

    /// `all:<N>` or `any:<N>`.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let err = |m: String| crate::task::TaskError::new("targets", m);
        let (goal, n) = s
            .split_once(':')
            .ok_or_else(|| err(format!("`{s}`: expected `all:<N>` or `any:<N>`")))?;
        let goal = goal.parse()?;
        let targets: usize = n
            .trim()
            .parse()
            .map_err(|_| err(format!("`{n}` is not a number of targets")))?;
        if !(1..=crate::task::MAX_TARGETS).contains(&targets) {
            return Err(err(format!(
                "{targets} targets: a task asks for 1 to {}",
                crate::task::MAX_TARGETS
            )));
        }
        Ok(Self { goal, targets })
    }
}

impl std::fmt::Display for TaskShape {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}:{}", self.goal, self.targets)
    }
}

/// Draws the tasks of a house: each asks for `shape.targets` distinct types present in the
/// house (those `protocol` allows), drawn uniformly and kept in the order drawn, with no
/// destination; a house draws `per_house` tasks, each of another set of targets. Revealed
/// containers hold none of a task's targets. A stream of its own, so the single-target draws
/// are untouched.
///
/// # Errors
/// [`PlanError::TooFewTargets`] for a house with fewer types than a task asks for (or fewer
/// sets of them than `per_house` tasks), [`PlanError::NoTarget`] for one with none; `per_house`
/// `all` is refused (every set of targets would be too many trials).
pub fn draw_tasks(
    (house, truth): (&House, &GroundTruth),
    seed: u64,
    reveal_fraction: f64,
    per_house: TrialsPerHouse,
    protocol: &Protocol,
    shape: TaskShape,
) -> Result<Vec<TrialSpec>, PlanError> {
    let types = allowed_types(house, truth, protocol);
    if types.is_empty() {
        return Err(PlanError::NoTarget {
            house: house.name.clone(),
        });
    }
    let count = match per_house {
        TrialsPerHouse::One => 1,
        TrialsPerHouse::Count(n) => n,
        TrialsPerHouse::All => {
            return Err(PlanError::Task(crate::task::TaskError::new(
                "trials per house",
                "`all` draws every target type once; with tasks give a number of tasks per house",
            )));
        }
    };
    let possible = binomial(types.len(), shape.targets);
    if types.len() < shape.targets || possible < count as u128 {
        return Err(PlanError::TooFewTargets {
            house: house.name.clone(),
            have: types.len(),
            want: shape.targets,
            tasks: count,
        });
    }
    let mut rng = house_rng(seed, house.index, 5);
    let mut trials: Vec<TrialSpec> = Vec::with_capacity(count);
    let mut sets: Vec<Vec<ObjectType>> = Vec::new();
    while trials.len() < count {
        let picked: Vec<ObjectType> =
            rand::seq::index::sample(&mut rng, types.len(), shape.targets)
                .into_iter()
                .map(|i| types[i].clone())
                .collect();
        let mut set = picked.clone();
        set.sort();
        if sets.contains(&set) {
            continue;
        }
        sets.push(set);
        let revealed = reveal(house, truth, &picked, reveal_fraction, &mut rng);
        let task = Task::new(picked, shape.goal, None)?;
        trials.push(TrialSpec { task, revealed });
    }
    paper_initial_belief(house, truth, seed, protocol, &mut trials);
    Ok(trials)
}

/// n choose k, saturating.
fn binomial(n: usize, k: usize) -> u128 {
    if k > n {
        return 0;
    }
    (0..k).fold(1u128, |acc, i| {
        acc.saturating_mul((n - i) as u128) / (i as u128 + 1)
    })
}

/// The seed of CPython's `random` for house `index` under trial seed `seed`: the house's index
/// itself for seed 0 (the reference seeds with the house's line index in its file), and for
/// other seeds the index with the seed in the high 32 bits, so that no two (house, seed) pairs
/// share a seed.
pub fn python_seed(index: usize, seed: u64) -> u64 {
    (index as u64).wrapping_add(seed.wrapping_shl(32))
}

/// The distinct types of the containers' contents that `allowed` admits, in the order the house
/// lists them (container by container, each one's objects in order): the order of the
/// reference's scene graph, which fixes what an index drawn into it means.
fn types_in_house_order(
    truth: &GroundTruth,
    allowed: &dyn Fn(&ObjectType) -> bool,
) -> Vec<ObjectType> {
    let mut seen = std::collections::HashSet::new();
    let mut types = Vec::new();
    for c in 0..truth.container_count() {
        for o in truth.contents(c) {
            if allowed(&o.object_type) && seen.insert(&o.object_type) {
                types.push(o.object_type.clone());
            }
        }
    }
    types
}

/// The trials of a house among target `types` (in name order).
fn draw_targets(
    house: &House,
    mut types: Vec<ObjectType>,
    truth: &GroundTruth,
    seed: u64,
    reveal_fraction: f64,
    per_house: TrialsPerHouse,
) -> Result<Vec<TrialSpec>, PlanError> {
    if types.is_empty() {
        return Err(PlanError::NoTarget {
            house: house.name.clone(),
        });
    }
    let n = match per_house {
        TrialsPerHouse::One => {
            // The same stream and draws as `draw_trial`.
            let mut rng = house_rng(seed, house.index, 1);
            let target = types[rng.random_range(0..types.len())].clone();
            let revealed = reveal(
                house,
                truth,
                std::slice::from_ref(&target),
                reveal_fraction,
                &mut rng,
            );
            return Ok(vec![TrialSpec {
                task: Task::single(target),
                revealed,
            }]);
        }
        TrialsPerHouse::Count(n) => n,
        TrialsPerHouse::All => types.len(),
    };
    let mut rng = house_rng(seed, house.index, 2);
    if per_house != TrialsPerHouse::All {
        rand::seq::SliceRandom::shuffle(types.as_mut_slice(), &mut rng);
        types.truncate(n);
    }
    Ok(types
        .into_iter()
        .map(|target| {
            let revealed = reveal(
                house,
                truth,
                std::slice::from_ref(&target),
                reveal_fraction,
                &mut rng,
            );
            TrialSpec {
                task: Task::single(target),
                revealed,
            }
        })
        .collect())
}

/// What happened in a trial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialOutcome {
    /// The strategy's name.
    pub strategy: String,
    /// What was asked.
    pub task: Task,
    /// Distance travelled until the goal held (or everything was searched) and, with a
    /// destination, the robot stood there; metres.
    pub cost: f64,
    /// Containers searched, in order.
    pub searched: Vec<usize>,
    /// The container where the goal came to hold (for one target: where it was found); `None`
    /// when it never held.
    pub found: Option<usize>,
    /// Where each target (task order) was first seen.
    pub found_each: Vec<Option<usize>>,
    /// The last leg, to the destination, metres (0 without one); part of `cost`.
    pub delivery: f64,
    /// The destination, when it is a place of the map (the start, a container).
    pub delivered_to: Option<Place>,
}

impl TrialOutcome {
    /// The places visited, from the start (and the destination, when it is a place).
    pub fn places(&self) -> Vec<Place> {
        std::iter::once(Place::Start)
            .chain(self.searched.iter().map(|&c| Place::Container(c)))
            .chain(self.delivered_to)
            .collect()
    }

    /// The cost to report for this trial, metres: [`cost`](Self::cost) itself for
    /// [`TravelCost::Plain`], the soft cost of its visits for [`TravelCost::Soft`] (the
    /// reference code's reported metric; the strategy still decided on plain distances).
    ///
    /// # Errors
    /// [`PlanError::TravelCost`] for the soft cost on distances that came from no grid, a
    /// destination that is no place of the map, or a trajectory with a leg the soft cost cannot
    /// travel.
    pub fn reported_cost(
        &self,
        house: &House,
        distances: &Distances,
        travel: TravelCost,
    ) -> Result<f64, PlanError> {
        if travel == TravelCost::Plain {
            return Ok(self.cost);
        }
        let err = |message: &str| PlanError::TravelCost {
            house: house.name.clone(),
            message: message.to_owned(),
        };
        if self.task.destination().is_some() && self.delivered_to.is_none() {
            return Err(err(
                "the soft travel cost measures legs between places of the map; a destination in a room or at a point is not one",
            ));
        }
        let cost = distances
            .travel_cost(&self.places(), travel)
            .ok_or_else(|| err("the soft travel cost needs distances measured on a grid"))?;
        if cost.is_finite() {
            Ok(cost)
        } else {
            Err(err(
                "a leg of the trial has no path under the soft travel cost",
            ))
        }
    }

    /// The trajectory on the floor (the cells walked), when the distances came from a grid;
    /// with the task's destination `legs`, the way there too.
    pub fn trajectory(
        &self,
        distances: &Distances,
        legs: Option<&DestinationLegs>,
    ) -> Option<Vec<Point>> {
        let mut points = Vec::new();
        let visits: Vec<Place> = std::iter::once(Place::Start)
            .chain(self.searched.iter().map(|&c| Place::Container(c)))
            .collect();
        for leg in visits.windows(2) {
            points.extend(distances.path(leg[0], leg[1])?);
        }
        if let Some(legs) = legs.filter(|_| self.task.destination().is_some()) {
            let last = visits.last().copied().unwrap_or(Place::Start);
            points.extend(legs.path(distances, last)?);
        }
        Some(points)
    }
}

/// One trial in progress, one search at a time: what a robot loop drives (ask for the next
/// container, go there, report what was seen, and at the end go to the destination). The
/// simulator [`run_trial`] is this loop with the ground truth answering, so a robot and a
/// simulation cannot plan differently.
pub struct Search<'a> {
    strategy: &'a dyn Strategy,
    policy: Box<dyn Policy + 'a>,
    belief: Belief<'a>,
    /// The task's destination on this map.
    destination: Option<std::borrow::Cow<'a, DestinationLegs>>,
    /// The last leg, once the robot went to the destination.
    delivered: Option<f64>,
}

impl<'a> Search<'a> {
    /// Starts `strategy` on `problem` from the house's start. `truth` is read only by strategies
    /// that declare [`needs_ground_truth`](Strategy::needs_ground_truth) (the oracle), which fail
    /// without it, and for what the containers searched beforehand (`problem.trial.revealed`)
    /// held; a robot, which has no ground truth, starts with none searched.
    ///
    /// # Errors
    /// The strategy's own failures, and a destination the map cannot serve.
    pub fn start(
        strategy: &'a dyn Strategy,
        problem: &SearchProblem<'a>,
        truth: Option<&'a GroundTruth>,
    ) -> Result<Self, PlanError> {
        let unusable = |why| PlanError::BadChoice {
            policy: strategy.name().into(),
            container: 0,
            why,
        };
        let ctx = TrialContext {
            problem: *problem,
            truth: if strategy.needs_ground_truth() {
                Some(truth.ok_or_else(|| {
                    unusable("unusable: the strategy needs the ground truth and none is known")
                })?)
            } else {
                None
            },
        };
        let destination = problem.destination_legs()?;
        let policy = strategy.policy(&ctx)?;
        let mut belief = Belief::new(problem.house, problem.distances, problem.task());
        if !problem.trial.revealed.is_empty() {
            let truth = truth.ok_or_else(|| {
                unusable("unusable: containers searched beforehand need the ground truth")
            })?;
            for &c in &problem.trial.revealed {
                belief.reveal(c, contents_of(truth, c));
            }
        }
        Ok(Self {
            strategy,
            policy,
            belief,
            destination,
            delivered: None,
        })
    }

    /// The container to search next, or `None` when the task's goal holds, every container
    /// has been searched, or the robot went to the destination.
    ///
    /// # Errors
    /// The policy's own failures, and a choice of a container that does not exist or was
    /// already searched.
    pub fn next_container(&mut self) -> Result<Option<usize>, PlanError> {
        if self.belief.unsearched_count() == 0
            || self.belief.goal_holds()
            || self.delivered.is_some()
        {
            return Ok(None);
        }
        let c = self.policy.choose(&self.belief)?;
        self.check(c)?;
        Ok(Some(c))
    }

    /// Records that container `c` was searched and held `seen`; returns the distance of the leg
    /// on the map, metres. The robot may search another container than the one proposed.
    ///
    /// # Errors
    /// [`PlanError::BadChoice`] for a container that does not exist or was already searched.
    pub fn record(&mut self, c: usize, seen: Vec<ObjectType>) -> Result<f64, PlanError> {
        self.check(c)?;
        Ok(self.belief.search(c, seen))
    }

    /// The container to search next while teammates are heading to `others`: chosen as if
    /// they were searched in vain (this robot's plan only matters where they hold nothing) and
    /// never one of them. `None` as [`next_container`](Self::next_container) says, and when
    /// every container left is one of `others`. With no `others` it is `next_container`.
    ///
    /// # Errors
    /// As [`next_container`](Self::next_container).
    pub fn next_container_leaving(&mut self, others: &[usize]) -> Result<Option<usize>, PlanError> {
        if others.is_empty() {
            return self.next_container();
        }
        if self.belief.goal_holds() || self.delivered.is_some() {
            return Ok(None);
        }
        let mut view = self.belief.clone();
        for &c in others {
            if c < view.house.containers.len() && !view.is_searched(c) {
                view.reveal(c, Vec::new());
            }
        }
        if view.unsearched_count() == 0 {
            return Ok(None);
        }
        let c = self.policy.choose(&view)?;
        self.check(c)?;
        if others.contains(&c) {
            return Err(PlanError::BadChoice {
                policy: self.strategy.name().into(),
                container: c,
                why: "claimed by another robot",
            });
        }
        Ok(Some(c))
    }

    /// Records that a teammate searched container `c` and saw `seen` there: known at once,
    /// without this robot moving.
    ///
    /// # Errors
    /// [`PlanError::BadChoice`] for a container that does not exist or was already searched.
    pub fn observe(&mut self, c: usize, seen: Vec<ObjectType>) -> Result<(), PlanError> {
        self.check(c)?;
        self.belief.reveal(c, seen);
        Ok(())
    }

    /// The robot drives to `c`, which was searched already (by a teammate, while it was on its
    /// way), learning nothing; returns the leg, metres.
    pub fn visit(&mut self, c: usize) -> f64 {
        self.belief.visit(c)
    }

    /// True once the task's goal holds (for one target: it was found).
    pub fn goal_holds(&self) -> bool {
        self.belief.goal_holds()
    }

    /// Ends the search: the robot goes from where it stands to the task's destination (the leg
    /// is added to the distance travelled) and searches no more. Returns that leg, metres: 0
    /// without a destination, and the same leg again when called twice.
    pub fn finish(&mut self) -> f64 {
        if let Some(leg) = self.delivered {
            return leg;
        }
        let leg = self
            .destination
            .as_ref()
            .map_or(0.0, |d| d.from(self.belief.position()));
        if self.destination.is_some() {
            self.belief.arrive(leg);
        }
        self.delivered = Some(leg);
        leg
    }

    /// The task's destination on this map, if it has one.
    pub fn destination(&self) -> Option<&DestinationLegs> {
        self.destination.as_deref()
    }

    /// What is known so far.
    pub fn belief(&self) -> &Belief<'a> {
        &self.belief
    }

    /// The container where the goal came to hold: where the target that completed it (`all`)
    /// or the first target (`any`) was found. `None` while it does not hold.
    pub fn goal_container(&self) -> Option<usize> {
        let b = &self.belief;
        if !b.goal_holds() {
            return None;
        }
        let found: Vec<usize> = b.found_each().iter().flatten().copied().collect();
        let rank = |c: &usize| b.searched_in_order().iter().position(|x| x == c);
        match b.task.goal() {
            Goal::All => found.iter().copied().max_by_key(rank),
            Goal::Any => found.iter().copied().min_by_key(rank),
        }
    }

    fn check(&self, c: usize) -> Result<(), PlanError> {
        let why = if c >= self.belief.house.containers.len() {
            "not in the house"
        } else if self.belief.is_searched(c) {
            "already searched"
        } else {
            return Ok(());
        };
        Err(PlanError::BadChoice {
            policy: self.strategy.name().into(),
            container: c,
            why,
        })
    }
}

/// Runs `strategy` on one trial: replans after every search until the task's goal holds (for
/// one target: a container holding it is searched) or none is left, then goes to the
/// destination.
pub fn run_trial(
    strategy: &dyn Strategy,
    problem: &SearchProblem<'_>,
    truth: &GroundTruth,
) -> Result<TrialOutcome, PlanError> {
    let mut search = Search::start(strategy, problem, Some(truth))?;
    while let Some(c) = search.next_container()? {
        search.record(c, contents_of(truth, c))?;
    }
    let delivery = search.finish();
    let found = search.goal_container();
    let delivered_to = search.destination().and_then(DestinationLegs::place);
    let belief = search.belief();
    Ok(TrialOutcome {
        strategy: strategy.name().to_string(),
        task: problem.trial.task.clone(),
        cost: belief.travelled(),
        searched: belief.searched_in_order().to_vec(),
        found,
        found_each: belief.found_each().to_vec(),
        delivery,
        delivered_to,
    })
}

pub(crate) fn contents_of(truth: &GroundTruth, c: usize) -> Vec<ObjectType> {
    truth
        .contents(c)
        .iter()
        .map(|o| o.object_type.clone())
        .collect()
}
