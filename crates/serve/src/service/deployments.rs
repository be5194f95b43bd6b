//! Deployments: created with their candidates, selector, exploration constant and seed; their
//! state (trials, per-strategy statistics, the next choice and why) rebuilt from the stored
//! trials on every read, through the same selector `ferret deploy` runs (trial starts keep it
//! between requests: `selectors`).

use std::sync::Arc;

use ferret_plan::{ReplayMode, Strategy};
use ferret_select::DEFAULT_C;
use ferret_world::TravelCost;

use super::replies::Begun;
use super::{Service, json, now_ms};
use crate::api::{
    CreateDeployment, DeploymentState, DeploymentSummary, MAX_C, MAX_LISTED_DEPLOYMENTS, MAX_SEED,
    NextChoice, StrategyRow, TrialSummary,
};
use crate::error::{ApiError, ErrorKind};
use crate::model::{ApiReply, DeploymentSpec, Outcome, StoredTrial, TrialStatus};
use crate::selectors::replayed;

impl Service {
    pub(crate) fn spec(&self, id: i64) -> Result<DeploymentSpec, ApiError> {
        let specs = || {
            self.specs
                .lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
        };
        if let Some(spec) = specs().get(&id) {
            return Ok(spec.clone());
        }
        let spec = self
            .store
            .read(|r| r.deployment(id))?
            .map(|d| d.spec)
            .ok_or_else(|| {
                ApiError::new(
                    ErrorKind::NotFound,
                    "deployment",
                    format!("no deployment {id}"),
                )
            })?;
        let mut kept = specs();
        if kept.len() >= KEPT_SPECS {
            kept.clear();
        }
        kept.insert(id, spec.clone());
        Ok(spec)
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

    /// The candidates of a stored deployment. A strategy this server does not offer means the
    /// deployment was made by a server started with other strategies (another replica, or this
    /// one before a restart): the server's configuration is at fault, not the request.
    pub(crate) fn stored_candidates(
        &self,
        id: i64,
        spec: &DeploymentSpec,
    ) -> Result<Vec<Arc<dyn Strategy>>, ApiError> {
        self.candidates_of(spec).map_err(|e| {
            ApiError::unavailable(
                "",
                format!(
                    "deployment {id} was made with a strategy this server does not offer ({}); replicas sharing a database must be started with the same --strategies",
                    e.message
                ),
            )
        })
    }

    /// `POST /deployments`.
    pub fn create_deployment(
        &self,
        req: CreateDeployment,
        body: &[u8],
    ) -> Result<ApiReply, ApiError> {
        let claim = match self.begin(req.request_id.as_deref(), "POST /deployments", body)? {
            Begun::Replied(reply) => return Ok(reply),
            Begun::Fresh(claim) => claim,
        };
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
            sequential: req.sequential.unwrap_or(false),
        };
        self.candidates_of(&spec)?;
        let mut created = None;
        let reply = claim.complete("POST /deployments", body, |w| {
            let id = w.insert_deployment(&spec)?;
            created = Some(id);
            let state = self.deployment_state(id, &spec, &w.reader().trials_of(id)?)?;
            json(Outcome::Created, &state)
        })?;
        if let Some(id) = created {
            self.events.deployment(id);
        }
        Ok(reply)
    }

    /// `GET /deployments`: the newest [`MAX_LISTED_DEPLOYMENTS`], ascending.
    pub fn list_deployments(&self) -> Result<ApiReply, ApiError> {
        let listed = self
            .store
            .read(|r| r.listed_deployments(MAX_LISTED_DEPLOYMENTS))?;
        let list: Vec<DeploymentSummary> = listed
            .into_iter()
            .map(|d| DeploymentSummary {
                id: d.id,
                selector: d.spec.selector.name().to_string(),
                sequential: d.spec.sequential,
                strategies: d.spec.strategies,
                trials: d.trials,
                open_trials: d.open,
            })
            .collect();
        json(Outcome::Done, &list)
    }

    /// `GET /deployments/{id}`.
    pub fn get_deployment(&self, id: i64) -> Result<ApiReply, ApiError> {
        let spec = self.spec(id)?;
        let trials = self.store.read(|r| r.trials_of(id))?;
        json(Outcome::Done, &self.deployment_state(id, &spec, &trials)?)
    }

    fn deployment_state(
        &self,
        id: i64,
        spec: &DeploymentSpec,
        trials: &[StoredTrial],
    ) -> Result<DeploymentState, ApiError> {
        let (live, _) = replayed(id, spec, trials)?;
        let now = now_ms();
        let stats = live.stats();
        let next = live.peek();
        Ok(DeploymentState {
            id,
            selector: spec.selector.name().to_string(),
            c: spec.c,
            seed: spec.seed,
            sequential: spec.sequential,
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
                    robot: crate::model::whose(
                        t.robot.as_deref(),
                        t.robots.iter().flatten().map(|r| r.id.as_str()),
                    ),
                    heard_s_ago: t.heard_ms.map(|h| (now - h).max(0) as f64 / 1000.0),
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
            open_trials: trials
                .iter()
                .filter(|t| t.status == TrialStatus::Searching)
                .map(|t| t.id)
                .collect(),
            next: NextChoice {
                strategy: spec.strategies.get(next).cloned().unwrap_or_default(),
                why: live.why(&spec.strategies),
            },
        })
    }
}
/// Deployment specs a replica keeps (a few hundred bytes each); past it they are all read
/// again, which costs one statement each.
const KEPT_SPECS: usize = 4096;

/// What a robot's replays assume: the target only where it was found, and plain path lengths,
/// since a robot's trial costs what it travelled.
pub(crate) const ROBOT_REPLAY: (ReplayMode, TravelCost) =
    (ReplayMode::Pessimistic, TravelCost::Plain);
