//! The grids and distances planning needs, built on demand: a scene placed at its own start or
//! at a robot's pose, kept in a cache of bounded size, and built a few at a time. A scene's work
//! goes through a gate of its own, so requests waiting for the same grid get its result instead
//! of repeating it.

use std::collections::{BTreeSet, HashMap};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};

use ferret_plan::{PlanMemo, ReplayMemo, SearchProblem, TrialSpec};
use ferret_world::distance::{self, Place};
use ferret_world::{Distances, GridParams, House, ObjectType, OccupancyGrid, Point, Pose, Scene};

use crate::error::{ApiError, ErrorKind};

/// How far a robot's pose may be from free floor (the grid moves it to the nearest free cell),
/// metres.
pub const MAX_POSE_SHIFT_M: f64 = 0.5;

/// Largest yaw of a pose, degrees either way: a heading needs no more than a turn, and a yaw
/// like 1e308 has lost every digit of its direction.
pub const MAX_YAW_DEG: f64 = 360.0;

/// A scene with the robot at a given pose: the house with that start and its distances.
pub(crate) struct Placed {
    pub(crate) house: House,
    pub(crate) distances: Distances,
    /// Paths from the start already traced for replies: tracing one searches the grid, and a
    /// fleet's robots are sent along the same few legs again and again.
    paths: Mutex<KeptPaths>,
    /// Paths between containers already traced, shared with the scene at every start on the
    /// same grid (they do not depend on where the robot started): robots that start each trial
    /// where the last left them place the scene anew every trial.
    between: Arc<Mutex<KeptPaths>>,
    /// Replays of trials that ended here: the same trial ends the same way for every robot of
    /// a fleet, and each end replays every other candidate.
    pub(crate) replays: ReplayMemo,
    /// First steps of the plans solved in this scene, shared with the scene at every start on
    /// the same grid (a plan over containers does not depend on where the robot starts).
    pub(crate) plans: Arc<PlanMemo>,
    /// The object types the scene lists in its containers: the names a trial may look for
    /// (any, when it lists none).
    pub(crate) targets: Arc<BTreeSet<ObjectType>>,
}

/// A traced path: `[x, y]` corners on the floor.
pub(crate) type FloorPath = Arc<[[f64; 2]]>;

/// Traced paths by their two ends.
pub(crate) type KeptPaths = HashMap<(Place, Place), FloorPath>;

/// Paths between containers a scene keeps: at most about 1 MiB.
const KEPT_PATHS: usize = 4096;

/// Room for one kept path: about 10 corners of 16 bytes, its key and the map's own.
const PATH_BYTES: usize = 256;

impl Placed {
    pub(crate) fn new(
        house: House,
        distances: Distances,
        kept_replays: usize,
        (plans, between): (Arc<PlanMemo>, Arc<Mutex<KeptPaths>>),
        targets: Arc<BTreeSet<ObjectType>>,
    ) -> Self {
        Self {
            house,
            distances,
            paths: Mutex::default(),
            between,
            replays: ReplayMemo::new(kept_replays),
            plans,
            targets,
        }
    }

    /// The search problem of `trial` here, with what this scene keeps for it.
    pub(crate) fn problem<'a>(&'a self, trial: &'a TrialSpec) -> SearchProblem<'a> {
        SearchProblem::new(&self.house, &self.distances, trial)
            .with_replay_memo(&self.replays)
            .with_plan_memo(&self.plans)
    }

    /// Memory it holds, roughly: three bytes per grid cell (the grid and the moves allowed
    /// from each cell, counted here even when another start shares them), the distance matrix,
    /// the house, and room for the paths from its start and the replays it keeps, and for the
    /// plans and the paths between containers when it is the first to keep them (the scene at
    /// its own start is placed before any other start shares them).
    fn bytes(&self) -> usize {
        let n = self.house.containers.len() + 1;
        let cells = self.distances.grid().map_or(0, OccupancyGrid::cell_count);
        let plans = if Arc::strong_count(&self.plans) == 1 {
            self.plans.capacity() * 512
        } else {
            0
        };
        let between = if Arc::strong_count(&self.between) == 1 {
            KEPT_PATHS * PATH_BYTES
        } else {
            0
        };
        cells * 3
            + n * n * 8
            + n * 64
            + 64 * 1024
            + n * PATH_BYTES
            + self.replays.capacity() * 128
            + plans
            + between
    }

    /// The path from `from` to `to` as `[x, y]` corners on the floor (empty without a grid).
    pub(crate) fn path(&self, from: Place, to: Place) -> FloorPath {
        let kept = if from == Place::Start || to == Place::Start {
            &self.paths
        } else {
            &*self.between
        };
        let lock = || {
            kept.lock()
                .unwrap_or_else(std::sync::PoisonError::into_inner)
        };
        if let Some(p) = lock().get(&(from, to)) {
            return p.clone();
        }
        let traced: FloorPath = self
            .distances
            .path(from, to)
            .unwrap_or_default()
            .iter()
            .map(|p| [p.x, p.z])
            .collect();
        let mut paths = lock();
        if paths.len() < KEPT_PATHS {
            paths.insert((from, to), traced.clone());
        }
        traced
    }
}

/// Placed scenes by scene name and pose (its bits; `None` = the scene's own start).
pub(crate) type PlaceKey = (String, Option<[u64; 3]>);

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

/// Built grids: the cache, the build permits, one gate per scene.
pub(crate) struct Grids {
    params: GridParams,
    /// Replay costs each placed scene keeps.
    kept_replays: usize,
    /// Plans' first steps each scene keeps.
    kept_plans: usize,
    cache: Mutex<GridCache>,
    builds: Permits,
    /// Whole grids built so far (each costs a search per container).
    built: AtomicU64,
    /// One gate per scene: its grid and new poses are worked out one at a time, so requests
    /// waiting for the same work get its result instead of repeating it, and a scene holds at
    /// most one of the `builds` permits.
    gates: Mutex<HashMap<String, Arc<Mutex<()>>>>,
}

impl Grids {
    /// Grids on `params`, at most `budget` bytes of them cached, `concurrent_builds` built at
    /// once, each placed scene keeping up to `kept_replays` replay costs and each scene the
    /// first steps of up to `kept_plans` plans.
    pub(crate) fn new(
        params: GridParams,
        budget: usize,
        concurrent_builds: usize,
        (kept_replays, kept_plans): (usize, usize),
    ) -> Self {
        Self {
            params,
            kept_replays,
            kept_plans,
            cache: Mutex::new(GridCache {
                budget,
                used: 0,
                clock: 0,
                entries: HashMap::new(),
            }),
            builds: Permits {
                free: Mutex::new(concurrent_builds),
                returned: Condvar::new(),
            },
            built: AtomicU64::new(0),
            gates: Mutex::new(HashMap::new()),
        }
    }

    /// The grid parameters every scene is planned on.
    pub(crate) fn params(&self) -> &GridParams {
        &self.params
    }

    /// Bytes the cached grids and distances hold now.
    pub(crate) fn cached_bytes(&self) -> usize {
        self.lock_cache().used
    }

    /// Whole grids built so far.
    pub(crate) fn built(&self) -> u64 {
        self.built.load(Ordering::Relaxed)
    }

    /// The scenes with a grid in the cache, each once, sorted.
    pub(crate) fn cached_scenes(&self) -> Vec<String> {
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

    /// Keeps `placed` as scene `name` at its own start, replacing whatever the cache held of
    /// that scene.
    pub(crate) fn keep(&self, name: &str, placed: Arc<Placed>) {
        let mut cache = self.lock_cache();
        cache.remove_scene(name);
        cache.insert((name.to_string(), None), placed);
    }

    /// The grid and distances of `house` with the robot at `pose` (its own start when `None`),
    /// built with at most `concurrent_builds` others at once.
    pub(crate) fn build(
        &self,
        house: &House,
        targets: Arc<BTreeSet<ObjectType>>,
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
        self.built.fetch_add(1, Ordering::Relaxed);
        let (grid, distances) = distance::build(&house, &self.params).map_err(|e| match pose {
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
        Ok(Arc::new(Placed::new(
            house,
            distances,
            self.kept_replays,
            (Arc::new(PlanMemo::new(self.kept_plans)), Arc::default()),
            targets,
        )))
    }

    /// The scene `name` with the robot at `pose` (cached per pose), `load` reading the scene
    /// when its grid is not cached. A new pose is one search from it on the grid of the scene's
    /// own start, not a new grid.
    pub(crate) fn placed(
        &self,
        name: &str,
        pose: Option<[f64; 3]>,
        load: impl FnOnce() -> Result<Arc<Scene>, ApiError>,
    ) -> Result<Arc<Placed>, ApiError> {
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
            self.place(name, key, pose, load)
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
        load: impl FnOnce() -> Result<Arc<Scene>, ApiError>,
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
                let scene = load()?;
                let field = if pose.is_some() { "pose" } else { "scene" };
                let targets = Arc::new(scene.truth.target_types());
                let b = self.build(&scene.house, targets, None, field)?;
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
            return self.build(&base.house, base.targets.clone(), Some(pose), "pose");
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
            return self.build(&base.house, base.targets.clone(), Some(pose), "pose");
        };
        check_shift(&grid, &house, pose, "pose")?;
        let distances = base.distances.with_start(&house, &grid).map_err(invalid)?;
        // The same grid, so the same travel between containers: plans and paths are shared.
        Ok(Arc::new(Placed::new(
            house,
            distances,
            self.kept_replays,
            (Arc::clone(&base.plans), Arc::clone(&base.between)),
            base.targets.clone(),
        )))
    }

    /// Replays answered from the replay costs of the placed scenes now cached.
    pub(crate) fn replays_reused(&self) -> u64 {
        self.lock_cache()
            .entries
            .values()
            .map(|e| e.0.replays.hits())
            .sum()
    }

    /// Decisions taken from the plans' first steps the scenes now cached keep.
    pub(crate) fn plans_reused(&self) -> u64 {
        let cache = self.lock_cache();
        // A scene's memo is shared by its placed scenes at every start: counted once.
        let mut seen = std::collections::HashSet::new();
        cache
            .entries
            .values()
            .filter(|e| seen.insert(Arc::as_ptr(&e.0.plans)))
            .map(|e| e.0.plans.hits())
            .sum()
    }

    fn lock_cache(&self) -> MutexGuard<'_, GridCache> {
        self.cache.lock().unwrap_or_else(PoisonError::into_inner)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use ferret_world::HouseLocation;
    use ferret_world::generate::{GeneratorOptions, generate_house};
    use ferret_world::procthor::scene_from_raw;

    fn traced(placed: &Placed, from: Place, to: Place) -> Vec<[f64; 2]> {
        let path = placed.distances.path(from, to).unwrap();
        path.iter().map(|p| [p.x, p.z]).collect()
    }

    /// Paths between containers are traced once per scene and shared by the scene at every
    /// start, and each is the path that start traces for itself; paths from the start are
    /// each start's own.
    #[test]
    fn paths_between_containers_are_shared_by_every_start_and_equal_traced_ones() {
        let raw = generate_house(5, 0, &GeneratorOptions::default());
        let at = HouseLocation {
            file: "<generated>".into(),
            index: 0,
        };
        let scene = Arc::new(scene_from_raw(&raw, &at, None).unwrap());
        let grids = Grids::new(GridParams::default(), 1 << 30, 2, (0, 0));
        let base = grids.placed("g", None, || Ok(scene.clone())).unwrap();
        let n = base.house.containers.len();
        assert!(n >= 2, "{n} containers");
        let pose = |c: usize| {
            let p = base.distances.point(Place::Container(c)).unwrap();
            [p.x, p.z, 0.0]
        };
        let not_loaded = || Err(ApiError::internal("the scene is cached"));
        let a = grids.placed("g", Some(pose(0)), not_loaded).unwrap();
        let b = grids.placed("g", Some(pose(n - 1)), not_loaded).unwrap();
        assert!(Arc::ptr_eq(&a.between, &base.between));
        assert!(Arc::ptr_eq(&b.between, &base.between));
        for i in 0..n {
            for j in 0..n {
                let (from, to) = (Place::Container(i), Place::Container(j));
                // Kept through `a`, then read back through `b`.
                assert_eq!(*a.path(from, to), *traced(&a, from, to));
                assert_eq!(*b.path(from, to), *traced(&b, from, to));
            }
        }
        let kept = |paths: &Mutex<KeptPaths>| paths.lock().map(|p| p.len()).unwrap_or_default();
        assert_eq!(kept(&base.between), n * n);
        let last = Place::Container(n - 1);
        assert_eq!(*a.path(Place::Start, last), *traced(&a, Place::Start, last));
        assert_eq!(*b.path(Place::Start, last), *traced(&b, Place::Start, last));
        assert_ne!(a.path(Place::Start, last), b.path(Place::Start, last));
        assert_eq!(
            (kept(&a.paths), kept(&b.paths), kept(&base.paths)),
            (1, 1, 0)
        );
    }
}
