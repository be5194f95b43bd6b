//! Offline replay (paper section V-C): what would another strategy have cost on a finished trial?
//!
//! The pessimistic hindsight belief: the target is only in the container where it was actually
//! found; containers searched in the trial are known (and held nothing else of use); every other
//! container is assumed empty. The replay reuses [`run_trial`] and the strategies' own policies,
//! so a replay cannot drift from a real run.

use std::collections::HashMap;
use std::sync::Mutex;
use std::sync::atomic::{AtomicU64, Ordering};

use ferret_world::{GroundTruth, House, ObjectType, SmallObject, TravelCost};

use crate::error::PlanError;
use crate::problem::SearchProblem;
use crate::protocol::ReplayMode;
use crate::strategy::Strategy;
use crate::trial::{TrialOutcome, run_trial};

/// The hindsight world of a finished trial: the target in `found` only.
pub fn hindsight_truth(
    house: &House,
    target: &ObjectType,
    found: usize,
) -> Result<GroundTruth, PlanError> {
    if found >= house.containers.len() {
        return Err(PlanError::Replay {
            house: house.name.clone(),
            message: format!("container {found} does not exist"),
        });
    }
    let mut contents = vec![Vec::new(); house.containers.len()];
    contents[found].push(SmallObject {
        id: "hindsight-target".into(),
        object_type: target.clone(),
    });
    Ok(GroundTruth::new(contents))
}

/// The replay cost under `mode`: [`replay_cost`] when pessimistic; when counterfactual (the
/// paper's reference code), the strategy is run on the true world `truth` and stops at the first
/// container that truly holds the target, whichever was found in the trial.
pub fn replay_cost_with(
    mode: ReplayMode,
    strategy: &dyn Strategy,
    problem: &SearchProblem<'_>,
    truth: &GroundTruth,
    found: usize,
) -> Result<f64, PlanError> {
    replay_outcome_with(mode, strategy, problem, truth, found).map(|o| o.cost)
}

/// The replayed trial itself under `mode` (see [`replay_cost_with`]): its searches give its
/// cost under any [`TravelCost`] through [`TrialOutcome::reported_cost`].
pub fn replay_outcome_with(
    mode: ReplayMode,
    strategy: &dyn Strategy,
    problem: &SearchProblem<'_>,
    truth: &GroundTruth,
    found: usize,
) -> Result<TrialOutcome, PlanError> {
    let house = problem.house;
    let (outcome, never) = match mode {
        ReplayMode::Pessimistic => {
            let hindsight = hindsight_truth(house, problem.target(), found)?;
            (
                run_trial(strategy, problem, &hindsight)?,
                format!("never searched container {found}"),
            )
        }
        ReplayMode::Counterfactual => (
            run_trial(strategy, problem, truth)?,
            format!("never found {}", problem.target()),
        ),
    };
    match outcome.found {
        Some(_) => Ok(outcome),
        None => Err(PlanError::Replay {
            house: house.name.clone(),
            message: format!("{} {never}", strategy.name()),
        }),
    }
}

/// The replay cost of `strategy` on a trial whose target was found in container `found`: the
/// distance it travels until it searches `found`.
pub fn replay_cost(
    strategy: &dyn Strategy,
    problem: &SearchProblem<'_>,
    found: usize,
) -> Result<f64, PlanError> {
    let truth = hindsight_truth(problem.house, problem.target(), found)?;
    replay_cost_with(ReplayMode::Pessimistic, strategy, problem, &truth, found)
}

/// The replay costs of every candidate on a finished trial, as selection needs them after each
/// deployment. `deployed` is the deployed candidate's index and its own cost (already in
/// `travel`'s terms), which its entry keeps; the others are replayed under `mode` and reported
/// under `travel`, so that every entry is in the same unit.
pub fn replay_costs(
    (mode, travel): (ReplayMode, TravelCost),
    candidates: &[std::sync::Arc<dyn Strategy>],
    problem: &SearchProblem<'_>,
    truth: &GroundTruth,
    found: usize,
    deployed: (usize, f64),
) -> Result<Vec<f64>, PlanError> {
    candidates
        .iter()
        .enumerate()
        .map(|(j, s)| {
            if j == deployed.0 {
                return Ok(deployed.1);
            }
            let replay = || {
                replay_outcome_with(mode, s.as_ref(), problem, truth, found)?.reported_cost(
                    problem.house,
                    problem.distances,
                    travel,
                )
            };
            match problem.replay_memo() {
                // A counterfactual replay also depends on the true world, which no key holds.
                Some(memo) if mode == ReplayMode::Pessimistic => {
                    let key = ReplayKey {
                        strategy: s.name().to_string(),
                        target: problem.trial.target.clone(),
                        revealed: problem.trial.revealed.clone(),
                        found,
                        travel,
                    };
                    memo.get_or_replay(key, replay)
                }
                _ => replay(),
            }
        })
        .collect()
}

/// Pessimistic replay costs already computed in one house seen from one start.
///
/// A fleet's robots search the same house for the same things from the same dock, so the same
/// trial ends the same way again and again; each end replays every other candidate, which is a
/// whole simulated search (an exact planner's one solves a Held–Karp problem per decision).
/// Under the pessimistic hindsight belief a replay depends only on the house, the start (both
/// fixed by whoever owns the memo), the trial (target, containers revealed), the container the
/// target was found in, the strategy and the travel cost; the last four are the key, the
/// strategy by name. So a memo must not outlive what its strategies' names mean (the registry
/// that built them) nor be shared between houses or starts. Counterfactual replays, which also
/// depend on the true world, are never kept.
///
/// Bounded by entry count (a key and a cost, about a hundred bytes): once full, new replays are
/// computed and not kept.
#[derive(Debug)]
pub struct ReplayMemo {
    capacity: usize,
    costs: Mutex<HashMap<ReplayKey, f64>>,
    hits: AtomicU64,
}

#[derive(Debug, Hash, PartialEq, Eq)]
struct ReplayKey {
    strategy: String,
    target: ObjectType,
    revealed: Vec<usize>,
    found: usize,
    travel: TravelCost,
}

impl ReplayMemo {
    /// A memo keeping at most `capacity` replay costs (0 keeps none).
    pub fn new(capacity: usize) -> Self {
        Self {
            capacity,
            costs: Mutex::default(),
            hits: AtomicU64::new(0),
        }
    }

    /// Most replay costs kept.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Replay costs kept.
    pub fn len(&self) -> usize {
        self.lock().len()
    }

    /// True when no replay cost is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Replays answered from the memo so far.
    pub fn hits(&self) -> u64 {
        self.hits.load(Ordering::Relaxed)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<ReplayKey, f64>> {
        // A poisoned map still holds only complete entries: each is inserted in one call.
        self.costs
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The kept cost of `key`, else `replay`'s, kept when there is room. The replay runs
    /// outside the lock: two ends of the same trial at once both compute it, and agree.
    fn get_or_replay(
        &self,
        key: ReplayKey,
        replay: impl FnOnce() -> Result<f64, PlanError>,
    ) -> Result<f64, PlanError> {
        if let Some(&cost) = self.lock().get(&key) {
            self.hits.fetch_add(1, Ordering::Relaxed);
            return Ok(cost);
        }
        let cost = replay()?;
        let mut costs = self.lock();
        if costs.len() < self.capacity {
            costs.insert(key, cost);
        }
        Ok(cost)
    }
}
