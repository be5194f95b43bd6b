//! Deployments: created with their candidates, selector, exploration constant and seed; their
//! state (trials, per-strategy statistics, the next choice and why) rebuilt from the stored
//! trials on every request, through the same deployment loop `ferret deploy` runs.

use std::sync::Arc;

use ferret_plan::{ReplayMode, Strategy};
use ferret_select::{DEFAULT_C, DeploymentLoop, FinishedTrial, LiveDeployment, TrialEnd};
use ferret_world::TravelCost;

use crate::api::{
    CreateDeployment, DeploymentState, MAX_C, MAX_SEED, NextChoice, StrategyRow, TrialSummary,
};
use crate::error::{ApiError, ErrorKind};
use crate::model::{ApiReply, DeploymentSpec, Outcome, StoredTrial, TrialStatus};
use crate::service::{Service, json};

impl Service {
    pub(crate) fn spec(&self, id: i64) -> Result<DeploymentSpec, ApiError> {
        self.store
            .read(|r| r.deployment(id))?
            .map(|d| d.spec)
            .ok_or_else(|| {
                ApiError::new(
                    ErrorKind::NotFound,
                    "deployment",
                    format!("no deployment {id}"),
                )
            })
    }

    pub(crate) fn candidates_of(
        &self,
        spec: &DeploymentSpec,
    ) -> Result<Vec<Arc<dyn Strategy>>, ApiError> {
        spec.strategies
            .iter()
            .enumerate()
            .map(|(i, name)| {
                self.candidates
                    .iter()
                    .find(|s| s.name() == name)
                    .cloned()
                    .ok_or_else(|| {
                        ApiError::new(
                            ErrorKind::Invalid,
                            format!("strategies[{i}]"),
                            format!(
                                "{name:?} is not offered by this server (it offers {})",
                                self.strategy_names().join(", ")
                            ),
                        )
                    })
            })
            .collect()
    }

    /// `POST /deployments`.
    pub fn create_deployment(
        &self,
        req: CreateDeployment,
        body: &[u8],
    ) -> Result<ApiReply, ApiError> {
        let strategies = req.strategies.unwrap_or_else(|| self.strategy_names());
        if strategies.is_empty() {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "strategies",
                "give at least one strategy",
            ));
        }
        for (i, s) in strategies.iter().enumerate() {
            if strategies[..i].contains(s) {
                return Err(ApiError::new(
                    ErrorKind::Invalid,
                    format!("strategies[{i}]"),
                    format!("{s:?} is listed twice"),
                ));
            }
        }
        // `+ 0.0` makes -0.0 the 0 it means, so it is stored and echoed as 0.
        let c = req.c.unwrap_or(DEFAULT_C) + 0.0;
        if !(c.is_finite() && (0.0..=MAX_C).contains(&c)) {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "c",
                format!("{c}: must be a number of metres from 0 to {MAX_C}"),
            ));
        }
        let seed = req.seed.unwrap_or(0);
        if seed > MAX_SEED {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "seed",
                format!(
                    "{seed}: at most {MAX_SEED} (2^53 − 1, what every JSON client reads exactly)"
                ),
            ));
        }
        let spec = DeploymentSpec {
            strategies,
            selector: req
                .selector
                .map_or(ferret_select::Method::ReplaySelection, |s| s.0),
            c,
            seed,
        };
        self.candidates_of(&spec)?;
        self.idempotent(req.request_id.as_deref(), "POST /deployments", body, |w| {
            let id = w.insert_deployment(&spec)?;
            let state = self.deployment_state(id, &spec, &w.reader().trials_of(id)?)?;
            json(Outcome::Created, &state)
        })
    }

    /// `GET /deployments/{id}`.
    pub fn get_deployment(&self, id: i64) -> Result<ApiReply, ApiError> {
        let spec = self.spec(id)?;
        let trials = self.store.read(|r| r.trials_of(id))?;
        json(Outcome::Done, &self.deployment_state(id, &spec, &trials)?)
    }

    fn live(
        &self,
        spec: &DeploymentSpec,
        trials: &[StoredTrial],
    ) -> Result<LiveDeployment, ApiError> {
        let (history, pending) = history(trials);
        LiveDeployment::restore(
            spec.selector,
            spec.strategies.len(),
            spec.c,
            spec.seed,
            &history,
            pending,
        )
        .map_err(|e| ApiError::internal(e.to_string()))
    }

    /// The deployment loop's state, rebuilt from the stored trials.
    pub(crate) fn deployment(
        &self,
        spec: &DeploymentSpec,
        trials: &[StoredTrial],
        candidates: Vec<Arc<dyn Strategy>>,
    ) -> Result<DeploymentLoop, ApiError> {
        let (history, pending) = history(trials);
        DeploymentLoop::restore(
            (spec.selector, spec.c, spec.seed),
            candidates,
            ROBOT_REPLAY,
            &history,
            pending,
        )
        .map_err(|e| ApiError::internal(e.to_string()))
    }

    fn deployment_state(
        &self,
        id: i64,
        spec: &DeploymentSpec,
        trials: &[StoredTrial],
    ) -> Result<DeploymentState, ApiError> {
        let live = self.live(spec, trials)?;
        let stats = live.stats();
        let next = live.peek();
        Ok(DeploymentState {
            id,
            selector: spec.selector.name().to_string(),
            c: spec.c,
            seed: spec.seed,
            strategies: spec.strategies.clone(),
            trials: trials
                .iter()
                .map(|t| TrialSummary {
                    trial: t.id,
                    k: t.k,
                    target: t.target.clone(),
                    strategy: spec.strategies.get(t.chosen).cloned().unwrap_or_default(),
                    status: t.status,
                    cost_m: t.cost,
                })
                .collect(),
            per_strategy: spec
                .strategies
                .iter()
                .zip(&stats)
                .map(|(name, s)| StrategyRow {
                    strategy: name.clone(),
                    deployed: s.deployed,
                    mean_cost_m: s.mean_cost,
                    replay_mean_m: s.replay_mean,
                    score: s.score.is_finite().then_some(s.score),
                })
                .collect(),
            open_trial: trials
                .iter()
                .find(|t| t.status == TrialStatus::Searching)
                .map(|t| t.id),
            next: NextChoice {
                strategy: spec.strategies.get(next).cloned().unwrap_or_default(),
                why: live.why(&spec.strategies),
            },
        })
    }
}
/// What a robot's replays assume: the target only where it was found, and plain path lengths,
/// since a robot's trial costs what it travelled.
pub(crate) const ROBOT_REPLAY: (ReplayMode, TravelCost) =
    (ReplayMode::Pessimistic, TravelCost::Plain);

/// How the stored trials ended, in order, and the choice of the open one.
fn history(trials: &[StoredTrial]) -> (Vec<TrialEnd>, Option<usize>) {
    let mut history = Vec::new();
    let mut pending = None;
    for t in trials {
        match t.status {
            TrialStatus::Done => history.push(TrialEnd::Finished(FinishedTrial {
                chosen: t.chosen,
                cost: t.cost.unwrap_or(f64::NAN),
                replays: t.replays.clone().unwrap_or_default(),
            })),
            TrialStatus::Exhausted => history.push(TrialEnd::Abandoned { chosen: t.chosen }),
            TrialStatus::Searching => pending = Some(t.chosen),
        }
    }
    (history, pending)
}
