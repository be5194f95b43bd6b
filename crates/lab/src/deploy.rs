//! The deployment loop: before each trial a selector chooses a strategy, the trial runs, every
//! other candidate is replayed on what the trial revealed, and the selector learns from the
//! costs. [`Deployment`] is the loop's state, shared by batch deployments ([`deploy`]) and by
//! a service that runs one step per request; [`house_order`] is the order of houses a batch
//! deployment visits. The selection experiment drives the same selector loop
//! ([`LiveDeployment`]) over a table of costs instead of trials.

use std::sync::Arc;

use ferret_plan::{
    DrawMode, Protocol, ReplayMode, SearchProblem, Strategy, TrialSpec, TrialsPerHouse,
    replay_costs, run_trial,
};
use ferret_select::{HouseOrder, LiveDeployment, Method, TrialEnd};
use ferret_world::{GridParams, GroundTruth, ObjectType, Scene, TravelCost};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

use crate::error::{LabError, Result};
use crate::evaluate::TrialDraw;
use crate::feedback::Feedback;

/// A deployment's selector, its candidates and what replays assume.
pub struct Deployment {
    candidates: Vec<Arc<dyn Strategy>>,
    live: LiveDeployment,
    settings: (ReplayMode, TravelCost),
}

/// One finished trial of a deployment.
#[derive(Clone, Debug, PartialEq)]
pub struct DeploymentStep {
    /// Index of the candidate deployed.
    pub chosen: usize,
    /// Its cost, metres, as the protocol reports it.
    pub cost: f64,
    /// The container where the target was found.
    pub found: usize,
    /// Every candidate's replay cost on this trial (entry `chosen` is `cost`).
    pub replays: Vec<f64>,
}

impl Deployment {
    /// A new deployment of `candidates` chosen by `method` with exploration constant `c` and
    /// tie-break `seed`; replays as `settings` say (mode, reported travel cost).
    pub fn new(
        method: Method,
        candidates: Vec<Arc<dyn Strategy>>,
        c: f64,
        seed: u64,
        settings: (ReplayMode, TravelCost),
    ) -> Result<Self> {
        let live = LiveDeployment::new(method, candidates.len(), c, seed)?;
        Ok(Self {
            candidates,
            live,
            settings,
        })
    }

    /// A deployment rebuilt from how its trials ended and, if one is open, its choice.
    pub fn restore(
        (method, c, seed): (Method, f64, u64),
        candidates: Vec<Arc<dyn Strategy>>,
        settings: (ReplayMode, TravelCost),
        history: &[TrialEnd],
        pending: Option<usize>,
    ) -> Result<Self> {
        let live = LiveDeployment::restore(method, candidates.len(), c, seed, history, pending)?;
        Ok(Self {
            candidates,
            live,
            settings,
        })
    }

    /// The candidates, in order.
    pub fn candidates(&self) -> &[Arc<dyn Strategy>] {
        &self.candidates
    }

    /// The selector's state (statistics, the next choice and why).
    pub fn live(&self) -> &LiveDeployment {
        &self.live
    }

    /// Chooses the candidate of the next trial.
    pub fn choose(&mut self) -> usize {
        self.live.choose()
    }

    /// Every candidate's replay cost on a trial where `chosen` was deployed, cost `cost` and
    /// found the target in `found`; nothing is learned yet.
    pub fn replays(
        &self,
        problem: &SearchProblem<'_>,
        truth: &GroundTruth,
        found: usize,
        (chosen, cost): (usize, f64),
    ) -> Result<Vec<f64>> {
        Ok(replay_costs(
            self.settings,
            &self.candidates,
            problem,
            truth,
            found,
            (chosen, cost),
        )?)
    }

    /// The selector learns a finished trial's cost and replays.
    pub fn learn(&mut self, cost: f64, replays: &[f64]) -> Result<()> {
        Ok(self.live.finish(cost, replays)?)
    }

    /// One whole step: choose, run the trial in simulation, replay the others, learn. The cost is
    /// the one `travel` reports (planners decide on plain distances either way).
    pub fn step(
        &mut self,
        problem: &SearchProblem<'_>,
        truth: &GroundTruth,
    ) -> Result<DeploymentStep> {
        let chosen = self.choose();
        let outcome = run_trial(self.candidates[chosen].as_ref(), problem, truth)?;
        let cost = outcome.reported_cost(problem.house, problem.distances, self.settings.1)?;
        let Some(found) = outcome.found else {
            return Err(LabError::invalid(format!(
                "{}: the target {} was not found",
                problem.house.name, problem.trial.target
            )));
        };
        let replays = self.replays(problem, truth, found, (chosen, cost))?;
        self.learn(cost, &replays)?;
        Ok(DeploymentStep {
            chosen,
            cost,
            found,
            replays,
        })
    }
}

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
    /// Object types to find, one per trial, in order; empty draws targets.
    pub find: &'a [ObjectType],
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
    /// The target.
    pub target: ObjectType,
    /// The step: choice, cost, container, replays.
    pub step: DeploymentStep,
}

/// Runs a batch deployment over `scenes`: houses in [`HouseOrder`], one trial each, every trial
/// a [`Deployment::step`]. A house without a map is skipped with a note; `on_trial` sees each
/// finished trial as it happens.
pub fn deploy(
    scenes: &[Scene],
    deployment: &mut Deployment,
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
            let target = settings.find[k].clone();
            if scene.truth.goal_containers(&target).is_empty() {
                return Err(LabError::invalid(format!(
                    "{}: no container holds {target}, so trial {} cannot end",
                    scene.house.name,
                    k + 1
                )));
            }
            TrialSpec {
                target,
                revealed: Vec::new(),
            }
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
        let problem = SearchProblem::new(&scene.house, &distances, &trial);
        let step = deployment.step(&problem, &scene.truth)?;
        let t = DeployedTrial {
            k: k + 1,
            house: h,
            target: trial.target.clone(),
            step,
        };
        on_trial(&t);
        done.push(t);
    }
    Ok(done)
}
