//! What each route does, without HTTP: scenes, deployments, trials. Every operation reads what
//! it needs from the store, plans without holding the database, then writes its rows and its
//! reply in one transaction (checking nothing changed in between).

use std::collections::{BTreeMap, HashMap};
use std::sync::{Arc, Mutex, RwLock};

use ferret_plan::{
    ReplayMode, Search, SearchProblem, Strategy, TrialSpec, hindsight_truth, replay_costs,
};
use ferret_select::{DEFAULT_C, FinishedTrial, LiveDeployment, Method, TrialEnd};
use ferret_world::distance::{self, Place};
use ferret_world::{
    Distances, GridParams, House, ObjectType, Point, Pose, Scene, SceneFile, TravelCost,
};
use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::api::{
    ContainerInfo, CreateDeployment, DeploymentState, NextChoice, NextContainer, Observe, RoomInfo,
    SceneDetail, SceneSummary, StartTrial, StrategyRow, TrialState, TrialSummary, UploadScene,
};
use crate::error::ApiError;
use crate::store::{DeploymentSpec, ObservationRow, Store, StoredReply, TrialRow, TrialStatus};

/// A reply: HTTP status and JSON body.
pub type Reply = (u16, serde_json::Value);

/// How far a robot's pose may be from free floor (the grid moves it to the nearest free cell),
/// metres.
pub const MAX_POSE_SHIFT_M: f64 = 0.5;

/// Longest accepted request id.
pub const MAX_REQUEST_ID: usize = 200;

/// A scene the service knows, with its distances from its own start.
struct Loaded {
    scene: Scene,
    /// The JSON a client uploaded (kept to tell a retry from a different scene of the same name).
    uploaded: Option<String>,
}

/// A scene with the robot at a given pose: the house with that start and its distances.
struct Placed {
    house: House,
    distances: Distances,
}

/// Scenes with the robot placed, by scene name and pose (the pose's bits).
type PlacedCache = HashMap<(String, [u64; 3]), Arc<Placed>>;

/// The service.
pub struct Service {
    store: Store,
    grid: GridParams,
    candidates: Vec<Arc<dyn Strategy>>,
    scenes: RwLock<BTreeMap<String, Arc<Loaded>>>,
    placed: Mutex<PlacedCache>,
}

impl std::fmt::Debug for Service {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Service")
            .field("candidates", &self.candidates.len())
            .finish_non_exhaustive()
    }
}

fn json<T: Serialize>(status: u16, value: &T) -> Result<Reply, ApiError> {
    serde_json::to_value(value)
        .map(|v| (status, v))
        .map_err(|e| ApiError::internal(format!("serializing a reply: {e}")))
}

fn is_type_name(s: &str) -> bool {
    !s.is_empty() && s.len() <= 100 && s.chars().all(char::is_alphanumeric)
}

impl Service {
    /// A service over `store`, offering `candidates` (strategies built by the caller, the same
    /// registry as `ferret eval`), planning on grids with `grid`. Scenes uploaded earlier are
    /// loaded back from the store.
    ///
    /// # Errors
    /// No candidates, a candidate that needs the ground truth (the oracle), or a stored scene
    /// that no longer loads.
    pub fn new(
        store: Store,
        grid: GridParams,
        candidates: Vec<Arc<dyn Strategy>>,
    ) -> Result<Service, ApiError> {
        if candidates.is_empty() {
            return Err(ApiError::internal("no candidate strategies"));
        }
        if let Some(s) = candidates.iter().find(|s| s.needs_ground_truth()) {
            return Err(ApiError::internal(format!(
                "{} reads the ground truth, which a robot does not have; it cannot be a candidate",
                s.name()
            )));
        }
        let service = Service {
            store,
            grid,
            candidates,
            scenes: RwLock::new(BTreeMap::new()),
            placed: Mutex::new(HashMap::new()),
        };
        let stored = service.store.read(|r| r.scenes())?;
        for (name, body) in stored {
            let scene = parse_uploaded(&body).map_err(|e| {
                ApiError::internal(format!(
                    "stored scene {name:?} no longer loads: {}",
                    e.message
                ))
            })?;
            service.insert_scene(name, scene, Some(body));
        }
        Ok(service)
    }

    /// Offers `scene` under `name` (scene files and houses named on the command line).
    ///
    /// # Errors
    /// 422 when a container cannot be reached from the scene's start, or the name is taken.
    pub fn add_scene(&self, name: &str, scene: Scene) -> Result<(), ApiError> {
        if self.scene(name).is_ok() {
            return Err(ApiError::new(
                409,
                "scene",
                format!("a scene named {name:?} exists already"),
            ));
        }
        let distances = self.check_reachable(&scene, "scene")?;
        self.remember_start(name, &scene, distances);
        self.insert_scene(name.to_string(), scene, None);
        Ok(())
    }

    /// Caches the distances from the scene's own start, computed while checking it.
    fn remember_start(&self, name: &str, scene: &Scene, distances: Distances) {
        let start = &scene.house.start;
        let pose = [
            start.position.x,
            start.position.z,
            ferret_world::scene::heading_to_ros(start.yaw_deg),
        ];
        let placed = Arc::new(Placed {
            house: scene.house.clone(),
            distances,
        });
        self.lock_placed()
            .insert((name.to_string(), pose.map(f64::to_bits)), placed);
    }

    fn insert_scene(&self, name: String, scene: Scene, uploaded: Option<String>) {
        let mut scenes = self
            .scenes
            .write()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        scenes.insert(name, Arc::new(Loaded { scene, uploaded }));
    }

    fn scene(&self, name: &str) -> Result<Arc<Loaded>, ApiError> {
        let scenes = self
            .scenes
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        scenes
            .get(name)
            .cloned()
            .ok_or_else(|| ApiError::new(404, "scene", format!("no scene named {name:?}")))
    }

    fn check_reachable(&self, scene: &Scene, field: &str) -> Result<Distances, ApiError> {
        match distance::build(&scene.house, &self.grid) {
            Ok((_, d)) => Ok(d),
            Err(e) => Err(ApiError::new(422, field, e.to_string())),
        }
    }

    /// The scene `name` with the robot at `pose` (cached per pose).
    fn placed(&self, name: &str, pose: Option<[f64; 3]>) -> Result<Arc<Placed>, ApiError> {
        let loaded = self.scene(name)?;
        let start = &loaded.scene.house.start;
        let pose = pose.unwrap_or([
            start.position.x,
            start.position.z,
            ferret_world::scene::heading_to_ros(start.yaw_deg),
        ]);
        let key = (name.to_string(), pose.map(f64::to_bits));
        if let Some(p) = self.lock_placed().get(&key) {
            return Ok(p.clone());
        }
        if pose.iter().any(|v| !v.is_finite()) {
            return Err(ApiError::new(
                422,
                "pose",
                "must be three finite numbers [x, y, yaw]",
            ));
        }
        let mut house = loaded.scene.house.clone();
        house.start = Pose {
            position: Point::new(pose[0], pose[1]),
            yaw_deg: ferret_world::scene::heading_from_ros(pose[2]),
        };
        let (grid, distances) = distance::build(&house, &self.grid)
            .map_err(|e| ApiError::new(422, "pose", format!("({}, {}): {e}", pose[0], pose[1])))?;
        let at = grid.center(grid.start_cell());
        let shift = at.distance(house.start.position);
        if shift > MAX_POSE_SHIFT_M {
            return Err(ApiError::new(
                422,
                "pose",
                format!(
                    "({}, {}) is {shift:.2} m from the nearest free floor (at most {MAX_POSE_SHIFT_M} m)",
                    pose[0], pose[1]
                ),
            ));
        }
        let placed = Arc::new(Placed { house, distances });
        self.lock_placed().insert(key, placed.clone());
        Ok(placed)
    }

    fn lock_placed(&self) -> std::sync::MutexGuard<'_, PlacedCache> {
        self.placed
            .lock()
            .unwrap_or_else(std::sync::PoisonError::into_inner)
    }

    /// The candidates' names, in order.
    pub fn strategy_names(&self) -> Vec<String> {
        self.candidates
            .iter()
            .map(|s| s.name().to_string())
            .collect()
    }

    /// `GET /scenes`.
    pub fn list_scenes(&self) -> Result<Reply, ApiError> {
        let scenes = self
            .scenes
            .read()
            .unwrap_or_else(std::sync::PoisonError::into_inner);
        let list: Vec<SceneSummary> = scenes
            .iter()
            .map(|(name, l)| SceneSummary {
                name: name.clone(),
                rooms: l.scene.house.rooms.len(),
                containers: l.scene.house.containers.len(),
                has_map: l.scene.house.map.is_some(),
            })
            .collect();
        json(200, &list)
    }

    /// `GET /scenes/{name}`.
    pub fn get_scene(&self, name: &str) -> Result<Reply, ApiError> {
        let loaded = self.scene(name)?;
        let placed = self.placed(name, None)?;
        let (house, truth) = (&loaded.scene.house, &loaded.scene.truth);
        let grid = placed.distances.grid();
        let containers = house
            .containers
            .iter()
            .enumerate()
            .map(|(i, c)| ContainerInfo {
                id: c.id.clone(),
                object_type: c.object_type.to_string(),
                room: house.container_room(i).map(|r| r.id.clone()),
                x: c.position.x,
                y: c.position.z,
                access: grid
                    .and_then(|g| g.access_cell(i).map(|cell| g.center(cell)))
                    .map(|p| [p.x, p.z]),
                contents: truth
                    .contents(i)
                    .iter()
                    .map(|o| o.object_type.to_string())
                    .collect(),
            })
            .collect();
        let places: Vec<(String, Place)> = std::iter::once(("start".to_string(), Place::Start))
            .chain(
                house
                    .containers
                    .iter()
                    .enumerate()
                    .map(|(i, c)| (c.id.clone(), Place::Container(i))),
            )
            .collect();
        let distances_m = places
            .iter()
            .map(|(a, pa)| {
                let row = places[1..]
                    .iter()
                    .map(|(b, pb)| (b.clone(), placed.distances.between(*pa, *pb)))
                    .collect();
                (a.clone(), row)
            })
            .collect();
        json(
            200,
            &SceneDetail {
                name: name.to_string(),
                rooms: house
                    .rooms
                    .iter()
                    .map(|r| RoomInfo {
                        name: r.id.clone(),
                        room_type: r.room_type.to_string(),
                        polygon: r.floor.vertices.iter().map(|p| [p.x, p.z]).collect(),
                    })
                    .collect(),
                containers,
                start: [
                    house.start.position.x,
                    house.start.position.z,
                    ferret_world::scene::heading_to_ros(house.start.yaw_deg),
                ],
                distances_m,
            },
        )
    }

    /// Runs a write operation with request-id idempotency: a stored reply for the same id and
    /// body is returned as it was; the same id with another body is a 409.
    fn idempotent(
        &self,
        request_id: Option<&str>,
        route: &str,
        body: &[u8],
        op: impl FnOnce(&crate::store::Writer<'_>) -> Result<Reply, ApiError>,
    ) -> Result<Reply, ApiError> {
        if let Some(id) = request_id
            && (id.is_empty() || id.len() > MAX_REQUEST_ID)
        {
            return Err(ApiError::new(
                400,
                "request_id",
                format!("must have 1 to {MAX_REQUEST_ID} characters"),
            ));
        }
        self.store.write(|w| {
            if let Some(reply) = stored_reply(&w.reader(), request_id, route, body)? {
                return Ok(reply);
            }
            let reply = op(w)?;
            if let Some(id) = request_id {
                w.insert_reply(
                    id,
                    &StoredReply {
                        fingerprint: fingerprint(route, body),
                        status: reply.0,
                        body: reply.1.to_string(),
                    },
                )?;
            }
            Ok(reply)
        })
    }

    /// The stored reply to this request, read before planning so a retry costs no planning.
    fn earlier_reply(
        &self,
        request_id: Option<&str>,
        route: &str,
        body: &[u8],
    ) -> Result<Option<Reply>, ApiError> {
        if request_id.is_none() {
            return Ok(None);
        }
        self.store
            .read(|r| Ok(stored_reply(r, request_id, route, body)))?
    }

    /// `POST /scenes`.
    pub fn upload_scene(&self, req: UploadScene, body: &[u8]) -> Result<Reply, ApiError> {
        let text = req.scene.to_string();
        let scene = parse_uploaded(&text)?;
        let name = req
            .scene
            .get("name")
            .and_then(|n| n.as_str())
            .unwrap_or_default()
            .to_string();
        self.check_reachable(&scene, "scene.containers")?;
        let reply = self.idempotent(req.request_id.as_deref(), "POST /scenes", body, |w| {
            if let Ok(existing) = self.scene(&name) {
                return if existing.uploaded.as_deref() == Some(text.as_str()) {
                    self.get_scene(&name)
                } else {
                    Err(ApiError::new(
                        409,
                        "scene.name",
                        format!("a different scene named {name:?} exists already"),
                    ))
                };
            }
            w.insert_scene(&name, &text)?;
            self.insert_scene(name.clone(), scene, Some(text.clone()));
            let (_, body) = self.get_scene(&name)?;
            Ok((201, body))
        })?;
        Ok(reply)
    }

    fn spec(&self, id: i64) -> Result<DeploymentSpec, ApiError> {
        self.store
            .read(|r| r.deployment(id))?
            .map(|d| d.spec)
            .ok_or_else(|| ApiError::new(404, "deployment", format!("no deployment {id}")))
    }

    fn candidates_of(&self, spec: &DeploymentSpec) -> Result<Vec<Arc<dyn Strategy>>, ApiError> {
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
                            422,
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
    pub fn create_deployment(&self, req: CreateDeployment, body: &[u8]) -> Result<Reply, ApiError> {
        let strategies = req.strategies.unwrap_or_else(|| self.strategy_names());
        if strategies.is_empty() {
            return Err(ApiError::new(
                422,
                "strategies",
                "give at least one strategy",
            ));
        }
        for (i, s) in strategies.iter().enumerate() {
            if strategies[..i].contains(s) {
                return Err(ApiError::new(
                    422,
                    format!("strategies[{i}]"),
                    format!("{s:?} is listed twice"),
                ));
            }
        }
        let c = req.c.unwrap_or(DEFAULT_C);
        if !(c.is_finite() && c >= 0.0) {
            return Err(ApiError::new(
                422,
                "c",
                format!("{c}: must be a finite number ≥ 0 m"),
            ));
        }
        let spec = DeploymentSpec {
            strategies,
            selector: req.selector.unwrap_or(Method::ReplaySelection),
            c,
            seed: req.seed.unwrap_or(0),
        };
        self.candidates_of(&spec)?;
        self.idempotent(req.request_id.as_deref(), "POST /deployments", body, |w| {
            let id = w.insert_deployment(&spec)?;
            let state = self.deployment_state(id, &spec, &w.reader().trials_of(id)?)?;
            json(201, &state)
        })
    }

    /// `GET /deployments/{id}`.
    pub fn get_deployment(&self, id: i64) -> Result<Reply, ApiError> {
        let spec = self.spec(id)?;
        let trials = self.store.read(|r| r.trials_of(id))?;
        json(200, &self.deployment_state(id, &spec, &trials)?)
    }

    fn live(&self, spec: &DeploymentSpec, trials: &[TrialRow]) -> Result<LiveDeployment, ApiError> {
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

    fn deployment_state(
        &self,
        id: i64,
        spec: &DeploymentSpec,
        trials: &[TrialRow],
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

    /// `POST /deployments/{id}/trials`.
    pub fn start_trial(
        &self,
        deployment: i64,
        req: StartTrial,
        body: &[u8],
    ) -> Result<Reply, ApiError> {
        let route = format!("POST /deployments/{deployment}/trials");
        if let Some(reply) = self.earlier_reply(req.request_id.as_deref(), &route, body)? {
            return Ok(reply);
        }
        let spec = self.spec(deployment)?;
        if !is_type_name(&req.target) {
            return Err(ApiError::new(
                422,
                "target",
                format!(
                    "{:?} is not a CamelCase object type such as CellPhone",
                    req.target
                ),
            ));
        }
        let placed = self.placed(&req.scene, req.pose)?;
        let trials = self.store.read(|r| r.trials_of(deployment))?;
        if let Some(open) = trials.iter().find(|t| t.status == TrialStatus::Searching) {
            return Err(ApiError::new(
                409,
                "deployment",
                format!(
                    "trial {} of deployment {deployment} is still searching; finish it first",
                    open.id
                ),
            ));
        }
        let candidates = self.candidates_of(&spec)?;
        let mut live = self.live(&spec, &trials)?;
        let chosen = live.choose();
        let trial = TrialSpec {
            target: ObjectType::new(req.target.clone()),
            revealed: Vec::new(),
        };
        let next = {
            let problem = SearchProblem::new(&placed.house, &placed.distances, &trial);
            let mut search =
                Search::start(candidates[chosen].as_ref(), &problem, None).map_err(plan_error)?;
            let c = search.next_container().map_err(plan_error)?;
            c.map(|c| next_container(&placed, Place::Start, c))
        };
        let k = trials.len() as i64 + 1;
        self.idempotent(req.request_id.as_deref(), &route, body, |w| {
            // Another request may have started a trial since the read above.
            if w.reader().trials_of(deployment)?.len() != trials.len() {
                return Err(ApiError::new(
                    409,
                    "deployment",
                    "another trial was started at the same time; read the deployment and retry",
                ));
            }
            let id = w.insert_trial(deployment, k, &req.scene, &req.target, req.pose, chosen)?;
            json(
                201,
                &TrialState {
                    trial: id,
                    deployment,
                    k,
                    scene: req.scene.clone(),
                    target: req.target.clone(),
                    strategy: spec.strategies[chosen].clone(),
                    status: TrialStatus::Searching,
                    searched: Vec::new(),
                    cost_m: 0.0,
                    travelled_m: None,
                    next: next.clone(),
                    replays_m: None,
                },
            )
        })
    }

    fn trial_row(&self, id: i64) -> Result<TrialRow, ApiError> {
        self.store
            .read(|r| r.trial(id))?
            .ok_or_else(|| ApiError::new(404, "trial", format!("no trial {id}")))
    }

    /// What a stored trial's next step needs, read from the store.
    fn stored_trial(&self, row: &TrialRow) -> Result<StoredTrial, ApiError> {
        let observations = self.store.read(|r| r.observations(row.id))?;
        let spec = self.spec(row.deployment)?;
        let candidates = self.candidates_of(&spec)?;
        let strategy = candidates.get(row.chosen).cloned().ok_or_else(|| {
            ApiError::internal(format!("trial {}: no strategy {}", row.id, row.chosen))
        })?;
        Ok(StoredTrial {
            observations,
            placed: self.placed(&row.scene, row.pose)?,
            trial: TrialSpec {
                target: ObjectType::new(row.target.clone()),
                revealed: Vec::new(),
            },
            strategy,
            candidates,
            spec,
        })
    }

    /// `GET /trials/{id}`.
    pub fn get_trial(&self, id: i64) -> Result<Reply, ApiError> {
        let row = self.trial_row(id)?;
        let t = self.stored_trial(&row)?;
        let (observations, spec) = (&t.observations, &t.spec);
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
        json(
            200,
            &trial_state(&row, spec, observations, search.belief().travelled(), next),
        )
    }

    /// `POST /trials/{id}/observations`.
    pub fn observe(&self, id: i64, req: Observe, body: &[u8]) -> Result<Reply, ApiError> {
        let route = format!("POST /trials/{id}/observations");
        if let Some(reply) = self.earlier_reply(req.request_id.as_deref(), &route, body)? {
            return Ok(reply);
        }
        let row = self.trial_row(id)?;
        if row.status != TrialStatus::Searching {
            return Err(ApiError::new(
                409,
                "trial",
                format!("trial {id} has ended ({:?})", row.status).to_lowercase(),
            ));
        }
        for (i, o) in req.objects.iter().enumerate() {
            if !is_type_name(o) {
                return Err(ApiError::new(
                    422,
                    format!("objects[{i}]"),
                    format!("{o:?} is not a CamelCase object type"),
                ));
            }
        }
        if let Some(t) = req.travelled_m
            && !(t.is_finite() && t >= 0.0)
        {
            return Err(ApiError::new(
                422,
                "travelled_m",
                format!("{t}: must be a finite distance ≥ 0"),
            ));
        }
        let t = self.stored_trial(&row)?;
        let (observations, spec, candidates, placed) =
            (&t.observations, &t.spec, &t.candidates, &t.placed);
        let house = &placed.house;
        let c = house.container_index(&req.container).ok_or_else(|| {
            ApiError::new(
                404,
                "container",
                format!(
                    "{:?} is not a container of scene {:?}",
                    req.container, row.scene
                ),
            )
        })?;
        let target = &t.trial.target;
        let mut search = t.search()?;
        if search.belief().is_searched(c) {
            return Err(ApiError::new(
                409,
                "container",
                format!("{:?} was already searched in trial {id}", req.container),
            ));
        }
        let mut seen: Vec<ObjectType> = req
            .objects
            .iter()
            .map(|o| ObjectType::new(o.clone()))
            .collect();
        if req.found && !seen.contains(target) {
            seen.push(target.clone());
        }
        let leg = search.record(c, seen).map_err(plan_error)?;
        let observation = ObservationRow {
            container: req.container.clone(),
            found: req.found,
            objects: req.objects.clone(),
            travelled: req.travelled_m,
            leg,
        };
        let cost = search.belief().travelled();
        let (status, next, replays) = if req.found {
            let truth = hindsight_truth(house, target, c).map_err(plan_error)?;
            // A robot's trial costs what it travelled; replays are plain path lengths to match.
            let replays = replay_costs(
                (ReplayMode::Pessimistic, TravelCost::Plain),
                candidates,
                &SearchProblem::new(house, &placed.distances, &t.trial),
                &truth,
                c,
                (row.chosen, cost),
            )
            .map_err(plan_error)?;
            (TrialStatus::Done, None, Some(replays))
        } else {
            let from = search.belief().position();
            match search.next_container().map_err(plan_error)? {
                Some(n) => (
                    TrialStatus::Searching,
                    Some(next_container(placed, from, n)),
                    None,
                ),
                None => (TrialStatus::Exhausted, None, None),
            }
        };
        self.idempotent(req.request_id.as_deref(), &route, body, |w| {
            let r = w.reader();
            let now = r.observations(id)?;
            let still = r
                .trial(id)?
                .is_some_and(|t| t.status == TrialStatus::Searching);
            if now.len() != observations.len() || !still {
                return Err(ApiError::new(
                    409,
                    "trial",
                    "the trial changed while this observation was planned; read it and retry",
                ));
            }
            w.insert_observation(id, observations.len(), &observation)?;
            if status != TrialStatus::Searching {
                w.end_trial(id, status, cost, replays.as_deref())?;
            }
            let mut all = observations.clone();
            all.push(observation.clone());
            let mut updated = row.clone();
            updated.status = status;
            updated.cost = (status != TrialStatus::Searching).then_some(cost);
            updated.replays = replays.clone();
            json(200, &trial_state(&updated, spec, &all, cost, next.clone()))
        })
    }
}

/// A stored trial with what it needs to plan its next step.
struct StoredTrial {
    observations: Vec<ObservationRow>,
    spec: DeploymentSpec,
    candidates: Vec<Arc<dyn Strategy>>,
    strategy: Arc<dyn Strategy>,
    placed: Arc<Placed>,
    trial: TrialSpec,
}

impl StoredTrial {
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

/// What tells a retried request from another one under the same id: route and body.
fn fingerprint(route: &str, body: &[u8]) -> String {
    let mut h = Sha256::new();
    h.update(route.as_bytes());
    h.update([0]);
    h.update(body);
    format!("{:x}", h.finalize())
}

/// The stored reply to `request_id` when it was this request (route and body); a 409 when the
/// id was used for another one.
fn stored_reply(
    r: &crate::store::Reader<'_>,
    request_id: Option<&str>,
    route: &str,
    body: &[u8],
) -> Result<Option<Reply>, ApiError> {
    let Some(id) = request_id else {
        return Ok(None);
    };
    let Some(stored) = r.reply(id)? else {
        return Ok(None);
    };
    if stored.fingerprint != fingerprint(route, body) {
        return Err(ApiError::new(
            409,
            "request_id",
            format!("{id:?} was used for another request"),
        ));
    }
    let body = serde_json::from_str(&stored.body)
        .map_err(|e| ApiError::internal(format!("stored reply: {e}")))?;
    Ok(Some((stored.status, body)))
}

/// The trial's search rebuilt from its stored observations.
fn rebuild<'a>(
    strategy: &'a dyn Strategy,
    placed: &'a Placed,
    trial: &'a TrialSpec,
    observations: &[ObservationRow],
) -> Result<Search<'a>, ApiError> {
    let problem = SearchProblem::new(&placed.house, &placed.distances, trial);
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
        if o.found && !seen.contains(&trial.target) {
            seen.push(trial.target.clone());
        }
        search.record(c, seen).map_err(plan_error)?;
    }
    Ok(search)
}

fn trial_state(
    row: &TrialRow,
    spec: &DeploymentSpec,
    observations: &[ObservationRow],
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

fn next_container(placed: &Placed, from: Place, c: usize) -> NextContainer {
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
        path: placed
            .distances
            .path(from, to)
            .unwrap_or_default()
            .iter()
            .map(|p| [p.x, p.z])
            .collect(),
    }
}

fn plan_error(e: ferret_plan::PlanError) -> ApiError {
    // Planning errors come from strategies (an LLM endpoint down, a policy failing), not from
    // the request: the request was valid and may be retried.
    ApiError::new(503, "", e.to_string())
}

/// Parses an uploaded scene (JSON text of a scene file without a map).
fn parse_uploaded(text: &str) -> Result<Scene, ApiError> {
    let file = std::path::Path::new("<uploaded>");
    let parsed = SceneFile::parse(text, file).map_err(|e| scene_error(&e))?;
    if parsed.map.is_some() {
        return Err(ApiError::new(
            422,
            "scene.map",
            "a scene with a map is loaded by the server (--scene), not uploaded",
        ));
    }
    parsed.to_scene(file, None).map_err(|e| scene_error(&e))
}

fn scene_error(e: &ferret_world::WorldError) -> ApiError {
    match e {
        ferret_world::WorldError::Scene { field, message, .. } => ApiError::new(
            422,
            if field.is_empty() {
                "scene".to_string()
            } else {
                format!("scene.{field}")
            },
            message.clone(),
        ),
        other => ApiError::new(422, "scene", other.to_string()),
    }
}
