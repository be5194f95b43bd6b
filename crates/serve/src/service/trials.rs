//! Trials after their start: one observation per searched container until the target is found
//! (the other candidates replayed and the selector credited) or every container was searched.
//! A trial's search is rebuilt from its stored observations on every request.

use std::sync::Arc;

use std::collections::BTreeMap;

use ferret_plan::{MAX_TARGETS, Search, Strategy, TrialSpec, hindsight_truth, replay_costs};
use ferret_world::ObjectType;
use ferret_world::distance::Place;

use super::tasks::{destination_state, found_in, goal_of, seen, targets_of, trial_spec};

use super::deployments::ROBOT_REPLAY;
use super::replies::Begun;
use super::{Service, json, now_ms};
use crate::api::{
    AbandonTrial, DestinationState, MAX_OBJECTS, MAX_TRAVELLED_M, NextContainer, ObservationInfo,
    Observe, TrialState, TrialView, is_type_name,
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
        let placed = self.placed(&row.scene, row.pose)?;
        Ok(LoadedTrial {
            language: self.language(&row.scene, &spec),
            observations,
            trial: trial_spec(row, &placed)?,
            placed,
            strategy,
            candidates,
            spec,
        })
    }

    /// `GET /trials/{id}`.
    pub fn get_trial(&self, id: i64) -> Result<ApiReply, ApiError> {
        let row = self.trial_row(id)?;
        if row.robots.is_some() {
            return json(Outcome::Done, &self.team_state_now(&row)?);
        }
        let t = self.stored_trial(&row)?;
        json(Outcome::Done, &Self::state_of(&row, &t)?)
    }

    /// The state of a stored trial, planned again from its observations (the next container
    /// while it searches).
    fn state_of(row: &StoredTrial, t: &LoadedTrial) -> Result<TrialState, ApiError> {
        let mut search = t.search()?;
        let from = search.belief().position();
        let next = match row.status {
            TrialStatus::Searching => search
                .next_container()
                .map_err(plan_error)?
                .map(|c| next_container(&t.placed, from, c)),
            _ => None,
        };
        // A search that ended (not given up) went on to its destination from there.
        let ended_at =
            matches!(row.status, TrialStatus::Done | TrialStatus::Exhausted).then_some(from);
        let destination =
            destination_state(row.task.as_ref(), &t.placed, search.destination(), ended_at);
        let travelled = search.belief().travelled();
        Ok(trial_state(
            row,
            &t.spec,
            &t.observations,
            travelled,
            (next, destination),
            t.language.clone(),
        ))
    }

    /// `GET /trials/{id}/view`: the trial with its way so far, what it saw and its likelihoods
    /// now, for a picture of it.
    /// A trial just written (the last observation of the trial a page watches) is not
    /// planned again: its state is the one the write answered.
    pub fn trial_view(&self, id: i64) -> Result<ApiReply, ApiError> {
        let row = self.trial_row(id)?;
        let t = self.stored_trial(&row)?;
        // A team's claims change without an observation: its state is always read anew.
        let state = match self.recent.get(id, t.observations.len(), row.status) {
            Some(kept) if row.robots.is_none() => TrialState::clone(&kept),
            _ if row.robots.is_some() => self.team_state_now(&row)?,
            _ => Self::state_of(&row, &t)?,
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
        // A team's searches are no one robot's way.
        let own_way = if row.robots.is_some() {
            &[][..]
        } else {
            &searched[..]
        };
        for &(c, _) in own_way {
            let to = Place::Container(c);
            // Each leg begins where the last ended.
            route.extend(t.placed.path(from, to).iter().skip(1).copied());
            from = to;
        }
        if let Some(way) = state.destination.as_ref().and_then(|d| d.path.as_ref()) {
            route.extend(way.iter().skip(1).copied());
        }
        let (likelihoods, target_likelihoods) =
            view_likelihoods(t.strategy.as_ref(), house, &state, &searched)?;
        let robot_routes = match row.robots {
            Some(_) => Some(self.team_routes(&row, &state)?),
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
            target_likelihoods,
            robot_routes,
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
        let targets = targets_of(&row);
        let (objects, found) = observed(&req, &targets)?;
        if row.robots.is_some() {
            return self.record_team_observation((&row, &req, body), (c, objects, found), claim);
        }
        if let Some(robot) = &req.robot {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "robot",
                format!("{robot:?}: trial {id} is searched by one robot and has no team"),
            ));
        }
        // The search this replica kept after the trial's last reply, else one rebuilt.
        let mut live = match self.searches.take(id, observations.len()) {
            Some(live) => live,
            None => t.live_search()?,
        };
        let observation = StoredObservation {
            container: req.container.clone(),
            found,
            objects,
            travelled: req.travelled_m,
            leg: 0.0,
            robot: None,
        };
        let seen = seen(&observation, &targets);
        let task = row.task.as_ref();
        let (leg, cost, step) = live.with_dependent_mut(|owner, search| {
            if search.belief().is_searched(c) {
                return Err(ApiError::new(
                    ErrorKind::Conflict,
                    "container",
                    format!("{:?} was already searched in trial {id}", req.container),
                ));
            }
            let leg = search.record(c, seen).map_err(plan_error)?;
            let from = search.belief().position();
            let step = if search.goal_holds() {
                search.finish();
                Step::Done(search.belief().found_each().to_vec())
            } else {
                match search.next_container().map_err(plan_error)? {
                    Some(n) => Step::Next(from, n),
                    None => {
                        // Everything searched: the robot goes to the destination empty-handed.
                        search.finish();
                        Step::Exhausted
                    }
                }
            };
            let ended_at = (!matches!(step, Step::Next(..))).then_some(from);
            let destination =
                destination_state(task, &owner.placed, search.destination(), ended_at);
            Ok((leg, search.belief().travelled(), (step, destination)))
        })?;
        let (step, destination) = step;
        let observation = StoredObservation { leg, ..observation };
        let (status, next, replays) = match step {
            Step::Done(found_each) => {
                let truth =
                    hindsight_truth(house, &t.trial.task, &found_each).map_err(plan_error)?;
                let replays = replay_costs(
                    ROBOT_REPLAY,
                    candidates,
                    &placed.problem(&t.trial),
                    &truth,
                    &found_each,
                    (row.chosen, cost),
                )
                .map_err(plan_error)?;
                (TrialStatus::Done, None, Some(replays))
            }
            Step::Next(from, n) => (
                TrialStatus::Searching,
                Some(next_container(placed, from, n)),
                None,
            ),
            Step::Exhausted => (TrialStatus::Exhausted, None, None),
        };
        let language = self.language(&row.scene, spec);
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
                now_ms(),
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
            let state = trial_state(
                &updated,
                spec,
                &all,
                cost,
                (next.clone(), destination.clone()),
                language.clone(),
            );
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
        // A team's cost is its makespan: the longest way any one robot drove.
        let mut ways: BTreeMap<Option<&str>, f64> = BTreeMap::new();
        for o in &observations {
            *ways.entry(o.robot.as_deref()).or_default() += o.leg;
        }
        let cost = ways.values().copied().fold(0.0, f64::max);
        // Where the task would have brought what it found: no way there, the search was given
        // up where the robot is.
        let destination = match &row.task {
            Some(task) if task.destination.is_some() => {
                let placed = self.placed(&row.scene, row.pose)?;
                let trial = trial_spec(&row, &placed)?;
                let legs = trial
                    .task
                    .destination()
                    .and_then(|d| d.legs(&placed.house, &placed.distances).ok());
                destination_state(Some(task), &placed, legs.as_ref(), None)
            }
            _ => None,
        };
        let language = self.language(&row.scene, &spec);
        let mut told = None;
        let reply = claim.complete_with(&route, body, |w| {
            // As any trial's end: the trial's row, then the deployment's.
            lock_unchanged(w, id, observations.len(), "it was being abandoned")?;
            let last = w.record_and_end_last(
                (id, row.deployment),
                now_ms(),
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
            let state = trial_state(
                &ended,
                &spec,
                &observations,
                cost,
                (None, destination.clone()),
                language.clone(),
            );
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

/// A trial's likelihoods now, for its picture: each target's from the strategy's source, 0 in
/// the containers searched without it and 1 where it was found; for several targets, also the
/// chance that a container holds one still wanted (1 where one was found, 0 once the goal
/// holds). `(None, None)` for a strategy without a likelihood source.
type ViewLikelihoods = (
    Option<BTreeMap<String, f64>>,
    Option<BTreeMap<String, BTreeMap<String, f64>>>,
);

fn view_likelihoods(
    strategy: &dyn Strategy,
    house: &ferret_world::House,
    state: &TrialState,
    searched: &[(usize, bool)],
) -> Result<ViewLikelihoods, ApiError> {
    let Some(source) = strategy.likelihood_source() else {
        return Ok((None, None));
    };
    let ids = |ps: Vec<f64>| -> BTreeMap<String, f64> {
        house
            .containers
            .iter()
            .zip(ps)
            .map(|(c, p)| (c.id.clone(), p))
            .collect()
    };
    let mut rows = Vec::with_capacity(state.targets.len());
    for t in &state.targets {
        let mut ps: Vec<f64> = source
            .likelihoods(house, &ObjectType::new(t.as_str()))
            .map_err(plan_error)?
            .iter()
            .map(|p| p.get())
            .collect();
        let found_at = state.found_in.get(t);
        for &(c, _) in searched {
            if let Some(p) = ps.get_mut(c) {
                *p = if found_at == Some(&house.containers[c].id) {
                    1.0
                } else {
                    0.0
                };
            }
        }
        rows.push(ps);
    }
    if let [one] = rows.as_slice() {
        return Ok((Some(ids(one.clone())), None));
    }
    let done = state.status == TrialStatus::Done;
    let found_anything: Vec<bool> = (0..house.containers.len())
        .map(|c| {
            state
                .found_in
                .values()
                .any(|id| *id == house.containers[c].id)
        })
        .collect();
    let wanted: Vec<&Vec<f64>> = state
        .targets
        .iter()
        .zip(&rows)
        .filter(|(t, _)| !state.found_in.contains_key(*t))
        .map(|(_, r)| r)
        .collect();
    let combined: Vec<f64> = (0..house.containers.len())
        .map(|c| {
            if found_anything[c] {
                1.0
            } else if done {
                0.0
            } else {
                1.0 - wanted.iter().map(|r| 1.0 - r[c]).product::<f64>()
            }
        })
        .collect();
    let each = state
        .targets
        .iter()
        .zip(rows)
        .map(|(t, r)| (t.clone(), ids(r)))
        .collect();
    Ok((Some(ids(combined)), Some(each)))
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
    /// What the strategies said of the scene's names.
    language: Vec<String>,
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
        let targets: Vec<String> = trial
            .task
            .targets()
            .iter()
            .map(ToString::to_string)
            .collect();
        search.record(c, seen(o, &targets)).map_err(plan_error)?;
    }
    Ok(search)
}

pub(super) fn trial_state(
    row: &StoredTrial,
    spec: &DeploymentSpec,
    observations: &[StoredObservation],
    cost: f64,
    (next, destination): (Option<NextContainer>, Option<DestinationState>),
    language: Vec<String>,
) -> TrialState {
    let reported: Vec<f64> = observations.iter().filter_map(|o| o.travelled).collect();
    let targets = targets_of(row);
    TrialState {
        trial: row.id,
        deployment: row.deployment,
        k: row.k,
        scene: row.scene.clone(),
        target: row.target.clone(),
        found_in: found_in(observations, &targets),
        targets,
        goal: goal_of(row),
        destination,
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
        robots: None,
        robot: row.robot.clone(),
        language,
    }
}

/// How a search went on after an observation.
enum Step {
    /// The goal holds: where each target was found.
    Done(Vec<Option<usize>>),
    /// Still searching: from where, which container next.
    Next(Place, usize),
    /// Every container searched without the goal holding.
    Exhausted,
}

/// What an observation says was in a container, checked: the object types to keep (those seen,
/// the targets named found among them) and whether a target was found. For a one-target trial
/// `found` says so as before; for a task, the targets found are those named in
/// `found_targets` or `objects`, and `found` without naming one is refused.
fn observed(req: &Observe, targets: &[String]) -> Result<(Vec<String>, bool), ApiError> {
    if req.found_targets.len() > MAX_TARGETS {
        return Err(ApiError::new(
            ErrorKind::Invalid,
            "found_targets",
            format!(
                "{} targets; a task has at most {MAX_TARGETS}",
                req.found_targets.len()
            ),
        ));
    }
    let mut objects = req.objects.clone();
    for (i, t) in req.found_targets.iter().enumerate() {
        if !targets.contains(t) {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                format!("found_targets[{i}]"),
                format!(
                    "{t:?} is not a target of this trial ({})",
                    targets.join(", ")
                ),
            ));
        }
        if !objects.contains(t) {
            objects.push(t.clone());
        }
    }
    let named = targets.iter().any(|t| objects.contains(t));
    let found = match targets {
        [_] => req.found || named,
        _ if req.found && !named => {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "found",
                format!(
                    "found, but no target of this trial ({}) is named: list the targets seen in found_targets",
                    targets.join(", ")
                ),
            ));
        }
        _ => named,
    };
    Ok((objects, found))
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
