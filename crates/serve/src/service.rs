//! What each route does, without HTTP: scenes, deployments, trials. Every operation reads what
//! it needs from the store, plans without holding the database, then writes its rows and its
//! reply in one transaction (checking nothing changed in between).
//!
//! Memory is bounded whatever the database holds: uploaded scenes stay in the store and are
//! read when a request needs them, and the grids and distances planning needs are built on
//! demand into a cache of bounded size, a few at a time.

use std::collections::{BTreeMap, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError, RwLock};

use ferret_lab::Deployment;
use ferret_plan::{ReplayMode, Search, SearchProblem, Strategy, TrialSpec, hindsight_truth};
use ferret_select::{DEFAULT_C, FinishedTrial, LiveDeployment, TrialEnd};
use ferret_world::distance::{self, Place};
use ferret_world::{
    Distances, GridParams, House, ObjectType, OccupancyGrid, Point, Pose, Scene, SceneFile,
    TravelCost,
};
use serde::Serialize;
use sha2::{Digest, Sha256};

use crate::api::{
    ContainerInfo, CreateDeployment, DeploymentState, MAX_C, MAX_OBJECTS, MAX_REQUEST_ID, MAX_SEED,
    MAX_TRAVELLED_M, MAX_TYPE_NAME, NextChoice, NextContainer, Observe, RoomInfo, SceneDetail,
    SceneSummary, StartTrial, StrategyRow, TrialState, TrialSummary, UploadScene,
};
use crate::error::{ApiError, ErrorKind};
use crate::store::{DeploymentSpec, ObservationRow, Store, StoredReply, TrialRow, TrialStatus};

/// What a request did: read or changed something, or created it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Outcome {
    /// Read, or done to something that exists (also: the same upload again).
    Done,
    /// Created a scene, a deployment or a trial.
    Created,
}

/// A reply: what the request did and the JSON text of its result. Kept as text so that a
/// retried request gets the very bytes of the first reply (a float parsed back from JSON may
/// differ in its last digit).
#[derive(Clone, Debug, PartialEq)]
pub struct Reply {
    /// What the request did.
    pub outcome: Outcome,
    /// The result as JSON.
    pub body: String,
}

/// How far a robot's pose may be from free floor (the grid moves it to the nearest free cell),
/// metres.
pub const MAX_POSE_SHIFT_M: f64 = 0.5;

/// Largest yaw of a pose, degrees either way: a heading needs no more than a turn, and a yaw
/// like 1e308 has lost every digit of its direction.
pub const MAX_YAW_DEG: f64 = 360.0;

/// What one uploaded scene and the store may hold. Planning a scene costs memory in proportion
/// to its grid cells and time in proportion to cells × containers, so both are bounded before a
/// grid is built.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct SceneLimits {
    /// Uploaded scenes the store may hold (413 past it).
    pub max_scenes: usize,
    /// Grid cells of an uploaded scene at the server's resolution (422 past it).
    pub max_cells: u64,
    /// Containers of an uploaded scene, and obstacles likewise (422 past it).
    pub max_containers: usize,
    /// Vertices of all room polygons of an uploaded scene together (422 past it).
    pub max_vertices: usize,
}

impl Default for SceneLimits {
    fn default() -> Self {
        Self {
            max_scenes: 1000,
            max_cells: 4_000_000,
            max_containers: 200,
            max_vertices: 1000,
        }
    }
}

/// How the service bounds its work.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ServiceOptions {
    /// Limits on uploaded scenes.
    pub limits: SceneLimits,
    /// Memory the built grids and distances may hold, bytes; the least recently used are
    /// dropped past it (and built again when asked for).
    pub grid_cache_bytes: usize,
    /// Grids built (or searched from a new pose) at once; more requests that need one wait.
    /// One scene's work takes one at a time, so with two or more a heavy scene never holds up
    /// the others.
    pub concurrent_builds: usize,
}

impl Default for ServiceOptions {
    fn default() -> Self {
        Self {
            limits: SceneLimits::default(),
            grid_cache_bytes: 256 << 20,
            // At least two, so that one scene's work (which holds one at a time) never holds
            // every other scene's up.
            concurrent_builds: std::thread::available_parallelism().map_or(2, |n| n.get().max(2)),
        }
    }
}

/// A scene with the robot at a given pose: the house with that start and its distances.
struct Placed {
    house: House,
    distances: Distances,
}

impl Placed {
    /// Memory it holds, roughly: two bytes per grid cell, the distance matrix, the house.
    fn bytes(&self) -> usize {
        let n = self.house.containers.len() + 1;
        let cells = self.distances.grid().map_or(0, OccupancyGrid::cell_count);
        cells * 2 + n * n * 8 + n * 64 + 64 * 1024
    }
}

/// Placed scenes by scene name and pose (its bits; `None` = the scene's own start).
type PlaceKey = (String, Option<[u64; 3]>);

/// Built grids, least recently used dropped first once they hold more than `budget` bytes.
/// Hand-written: the LRU crates count entries, and entries here differ in size by a thousand
/// times.
struct GridCache {
    budget: usize,
    used: usize,
    clock: u64,
    entries: HashMap<PlaceKey, (Arc<Placed>, usize, u64)>,
}

impl GridCache {
    fn get(&mut self, key: &PlaceKey) -> Option<Arc<Placed>> {
        self.clock += 1;
        let clock = self.clock;
        self.entries.get_mut(key).map(|e| {
            e.2 = clock;
            e.0.clone()
        })
    }

    fn insert(&mut self, key: PlaceKey, placed: Arc<Placed>) {
        let bytes = placed.bytes();
        if bytes > self.budget {
            return;
        }
        if let Some(old) = self.entries.remove(&key) {
            self.used -= old.1;
        }
        while self.used + bytes > self.budget {
            let Some(oldest) = self
                .entries
                .iter()
                .min_by_key(|(_, e)| e.2)
                .map(|(k, _)| k.clone())
            else {
                break;
            };
            if let Some(e) = self.entries.remove(&oldest) {
                self.used -= e.1;
            }
        }
        self.clock += 1;
        self.used += bytes;
        self.entries.insert(key, (placed, bytes, self.clock));
    }

    fn remove_scene(&mut self, name: &str) {
        let used = &mut self.used;
        self.entries.retain(|k, e| {
            let keep = k.0 != name;
            if !keep {
                *used -= e.1;
            }
            keep
        });
    }
}

/// A counting semaphore for grid builds on the blocking threads that run requests.
struct Permits {
    free: Mutex<usize>,
    returned: Condvar,
}

struct Permit<'a>(&'a Permits);

impl Permits {
    fn acquire(&self) -> Permit<'_> {
        let mut free = self.free.lock().unwrap_or_else(PoisonError::into_inner);
        while *free == 0 {
            free = self
                .returned
                .wait(free)
                .unwrap_or_else(PoisonError::into_inner);
        }
        *free -= 1;
        Permit(self)
    }
}

impl Drop for Permit<'_> {
    fn drop(&mut self) {
        *self.0.free.lock().unwrap_or_else(PoisonError::into_inner) += 1;
        self.0.returned.notify_one();
    }
}

/// The scenes the service offers.
#[derive(Default)]
struct Scenes {
    /// Given on the command line: loaded for good.
    fixed: BTreeMap<String, (Arc<Scene>, SceneSummary)>,
    /// Uploaded: only what the list shows; the scene is read from the store when needed.
    uploaded: BTreeMap<String, SceneSummary>,
}

/// The service.
pub struct Service {
    store: Store,
    grid: GridParams,
    candidates: Vec<Arc<dyn Strategy>>,
    options: ServiceOptions,
    scenes: RwLock<Scenes>,
    cache: Mutex<GridCache>,
    builds: Permits,
    /// Whole grids built so far (each costs a search per container).
    grids_built: AtomicU64,
    /// One gate per scene: its grid and new poses are worked out one at a time, so requests
    /// waiting for the same work get its result instead of repeating it, and a scene holds at
    /// most one of the `builds` permits.
    gates: Mutex<HashMap<String, Arc<Mutex<()>>>>,
}

impl std::fmt::Debug for Service {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Service")
            .field("candidates", &self.candidates.len())
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

fn json<T: Serialize>(outcome: Outcome, value: &T) -> Result<Reply, ApiError> {
    serde_json::to_string(value)
        .map(|body| Reply { outcome, body })
        .map_err(|e| ApiError::internal(format!("serializing a reply: {e}")))
}

/// An object type as the API takes it: ASCII letters and digits, as in `CellPhone`.
fn is_type_name(s: &str) -> bool {
    !s.is_empty() && s.len() <= MAX_TYPE_NAME && s.chars().all(|c| c.is_ascii_alphanumeric())
}

/// A name or id in an uploaded scene: printable ASCII, not only spaces, at most 100 characters
/// (they appear in URLs and replies; the scene file format itself is more lenient).
fn is_upload_name(s: &str) -> bool {
    s.len() <= MAX_TYPE_NAME
        && s.chars().all(|c| matches!(c, ' '..='~'))
        && s.chars().any(|c| matches!(c, '!'..='~'))
}

fn summary(name: &str, scene: &Scene) -> SceneSummary {
    SceneSummary {
        name: name.to_string(),
        rooms: scene.house.rooms.len(),
        containers: scene.house.containers.len(),
        has_map: scene.house.map.is_some(),
    }
}

/// Refuses a pose farther than [`MAX_POSE_SHIFT_M`] from the free floor the grid starts it on.
fn check_shift(
    grid: &OccupancyGrid,
    house: &House,
    pose: [f64; 3],
    field: &str,
) -> Result<(), ApiError> {
    let shift = grid
        .center(grid.start_cell())
        .distance(house.start.position);
    if shift > MAX_POSE_SHIFT_M {
        return Err(ApiError::new(
            ErrorKind::Invalid,
            field,
            format!(
                "({}, {}) is {shift:.2} m from the nearest free floor (at most {MAX_POSE_SHIFT_M} m)",
                pose[0], pose[1]
            ),
        ));
    }
    Ok(())
}

fn start_pose(house: &House) -> [f64; 3] {
    let start = &house.start;
    [
        start.position.x,
        start.position.z,
        ferret_world::scene::heading_to_ros(start.yaw_deg),
    ]
}

impl Service {
    /// A service over `store`, offering `candidates` (strategies built by the caller, the same
    /// registry as `ferret eval`), planning on grids with `grid`, with the default limits.
    ///
    /// # Errors
    /// See [`Service::with_options`].
    pub fn new(
        store: Store,
        grid: GridParams,
        candidates: Vec<Arc<dyn Strategy>>,
    ) -> Result<Service, ApiError> {
        Self::with_options(store, grid, candidates, ServiceOptions::default())
    }

    /// A service with `options`. Scenes uploaded earlier are listed from the store without
    /// being loaded, so start-up takes the same time whatever the store holds.
    ///
    /// # Errors
    /// No candidates, a candidate that needs the ground truth (the oracle), options of zero,
    /// or a store that cannot be read.
    pub fn with_options(
        store: Store,
        grid: GridParams,
        candidates: Vec<Arc<dyn Strategy>>,
        options: ServiceOptions,
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
        if options.concurrent_builds == 0 {
            return Err(ApiError::internal(
                "concurrent grid builds must be at least 1",
            ));
        }
        let uploaded = store
            .read(|r| r.scene_summaries())?
            .into_iter()
            .map(|(name, rooms, containers)| {
                let s = SceneSummary {
                    name: name.clone(),
                    rooms,
                    containers,
                    has_map: false,
                };
                (name, s)
            })
            .collect();
        Ok(Service {
            store,
            grid,
            candidates,
            options,
            scenes: RwLock::new(Scenes {
                fixed: BTreeMap::new(),
                uploaded,
            }),
            cache: Mutex::new(GridCache {
                budget: options.grid_cache_bytes,
                used: 0,
                clock: 0,
                entries: HashMap::new(),
            }),
            builds: Permits {
                free: Mutex::new(options.concurrent_builds),
                returned: Condvar::new(),
            },
            grids_built: AtomicU64::new(0),
            gates: Mutex::new(HashMap::new()),
        })
    }

    /// The limits it enforces.
    pub fn options(&self) -> &ServiceOptions {
        &self.options
    }

    /// Bytes the cached grids and distances hold now (at most
    /// [`ServiceOptions::grid_cache_bytes`]).
    pub fn grid_cache_bytes(&self) -> usize {
        self.lock_cache().used
    }

    /// Whole grids with their distance matrices built so far: what a scene costs the first time
    /// it is used (or again after the cache dropped it), for monitoring.
    pub fn grids_built(&self) -> u64 {
        self.grids_built.load(Ordering::Relaxed)
    }

    /// The scenes with a grid in the cache, each once, sorted.
    pub fn cached_grids(&self) -> Vec<String> {
        let mut names: Vec<String> = self
            .lock_cache()
            .entries
            .keys()
            .map(|k| k.0.clone())
            .collect();
        names.sort();
        names.dedup();
        names
    }

    /// Offers `scene` under `name` (scene files and houses named on the command line; no limits
    /// apply, the operator chose them). Its grid is built now, to check it.
    ///
    /// # Errors
    /// 422 when a container cannot be reached from the scene's start; 409 when the name is
    /// taken.
    pub fn add_scene(&self, name: &str, scene: Scene) -> Result<(), ApiError> {
        if self.knows(name)? {
            return Err(ApiError::new(
                ErrorKind::Conflict,
                "scene",
                format!("a scene named {name:?} exists already"),
            ));
        }
        let placed = self.build(&scene.house, None, "scene")?;
        let s = summary(name, &scene);
        self.write_scenes()
            .fixed
            .insert(name.to_string(), (Arc::new(scene), s));
        self.lock_cache().insert((name.to_string(), None), placed);
        Ok(())
    }

    fn read_scenes(&self) -> std::sync::RwLockReadGuard<'_, Scenes> {
        self.scenes.read().unwrap_or_else(PoisonError::into_inner)
    }

    fn write_scenes(&self) -> std::sync::RwLockWriteGuard<'_, Scenes> {
        self.scenes.write().unwrap_or_else(PoisonError::into_inner)
    }

    fn lock_cache(&self) -> MutexGuard<'_, GridCache> {
        self.cache.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// True when a scene is offered under `name` (also one another process uploaded to the
    /// same store).
    fn knows(&self, name: &str) -> Result<bool, ApiError> {
        {
            let scenes = self.read_scenes();
            if scenes.fixed.contains_key(name) || scenes.uploaded.contains_key(name) {
                return Ok(true);
            }
        }
        Ok(self.store.read(|r| r.scene(name))?.is_some())
    }

    /// The scene called `name`: a fixed one, or an uploaded one read from the store.
    fn scene(&self, name: &str) -> Result<Arc<Scene>, ApiError> {
        if let Some((scene, _)) = self.read_scenes().fixed.get(name) {
            return Ok(scene.clone());
        }
        let Some(text) = self.store.read(|r| r.scene(name))? else {
            return Err(ApiError::new(
                ErrorKind::NotFound,
                "scene",
                format!("no scene named {name:?}"),
            ));
        };
        let (_, scene) = parse_uploaded(&text).map_err(|e| {
            ApiError::internal(format!(
                "stored scene {name:?} no longer loads: {}",
                e.message
            ))
        })?;
        self.write_scenes()
            .uploaded
            .entry(name.to_string())
            .or_insert_with(|| summary(name, &scene));
        Ok(Arc::new(scene))
    }

    /// The grid and distances of `house` with the robot at `pose` (its own start when `None`),
    /// built with at most `concurrent_builds` others at once.
    fn build(
        &self,
        house: &House,
        pose: Option<[f64; 3]>,
        field: &str,
    ) -> Result<Arc<Placed>, ApiError> {
        let mut house = house.clone();
        if let Some(pose) = pose {
            house.start = Pose {
                position: Point::new(pose[0], pose[1]),
                yaw_deg: ferret_world::scene::heading_from_ros(pose[2]),
            };
        }
        let _permit = self.builds.acquire();
        self.grids_built.fetch_add(1, Ordering::Relaxed);
        let (grid, distances) = distance::build(&house, &self.grid).map_err(|e| match pose {
            Some(p) => ApiError::new(
                ErrorKind::Invalid,
                field,
                format!("({}, {}): {e}", p[0], p[1]),
            ),
            None => ApiError::new(ErrorKind::Invalid, field, e.to_string()),
        })?;
        if let Some(pose) = pose {
            check_shift(&grid, &house, pose, field)?;
        }
        Ok(Arc::new(Placed { house, distances }))
    }

    /// The scene `name` with the robot at `pose` (cached per pose). A new pose is one search
    /// from it on the grid of the scene's own start, not a new grid.
    fn placed(&self, name: &str, pose: Option<[f64; 3]>) -> Result<Arc<Placed>, ApiError> {
        let key = (name.to_string(), pose.map(|p| p.map(f64::to_bits)));
        if let Some(p) = self.lock_cache().get(&key) {
            return Ok(p);
        }
        if let Some(p) = pose
            && !(p.iter().all(|v| v.is_finite()) && p[2].abs() <= MAX_YAW_DEG)
        {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "pose",
                format!(
                    "must be [x, y, yaw]: finite metres, and a yaw in degrees from -{MAX_YAW_DEG} to {MAX_YAW_DEG}"
                ),
            ));
        }
        let gate = self.gate(name);
        let placed = {
            let _turn = gate.lock().unwrap_or_else(PoisonError::into_inner);
            self.place(name, key, pose)
        };
        self.release_gate(name, &gate);
        placed
    }

    /// [`placed`](Self::placed) for a caller holding the scene's gate.
    fn place(
        &self,
        name: &str,
        key: PlaceKey,
        pose: Option<[f64; 3]>,
    ) -> Result<Arc<Placed>, ApiError> {
        // Whoever held the gate before may have placed it already.
        if let Some(p) = self.lock_cache().get(&key) {
            return Ok(p);
        }
        let base_key = (name.to_string(), None);
        let cached = self.lock_cache().get(&base_key);
        let base = match cached {
            Some(b) => b,
            None => {
                let scene = self.scene(name)?;
                let field = if pose.is_some() { "pose" } else { "scene" };
                let b = self.build(&scene.house, None, field)?;
                self.lock_cache().insert(base_key, b.clone());
                b
            }
        };
        let Some(pose) = pose else {
            return Ok(base);
        };
        let placed = self.moved(&base, pose)?;
        self.lock_cache().insert(key, placed.clone());
        Ok(placed)
    }

    /// The gate of scene `name`.
    fn gate(&self, name: &str) -> Arc<Mutex<()>> {
        self.lock_gates()
            .entry(name.to_string())
            .or_default()
            .clone()
    }

    /// Drops the gate of `name` when no one else holds or waits for it, so that the map holds
    /// only scenes being worked on, whatever names clients send.
    fn release_gate(&self, name: &str, gate: &Arc<Mutex<()>>) {
        let mut gates = self.lock_gates();
        // Ours and the map's: every clone is taken under this lock, so none can appear now.
        if Arc::strong_count(gate) == 2 {
            gates.remove(name);
        }
    }

    fn lock_gates(&self) -> MutexGuard<'_, HashMap<String, Arc<Mutex<()>>>> {
        self.gates.lock().unwrap_or_else(PoisonError::into_inner)
    }

    /// `base` with the robot at `pose`: one search from the pose on its grid when the pose is on
    /// floor the scene's start reaches; a new build when it is not (only that says which
    /// containers can be reached from there).
    fn moved(&self, base: &Placed, pose: [f64; 3]) -> Result<Arc<Placed>, ApiError> {
        let Some(grid) = base.distances.grid() else {
            return self.build(&base.house, Some(pose), "pose");
        };
        let mut house = base.house.clone();
        house.start = Pose {
            position: Point::new(pose[0], pose[1]),
            yaw_deg: ferret_world::scene::heading_from_ros(pose[2]),
        };
        let invalid = |e: ferret_world::WorldError| {
            ApiError::new(
                ErrorKind::Invalid,
                "pose",
                format!("({}, {}): {e}", pose[0], pose[1]),
            )
        };
        let permit = self.builds.acquire();
        let Some(grid) = grid
            .with_start(&house.name, house.start.position)
            .map_err(invalid)?
        else {
            drop(permit);
            return self.build(&base.house, Some(pose), "pose");
        };
        check_shift(&grid, &house, pose, "pose")?;
        let distances = base.distances.with_start(&house, &grid).map_err(invalid)?;
        Ok(Arc::new(Placed { house, distances }))
    }

    /// The candidates' names, in order.
    pub fn strategy_names(&self) -> Vec<String> {
        self.candidates
            .iter()
            .map(|s| s.name().to_string())
            .collect()
    }

    /// `GET /health`: done when the store answers and its file reads whole, else unavailable.
    pub fn health(&self) -> Result<Reply, ApiError> {
        match self
            .store
            .read(|r| r.check())
            .and_then(|()| self.store.check_file())
        {
            Ok(()) => Ok(Reply {
                outcome: Outcome::Done,
                body: r#"{"status":"ok"}"#.to_string(),
            }),
            Err(e) => {
                tracing::error!("health check: {e}");
                Err(ApiError::unavailable(
                    "",
                    "the database cannot be read; see the server's log",
                ))
            }
        }
    }

    /// `GET /scenes`.
    pub fn list_scenes(&self) -> Result<Reply, ApiError> {
        let scenes = self.read_scenes();
        let mut list: Vec<&SceneSummary> = scenes
            .fixed
            .values()
            .map(|(_, s)| s)
            .chain(scenes.uploaded.values())
            .collect();
        list.sort_by(|a, b| a.name.cmp(&b.name));
        json(Outcome::Done, &list)
    }

    /// `GET /scenes/{name}`.
    pub fn get_scene(&self, name: &str) -> Result<Reply, ApiError> {
        let scene = self.scene(name)?;
        let placed = self.placed(name, None)?;
        scene_detail(name, &scene, &placed).and_then(|d| json(Outcome::Done, &d))
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
            && (id.is_empty() || id.chars().count() > MAX_REQUEST_ID)
        {
            return Err(ApiError::new(
                ErrorKind::Malformed,
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
                        outcome: reply.outcome,
                        body: reply.body.clone(),
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
        const ROUTE: &str = "POST /scenes";
        let request_id = req.request_id.as_deref();
        if let Some(reply) = self.earlier_reply(request_id, ROUTE, body)? {
            return Ok(reply);
        }
        let text = req.scene.to_string();
        let file = parse_file(&text)?;
        // Counts first: checking the rooms for overlaps takes time in their vertices squared.
        self.check_upload(&file)?;
        let scene = to_scene(&file)?;
        self.check_cells(&scene)?;
        let name = file.name;
        if self.read_scenes().fixed.contains_key(&name) {
            return Err(taken(&name));
        }
        // The same scene again: nothing to build.
        match self.store.read(|r| r.scene(&name))? {
            Some(stored) if stored == text => {
                let reply = self.get_scene(&name)?;
                return self.idempotent(request_id, ROUTE, body, |_| Ok(reply));
            }
            Some(_) => return Err(taken(&name)),
            None => {}
        }
        let placed = self.build(&scene.house, None, "scene.containers")?;
        let detail = json(Outcome::Created, &scene_detail(&name, &scene, &placed)?)?;
        let max = self.options.limits.max_scenes;
        let reply = self.idempotent(request_id, ROUTE, body, |w| {
            match w.reader().scene(&name)? {
                Some(stored) if stored == text => {
                    return Ok(Reply {
                        outcome: Outcome::Done,
                        body: detail.body.clone(),
                    });
                }
                Some(_) => return Err(taken(&name)),
                None => {}
            }
            if w.reader().scene_count()? >= max {
                return Err(ApiError::new(
                    ErrorKind::TooLarge,
                    "scene",
                    format!("the server holds {max} uploaded scenes, its limit (--max-scenes)"),
                ));
            }
            w.insert_scene(&name, &text)?;
            Ok(detail.clone())
        })?;
        self.lock_cache().remove_scene(&name);
        self.lock_cache().insert((name.clone(), None), placed);
        self.write_scenes()
            .uploaded
            .insert(name.clone(), summary(&name, &scene));
        Ok(reply)
    }

    /// The limits of uploaded scenes, and names the API can carry; checked before any grid is
    /// built.
    fn check_upload(&self, file: &SceneFile) -> Result<(), ApiError> {
        let limits = &self.options.limits;
        let bad =
            |field: String, message: String| Err(ApiError::new(ErrorKind::Invalid, field, message));
        let names = std::iter::once(("scene.name".to_string(), file.name.as_str()))
            .chain(
                file.rooms
                    .iter()
                    .enumerate()
                    .map(|(i, r)| (format!("scene.rooms[{i}].name"), r.name.as_str())),
            )
            .chain(file.containers.iter().enumerate().flat_map(|(i, c)| {
                std::iter::once((format!("scene.containers[{i}].id"), c.id.as_str())).chain(
                    c.room
                        .as_deref()
                        .map(|r| (format!("scene.containers[{i}].room"), r)),
                )
            }))
            .chain(
                file.obstacles
                    .iter()
                    .enumerate()
                    .map(|(i, o)| (format!("scene.obstacles[{i}].id"), o.id.as_str())),
            );
        for (field, name) in names {
            if !is_upload_name(name) {
                return bad(
                    field,
                    format!(
                        "{name:?}: names and ids of uploaded scenes are printable ASCII, 1 to {MAX_TYPE_NAME} characters, not only spaces"
                    ),
                );
            }
        }
        let types =
            file.rooms
                .iter()
                .enumerate()
                .map(|(i, r)| (format!("scene.rooms[{i}].type"), r.room_type.as_str()))
                .chain(file.containers.iter().enumerate().flat_map(|(i, c)| {
                    std::iter::once((
                        format!("scene.containers[{i}].type"),
                        c.object_type.as_str(),
                    ))
                    .chain(c.contents.iter().enumerate().map(
                        move |(k, t)| (format!("scene.containers[{i}].contents[{k}]"), t.as_str()),
                    ))
                }))
                .chain(
                    file.obstacles.iter().enumerate().map(|(i, o)| {
                        (format!("scene.obstacles[{i}].type"), o.object_type.as_str())
                    }),
                );
        for (field, t) in types {
            if !is_type_name(t) {
                return bad(
                    field,
                    format!("{t:?} is not a CamelCase type of ASCII letters and digits"),
                );
            }
        }
        if file.containers.len() > limits.max_containers {
            return bad(
                "scene.containers".into(),
                format!(
                    "{} containers; this server takes at most {} per uploaded scene (--max-scene-containers)",
                    file.containers.len(),
                    limits.max_containers
                ),
            );
        }
        if file.obstacles.len() > limits.max_containers {
            return bad(
                "scene.obstacles".into(),
                format!(
                    "{} obstacles; this server takes at most {} per uploaded scene (--max-scene-containers)",
                    file.obstacles.len(),
                    limits.max_containers
                ),
            );
        }
        let vertices: usize = file.rooms.iter().map(|r| r.polygon.len()).sum();
        if vertices > limits.max_vertices {
            return bad(
                "scene.rooms".into(),
                format!(
                    "{vertices} polygon vertices in all; this server takes at most {} per uploaded scene (--max-scene-vertices)",
                    limits.max_vertices
                ),
            );
        }
        Ok(())
    }

    /// The grid cells limit of uploaded scenes.
    fn check_cells(&self, scene: &Scene) -> Result<(), ApiError> {
        let limits = &self.options.limits;
        let cells = OccupancyGrid::planned_cells(&scene.house, &self.grid).unwrap_or(0.0);
        if cells > limits.max_cells as f64 {
            return Err(ApiError::new(
                ErrorKind::Invalid,
                "scene.rooms",
                format!(
                    "the rooms span {cells:.0} grid cells at {} m; this server takes at most {} per uploaded scene (--max-scene-cells)",
                    self.grid.resolution, limits.max_cells
                ),
            ));
        }
        Ok(())
    }

    fn spec(&self, id: i64) -> Result<DeploymentSpec, ApiError> {
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
    pub fn create_deployment(&self, req: CreateDeployment, body: &[u8]) -> Result<Reply, ApiError> {
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
    pub fn get_deployment(&self, id: i64) -> Result<Reply, ApiError> {
        let spec = self.spec(id)?;
        let trials = self.store.read(|r| r.trials_of(id))?;
        json(Outcome::Done, &self.deployment_state(id, &spec, &trials)?)
    }

    fn live(&self, spec: &DeploymentSpec, trials: &[TrialRow]) -> Result<LiveDeployment, ApiError> {
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
    fn deployment(
        &self,
        spec: &DeploymentSpec,
        trials: &[TrialRow],
        candidates: Vec<Arc<dyn Strategy>>,
    ) -> Result<Deployment, ApiError> {
        let (history, pending) = history(trials);
        Deployment::restore(
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
                ErrorKind::Invalid,
                "target",
                format!(
                    "{:?} is not a CamelCase object type of ASCII letters and digits such as CellPhone",
                    req.target
                ),
            ));
        }
        let placed = self.placed(&req.scene, req.pose)?;
        let trials = self.store.read(|r| r.trials_of(deployment))?;
        if let Some(open) = trials.iter().find(|t| t.status == TrialStatus::Searching) {
            return Err(ApiError::new(
                ErrorKind::Conflict,
                "deployment",
                format!(
                    "trial {} of deployment {deployment} is still searching; finish it first",
                    open.id
                ),
            ));
        }
        let candidates = self.candidates_of(&spec)?;
        let mut state = self.deployment(&spec, &trials, candidates.clone())?;
        let chosen = state.choose();
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
                    ErrorKind::Conflict,
                    "deployment",
                    "another trial was started at the same time; read the deployment and retry",
                ));
            }
            let id = w.insert_trial(deployment, k, &req.scene, &req.target, req.pose, chosen)?;
            json(
                Outcome::Created,
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
            .ok_or_else(|| ApiError::new(ErrorKind::NotFound, "trial", format!("no trial {id}")))
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
            Outcome::Done,
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
                ErrorKind::Conflict,
                "trial",
                format!("trial {id} has ended ({:?})", row.status).to_lowercase(),
            ));
        }
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
                ErrorKind::NotFound,
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
                ErrorKind::Conflict,
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
            let trials = self.store.read(|r| r.trials_of(row.deployment))?;
            let replays = self
                .deployment(spec, &trials, candidates.clone())?
                .replays(
                    &SearchProblem::new(house, &placed.distances, &t.trial),
                    &truth,
                    c,
                    (row.chosen, cost),
                )
                .map_err(lab_error)?;
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
                    ErrorKind::Conflict,
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
            json(
                Outcome::Done,
                &trial_state(&updated, spec, &all, cost, next.clone()),
            )
        })
    }
}

/// What a robot's replays assume: the target only where it was found, and plain path lengths,
/// since a robot's trial costs what it travelled.
const ROBOT_REPLAY: (ReplayMode, TravelCost) = (ReplayMode::Pessimistic, TravelCost::Plain);

/// How the stored trials ended, in order, and the choice of the open one.
fn history(trials: &[TrialRow]) -> (Vec<TrialEnd>, Option<usize>) {
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

/// A replay that failed: a plan error as the service reports it, anything else internal.
fn lab_error(e: ferret_lab::LabError) -> ApiError {
    match e {
        ferret_lab::LabError::Plan(p) => plan_error(p),
        other => ApiError::internal(other.to_string()),
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
            ErrorKind::Conflict,
            "request_id",
            format!("{id:?} was used for another request"),
        ));
    }
    Ok(Some(Reply {
        outcome: stored.outcome,
        body: stored.body,
    }))
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
    ApiError::new(ErrorKind::Unavailable, "", e.to_string())
}

/// Parses an uploaded scene's text (a scene file without a map).
fn parse_file(text: &str) -> Result<SceneFile, ApiError> {
    let parsed =
        SceneFile::parse(text, std::path::Path::new("<uploaded>")).map_err(|e| scene_error(&e))?;
    if parsed.map.is_some() {
        return Err(ApiError::new(
            ErrorKind::Invalid,
            "scene.map",
            "a scene with a map is loaded by the server (--scene), not uploaded",
        ));
    }
    Ok(parsed)
}

fn to_scene(file: &SceneFile) -> Result<Scene, ApiError> {
    file.to_scene(std::path::Path::new("<uploaded>"), None)
        .map_err(|e| scene_error(&e))
}

/// Parses a stored uploaded scene.
fn parse_uploaded(text: &str) -> Result<(SceneFile, Scene), ApiError> {
    let file = parse_file(text)?;
    let scene = to_scene(&file)?;
    Ok((file, scene))
}

fn taken(name: &str) -> ApiError {
    ApiError::new(
        ErrorKind::Conflict,
        "scene.name",
        format!("a different scene named {name:?} exists already"),
    )
}

/// What `GET /scenes/{name}` says about a scene placed at its start.
fn scene_detail(name: &str, scene: &Scene, placed: &Placed) -> Result<SceneDetail, ApiError> {
    let (house, truth) = (&scene.house, &scene.truth);
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
    Ok(SceneDetail {
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
        start: start_pose(house),
        distances_m,
    })
}

fn scene_error(e: &ferret_world::WorldError) -> ApiError {
    match e {
        ferret_world::WorldError::Scene { field, message, .. } => ApiError::new(
            ErrorKind::Invalid,
            if field.is_empty() {
                "scene".to_string()
            } else {
                format!("scene.{field}")
            },
            message.clone(),
        ),
        other => ApiError::new(ErrorKind::Invalid, "scene", other.to_string()),
    }
}
