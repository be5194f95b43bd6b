//! Offline replay (paper section V-C): what would another strategy have cost on a finished trial?
//!
//! The pessimistic hindsight belief: the target is only in the container where it was actually
//! found (for a task, each target found only where it was found, the others nowhere);
//! containers searched in the trial are known (and held nothing else of use); every other
//! container is assumed empty. The replay reuses [`run_trial`] and the strategies' own policies,
//! so a replay cannot drift from a real run: it ends when the task's goal holds in that world,
//! at the task's destination.

use ferret_world::{GroundTruth, House, SmallObject, TravelCost};

use crate::error::PlanError;
use crate::problem::SearchProblem;
use crate::protocol::ReplayMode;
use crate::replay_memo::ReplayKey;
use crate::strategy::Strategy;
use crate::task::Task;
use crate::trial::{TrialOutcome, run_trial};

/// The hindsight world of a finished trial: each target of `task` only in the container
/// `found_each` says it was found in (task order; `None`: found nowhere).
pub fn hindsight_truth(
    house: &House,
    task: &Task,
    found_each: &[Option<usize>],
) -> Result<GroundTruth, PlanError> {
    let mut contents = vec![Vec::new(); house.containers.len()];
    for (i, (target, found)) in task.targets().iter().zip(found_each).enumerate() {
        let Some(c) = *found else { continue };
        let slot = contents.get_mut(c).ok_or_else(|| PlanError::Replay {
            house: house.name.clone(),
            message: format!("container {c} does not exist"),
        })?;
        slot.push(SmallObject {
            id: if i == 0 {
                "hindsight-target".into()
            } else {
                format!("hindsight-target-{i}")
            },
            object_type: target.clone(),
        });
    }
    if !task.holds(found_each.iter().map(Option::is_some)) {
        return Err(PlanError::Replay {
            house: house.name.clone(),
            message: format!("the trial's goal did not hold ({task})"),
        });
    }
    Ok(GroundTruth::new(contents))
}

/// The replay cost under `mode`: [`replay_cost`] when pessimistic; when counterfactual (the
/// paper's reference code), the strategy is run on the true world `truth` and stops where the
/// goal truly holds, whichever containers it was met at in the trial.
pub fn replay_cost_with(
    mode: ReplayMode,
    strategy: &dyn Strategy,
    problem: &SearchProblem<'_>,
    truth: &GroundTruth,
    found_each: &[Option<usize>],
) -> Result<f64, PlanError> {
    replay_outcome_with(mode, strategy, problem, truth, found_each).map(|o| o.cost)
}

/// The replayed trial itself under `mode` (see [`replay_cost_with`]): its searches give its
/// cost under any [`TravelCost`] through [`TrialOutcome::reported_cost`].
pub fn replay_outcome_with(
    mode: ReplayMode,
    strategy: &dyn Strategy,
    problem: &SearchProblem<'_>,
    truth: &GroundTruth,
    found_each: &[Option<usize>],
) -> Result<TrialOutcome, PlanError> {
    let house = problem.house;
    let task = problem.task();
    let (outcome, never) = match mode {
        ReplayMode::Pessimistic => {
            let hindsight = hindsight_truth(house, task, found_each)?;
            let never = match found_each {
                [Some(found)] => format!("never searched container {found}"),
                _ => format!("never reached the goal of {task}"),
            };
            (run_trial(strategy, problem, &hindsight)?, never)
        }
        ReplayMode::Counterfactual => (
            run_trial(strategy, problem, truth)?,
            if task.targets().len() == 1 {
                format!("never found {}", task.first())
            } else {
                format!("never reached the goal of {task}")
            },
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

/// The replay cost of `strategy` on a trial whose targets were found in `found_each` (task
/// order): the distance it travels until its goal holds in the hindsight world (for one
/// target: until it searches the container where it was found), and on to the destination.
pub fn replay_cost(
    strategy: &dyn Strategy,
    problem: &SearchProblem<'_>,
    found_each: &[Option<usize>],
) -> Result<f64, PlanError> {
    let truth = hindsight_truth(problem.house, problem.task(), found_each)?;
    replay_cost_with(
        ReplayMode::Pessimistic,
        strategy,
        problem,
        &truth,
        found_each,
    )
}

/// The replay costs of every candidate on a finished trial whose targets were found in
/// `found_each`, as selection needs them after each deployment. `deployed` is the deployed candidate's index and its own cost (already in
/// `travel`'s terms), which its entry keeps; the others are replayed under `mode` and reported
/// under `travel`, so that every entry is in the same unit.
pub fn replay_costs(
    (mode, travel): (ReplayMode, TravelCost),
    candidates: &[std::sync::Arc<dyn Strategy>],
    problem: &SearchProblem<'_>,
    truth: &GroundTruth,
    found_each: &[Option<usize>],
    deployed: (usize, f64),
) -> Result<Vec<f64>, PlanError> {
    let replay = |s: &dyn Strategy| {
        replay_outcome_with(mode, s, problem, truth, found_each)?.reported_cost(
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
        task: problem.trial.task.to_string(),
        revealed: problem.trial.revealed.clone(),
        found: found_each.to_vec(),
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

/// The replay cost of `strategy` run by a team (one problem per robot, each from its own start)
/// on a finished trial, under `mode` (see [`replay_cost_with`]): the team's makespan until the
/// goal holds in the hindsight world (pessimistic) or in the true world `truth`
/// (counterfactual).
///
/// # Errors
/// A goal that did not hold, a team that never reaches it, and what
/// [`run_team`](crate::run_team) refuses.
pub fn replay_team_cost_with(
    mode: ReplayMode,
    strategy: &dyn Strategy,
    problems: &[SearchProblem<'_>],
    truth: &GroundTruth,
    found_each: &[Option<usize>],
) -> Result<f64, PlanError> {
    let first = problems.first().ok_or_else(|| PlanError::Team {
        house: String::new(),
        message: "a team needs at least one robot".into(),
    })?;
    let (house, task) = (first.house, first.task());
    let team = match mode {
        ReplayMode::Pessimistic => {
            let hindsight = hindsight_truth(house, task, found_each)?;
            crate::team::run_team(strategy, problems, &hindsight)?
        }
        ReplayMode::Counterfactual => crate::team::run_team(strategy, problems, truth)?,
    };
    match team.trial.found {
        Some(_) => Ok(team.trial.cost),
        None => Err(PlanError::Replay {
            house: house.name.clone(),
            message: format!(
                "{} never reached the goal of {task} with its team",
                strategy.name()
            ),
        }),
    }
}

/// The replay costs of every candidate on a team's finished trial whose targets were found in
/// `found_each`: each candidate run by the same team (one problem per robot, each from its own
/// start) in the pessimistic hindsight world, scored by its makespan. `deployed` keeps the
/// deployed candidate's own cost, as in [`replay_costs`].
///
/// # Errors
/// A goal that did not hold, a candidate that never reaches it in the hindsight world, and
/// what [`run_team`](crate::run_team) refuses.
pub fn replay_team_costs(
    candidates: &[std::sync::Arc<dyn Strategy>],
    problems: &[SearchProblem<'_>],
    found_each: &[Option<usize>],
    deployed: (usize, f64),
) -> Result<Vec<f64>, PlanError> {
    // The true world is not needed in the pessimistic replay.
    let nothing = GroundTruth::new(Vec::new());
    candidates
        .iter()
        .enumerate()
        .map(|(j, s)| {
            if j == deployed.0 {
                return Ok(deployed.1);
            }
            replay_team_cost_with(
                ReplayMode::Pessimistic,
                s.as_ref(),
                problems,
                &nothing,
                found_each,
            )
        })
        .collect()
}
