//! Offline replay (paper section V-C): what would another strategy have cost on a finished trial?
//!
//! The pessimistic hindsight belief: the target is only in the container where it was actually
//! found; containers searched in the trial are known (and held nothing else of use); every other
//! container is assumed empty. The replay reuses [`run_trial`] and the strategies' own policies,
//! so a replay cannot drift from a real run.

use std::collections::HashMap;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard};

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
    let replay = |s: &dyn Strategy| {
        replay_outcome_with(mode, s, problem, truth, found)?.reported_cost(
            problem.house,
            problem.distances,
            travel,
        )
    };
    // A counterfactual replay also depends on the true world, which no key holds.
    let memo = problem
        .replay_memo()
        .filter(|_| mode == ReplayMode::Pessimistic);
    let Some(memo) = memo else {
        return candidates
            .iter()
            .enumerate()
            .map(|(j, s)| {
                if j == deployed.0 {
                    Ok(deployed.1)
                } else {
                    replay(s.as_ref())
                }
            })
            .collect();
    };
    let key = |s: &dyn Strategy| ReplayKey {
        strategy: s.name().to_string(),
        target: problem.trial.target.clone(),
        revealed: problem.trial.revealed.clone(),
        found,
        travel,
    };
    let mut missed = false;
    let costs = candidates
        .iter()
        .enumerate()
        .map(|(j, s)| {
            if j == deployed.0 {
                return Ok(deployed.1);
            }
            let (cost, hit) = memo.get_or_replay(key(s.as_ref()), || replay(s.as_ref()))?;
            missed |= !hit;
            Ok(cost)
        })
        .collect::<Result<Vec<f64>, PlanError>>()?;
    // A trial that ends as none before it did is replayed for the deployed candidate too (its
    // own entry stays the cost it was deployed at): the next trial that ends this way, with
    // another candidate deployed, then finds every replay it needs. Nothing here needs that
    // replay, so its failure (an LLM endpoint down) fails nothing: that end replays it later.
    if missed
        && let Some(s) = candidates.get(deployed.0)
        && let Err(e) = memo.fill(key(s.as_ref()), || replay(s.as_ref()))
    {
        tracing::debug!(
            strategy = s.name(),
            "replay kept for later ends failed: {e}"
        );
    }
    Ok(costs)
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
    /// One slot per key, filled by whichever end of that trial replays it first; the others
    /// wait on the slot instead of replaying the same thing at once (a fleet's robots that set
    /// out together end together).
    slots: Mutex<HashMap<ReplayKey, Slot>>,
    hits: AtomicU64,
}

type Slot = Arc<Mutex<Option<f64>>>;

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
            slots: Mutex::default(),
            hits: AtomicU64::new(0),
        }
    }

    /// Most replay costs kept.
    pub fn capacity(&self) -> usize {
        self.capacity
    }

    /// Replay costs kept.
    pub fn len(&self) -> usize {
        let slots: Vec<Slot> = self.lock().values().cloned().collect();
        slots.iter().filter(|s| lock(s).is_some()).count()
    }

    /// True when no replay cost is kept.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Replays answered from the memo so far.
    pub fn hits(&self) -> u64 {
        self.hits.load(Ordering::Relaxed)
    }

    fn lock(&self) -> MutexGuard<'_, HashMap<ReplayKey, Slot>> {
        lock(&self.slots)
    }

    /// The kept cost of `key` (and true), else `replay`'s (and false), kept when there is
    /// room. A replay of the same key under way elsewhere is waited for, not repeated; one
    /// that fails leaves the slot empty for the next to try.
    fn get_or_replay(
        &self,
        key: ReplayKey,
        replay: impl FnOnce() -> Result<f64, PlanError>,
    ) -> Result<(f64, bool), PlanError> {
        let Some(slot) = self.slot(key) else {
            return Ok((replay()?, false));
        };
        let mut cost = lock(&slot);
        if let Some(c) = *cost {
            self.hits.fetch_add(1, Ordering::Relaxed);
            return Ok((c, true));
        }
        let c = replay()?;
        *cost = Some(c);
        Ok((c, false))
    }

    /// Keeps `replay`'s cost for `key` unless one is kept already or there is no room.
    fn fill(
        &self,
        key: ReplayKey,
        replay: impl FnOnce() -> Result<f64, PlanError>,
    ) -> Result<(), PlanError> {
        if let Some(slot) = self.slot(key) {
            let mut cost = lock(&slot);
            if cost.is_none() {
                *cost = Some(replay()?);
            }
        }
        Ok(())
    }

    /// The slot of `key`, made when there is room; `None` when there is none.
    fn slot(&self, key: ReplayKey) -> Option<Slot> {
        let mut slots = self.lock();
        if let Some(s) = slots.get(&key) {
            return Some(s.clone());
        }
        if slots.len() >= self.capacity {
            return None;
        }
        let s = Slot::default();
        slots.insert(key, s.clone());
        Some(s)
    }
}

/// Locks `m`; a poisoned lock still guards whole values (each is written in one assignment).
fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(std::sync::PoisonError::into_inner)
}
