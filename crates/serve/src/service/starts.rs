//! Trial starts: a trial started in a deployment with the strategy its selector chooses, its
//! place in the deployment's order decided under the deployment's lock, and its first
//! container planned once it is stored. Starts of one deployment that wait for its lock on one
//! replica are stored together.

use ferret_plan::Search;
use ferret_world::distance::Place;

use super::replies::{Begun, ReplyTo, RequestClaim};
use super::tasks::{destination_state, requested_task, trial_spec};
use super::trials::{next_container, trial_state};
use super::{Service, json, now_ms};
use crate::api::{StartTrial, TaskBody};
use crate::error::{ApiError, ErrorKind, plan_error};
use crate::model::{ApiReply, DeploymentSpec, Outcome, StoredTrial, TrialStatus};
use crate::searches::{LiveSearch, Owner};
use crate::store::{Final, NewTrial, Writer};

impl Service {
    /// `POST /deployments/{id}/trials`. What must be decided under the deployment's lock is
    /// decided there and nothing more: the strategy, chosen from the trials ended so far (the
    /// selector goes on from where this replica kept it, reading the trials since in the same
    /// round trip as the lock), and the trial's place in the deployment's order. The first
    /// container is planned once the trial is stored, without the lock, since planning can
    /// take a while and every start and end of the deployment waits for it. So a start is never
    /// refused or made again for being overtaken by other robots' trials. Starts of one
    /// deployment that wait for its lock on this replica are stored together, by one of them,
    /// in one transaction: the deployment is then held once for all of them.
    pub fn start_trial(
        &self,
        deployment: i64,
        req: StartTrial,
        body: &[u8],
    ) -> Result<ApiReply, ApiError> {
        let route = format!("POST /deployments/{deployment}/trials");
        let claim = match self.begin(req.request_id.as_deref(), &route, body)? {
            Begun::Replied(reply) => return self.planned_start(reply, None, None),
            Begun::Fresh(claim) => claim,
        };
        let spec = self.spec(deployment)?;
        // The route's resource is the deployment (404 when missing); a scene named in the body
        // that does not exist makes the body unusable: 422.
        let placed = self.placed(&req.scene, req.pose).map_err(|e| {
            if e.kind == ErrorKind::NotFound {
                ApiError::new(ErrorKind::Invalid, e.field, e.message)
            } else {
                e
            }
        })?;
        let asked = Asked::from(requested_task(&req, &placed)?);
        self.check_team(&req)?;
        self.stored_candidates(deployment, &spec)?;
        // Made alone: the trial as stored is kept, so that planning it needs no read.
        let alone = || {
            let started = std::cell::RefCell::new(None);
            let stored = claim.complete_with(&route, body, |w| {
                let (mut trials, finals) =
                    self.store_starts(w, deployment, &spec, &[(&req, &asked)])?;
                let trial = trials
                    .pop()
                    .ok_or_else(|| ApiError::internal("a start stored no trial"))?;
                let reply = unplanned(trial.id);
                started.replace(Some(trial));
                Ok((reply, finals))
            })?;
            Ok::<_, ApiError>((stored, started.into_inner().filter(|_| claim.wrote())))
        };
        // Robots sharing a deployment start trials at once: those that wait for the lock on
        // this replica are made together by one of them (a sequential deployment's starts,
        // one at a time by definition, are not).
        let gathered = if spec.sequential {
            Gathered::Alone
        } else {
            let job = StartJob {
                req: req.clone(),
                asked: asked.clone(),
                reply_to: claim.reply_to(&route, body),
            };
            self.starts.run(
                &deployment,
                job,
                |jobs| match jobs.len() {
                    // This request's own, the only one waiting.
                    1 => vec![match alone() {
                        Ok((stored, trial)) => Gathered::Started(stored, trial.map(Box::new)),
                        Err(e) => Gathered::Failed(e),
                    }],
                    _ => self.start_together(deployment, &spec, &jobs),
                },
                || Gathered::Alone,
            )
        };
        let (stored, known) = match gathered {
            Gathered::Started(stored, trial) => (stored, trial.map(|t| *t)),
            Gathered::Failed(e) => return Err(e),
            Gathered::Alone => alone()?,
        };
        self.planned_start(stored, Some(&claim), known)
    }

    /// Starts of one deployment that waited for each other, stored in one transaction: one
    /// lock, one read, one commit. Every start gets the choice it would have got alone in
    /// this order. Should a statement fail (a request whose reply another replica stored
    /// meanwhile), nothing is stored and each start is made alone.
    fn start_together(
        &self,
        deployment: i64,
        spec: &DeploymentSpec,
        jobs: &[StartJob],
    ) -> Vec<Gathered> {
        let reqs: Vec<(&StartTrial, &Asked)> = jobs.iter().map(|j| (&j.req, &j.asked)).collect();
        let done = self.store.write_finishing(|w| {
            let (trials, mut finals) = self.store_starts(w, deployment, spec, &reqs)?;
            let mut started = Vec::with_capacity(trials.len());
            for (trial, job) in trials.into_iter().zip(jobs) {
                let reply = unplanned(trial.id);
                if let Some(to) = &job.reply_to {
                    finals.push(to.store(&reply));
                }
                started.push(Gathered::Started(reply, Some(Box::new(trial))));
            }
            Ok::<_, ApiError>((started, finals))
        });
        match done {
            Ok(Ok(started)) => {
                tracing::debug!(
                    deployment,
                    starts = jobs.len(),
                    "trial starts stored together"
                );
                started
            }
            Ok(Err(failed)) => {
                tracing::debug!(deployment, error = %failed.error, "trial starts stored together failed; each is made alone");
                self.selectors.forget(deployment);
                jobs.iter().map(|_| Gathered::Alone).collect()
            }
            Err(e) => {
                self.selectors.forget(deployment);
                jobs.iter().map(|_| Gathered::Failed(e.clone())).collect()
            }
        }
    }

    /// Under deployment `deployment`'s lock (taken here), the choices for trials started by
    /// `reqs` in this order and their places in the deployment's order; returns the trials and
    /// the statements that store them, to run with the commit. What must be decided under the
    /// lock is decided here and nothing more.
    fn store_starts(
        &self,
        w: &Writer<'_>,
        deployment: i64,
        spec: &DeploymentSpec,
        reqs: &[(&StartTrial, &Asked)],
    ) -> Result<(Vec<StoredTrial>, Vec<Final>), ApiError> {
        let mark = self.selectors.mark(deployment);
        let now = w
            .lock_deployment_since(deployment, (mark.started, mark.ended), reqs.len())?
            .ok_or_else(|| {
                ApiError::new(
                    ErrorKind::NotFound,
                    "deployment",
                    format!("no deployment {deployment}"),
                )
            })?;
        let choices = self
            .selectors
            .choose(deployment, spec, reqs.len(), |started, ended| {
                if (started, ended) == (mark.started, mark.ended) {
                    Ok(now.since.clone())
                } else {
                    Ok(w.reader().trials_since(deployment, started, ended)?)
                }
            })?;
        if spec.sequential && choices.first().is_some_and(|(_, counts)| counts.open > 0) {
            check_sequential(deployment, w.reader().open_trial(deployment)?)?;
        }
        let mut trials = Vec::with_capacity(reqs.len());
        let mut finals = Vec::with_capacity(reqs.len());
        let heard_ms = now_ms();
        for (((req, asked), (chosen, counts)), id) in reqs.iter().zip(choices).zip(now.next_trials)
        {
            let new = NewTrial {
                deployment,
                k: counts.started as i64 + 1,
                scene: &req.scene,
                target: &asked.label,
                pose: req.pose,
                chosen,
                started_after: counts.ended as i64,
                task: asked.task.as_ref(),
                robots: req.robots.as_deref(),
                robot: req.robot.as_deref(),
                heard_ms,
            };
            finals.push(w.insert_trial_last(id, &new));
            trials.push(StoredTrial {
                id,
                deployment,
                k: new.k,
                scene: req.scene.clone(),
                target: asked.label.clone(),
                pose: req.pose,
                chosen,
                status: TrialStatus::Searching,
                cost: None,
                replays: None,
                started_after: new.started_after,
                end_seq: None,
                task: asked.task.clone(),
                robots: req.robots.clone(),
                robot: req.robot.clone(),
                heard_ms: Some(heard_ms),
            });
        }
        Ok((trials, finals))
    }

    /// The reply to a trial's start from what was stored for it: the trial as it started
    /// (`known` when this request stored it, else read), with its first container planned now.
    /// The reply stored with the trial names the trial only (planning waits until the
    /// deployment is let go); once planned it is stored whole, under the request's `claim`, so
    /// that a retry gets these very bytes. A retry that finds only the trial's name (the server
    /// stopped in between) plans it again, to the same reply.
    fn planned_start(
        &self,
        stored: ApiReply,
        claim: Option<&RequestClaim<'_>>,
        known: Option<StoredTrial>,
    ) -> Result<ApiReply, ApiError> {
        let Some(id) = unplanned_trial(&stored.body) else {
            return Ok(stored);
        };
        let row = match known {
            Some(row) if row.id == id => row,
            _ => self.trial_row(id)?,
        };
        if row.robots.is_some() {
            // Each robot of a team asks for its own first container.
            let state = self.team_state_now(&row)?;
            let reply = json(Outcome::Created, &state)?;
            if let Some(claim) = claim {
                claim.replace(&reply)?;
            }
            self.told(state, None);
            return Ok(reply);
        }
        let spec = self.spec(row.deployment)?;
        let candidates = self.stored_candidates(row.deployment, &spec)?;
        let strategy = candidates
            .get(row.chosen)
            .cloned()
            .ok_or_else(|| ApiError::internal(format!("trial {id}: no strategy {}", row.chosen)))?;
        let placed = self.placed(&row.scene, row.pose)?;
        let owner = Owner {
            placed: placed.clone(),
            trial: trial_spec(&row, &placed)?,
            strategy,
        };
        let mut live = LiveSearch::try_new(owner, |o| {
            let problem = o.placed.problem(&o.trial);
            Search::start(o.strategy.as_ref(), &problem, None).map_err(plan_error)
        })?;
        let (next, destination) = live.with_dependent_mut(|owner, search| {
            let next = search
                .next_container()
                .map_err(plan_error)?
                .map(|c| next_container(&placed, Place::Start, c));
            let destination =
                destination_state(row.task.as_ref(), &owner.placed, search.destination(), None);
            Ok::<_, ApiError>((next, destination))
        })?;
        let language = self.language(&row.scene, &spec);
        let state = trial_state(&row, &spec, &[], 0.0, (next, destination), language);
        let reply = json(Outcome::Created, &state)?;
        if let Some(claim) = claim {
            claim.replace(&reply)?;
        }
        self.searches.keep(id, 0, live);
        self.told(state, None);
        Ok(reply)
    }
}

/// What is stored as the reply to a trial's start until its first container is planned.
fn unplanned(trial: i64) -> ApiReply {
    ApiReply {
        outcome: Outcome::Created,
        body: serde_json::json!({ UNPLANNED: trial }).to_string(),
    }
}

/// A trial's start waiting to be stored with others of its deployment.
pub(crate) struct StartJob {
    req: StartTrial,
    asked: Asked,
    reply_to: Option<ReplyTo>,
}

/// What a start asks for, checked: the name its row keeps as the target, and its task.
#[derive(Clone, Debug)]
pub(crate) struct Asked {
    label: String,
    task: Option<TaskBody>,
}

impl From<(String, Option<TaskBody>)> for Asked {
    fn from((label, task): (String, Option<TaskBody>)) -> Self {
        Self { label, task }
    }
}

/// What became of a gathered start.
pub(crate) enum Gathered {
    /// Stored: the reply stored for it (naming the trial) and the trial, when this write
    /// stored it (not when a reply stored before was found).
    Started(ApiReply, Option<Box<StoredTrial>>),
    /// Not stored: to be made alone.
    Alone,
    /// Refused, or the database failed.
    Failed(ApiError),
}

/// The trial named by a stored reply that waits for its plan.
fn unplanned_trial(body: &str) -> Option<i64> {
    // A planned reply is a trial's state, which never has this key.
    if !body.contains(UNPLANNED) {
        return None;
    }
    serde_json::from_str::<serde_json::Value>(body).ok()?[UNPLANNED].as_i64()
}

/// The key of [`unplanned`] replies.
const UNPLANNED: &str = "unplanned_trial";

/// 409 naming the trial of a sequential deployment still searching, if there is one.
fn check_sequential(deployment: i64, open: Option<i64>) -> Result<(), ApiError> {
    match open {
        Some(open) => Err(ApiError::new(
            ErrorKind::Conflict,
            "deployment",
            format!(
                "trial {open} of deployment {deployment} is still searching and the deployment is sequential; finish it first"
            ),
        )),
        None => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use ferret_plan::{PlannerConfig, StrategyRegistry};
    use ferret_select::{LiveDeployment, Method};
    use ferret_world::GridParams;

    use super::*;
    use crate::model::StoredReply;
    use crate::store::{Store, store_reply};

    const BODY: &[u8] = br#"{"scene": "flat", "target": "Wallet"}"#;

    fn job(request_id: Option<&str>, route: &str) -> StartJob {
        StartJob {
            req: StartTrial {
                request_id: request_id.map(str::to_string),
                scene: "flat".into(),
                target: Some("Wallet".into()),
                targets: None,
                goal: None,
                destination: None,
                pose: None,
                robots: None,
                robot: None,
            },
            asked: Asked {
                label: "Wallet".into(),
                task: None,
            },
            reply_to: request_id.map(|id| ReplyTo::new(id, route, BODY)),
        }
    }

    /// Starts stored together get the choices one start after another would get and the
    /// replies that name their trials; when one of them cannot be stored (its request was
    /// answered meanwhile, by another replica), none is, and each is made alone.
    #[test]
    fn starts_stored_together_or_none_of_them() {
        let registry = StrategyRegistry::builtin(None, PlannerConfig::default(), 10);
        let strategies = ["optimistic+greedy", "model/uniform", "model/uniform/k2"]
            .iter()
            .map(|s| registry.build(s).unwrap())
            .collect();
        let s = Service::new(
            Store::in_memory().unwrap(),
            GridParams::default(),
            strategies,
        )
        .unwrap();
        let created = s
            .create_deployment(serde_json::from_str("{}").unwrap(), b"{}")
            .unwrap();
        let deployment = serde_json::from_str::<serde_json::Value>(&created.body).unwrap()["id"]
            .as_i64()
            .unwrap();
        let spec = s.spec(deployment).unwrap();
        let route = format!("POST /deployments/{deployment}/trials");
        let answered = StoredReply {
            fingerprint: String::new(),
            outcome: Outcome::Created,
            body: "answered by another replica".into(),
        };
        s.store
            .write_finishing(|_| Ok::<_, ApiError>(((), vec![store_reply("dup", &answered)])))
            .unwrap()
            .unwrap();

        let jobs = [
            job(Some("a"), &route),
            job(Some("dup"), &route),
            job(None, &route),
        ];
        let made = s.start_together(deployment, &spec, &jobs);
        assert!(made.iter().all(|g| matches!(g, Gathered::Alone)));
        assert!(
            s.store
                .read(|r| r.trials_of(deployment))
                .unwrap()
                .is_empty()
        );
        assert_eq!(s.store.read(|r| r.reply("a")).unwrap(), None);

        let jobs = [
            job(Some("a"), &route),
            job(None, &route),
            job(Some("b"), &route),
        ];
        let made = s.start_together(deployment, &spec, &jobs);
        let mut live = LiveDeployment::new(Method::ReplaySelection, 3, 5.0, 0).unwrap();
        for (k, (g, j)) in made.iter().zip(&jobs).enumerate() {
            let Gathered::Started(reply, Some(trial)) = g else {
                panic!("start {k} was not stored");
            };
            assert_eq!(trial.k, k as i64 + 1);
            assert_eq!(trial.chosen, live.choose_overlapping(), "start {k}");
            assert_eq!(*reply, unplanned(trial.id));
            if let Some(id) = &j.req.request_id {
                let stored = s.store.read(|r| r.reply(id)).unwrap().unwrap();
                assert_eq!(stored.body, reply.body);
            }
        }
        let stored = s.store.read(|r| r.trials_of(deployment)).unwrap();
        assert_eq!(stored.len(), 3);
    }
}
