//! Trials after their start: one observation per searched container until the target is found
//! (the other candidates replayed and the selector credited) or every container was searched.
//! A trial's search is rebuilt from its stored observations on every request.

use std::sync::Arc;

use ferret_plan::{Search, Strategy, TrialSpec, hindsight_truth, replay_costs};
use ferret_world::ObjectType;
use ferret_world::distance::Place;

use super::deployments::ROBOT_REPLAY;
use super::replies::Begun;
use super::{Service, json};
use crate::api::{
    AbandonTrial, MAX_OBJECTS, MAX_TRAVELLED_M, NextContainer, ObservationInfo, Observe,
    TrialState, TrialView, is_type_name,
};
use crate::error::{ApiError, ErrorKind, plan_error};
use crate::grids::Placed;
use crate::model::{
    ApiReply, DeploymentSpec, Outcome, StoredObservation, StoredTrial, TrialStatus,
};
use crate::searches::{LiveSearch, Owner};
use crate::store::{TrialEnding, Writer};

impl Service {
    pub(super) fn trial_row(&self, id: i64) -> Result<StoredTrial, ApiError> {
        self.store
            .read(|r| r.trial(id))?
            .ok_or_else(|| ApiError::new(ErrorKind::NotFound, "trial", format!("no trial {id}")))
    }

    /// What a stored trial's next step needs, read from the store.
    fn stored_trial(&self, row: &StoredTrial) -> Result<LoadedTrial, ApiError> {
        let observations = self.store.read(|r| r.observations(row.id))?;
        let spec = self.spec(row.deployment)?;
        let candidates = self.stored_candidates(row.deployment, &spec)?;
        let strategy = candidates.get(row.chosen).cloned().ok_or_else(|| {
            ApiError::internal(format!("trial {}: no strategy {}", row.id, row.chosen))
        })?;
        Ok(LoadedTrial {
            observations,
            placed: self.placed(&row.scene, row.pose)?,
            trial: TrialSpec::single(ObjectType::new(row.target.clone())),
            strategy,
            candidates,
            spec,
        })
    }

    /// `GET /trials/{id}`.
    pub fn get_trial(&self, id: i64) -> Result<ApiReply, ApiError> {
        let row = self.trial_row(id)?;
        let t = self.stored_trial(&row)?;
        json(Outcome::Done, &Self::state_of(&row, &t)?)
    }

    /// The state of a stored trial, planned again from its observations (the next container
    /// while it searches).
    fn state_of(row: &StoredTrial, t: &LoadedTrial) -> Result<TrialState, ApiError> {
        let mut search = t.search()?;
        let next = match row.status {
            TrialStatus::Searching => {
                let from = search.belief().position();
                search
                    .next_container()
                    .map_err(plan_error)?
                    .map(|c| next_container(&t.placed, from, c))
            }
            _ => None,
        };
        let travelled = search.belief().travelled();
        Ok(trial_state(row, &t.spec, &t.observations, travelled, next))
    }

    /// `GET /trials/{id}/view`: the trial with its way so far, what it saw and its likelihoods
    /// now, for a picture of it.
    /// A trial just written (the last observation of the trial a page watches) is not
    /// planned again: its state is the one the write answered.
    pub fn trial_view(&self, id: i64) -> Result<ApiReply, ApiError> {
        let row = self.trial_row(id)?;
        let t = self.stored_trial(&row)?;
        let state = match self.recent.get(id, t.observations.len(), row.status) {
            Some(kept) => TrialState::clone(&kept),
            None => Self::state_of(&row, &t)?,
        };
        let house = &t.placed.house;
        let mut searched = Vec::with_capacity(t.observations.len());
        for o in &t.observations {
            let c = house.container_index(&o.container).ok_or_else(|| {
                ApiError::internal(format!(
                    "trial {id}: stored container {:?} is not in the scene",
                    o.container
                ))
            })?;
            searched.push((c, o.found));
        }
        let start = super::scenes::start_pose(house);
        let mut route = vec![[start[0], start[1]]];
        let mut from = Place::Start;
        for &(c, _) in &searched {
            let to = Place::Container(c);
            // Each leg begins where the last ended.
            route.extend(t.placed.path(from, to).iter().skip(1).copied());
            from = to;
        }
        let likelihoods = match t.strategy.likelihood_source() {
            Some(source) => {
                let mut ps: Vec<f64> = source
                    .likelihoods(house, t.trial.task.first())
                    .map_err(plan_error)?
                    .iter()
                    .map(|p| p.get())
                    .collect();
                for &(c, found) in &searched {
                    if let Some(p) = ps.get_mut(c) {
                        *p = if found { 1.0 } else { 0.0 };
                    }
                }
                Some(
                    house
                        .containers
                        .iter()
                        .zip(ps)
                        .map(|(c, p)| (c.id.clone(), p))
                        .collect(),
                )
            }
            None => None,
        };
        let view = TrialView {
            trial: state,
            start,
            route,
            observations: t
                .observations
                .iter()
                .map(|o| ObservationInfo {
                    container: o.container.clone(),
                    found: o.found,
                    objects: o.objects.clone(),
                })
                .collect(),
            likelihoods,
        };
        json(Outcome::Done, &view)
    }

    /// `POST /trials/{id}/observations`.
    pub fn record_observation(
        &self,
        id: i64,
        req: Observe,
        body: &[u8],
    ) -> Result<ApiReply, ApiError> {
        let route = format!("POST /trials/{id}/observations");
        let claim = match self.begin(req.request_id.as_deref(), &route, body)? {
            Begun::Replied(reply) => return Ok(reply),
            Begun::Fresh(claim) => claim,
        };
        let row = self.trial_row(id)?;
        check_searching(&row)?;
        if req.objects.len() > MAX_OBJECTS {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "objects",
                format!("{} object types; at most {MAX_OBJECTS}", req.objects.len()),
            ));
        }
        for (i, o) in req.objects.iter().enumerate() {
            if !is_type_name(o) {
                return Err(ApiError::new(
                    ErrorKind::Invalid,
                    format!("objects[{i}]"),
                    format!("{o:?} is not a CamelCase object type"),
                ));
            }
        }
        if let Some(t) = req.travelled_m
            && !(t.is_finite() && (0.0..=MAX_TRAVELLED_M).contains(&t))
        {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "travelled_m",
                format!("{t}: must be a distance from 0 to {MAX_TRAVELLED_M} m"),
            ));
        }
        let t = self.stored_trial(&row)?;
        let (observations, spec, candidates, placed) =
            (&t.observations, &t.spec, &t.candidates, &t.placed);
        let house = &placed.house;
        let c = house.container_index(&req.container).ok_or_else(|| {
            ApiError::new(
                ErrorKind::Invalid,
                "container",
                format!(
                    "{:?} is not a container of scene {:?}",
                    req.container, row.scene
                ),
            )
        })?;
        let target = t.trial.task.first();
        // The search this replica kept after the trial's last reply, else one rebuilt.
        let mut live = match self.searches.take(id, observations.len()) {
            Some(live) => live,
            None => t.live_search()?,
        };
        let mut seen: Vec<ObjectType> = req
            .objects
            .iter()
            .map(|o| ObjectType::new(o.clone()))
            .collect();
        if req.found && !seen.contains(target) {
            seen.push(target.clone());
        }
        let (leg, cost, upcoming) = live.with_dependent_mut(|_, search| {
            if search.belief().is_searched(c) {
                return Err(ApiError::new(
                    ErrorKind::Conflict,
                    "container",
                    format!("{:?} was already searched in trial {id}", req.container),
                ));
            }
            let leg = search.record(c, seen).map_err(plan_error)?;
            let cost = search.belief().travelled();
            let upcoming = if req.found {
                None
            } else {
                let from = search.belief().position();
                Some(
                    search
                        .next_container()
                        .map_err(plan_error)?
                        .map(|n| (from, n)),
                )
            };
            Ok((leg, cost, upcoming))
        })?;
        let observation = StoredObservation {
            container: req.container.clone(),
            found: req.found,
            objects: req.objects.clone(),
            travelled: req.travelled_m,
            leg,
        };
        let (status, next, replays) = if req.found {
            let truth = hindsight_truth(house, &t.trial.task, &[Some(c)]).map_err(plan_error)?;
            let replays = replay_costs(
                ROBOT_REPLAY,
                candidates,
                &placed.problem(&t.trial),
                &truth,
                &[Some(c)],
                (row.chosen, cost),
            )
            .map_err(plan_error)?;
            (TrialStatus::Done, None, Some(replays))
        } else {
            match upcoming.flatten() {
                Some((from, n)) => (
                    TrialStatus::Searching,
                    Some(next_container(placed, from, n)),
                    None,
                ),
                None => (TrialStatus::Exhausted, None, None),
            }
        };
        let mut told = None;
        let reply = claim.complete_with(&route, body, |w| {
            // Every observation holds its trial's row, so one observation per sequence number
            // is kept; an end then holds its deployment's too (the order trials end in is the
            // deployment's history, which starts are chosen from), taken by a statement that
            // goes with the commit, since every start and end of the deployment waits for it.
            // Steps, most of a fleet's requests, leave the deployment free.
            lock_unchanged(w, id, observations.len(), "this observation was planned")?;
            let last = w.record_and_end_last(
                (id, row.deployment),
                Some((observations.len(), &observation)),
                (status != TrialStatus::Searching).then_some(TrialEnding {
                    status,
                    cost,
                    replays: replays.as_deref(),
                }),
            );
            let mut all = observations.clone();
            all.push(observation.clone());
            let mut updated = row.clone();
            updated.status = status;
            updated.cost = (status != TrialStatus::Searching).then_some(cost);
            updated.replays = replays.clone();
            let state = trial_state(&updated, spec, &all, cost, next.clone());
            let reply = json(Outcome::Done, &state)?;
            told = Some(state);
            Ok((reply, last))
        });
        if reply.is_ok()
            && let Some(state) = told
        {
            self.told(
                state,
                Some(ObservationInfo {
                    container: observation.container.clone(),
                    found: observation.found,
                    objects: observation.objects.clone(),
                }),
            );
        }
        if reply.is_ok() && status == TrialStatus::Searching {
            self.searches.keep(id, observations.len() + 1, live);
        } else {
            self.searches.forget(id);
        }
        reply
    }

    /// `POST /trials/{id}/abandon`: ends a trial still searching without a cost to learn
    /// from, as a trial that searched every container does, so that a robot whose search
    /// failed does not leave it open (a sequential deployment would take no other trial).
    pub fn abandon_trial(
        &self,
        id: i64,
        req: AbandonTrial,
        body: &[u8],
    ) -> Result<ApiReply, ApiError> {
        let route = format!("POST /trials/{id}/abandon");
        let claim = match self.begin(req.request_id.as_deref(), &route, body)? {
            Begun::Replied(reply) => return Ok(reply),
            Begun::Fresh(claim) => claim,
        };
        let row = self.trial_row(id)?;
        check_searching(&row)?;
        let observations = self.store.read(|r| r.observations(id))?;
        let spec = self.spec(row.deployment)?;
        let cost: f64 = observations.iter().map(|o| o.leg).sum();
        let mut told = None;
        let reply = claim.complete_with(&route, body, |w| {
            // As any trial's end: the trial's row, then the deployment's.
            lock_unchanged(w, id, observations.len(), "it was being abandoned")?;
            let last = w.record_and_end_last(
                (id, row.deployment),
                None,
                Some(TrialEnding {
                    status: TrialStatus::Abandoned,
                    cost,
                    replays: None,
                }),
            );
            let mut ended = row.clone();
            ended.status = TrialStatus::Abandoned;
            ended.cost = Some(cost);
            let state = trial_state(&ended, &spec, &observations, cost, None);
            let reply = json(Outcome::Done, &state)?;
            told = Some(state);
            Ok((reply, last))
        });
        self.searches.forget(id);
        if reply.is_ok()
            && let Some(state) = told
        {
            self.told(state, None);
        }
        reply
    }
}

/// Locks trial `id` and checks it is still searching with the `seen` observations it was read
/// with; 409 when another request changed it while `meanwhile`.
fn lock_unchanged(w: &Writer<'_>, id: i64, seen: usize, meanwhile: &str) -> Result<(), ApiError> {
    if w.lock_trial_progress(id)? == Some((TrialStatus::Searching, seen)) {
        return Ok(());
    }
    Err(ApiError::new(
        ErrorKind::Conflict,
        "trial",
        format!("the trial changed while {meanwhile}; read it and retry"),
    ))
}

/// 409 for a trial that has ended.
fn check_searching(row: &StoredTrial) -> Result<(), ApiError> {
    if row.status == TrialStatus::Searching {
        return Ok(());
    }
    Err(ApiError::new(
        ErrorKind::Conflict,
        "trial",
        format!("trial {} has ended ({})", row.id, row.status.as_str()),
    ))
}

/// A stored trial with what it needs to plan its next step.
struct LoadedTrial {
    observations: Vec<StoredObservation>,
    spec: DeploymentSpec,
    candidates: Vec<Arc<dyn Strategy>>,
    strategy: Arc<dyn Strategy>,
    placed: Arc<Placed>,
    trial: TrialSpec,
}

impl LoadedTrial {
    /// The trial's search replayed up to its last observation, owning what it borrows.
    fn live_search(&self) -> Result<LiveSearch, ApiError> {
        let owner = Owner {
            placed: self.placed.clone(),
            trial: self.trial.clone(),
            strategy: self.strategy.clone(),
        };
        LiveSearch::try_new(owner, |o| {
            rebuild(o.strategy.as_ref(), &o.placed, &o.trial, &self.observations)
        })
    }

    /// The trial's search, replayed up to its last observation.
    fn search(&self) -> Result<Search<'_>, ApiError> {
        rebuild(
            self.strategy.as_ref(),
            &self.placed,
            &self.trial,
            &self.observations,
        )
    }
}

/// The trial's search rebuilt from its stored observations.
fn rebuild<'a>(
    strategy: &'a dyn Strategy,
    placed: &'a Placed,
    trial: &'a TrialSpec,
    observations: &[StoredObservation],
) -> Result<Search<'a>, ApiError> {
    let problem = placed.problem(trial);
    let mut search = Search::start(strategy, &problem, None).map_err(plan_error)?;
    for o in observations {
        let c = placed.house.container_index(&o.container).ok_or_else(|| {
            ApiError::internal(format!(
                "stored container {:?} is not in the scene",
                o.container
            ))
        })?;
        let mut seen: Vec<ObjectType> = o
            .objects
            .iter()
            .map(|t| ObjectType::new(t.clone()))
            .collect();
        if o.found && !seen.contains(trial.task.first()) {
            seen.push(trial.task.first().clone());
        }
        search.record(c, seen).map_err(plan_error)?;
    }
    Ok(search)
}

fn trial_state(
    row: &StoredTrial,
    spec: &DeploymentSpec,
    observations: &[StoredObservation],
    cost: f64,
    next: Option<NextContainer>,
) -> TrialState {
    let reported: Vec<f64> = observations.iter().filter_map(|o| o.travelled).collect();
    TrialState {
        trial: row.id,
        deployment: row.deployment,
        k: row.k,
        scene: row.scene.clone(),
        target: row.target.clone(),
        strategy: spec.strategies.get(row.chosen).cloned().unwrap_or_default(),
        status: row.status,
        searched: observations.iter().map(|o| o.container.clone()).collect(),
        cost_m: row.cost.unwrap_or(cost),
        travelled_m: (!reported.is_empty()).then(|| reported.iter().sum()),
        next,
        replays_m: row.replays.as_ref().map(|r| {
            spec.strategies
                .iter()
                .cloned()
                .zip(r.iter().copied())
                .collect()
        }),
    }
}

pub(super) fn next_container(placed: &Placed, from: Place, c: usize) -> NextContainer {
    let house = &placed.house;
    let container = &house.containers[c];
    let to = Place::Container(c);
    NextContainer {
        container: container.id.clone(),
        object_type: container.object_type.to_string(),
        room: house.container_room(c).map(|r| r.id.clone()),
        x: container.position.x,
        y: container.position.z,
        distance_m: placed.distances.between(from, to),
        path: placed.path(from, to).to_vec(),
    }
}
