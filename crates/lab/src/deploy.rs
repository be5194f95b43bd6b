//! Batch deployments in simulation: [`deploy`] visits houses in [`house_order`] and runs one
//! step of the deployment loop ([`DeploymentLoop`], owned by the select crate and shared with
//! the HTTP service) in each.

use ferret_plan::{DrawMode, Protocol, SearchProblem, Task, TrialSpec, TrialsPerHouse};
use ferret_select::{DeploymentLoop, DeploymentStep, HouseOrder};
use ferret_world::{GridParams, Scene};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::error::{LabError, Result};
use crate::evaluate::TrialDraw;
use crate::feedback::Feedback;
use crate::tasks::{TaskText, Tasks};

/// The houses a batch deployment visits: `trials` visits of `count` houses, cycling through
/// them in file order when the targets are given (a robot in one home), else shuffled distinct
/// houses or draws with replacement as `draw` says, from `seed`; the same stream then picks
/// among a house's drawn targets.
pub fn house_order(
    count: usize,
    trials: usize,
    given_targets: bool,
    draw: DrawMode,
    seed: u64,
) -> Result<HouseOrder> {
    if count == 0 {
        return Err(LabError::invalid("no houses to deploy in"));
    }
    if !given_targets && draw == DrawMode::Distinct && trials > count {
        return Err(LabError::invalid(format!(
            "{trials} trials need {trials} distinct houses; there are {count}"
        )));
    }
    let rng = ChaCha8Rng::seed_from_u64(seed);
    Ok(if given_targets {
        HouseOrder::cycling(count, trials, seed)?
    } else {
        match draw {
            DrawMode::Distinct => HouseOrder::shuffled(count, trials, rng)?,
            DrawMode::Replacement => HouseOrder::with_replacement(count, trials, rng)?,
        }
    })
}

/// What a batch deployment runs.
pub struct DeploySettings<'a> {
    /// Trials in all.
    pub trials: usize,
    /// What to find, one task per trial (a target, or several with a goal and a destination),
    /// in order; empty draws them.
    pub find: &'a [TaskText],
    /// Household tasks drawn per house instead of one target (when `find` is empty).
    pub tasks: Option<&'a Tasks>,
    /// Targets drawn per house; each trial runs one of them, picked at random.
    pub per_house: TrialsPerHouse,
    /// Seed of the house order and targets (the selector's tie breaks have their own).
    pub seed: u64,
    /// The protocol (trial draws, replay mode, travel cost, house draw).
    pub protocol: &'a Protocol,
    /// The grid the houses are mapped on.
    pub grid: &'a GridParams,
}

/// A trial of a batch deployment, as it happened.
#[derive(Clone, Debug)]
pub struct DeployedTrial {
    /// 1-based trial number.
    pub k: usize,
    /// Position of the house among the loaded houses.
    pub house: usize,
    /// What was asked.
    pub task: Task,
    /// The step: choice, cost, container, replays.
    pub step: DeploymentStep,
}

/// Runs a batch deployment over `scenes`: houses in [`HouseOrder`], one trial each, every trial
/// a [`DeploymentLoop::step`]. A house without a map is skipped with a note; `on_trial` sees each
/// finished trial as it happens.
pub fn deploy(
    scenes: &[Scene],
    deployment: &mut DeploymentLoop,
    settings: &DeploySettings<'_>,
    feedback: &dyn Feedback,
    on_trial: &mut dyn FnMut(&DeployedTrial),
) -> Result<Vec<DeployedTrial>> {
    let given = !settings.find.is_empty();
    if given && settings.trials > settings.find.len() {
        return Err(LabError::invalid(format!(
            "--trials {} but only {} types to --find: give one per trial",
            settings.trials,
            settings.find.len()
        )));
    }
    let mut order = house_order(
        scenes.len(),
        settings.trials,
        given,
        settings.protocol.draw,
        settings.seed,
    )?;
    let draw = TrialDraw {
        seed: settings.seed,
        reveal_fraction: 0.0,
        per_house: settings.per_house,
        protocol: settings.protocol,
        holdout: None,
        tasks: settings.tasks,
        team: None,
    };
    let mut done = Vec::new();
    let houses = order.houses().to_vec();
    for (k, &h) in houses.iter().enumerate() {
        let scene = &scenes[h];
        let (_, distances) = match ferret_world::distance::build(&scene.house, settings.grid) {
            Ok(m) => m,
            Err(e) => {
                feedback.note(&format!("skipping {}: {e}", scene.house.name));
                continue;
            }
        };
        let trial = if given {
            let task = settings.find[k]
                .task(scene)
                .map_err(|error| LabError::Task {
                    place: format!("trial {}", k + 1),
                    error,
                })?;
            TrialSpec::of(task)
        } else {
            let mut drawn = draw.trials(scene)?;
            // One trial is the paper's draw; the stream is touched only when there is a choice,
            // so that single-target deployments do not depend on it.
            let pick = match settings.per_house {
                TrialsPerHouse::One => 0,
                _ => order.pick(drawn.len()),
            };
            drawn.swap_remove(pick)
        };
        let legs = trial
            .task
            .destination()
            .map(|d| d.legs(&scene.house, &distances))
            .transpose()
            .map_err(|e| LabError::Task {
                place: format!("trial {}", k + 1),
                error: e,
            })?;
        let mut problem = SearchProblem::new(&scene.house, &distances, &trial);
        if let Some(l) = legs.as_ref() {
            problem = problem.with_destination(l);
        }
        let step = deployment.step(&problem, &scene.truth)?;
        let t = DeployedTrial {
            k: k + 1,
            house: h,
            task: trial.task.clone(),
            step,
        };
        on_trial(&t);
        done.push(t);
    }
    Ok(done)
}
