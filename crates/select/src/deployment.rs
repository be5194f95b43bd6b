//! The deployment loop: before each trial a selector chooses a strategy, the trial runs, every
//! other candidate is replayed on what the trial revealed, and the selector learns from the
//! costs. [`DeploymentLoop`] is the loop's state, shared by batch deployments (`ferret deploy`)
//! and by a service that runs one step per request and rebuilds the loop from its stored
//! trials; the selection experiment drives the same selector ([`LiveDeployment`]) over a table
//! of costs instead of trials.

use std::sync::Arc;

use ferret_plan::{PlanError, ReplayMode, SearchProblem, Strategy, replay_costs, run_trial};
use ferret_world::{GroundTruth, TravelCost};

use crate::{LiveDeployment, Method, SelectError, TrialEnd};

/// What a deployment step can fail on.
#[derive(Debug, thiserror::Error)]
pub enum DeploymentError {
    /// The selector refused (a restore out of order, a cost that is not finite).
    #[error(transparent)]
    Select(#[from] SelectError),
    /// A trial or a replay could not be planned.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// The simulated trial ended without its goal holding (the target not found), so it
    /// cannot be learned from.
    #[error("{house}: {task} was not done (a target was not found)")]
    NotFound {
        /// The house's name.
        house: String,
        /// The task, as written.
        task: String,
    },
}

/// How replays of a deployment are run: what they assume where the target was not seen, and
/// which travel cost they report.
pub type ReplaySettings = (ReplayMode, TravelCost);

/// A deployment's selector, its candidates and what replays assume.
///
/// ```
/// use ferret_plan::{PlannerConfig, ReplayMode, SearchProblem, StrategyRegistry, draw_trial};
/// use ferret_select::{DeploymentLoop, Method};
/// use ferret_world::{GridParams, TravelCost, distance, generate};
///
/// // Two candidates, chosen by replay selection, on three generated houses.
/// let registry = StrategyRegistry::builtin(None, PlannerConfig::default(), 16);
/// let candidates = vec![
///     registry.build("optimistic+greedy")?,
///     registry.build("model/uniform")?,
/// ];
/// let mut deployment = DeploymentLoop::new(
///     Method::ReplaySelection,
///     candidates,
///     5.0,
///     0,
///     (ReplayMode::Pessimistic, TravelCost::Plain),
/// )?;
/// for scene in generate::default_scenes(3, 7)? {
///     let (_, distances) = distance::build(&scene.house, &GridParams::default())?;
///     let trial = draw_trial(&scene.house, &scene.truth, 0, 0.0)?;
///     let problem = SearchProblem::new(&scene.house, &distances, &trial);
///     let step = deployment.step(&problem, &scene.truth)?;
///     // The deployed strategy's replay is its own cost.
///     assert_eq!(step.replays[step.chosen], step.cost);
/// }
/// let deployed: usize = deployment.live().stats().iter().map(|s| s.deployed).sum();
/// assert_eq!(deployed, 3);
/// # Ok::<(), Box<dyn std::error::Error>>(())
/// ```
pub struct DeploymentLoop {
    candidates: Vec<Arc<dyn Strategy>>,
    live: LiveDeployment,
    settings: ReplaySettings,
}

/// One finished trial of a deployment.
#[derive(Clone, Debug, PartialEq)]
pub struct DeploymentStep {
    /// Index of the candidate deployed.
    pub chosen: usize,
    /// Its cost, metres, as the protocol reports it.
    pub cost: f64,
    /// The container where the goal came to hold (for one target: where it was found).
    pub found: usize,
    /// Where each target (task order) was first seen.
    pub found_each: Vec<Option<usize>>,
    /// Every candidate's replay cost on this trial (entry `chosen` is `cost`).
    pub replays: Vec<f64>,
}

impl DeploymentLoop {
    /// A new deployment of `candidates` chosen by `method` with exploration constant `c` and
    /// tie-break `seed`; replays as `settings` say (mode, reported travel cost).
    ///
    /// # Errors
    /// No candidates, or a `c` that is not a finite number ≥ 0.
    pub fn new(
        method: Method,
        candidates: Vec<Arc<dyn Strategy>>,
        c: f64,
        seed: u64,
        settings: ReplaySettings,
    ) -> Result<Self, SelectError> {
        let live = LiveDeployment::new(method, candidates.len(), c, seed)?;
        Ok(Self {
            candidates,
            live,
            settings,
        })
    }

    /// A deployment rebuilt from how its trials ended and, if one is open, its choice.
    ///
    /// # Errors
    /// What [`LiveDeployment::restore`] refuses.
    pub fn restore(
        (method, c, seed): (Method, f64, u64),
        candidates: Vec<Arc<dyn Strategy>>,
        settings: ReplaySettings,
        history: &[TrialEnd],
        pending: Option<usize>,
    ) -> Result<Self, SelectError> {
        let live = LiveDeployment::restore(method, candidates.len(), c, seed, history, pending)?;
        Ok(Self {
            candidates,
            live,
            settings,
        })
    }

    /// Chooses the candidate of a new trial that may run alongside open ones (see
    /// [`LiveDeployment::choose_overlapping`]).
    pub fn choose_overlapping(&mut self) -> usize {
        self.live.choose_overlapping()
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
    /// found the task's targets in `found_each` (task order); nothing is learned yet.
    ///
    /// # Errors
    /// A candidate that cannot be replayed (an LLM endpoint down, a policy failing).
    pub fn replays(
        &self,
        problem: &SearchProblem<'_>,
        truth: &GroundTruth,
        found_each: &[Option<usize>],
        (chosen, cost): (usize, f64),
    ) -> Result<Vec<f64>, PlanError> {
        replay_costs(
            self.settings,
            &self.candidates,
            problem,
            truth,
            found_each,
            (chosen, cost),
        )
    }

    /// Ends the trial in progress without a cost (the target was nowhere): the selector learns
    /// nothing from it.
    ///
    /// # Errors
    /// No trial in progress.
    pub fn abandon(&mut self) -> Result<(), SelectError> {
        self.live.abandon()
    }

    /// The selector learns a finished trial's cost and replays.
    ///
    /// # Errors
    /// Costs that are not finite, or no trial chosen.
    pub fn learn(&mut self, cost: f64, replays: &[f64]) -> Result<(), SelectError> {
        self.live.finish(cost, replays)
    }

    /// One whole step: choose, run the trial in simulation, replay the others, learn. The cost is
    /// the one the replay settings' travel cost reports (planners decide on plain distances
    /// either way). A trial of a household task is replayed on the same task.
    ///
    /// # Errors
    /// A trial or replay that cannot be planned, or a trial whose goal never holds.
    pub fn step(
        &mut self,
        problem: &SearchProblem<'_>,
        truth: &GroundTruth,
    ) -> Result<DeploymentStep, DeploymentError> {
        let chosen = self.choose();
        let outcome = run_trial(self.candidates[chosen].as_ref(), problem, truth)?;
        let cost = outcome.reported_cost(problem.house, problem.distances, self.settings.1)?;
        let Some(found) = outcome.found else {
            return Err(DeploymentError::NotFound {
                house: problem.house.name.clone(),
                task: problem.trial.task.to_string(),
            });
        };
        let replays = self.replays(problem, truth, &outcome.found_each, (chosen, cost))?;
        self.learn(cost, &replays)?;
        Ok(DeploymentStep {
            chosen,
            cost,
            found,
            found_each: outcome.found_each,
            replays,
        })
    }
}
