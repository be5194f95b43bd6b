//! `ferret.House` and its parts, and the functions that load or generate houses (the command
//! line's `--houses`, `--range`, `--asset-db`, `--generate`, `--house-seed`).

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ferret_lab::HouseSource;
use ferret_world::{ContainerSet, Distances, OccupancyGrid, Place, Point, Scene};
use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::convert;
use crate::errors;
use crate::settings::{self, Grid};

/// A house's map: its occupancy grid and the travel distances on it.
pub type Map = Arc<(OccupancyGrid, Distances)>;

/// Grid parameters as a key (bit patterns, so that equal options share a map).
type MapKey = [u64; 4];

/// A house: rooms, containers and what the containers hold, with its maps built on first use.
/// Immutable; a house in several lists is one object.
#[pyclass(name = "House", module = "ferret", frozen)]
pub struct House {
    /// The house and what its containers hold.
    pub scene: Arc<Scene>,
    /// The container set a ProcTHOR file was read with; `None` for houses that name their
    /// containers themselves (generated houses, scene files).
    pub read_with: Option<ContainerSet>,
    /// Where the house was loaded or generated from, shared by the houses of one call: what
    /// `run.json` names so that `ferret select` can load the houses again.
    pub origin: Arc<HouseSource>,
    maps: Mutex<Vec<(MapKey, Map)>>,
}

impl House {
    fn new(scene: Scene, read_with: Option<ContainerSet>, origin: Arc<HouseSource>) -> Self {
        Self {
            scene: Arc::new(scene),
            read_with,
            origin,
            maps: Mutex::new(Vec::new()),
        }
    }

    /// The map under these grid options and protocol, built once (without the GIL).
    pub fn map(
        &self,
        py: Python<'_>,
        grid: &Grid,
        protocol: &ferret_plan::Protocol,
    ) -> PyResult<Map> {
        let params = grid.params(protocol);
        let key = [
            params.resolution.to_bits(),
            params.robot_radius.to_bits(),
            params.wall_thickness.to_bits(),
            u64::from(params.access == ferret_world::AccessRule::NearestFree),
        ];
        if let Some((_, m)) = self.lock().iter().find(|(k, _)| *k == key) {
            return Ok(m.clone());
        }
        let scene = self.scene.clone();
        let built = py.allow_threads(|| {
            errors::guarded("building the map", || {
                ferret_world::distance::build(&scene.house, &params).map_err(errors::world)
            })
        })?;
        let mut maps = self.lock();
        // Another thread may have built the same map meanwhile: keep one.
        if let Some((_, m)) = maps.iter().find(|(k, _)| *k == key) {
            return Ok(m.clone());
        }
        let map = Arc::new(built);
        maps.push((key, map.clone()));
        Ok(map)
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, Vec<(MapKey, Map)>> {
        self.maps.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// The index of a container given as its id or as a `Container`.
    pub fn container_index(&self, arg: &Bound<'_, PyAny>) -> PyResult<usize> {
        let house = &self.scene.house;
        let id = if let Ok(c) = arg.downcast::<PyContainer>() {
            let c = c.get();
            // Ids repeat across houses (generated houses number their containers alike): a
            // container from another house would otherwise pass for this house's namesake.
            if !Arc::ptr_eq(&c.scene, &self.scene) {
                return Err(errors::search(format!(
                    "{:?} is a container of another house ({}), not of house {}",
                    c.id, c.scene.house.name, house.name
                )));
            }
            c.id.clone()
        } else if let Ok(s) = arg.extract::<String>() {
            s
        } else {
            return Err(errors::config(
                "container: expected a container id (str) or a ferret.Container",
            ));
        };
        house.container_index(&id).ok_or_else(|| {
            errors::search(format!("{id:?} is not a container of house {}", house.name))
        })
    }

    /// Container `c` as Python sees it, its access point taken from `map` when there is one.
    pub fn container(&self, c: usize, map: Option<&Distances>) -> PyContainer {
        let house = &self.scene.house;
        let container = &house.containers[c];
        let room = house.container_room(c);
        let xy = |p: Point| (p.x, p.z);
        PyContainer {
            scene: self.scene.clone(),
            index: c,
            id: container.id.clone(),
            object_type: container.object_type.to_string(),
            room: room.map(|r| r.id.clone()),
            room_type: room.map(|r| r.room_type.to_string()),
            position: xy(container.position),
            access: map
                .and_then(|d| d.point(Place::Container(c)))
                .or(container.access)
                .map(xy),
        }
    }

    fn default_map(&self, py: Python<'_>) -> Option<Map> {
        let grid = Grid::default();
        self.map(py, &grid, &ferret_plan::Protocol::FERRET).ok()
    }
}

/// The scenes of a list of houses, shared.
pub fn scenes_of(houses: &[Py<House>]) -> Vec<Arc<Scene>> {
    houses.iter().map(|h| h.get().scene.clone()).collect()
}

#[pymethods]
impl House {
    /// A label naming where the house came from, e.g. `multiroom-val150.jsonl.gz#3`.
    #[getter]
    fn name(&self) -> &str {
        &self.scene.house.name
    }

    /// The house's index in its file (or among the generated houses).
    #[getter]
    fn index(&self) -> usize {
        self.scene.house.index
    }

    /// The robot's start (x, y) on the floor, metres.
    #[getter]
    fn start(&self) -> (f64, f64) {
        let p = self.scene.house.start.position;
        (p.x, p.z)
    }

    /// The rooms, in the house's order.
    #[getter]
    fn rooms(&self) -> Vec<PyRoom> {
        self.scene
            .house
            .rooms
            .iter()
            .map(|r| PyRoom {
                id: r.id.clone(),
                room_type: r.room_type.to_string(),
                polygon: r.floor.vertices.iter().map(|p| (p.x, p.z)).collect(),
            })
            .collect()
    }

    /// The containers, in the house's order (row/column `i + 1` of `distances()`). Their access
    /// points come from the default map, built on first use; a house that cannot be mapped has
    /// none but those its scene file names.
    #[getter]
    fn containers(&self, py: Python<'_>) -> Vec<PyContainer> {
        let map = self.default_map(py);
        (0..self.scene.house.containers.len())
            .map(|c| self.container(c, map.as_ref().map(|m| &m.1)))
            .collect()
    }

    /// Every small object and the container holding it, container by container.
    #[getter]
    fn objects(&self) -> Vec<PyObject_> {
        let house = &self.scene.house;
        (0..house.containers.len())
            .flat_map(|c| {
                self.scene.truth.contents(c).iter().map(move |o| PyObject_ {
                    id: o.id.clone(),
                    object_type: o.object_type.to_string(),
                    container: house.containers[c].id.clone(),
                })
            })
            .collect()
    }

    /// The object types a container holds (its ground truth), given its id or the `Container`.
    fn contents(&self, container: &Bound<'_, PyAny>) -> PyResult<Vec<String>> {
        let c = self.container_index(container)?;
        Ok(self
            .scene
            .truth
            .contents(c)
            .iter()
            .map(|o| o.object_type.to_string())
            .collect())
    }

    /// The object types that can be searched for: those held by some container, in name order.
    fn target_types(&self) -> Vec<String> {
        self.scene
            .truth
            .target_types()
            .into_iter()
            .map(|t| t.to_string())
            .collect()
    }

    /// The container with this id.
    fn container_by_id(&self, py: Python<'_>, id: &str) -> PyResult<PyContainer> {
        let c = self.container_index(&id.into_pyobject(py)?.into_any())?;
        let map = self.default_map(py);
        Ok(self.container(c, map.as_ref().map(|m| &m.1)))
    }

    /// Shortest travel distances, metres, as a `(n + 1) × (n + 1)` float64 array over n
    /// containers: row and column 0 are the robot's start, `i + 1` container `i`. Measured on the
    /// occupancy grid `ferret eval` builds with the same options (built once per options, without
    /// the GIL). Raises `HouseError` for a house with an unreachable container.
    #[pyo3(signature = (*, resolution = 0.05, robot_radius = 0.18, wall_thickness = 0.05, protocol = "ferret"))]
    fn distances<'py>(
        &self,
        py: Python<'py>,
        resolution: f64,
        robot_radius: f64,
        wall_thickness: f64,
        protocol: &str,
    ) -> PyResult<Bound<'py, PyAny>> {
        let grid = Grid::new(resolution, robot_radius, wall_thickness)?;
        let protocol = settings::protocol(protocol)?;
        let map = self.map(py, &grid, &protocol)?;
        let d = &map.1;
        let n = d.container_count() + 1;
        let array = PyArray1::from_slice(py, d.matrix()).reshape([n, n])?;
        Ok(array.into_any())
    }

    fn __repr__(&self) -> String {
        format!(
            "House(name={}, index={}, rooms={}, containers={}, objects={})",
            convert::quote(&self.scene.house.name),
            self.scene.house.index,
            self.scene.house.rooms.len(),
            self.scene.house.containers.len(),
            self.scene.truth.object_count()
        )
    }
}

/// A container: a piece of furniture the robot can search.
#[pyclass(name = "Container", module = "ferret", frozen, eq)]
#[derive(Clone, Debug)]
pub struct PyContainer {
    /// The house it belongs to (the very one: equal ids in two houses are two containers).
    pub scene: Arc<Scene>,
    /// Its position in `House.containers`.
    #[pyo3(get)]
    pub index: usize,
    /// Its id in the house file.
    #[pyo3(get)]
    pub id: String,
    /// Its object type, e.g. `Fridge`.
    #[pyo3(get, name = "type")]
    pub object_type: String,
    /// The id of the room it stands in.
    #[pyo3(get)]
    pub room: Option<String>,
    /// The type of that room, e.g. `Kitchen`.
    #[pyo3(get)]
    pub room_type: Option<String>,
    /// The centre of its footprint (x, y), metres.
    #[pyo3(get)]
    pub position: (f64, f64),
    /// Where the robot stands to search it (x, y), metres.
    #[pyo3(get)]
    pub access: Option<(f64, f64)>,
}

impl PartialEq for PyContainer {
    fn eq(&self, other: &Self) -> bool {
        Arc::ptr_eq(&self.scene, &other.scene)
            && (
                self.index,
                &self.id,
                &self.object_type,
                &self.room,
                &self.room_type,
                self.position,
                self.access,
            ) == (
                other.index,
                &other.id,
                &other.object_type,
                &other.room,
                &other.room_type,
                other.position,
                other.access,
            )
    }
}

#[pymethods]
impl PyContainer {
    /// The name of the house it belongs to.
    #[getter]
    fn house(&self) -> String {
        self.scene.house.name.clone()
    }

    fn __repr__(&self) -> String {
        format!(
            "Container(id={}, type={}, room={})",
            convert::quote(&self.id),
            convert::quote(&self.object_type),
            convert::quote_opt(self.room.as_deref())
        )
    }
}

/// A room.
#[pyclass(name = "Room", module = "ferret", frozen)]
#[derive(Clone, Debug)]
pub struct PyRoom {
    /// Its id in the house file.
    #[pyo3(get)]
    pub id: String,
    /// Its type, e.g. `Kitchen`.
    #[pyo3(get, name = "type")]
    pub room_type: String,
    /// Its floor polygon's vertices (x, y), metres.
    #[pyo3(get)]
    pub polygon: Vec<(f64, f64)>,
}

#[pymethods]
impl PyRoom {
    fn __repr__(&self) -> String {
        format!(
            "Room(id={}, type={})",
            convert::quote(&self.id),
            convert::quote(&self.room_type)
        )
    }
}

/// A small object inside or on a container.
#[pyclass(name = "Object", module = "ferret", frozen)]
#[derive(Clone, Debug)]
pub struct PyObject_ {
    /// Its id in the house file.
    #[pyo3(get)]
    pub id: String,
    /// Its object type, e.g. `CellPhone`.
    #[pyo3(get, name = "type")]
    pub object_type: String,
    /// The id of the container holding it.
    #[pyo3(get)]
    pub container: String,
}

#[pymethods]
impl PyObject_ {
    fn __repr__(&self) -> String {
        format!(
            "Object(id={}, type={}, container={})",
            convert::quote(&self.id),
            convert::quote(&self.object_type),
            convert::quote(&self.container)
        )
    }
}

fn container_set(name: &str) -> PyResult<ContainerSet> {
    name.parse::<ContainerSet>()
        .map_err(|e| errors::config(format!("containers={name:?}: {e}")))
}

fn into_houses(
    py: Python<'_>,
    source: HouseSource,
    read_with: Option<ContainerSet>,
) -> PyResult<Vec<Py<House>>> {
    let containers = read_with.unwrap_or_default();
    let origin = Arc::new(source.clone());
    let loaded = py.allow_threads(|| {
        errors::guarded("loading houses", || {
            source.load_for(containers).map_err(errors::lab)
        })
    })?;
    if !loaded.skipped.is_empty() {
        let warnings = py.import("warnings")?;
        for s in &loaded.skipped {
            warnings.call_method1("warn", (format!("skipped: {s}"),))?;
        }
    }
    let from_file = source
        .houses
        .as_deref()
        .is_some_and(|p| !ferret_world::scene::is_scene_file(p));
    loaded
        .scenes
        .into_iter()
        .map(|s| {
            Py::new(
                py,
                House::new(
                    s,
                    if from_file { Some(containers) } else { None },
                    origin.clone(),
                ),
            )
        })
        .collect()
}

/// Loads houses: a ProcTHOR `.json` house or `.jsonl`/`.jsonl.gz` file with one house per line,
/// or a ferret scene file (`.yaml`/`.yml`, or `.json` with `ferret_scene`) — what `ferret eval
/// --houses` reads. `range` picks houses by 0-based index (`"0..150"`, `"7"`, `"3.."`, or a
/// Python `range`); `asset_db` is the ProcTHOR generator's asset database; `skip_invalid` warns
/// about invalid houses and goes on; `containers` is the container set (`"receptacles"`, or
/// `"furniture"` for `protocol="paper"`). Releases the GIL while reading. Raises `HouseError`
/// naming the file, the house and the field.
#[pyfunction]
#[pyo3(signature = (path, *, asset_db = None, range = None, skip_invalid = false, containers = "receptacles"))]
pub fn load_houses(
    py: Python<'_>,
    path: PathBuf,
    asset_db: Option<PathBuf>,
    range: Option<&Bound<'_, PyAny>>,
    skip_invalid: bool,
    containers: &str,
) -> PyResult<Py<PyList>> {
    let set = container_set(containers)?;
    let range = range
        .filter(|r| !r.is_none())
        .map(convert::house_range)
        .transpose()?;
    let source = HouseSource {
        houses: Some(path),
        range,
        asset_db,
        skip_invalid,
        generate: 0,
        house_seed: 0,
    };
    let houses = into_houses(py, source, Some(set))?;
    Ok(PyList::new(py, houses)?.unbind())
}

/// Generates `n` houses from `seed` with ferret's own generator: the houses of `ferret eval
/// --generate n --house-seed seed`.
#[pyfunction]
#[pyo3(signature = (n, seed = 0))]
pub fn generate_houses(py: Python<'_>, n: usize, seed: u64) -> PyResult<Py<PyList>> {
    let source = HouseSource {
        generate: n,
        house_seed: seed,
        ..HouseSource::default()
    };
    let houses = into_houses(py, source, None)?;
    Ok(PyList::new(py, houses)?.unbind())
}
