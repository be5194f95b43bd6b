//! Teams in the service: a trial searched by several robots at once. Each robot names itself,
//! asks for its next container and reports what it saw; the server plans each robot's next
//! container with its own search (what every teammate saw known at once) and never one a
//! teammate holds, and keeps the claim in the store, so that robots on different replicas of
//! one database never get the same container. A claim lapses when its robot is not heard from
//! for the service's claim time. The planner is `ferret_plan::Search::next_container_leaving`,
//! as in the team simulator; the replays after a team's trial are `ferret_plan::run_team`'s,
//! with the same robots from the same starts.
//!
//! Unlike the simulator, where a robot may make for a container a teammate claimed when it
//! would get there first, the service knows no robot's arrival time, so a claim is its robot's
//! alone until it lapses.

use std::collections::BTreeSet;
use std::sync::Arc;

use ferret_plan::{
    Destination, DestinationLegs, MAX_ROBOTS, Search, Strategy, TrialSpec, replay_team_costs,
};
use ferret_world::distance::Place;

use super::replies::{Begun, RequestClaim};
use super::tasks::{destination_state, seen, targets_of, trial_spec};
use super::trials::{next_container, trial_state};
use super::{Service, json, now_ms};
use crate::api::{
    ClaimNext, NextContainer, Observe, RobotRoute, RobotState, StartTrial, TrialState,
};
use crate::error::{ApiError, ErrorKind, plan_error};
use crate::grids::Placed;
use crate::model::{
    ApiReply, DeploymentSpec, Outcome, StoredObservation, StoredRobot, StoredTrial, TeamRobot,
    TrialStatus,
};
use crate::store::{TrialEnding, Writer};

/// Longest robot id, characters.
pub const MAX_ROBOT_ID: usize = 64;

fn invalid(field: impl Into<String>, message: impl Into<String>) -> ApiError {
    ApiError::new(ErrorKind::Invalid, field, message)
}

/// True for a robot id: 1 to [`MAX_ROBOT_ID`] letters, digits, `_`, `-`, `.` or `/`.
pub(crate) fn is_robot_id(id: &str) -> bool {
    (1..=MAX_ROBOT_ID).contains(&id.len())
        && id
            .bytes()
            .all(|b| b.is_ascii_alphanumeric() || b"_-./".contains(&b))
}

impl Service {
    /// Checks a start's team, if it has one: 1 to [`MAX_ROBOTS`] robots with distinct, well
    /// formed ids, each pose one the scene can place.
    ///
    /// # Errors
    /// 422 naming the field (`robots[1].id`, `robots[0].pose`).
    pub(super) fn check_team(&self, req: &StartTrial) -> Result<(), ApiError> {
        if let Some(robot) = &req.robot
            && !is_robot_id(robot)
        {
            return Err(invalid(
                "robot",
                format!(
                    "{robot:?} is not a robot id: 1 to {MAX_ROBOT_ID} letters, digits, '_', '-', '.' or '/'"
                ),
            ));
        }
        let Some(robots) = &req.robots else {
            return Ok(());
        };
        if req.robot.is_some() {
            return Err(invalid(
                "robot",
                "a team's robots are named in `robots`; `robot` names a robot that searches alone",
            ));
        }
        if robots.is_empty() || robots.len() > MAX_ROBOTS {
            return Err(invalid(
                "robots",
                format!("{} robots: a team has 1 to {MAX_ROBOTS}", robots.len()),
            ));
        }
        let mut ids = BTreeSet::new();
        for (i, r) in robots.iter().enumerate() {
            if !is_robot_id(&r.id) {
                return Err(invalid(
                    format!("robots[{i}].id"),
                    format!(
                        "{:?} is not a robot id: 1 to {MAX_ROBOT_ID} letters, digits, '_', '-', '.' or '/'",
                        r.id
                    ),
                ));
            }
            if !ids.insert(r.id.as_str()) {
                return Err(invalid(
                    format!("robots[{i}].id"),
                    format!(
                        "{:?} is given twice: each robot of a team has its own id",
                        r.id
                    ),
                ));
            }
            if r.pose.is_some() {
                self.placed(&req.scene, r.pose)
                    .map_err(|e| invalid(format!("robots[{i}].pose"), e.message))?;
            }
        }
        Ok(())
    }

    /// A team trial as its robots plan it, read from the store (every robot's placing of the
    /// scene, the trial's task, the strategy).
    fn team_trial(&self, row: &StoredTrial) -> Result<TeamTrial, ApiError> {
        let robots = team_of(row)?.to_vec();
        let spec = self.spec(row.deployment)?;
        let candidates = self.stored_candidates(row.deployment, &spec)?;
        let strategy = candidates.get(row.chosen).cloned().ok_or_else(|| {
            ApiError::internal(format!("trial {}: no strategy {}", row.id, row.chosen))
        })?;
        let home = self.placed(&row.scene, row.pose)?;
        let trial = trial_spec(row, &home)?;
        let mut placed = Vec::with_capacity(robots.len());
        let mut legs = Vec::with_capacity(robots.len());
        for r in &robots {
            let p = match r.pose {
                Some(_) => self.placed(&row.scene, r.pose)?,
                None => home.clone(),
            };
            // "Bring it to me" means the trial's start, wherever this robot started.
            let destination = match trial.task.destination() {
                Some(Destination::Start) if r.pose.is_some() => {
                    let at = home.house.start.position;
                    Some(Destination::Point { x: at.x, z: at.z })
                }
                other => other.cloned(),
            };
            let l = destination
                .map(|d| d.legs(&p.house, &p.distances))
                .transpose()
                .map_err(|e| invalid("destination", format!("robot {}: {}", r.id, e.message)))?;
            placed.push(p);
            legs.push(l);
        }
        Ok(TeamTrial {
            language: self.language(&row.scene, &spec),
            targets: targets_of(row),
            robots,
            spec,
            candidates,
            strategy,
            placed,
            legs,
            trial,
        })
    }

    /// `POST /trials/{id}/claims`: robot `req.robot` of a team's trial asks for its next
    /// container. A robot that holds a claim gets it again (and it is renewed); else its search
    /// chooses one that no teammate holds, and it is claimed for it.
    pub fn claim_container(
        &self,
        id: i64,
        req: ClaimNext,
        body: &[u8],
    ) -> Result<ApiReply, ApiError> {
        let route = format!("POST /trials/{id}/claims");
        let claim = match self.begin(req.request_id.as_deref(), &route, body)? {
            Begun::Replied(reply) => return Ok(reply),
            Begun::Fresh(claim) => claim,
        };
        let row = self.trial_row(id)?;
        let team = self.team_trial(&row)?;
        let me = team.member(id, &req.robot, "robot")?;
        let ttl = self.claim_ttl_ms();
        let mut told = None;
        let reply = claim.complete_with(&route, body, |w| {
            let now = now_ms();
            let (row, observations, robots) = locked(w, &row)?;
            if row.status != TrialStatus::Searching {
                let searches = team.searches(&observations)?;
                let state = team.state(&row, (&observations, &searches), &robots, now, None)?;
                return Ok((json(Outcome::Done, &state)?, Vec::new()));
            }
            let mut searches = team.searches(&observations)?;
            let held = robots
                .iter()
                .find(|r| r.robot == req.robot)
                .and_then(|r| r.claim.clone())
                .filter(|(_, expires)| *expires > now)
                .and_then(|(c, _)| team.container(&c).ok());
            let next = match held {
                Some(c) => Some(c),
                None => {
                    let others = team.claims_of_others(&robots, &req.robot, now, None);
                    searches[me]
                        .next_container_leaving(&others)
                        .map_err(plan_error)?
                }
            };
            let claimed = next.map(|c| (team.id_of(c), now + ttl));
            let finals = w.claim_last(
                (id, &req.robot),
                now,
                None,
                claimed.as_ref().map(|(c, at)| (c.as_str(), *at)),
            );
            let robots = with_claim(robots, (&req.robot, None), claimed, now);
            let from = searches[me].belief().position();
            let step = next.map(|c| next_container(&team.placed[me], from, c));
            let state = team.state(&row, (&observations, &searches), &robots, now, step)?;
            let reply = json(Outcome::Done, &state)?;
            told = Some(state);
            Ok((reply, finals))
        });
        if reply.is_ok()
            && let Some(state) = told
        {
            self.told(state, None);
        }
        reply
    }

    /// `POST /trials/{id}/observations` in a team's trial: what robot `req.robot` saw in
    /// container `c`, known at once to every teammate; its claim there (and any teammate's)
    /// let go, and its next container claimed for it in the same write. The trial is done once
    /// the goal holds, its cost the makespan: the longest way any robot drove, with the way
    /// to the destination of each robot carrying a target.
    pub(super) fn record_team_observation(
        &self,
        (row, req, body): (&StoredTrial, &Observe, &[u8]),
        (c, objects, found): (usize, Vec<String>, bool),
        claim: RequestClaim<'_>,
    ) -> Result<ApiReply, ApiError> {
        let id = row.id;
        let route = format!("POST /trials/{id}/observations");
        let team = self.team_trial(row)?;
        let robot = req.robot.as_deref().ok_or_else(|| {
            invalid(
                "robot",
                format!(
                    "trial {id} is searched by a team ({}): name the robot that searched",
                    team.names()
                ),
            )
        })?;
        let me = team.member(id, robot, "robot")?;
        let ttl = self.claim_ttl_ms();
        let mut told = None;
        let reply = claim.complete_with(&route, body, |w| {
            let now = now_ms();
            let (row, observations, robots) = locked(w, row)?;
            if row.status != TrialStatus::Searching {
                return Err(ApiError::new(
                    ErrorKind::Conflict,
                    "trial",
                    format!("trial {id} has ended ({})", row.status.as_str()),
                ));
            }
            if let Some(o) = observations.iter().find(|o| o.container == req.container) {
                return Err(ApiError::new(
                    ErrorKind::Conflict,
                    "container",
                    format!(
                        "{:?} was already searched in trial {id}, by robot {}",
                        req.container,
                        o.robot.as_deref().unwrap_or("?")
                    ),
                ));
            }
            let mut searches = team.searches(&observations)?;
            let observation = StoredObservation {
                container: req.container.clone(),
                found,
                objects: objects.clone(),
                travelled: req.travelled_m,
                leg: 0.0,
                robot: Some(robot.to_string()),
            };
            let saw = seen(&observation, &team.targets);
            let leg = searches[me].record(c, saw.clone()).map_err(plan_error)?;
            for (r, s) in searches.iter_mut().enumerate() {
                if r != me {
                    s.observe(c, saw.clone()).map_err(plan_error)?;
                }
            }
            let observation = StoredObservation { leg, ..observation };
            let mut all = observations.clone();
            all.push(observation.clone());
            let (status, next) = if searches[me].goal_holds() {
                (TrialStatus::Done, None)
            } else {
                let others = team.claims_of_others(&robots, robot, now, Some(c));
                match searches[me]
                    .next_container_leaving(&others)
                    .map_err(plan_error)?
                {
                    Some(n) => (TrialStatus::Searching, Some(n)),
                    None if searches[me].belief().unsearched_count() == 0 => {
                        (TrialStatus::Exhausted, None)
                    }
                    // Everything left is a teammate's: this robot asks again later.
                    None => (TrialStatus::Searching, None),
                }
            };
            let mut ended = row.clone();
            ended.status = status;
            let (cost, replays) = match status {
                TrialStatus::Searching => (team.makespan(&mut searches, &all, false), None),
                TrialStatus::Done => {
                    let cost = team.makespan(&mut searches, &all, true);
                    let found_each = searches[me].belief().found_each().to_vec();
                    let problems = team.problems();
                    let replays = replay_team_costs(
                        &team.candidates,
                        &problems,
                        &found_each,
                        (row.chosen, cost),
                    )
                    .map_err(plan_error)?;
                    (cost, Some(replays))
                }
                _ => (team.makespan(&mut searches, &all, false), None),
            };
            if status != TrialStatus::Searching {
                ended.cost = Some(cost);
                ended.replays = replays.clone();
            }
            let mut finals = w.record_and_end_last(
                (id, row.deployment),
                now,
                Some((observations.len(), &observation)),
                (status != TrialStatus::Searching).then_some(TrialEnding {
                    status,
                    cost,
                    replays: replays.as_deref(),
                }),
            );
            let claimed = next.map(|n| (team.id_of(n), now + ttl));
            finals.extend(w.claim_last(
                (id, robot),
                now,
                Some(&req.container),
                claimed.as_ref().map(|(n, at)| (n.as_str(), *at)),
            ));
            let mut robots = with_claim(robots, (robot, Some(&req.container)), claimed, now);
            if status != TrialStatus::Searching {
                // An ended trial sends no robot anywhere.
                finals.push(w.release_claims_last(id));
                for r in &mut robots {
                    r.claim = None;
                }
            }
            let from = searches[me].belief().position();
            let step = next.map(|n| next_container(&team.placed[me], from, n));
            // A trial done has sent its carriers on to the destination in `searches`; its
            // robots are shown as they searched, rebuilt.
            let state = if status == TrialStatus::Done {
                let rebuilt = team.searches(&all)?;
                team.state(&ended, (&all, &rebuilt), &robots, now, step)?
            } else {
                team.state(&ended, (&all, &searches), &robots, now, step)?
            };
            let reply = json(Outcome::Done, &state)?;
            told = Some((state, observation));
            Ok((reply, finals))
        });
        if reply.is_ok()
            && let Some((state, o)) = told
        {
            self.told(
                state,
                Some(crate::api::ObservationInfo {
                    container: o.container,
                    found: o.found,
                    objects: o.objects,
                }),
            );
        }
        reply
    }

    /// A team trial's state as `GET /trials/{id}` gives it (no robot asked: `next` is none).
    pub(super) fn team_state_now(&self, row: &StoredTrial) -> Result<TrialState, ApiError> {
        let team = self.team_trial(row)?;
        let observations = self.store.read(|r| r.observations(row.id))?;
        let robots = self.store.read(|r| r.trial_robots(row.id))?;
        let searches = team.searches(&observations)?;
        team.state(row, (&observations, &searches), &robots, now_ms(), None)
    }

    /// Each robot's way so far and to its claim, for the picture of team trial `row` whose
    /// state is `state`.
    pub(super) fn team_routes(
        &self,
        row: &StoredTrial,
        state: &TrialState,
    ) -> Result<Vec<RobotRoute>, ApiError> {
        let team = self.team_trial(row)?;
        let observations = self.store.read(|r| r.observations(row.id))?;
        let mut out = Vec::with_capacity(team.robots.len());
        for (r, robot) in team.robots.iter().enumerate() {
            let p = &team.placed[r];
            let start = p.house.start.position;
            let mut route = vec![[start.x, start.z]];
            let mut from = Place::Start;
            for o in observations
                .iter()
                .filter(|o| o.robot.as_deref() == Some(robot.id.as_str()))
            {
                let to = Place::Container(team.container(&o.container)?);
                route.extend(p.path(from, to).iter().skip(1).copied());
                from = to;
            }
            let claimed = state
                .robots
                .as_ref()
                .and_then(|rs| rs.iter().find(|s| s.id == robot.id))
                .and_then(|s| s.claim.as_deref());
            let claim_path = match claimed {
                Some(c) => Some(p.path(from, Place::Container(team.container(c)?)).to_vec()),
                None => None,
            };
            out.push(RobotRoute {
                id: robot.id.clone(),
                route,
                claim_path,
            });
        }
        Ok(out)
    }

    fn claim_ttl_ms(&self) -> i64 {
        i64::try_from(self.options.claim_ttl.as_millis()).unwrap_or(i64::MAX)
    }
}

/// The trial's row, observations and robots read under the trial's lock, so that every write
/// of a team's trial (a claim or an observation, on any replica) sees the last one's.
fn locked(
    w: &Writer<'_>,
    row: &StoredTrial,
) -> Result<(StoredTrial, Vec<StoredObservation>, Vec<StoredRobot>), ApiError> {
    let id = row.id;
    let (status, _) = w
        .lock_trial_progress(id)?
        .ok_or_else(|| ApiError::new(ErrorKind::NotFound, "trial", format!("no trial {id}")))?;
    let r = w.reader();
    let mut now = if status == row.status {
        row.clone()
    } else {
        r.trial(id)?
            .ok_or_else(|| ApiError::new(ErrorKind::NotFound, "trial", format!("no trial {id}")))?
    };
    now.status = status;
    Ok((now, r.observations(id)?, r.trial_robots(id)?))
}

/// `robots` as this write leaves them (as [`Writer::claim_last`] does): claims on `searched`
/// let go, `robot` heard at `now`, holding `claim`.
fn with_claim(
    mut robots: Vec<StoredRobot>,
    (robot, searched): (&str, Option<&str>),
    claim: Option<(String, i64)>,
    now: i64,
) -> Vec<StoredRobot> {
    robots.retain(|r| r.robot != robot);
    for r in &mut robots {
        if r.claim
            .as_ref()
            .is_some_and(|(c, _)| Some(c.as_str()) == searched)
        {
            r.claim = None;
        }
    }
    robots.push(StoredRobot {
        robot: robot.to_string(),
        claim,
        heard_ms: now,
    });
    robots
}

/// The robots of a trial; 422 for one without a team.
fn team_of(row: &StoredTrial) -> Result<&[TeamRobot], ApiError> {
    row.robots.as_deref().ok_or_else(|| {
        invalid(
            "robot",
            format!(
                "trial {} is searched by one robot, which its replies steer: it has no team to name a robot of",
                row.id
            ),
        )
    })
}

/// A team trial with what its robots' plans need.
struct TeamTrial {
    /// What the strategies said of the scene's names.
    language: Vec<String>,
    robots: Vec<TeamRobot>,
    targets: Vec<String>,
    spec: DeploymentSpec,
    candidates: Vec<Arc<dyn Strategy>>,
    strategy: Arc<dyn Strategy>,
    /// The scene placed at each robot's start.
    placed: Vec<Arc<Placed>>,
    /// The task's destination on each robot's map.
    legs: Vec<Option<DestinationLegs>>,
    trial: TrialSpec,
}

impl TeamTrial {
    fn names(&self) -> String {
        let ids: Vec<&str> = self.robots.iter().map(|r| r.id.as_str()).collect();
        ids.join(", ")
    }

    /// The index of robot `robot`; 422 on `field` for a robot of no team of this trial.
    fn member(&self, trial: i64, robot: &str, field: &str) -> Result<usize, ApiError> {
        self.robots
            .iter()
            .position(|r| r.id == robot)
            .ok_or_else(|| {
                invalid(
                    field,
                    format!(
                        "{robot:?} is not a robot of trial {trial}: its robots are {}",
                        self.names()
                    ),
                )
            })
    }

    fn house(&self) -> &ferret_world::House {
        &self.placed[0].house
    }

    fn container(&self, id: &str) -> Result<usize, ApiError> {
        self.house().container_index(id).ok_or_else(|| {
            ApiError::internal(format!("stored container {id:?} is not in the scene"))
        })
    }

    fn id_of(&self, c: usize) -> String {
        self.house().containers[c].id.clone()
    }

    /// Each robot's search problem, from its own start.
    fn problems(&self) -> Vec<ferret_plan::SearchProblem<'_>> {
        self.placed
            .iter()
            .zip(&self.legs)
            .map(|(p, l)| {
                let problem = p.problem(&self.trial);
                match l {
                    Some(l) => problem.with_destination(l),
                    None => problem,
                }
            })
            .collect()
    }

    /// Every robot's search, rebuilt from the trial's observations: its own searched (it moved
    /// there), its teammates' known.
    fn searches(&self, observations: &[StoredObservation]) -> Result<Vec<Search<'_>>, ApiError> {
        let mut searches = self
            .problems()
            .iter()
            .map(|p| Search::start(self.strategy.as_ref(), p, None).map_err(plan_error))
            .collect::<Result<Vec<_>, _>>()?;
        for o in observations {
            let c = self.container(&o.container)?;
            let saw = seen(o, &self.targets);
            for (r, s) in searches.iter_mut().enumerate() {
                if o.robot.as_deref() == Some(self.robots[r].id.as_str()) {
                    s.record(c, saw.clone()).map_err(plan_error)?;
                } else {
                    s.observe(c, saw.clone()).map_err(plan_error)?;
                }
            }
        }
        Ok(searches)
    }

    /// The containers teammates of `robot` hold claims on at `now`, but `searched`.
    fn claims_of_others(
        &self,
        robots: &[StoredRobot],
        robot: &str,
        now: i64,
        searched: Option<usize>,
    ) -> Vec<usize> {
        robots
            .iter()
            .filter(|r| r.robot != robot)
            .filter_map(|r| r.claim.as_ref())
            .filter(|(_, expires)| *expires > now)
            .filter_map(|(c, _)| self.container(c).ok())
            .filter(|&c| Some(c) != searched)
            .collect()
    }

    /// The longest way any robot drove (its legs); once the goal holds, with the way to the
    /// destination of every robot that carries a target.
    fn makespan(
        &self,
        searches: &mut [Search<'_>],
        observations: &[StoredObservation],
        done: bool,
    ) -> f64 {
        let found: Vec<usize> = searches
            .first()
            .map(|s| s.belief().found_each().iter().flatten().copied().collect())
            .unwrap_or_default();
        let mut longest = 0.0_f64;
        for (r, s) in searches.iter_mut().enumerate() {
            let id = self.robots[r].id.as_str();
            let carries = observations.iter().any(|o| {
                o.robot.as_deref() == Some(id)
                    && self
                        .container(&o.container)
                        .is_ok_and(|c| found.contains(&c))
            });
            if done && carries {
                s.finish();
            }
            longest = longest.max(s.belief().travelled());
        }
        longest
    }

    /// The trial's state with every robot's: where it is, its claim, what it searched.
    /// `searches` are the robots' searches of `observations` (as [`searches`](Self::searches)
    /// rebuilds them), given by a caller that holds them already.
    fn state(
        &self,
        row: &StoredTrial,
        (observations, searches): (&[StoredObservation], &[Search<'_>]),
        robots: &[StoredRobot],
        now: i64,
        next: Option<NextContainer>,
    ) -> Result<TrialState, ApiError> {
        let status = row.status;
        let mut team = Vec::with_capacity(self.robots.len());
        let mut longest = 0.0_f64;
        for (r, robot) in self.robots.iter().enumerate() {
            let search = &searches[r];
            let p = &self.placed[r];
            let at = match search.belief().position() {
                Place::Container(c) => p.distances.point(Place::Container(c)).map_or_else(
                    || {
                        let pos = p.house.containers[c].position;
                        [pos.x, pos.z]
                    },
                    |q| [q.x, q.z],
                ),
                _ => {
                    let s = p.house.start.position;
                    [s.x, s.z]
                }
            };
            let row = robots.iter().find(|s| s.robot == robot.id);
            let claim = row
                .and_then(|s| s.claim.clone())
                .filter(|(_, expires)| *expires > now)
                .filter(|_| status == TrialStatus::Searching);
            let cost = search.belief().travelled();
            longest = longest.max(cost);
            team.push(RobotState {
                id: robot.id.clone(),
                at,
                claim: claim.as_ref().map(|(c, _)| c.clone()),
                claim_expires_in_s: claim.map(|(_, e)| (e - now) as f64 / 1000.0),
                searched: observations
                    .iter()
                    .filter(|o| o.robot.as_deref() == Some(robot.id.as_str()))
                    .map(|o| o.container.clone())
                    .collect(),
                cost_m: cost,
                heard_s_ago: row.map(|s| (now - s.heard_ms).max(0) as f64 / 1000.0),
            });
        }
        let destination = destination_state(
            row.task.as_ref(),
            &self.placed[0],
            self.legs[0].as_ref(),
            None,
        );
        let mut state = trial_state(
            row,
            &self.spec,
            observations,
            row.cost.unwrap_or(longest),
            (next, destination),
            self.language.clone(),
        );
        state.robots = Some(team);
        Ok(state)
    }
}
