//! Offline replay (paper section V-C): what would another strategy have cost on a finished trial?
//!
//! The pessimistic hindsight belief: the target is only in the container where it was actually
//! found; containers searched in the trial are known (and held nothing else of use); every other
//! container is assumed empty. The replay reuses [`run_trial`] and the strategies' own policies,
//! so a replay cannot drift from a real run.

use ferret_world::{Distances, GroundTruth, House, ObjectType, SmallObject, TravelCost};

use crate::error::PlanError;
use crate::protocol::ReplayMode;
use crate::strategy::Strategy;
use crate::trial::{TrialOutcome, TrialSpec, run_trial};

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
    house: &House,
    truth: &GroundTruth,
    distances: &Distances,
    trial: &TrialSpec,
    found: usize,
) -> Result<f64, PlanError> {
    replay_outcome_with(mode, strategy, house, truth, distances, trial, found).map(|o| o.cost)
}

/// The replayed trial itself under `mode` (see [`replay_cost_with`]): its searches give its
/// cost under any [`TravelCost`](ferret_world::TravelCost) through
/// [`TrialOutcome::reported_cost`].
pub fn replay_outcome_with(
    mode: ReplayMode,
    strategy: &dyn Strategy,
    house: &House,
    truth: &GroundTruth,
    distances: &Distances,
    trial: &TrialSpec,
    found: usize,
) -> Result<TrialOutcome, PlanError> {
    let (outcome, never) = match mode {
        ReplayMode::Pessimistic => {
            let hindsight = hindsight_truth(house, &trial.target, found)?;
            (
                run_trial(strategy, house, &hindsight, distances, trial)?,
                format!("never searched container {found}"),
            )
        }
        ReplayMode::Counterfactual => (
            run_trial(strategy, house, truth, distances, trial)?,
            format!("never found {}", trial.target),
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
    house: &House,
    distances: &Distances,
    trial: &TrialSpec,
    found: usize,
) -> Result<f64, PlanError> {
    let truth = hindsight_truth(house, &trial.target, found)?;
    replay_outcome_with(
        ReplayMode::Pessimistic,
        strategy,
        house,
        &truth,
        distances,
        trial,
        found,
    )
    .map(|o| o.cost)
}

/// The replay costs of every candidate on a finished trial, as selection needs them after each
/// deployment: entry `chosen` is the deployed strategy's own `cost` (already in `travel`'s
/// terms), the others are replayed under `mode` and reported under `travel`, so that every
/// entry is in the same unit. `ferret deploy` and `ferret serve` both call this.
#[allow(clippy::too_many_arguments)]
pub fn replay_costs(
    mode: ReplayMode,
    travel: TravelCost,
    candidates: &[std::sync::Arc<dyn Strategy>],
    chosen: usize,
    cost: f64,
    house: &House,
    truth: &GroundTruth,
    distances: &Distances,
    trial: &TrialSpec,
    found: usize,
) -> Result<Vec<f64>, PlanError> {
    candidates
        .iter()
        .enumerate()
        .map(|(j, s)| {
            if j == chosen {
                Ok(cost)
            } else {
                replay_outcome_with(mode, s.as_ref(), house, truth, distances, trial, found)?
                    .reported_cost(house, distances, travel)
            }
        })
        .collect()
}
