//! `ferret.Search`: one trial step by step, what a robot loop drives — the plan crate's
//! `Search` under the strategy `ferret eval` and `ferret serve` build from the same spec.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ferret_plan::{Protocol, Search, SearchProblem, Strategy, TrialSpec};
use ferret_world::{ObjectType, Place, Scene};
use pyo3::prelude::*;
use self_cell::self_cell;

use crate::errors;
use crate::houses::{House, Map, PyContainer};
use crate::planning::{self, Planning};
use crate::settings::{self, Grid};

/// What a search borrows from: the house, its map, the trial and the strategy.
struct Owner {
    scene: Arc<Scene>,
    map: Map,
    trial: TrialSpec,
    strategy: Arc<dyn Strategy>,
}

type LiveSearch<'a> = Search<'a>;

self_cell!(
    /// A search with what it borrows, so that Python can hold it between steps.
    struct Live {
        owner: Owner,
        #[not_covariant]
        dependent: LiveSearch,
    }
);

/// One trial in progress: ask `next_container()` where to go, go there, search, and
/// `record()` what was seen; repeat until the target is found or `next_container()` returns
/// `None`. The robot may search another container than the one proposed. The search knows no
/// ground truth (strategies that need it, the oracle, cannot be driven this way) and starts
/// with nothing searched, as a `ferret serve` trial does; a simulated loop that answers from the
/// house's contents travels exactly what `ferret.evaluate` reports for the same house, target
/// and strategy. Not shared between threads at once (a second thread gets a `RuntimeError`).
#[pyclass(name = "Search", module = "ferret")]
pub struct PySearch {
    live: Mutex<Live>,
    map: Map,
    house: Py<House>,
    target: String,
    strategy: String,
    found: Option<usize>,
}

impl PySearch {
    fn live(&mut self) -> &mut Live {
        self.live.get_mut().unwrap_or_else(|p| p.into_inner())
    }

    fn container(&self, c: usize) -> PyContainer {
        self.house.get().container(c, Some(&self.map.1))
    }

    /// The strategy spec it runs.
    pub(crate) fn strategy_spec(&self) -> &str {
        &self.strategy
    }

    /// The object type searched for.
    pub(crate) fn target_type(&self) -> &str {
        &self.target
    }

    /// The index of the container where the target was found, if it was.
    pub(crate) fn found_index(&self) -> Option<usize> {
        self.found
    }

    /// Metres travelled so far.
    pub(crate) fn travelled(&mut self) -> f64 {
        self.live()
            .with_dependent_mut(|_, s| s.belief().travelled())
    }

    /// The scene and the map the search plans on.
    pub(crate) fn scene_and_map(&mut self) -> (Arc<Scene>, Map) {
        (self.live().borrow_owner().scene.clone(), self.map.clone())
    }

    fn ids(&self, cs: &[usize]) -> Vec<String> {
        let h = &self.house.get().scene.house;
        cs.iter()
            .filter_map(|&c| h.containers.get(c).map(|x| x.id.clone()))
            .collect()
    }
}

#[pymethods]
impl PySearch {
    /// Starts a search for an object of type `target` in `house` from its start pose, with the
    /// strategy `strategy` (a spec as in `ferret eval --strategies`, e.g. `"model/prior"`,
    /// `"model/prior/exact"`, `"optimistic+greedy"`, `"llm+model/p-yesno/<llm>"`). Planner,
    /// prior, LLM and grid keywords are those of `ferret.evaluate`. Raises `StrategyError` for
    /// an unknown spec, `HouseError` for a house that cannot be mapped, `ConfigError` for a
    /// target the house's containers do not hold (naming the type most likely meant).
    #[new]
    #[pyo3(signature = (
        house, target, strategy = "model/prior", *, prior = None, config = None, llm_cache = None,
        offline = false, fusion = None, max_containers = 8, exact_max = 16, search_cost = 0.0,
        resolution = 0.05, robot_radius = 0.18, wall_thickness = 0.05,
        protocol = "ferret"
    ))]
    fn new(
        py: Python<'_>,
        house: Py<House>,
        target: &str,
        strategy: &str,
        prior: Option<&Bound<'_, PyAny>>,
        config: Option<PathBuf>,
        llm_cache: Option<PathBuf>,
        offline: bool,
        fusion: Option<PathBuf>,
        max_containers: usize,
        exact_max: usize,
        search_cost: f64,
        resolution: f64,
        robot_radius: f64,
        wall_thickness: f64,
        protocol: &str,
    ) -> PyResult<Self> {
        let target = target.trim();
        if target.is_empty() {
            return Err(errors::config("target: an empty object type"));
        }
        let grid = Grid::new(resolution, robot_radius, wall_thickness)?;
        let protocol: Protocol = settings::protocol(protocol)?;
        let planning = Planning::new(prior, max_containers, exact_max, search_cost)?;
        let llm = settings::llm(config, llm_cache, offline, false, fusion);
        let h = house.get();
        let map = h.map(py, &grid, &protocol)?;
        let spec = vec![strategy.trim().to_string()];
        let built = py.allow_threads(|| {
            errors::guarded("Search", || {
                // Each search has its own LLM service: a failed endpoint fails this trial only.
                let setup = planning::registry(&planning, &llm, &spec).map_err(errors::lab)?;
                setup.registry.build(&spec[0]).map_err(errors::plan)
            })
        })?;
        if built.needs_ground_truth() {
            return Err(errors::StrategyError::new_err(format!(
                "{}: needs the ground truth, which a search driven step by step does not have; use ferret.evaluate",
                built.name()
            )));
        }
        // A target the house does not hold could only end "not found" after every container.
        let target = ferret_world::check_target(target, &h.scene.truth.target_types())
            .map_err(|e| errors::config(e.to_string()))?;
        let owner = Owner {
            scene: h.scene.clone(),
            map: map.clone(),
            trial: TrialSpec::single(target.clone()),
            strategy: built,
        };
        let live = py.allow_threads(|| {
            errors::guarded("Search", || {
                Live::try_new(owner, |o| {
                    let problem = SearchProblem::new(&o.scene.house, &o.map.1, &o.trial);
                    Search::start(o.strategy.as_ref(), &problem, None)
                })
                .map_err(errors::plan)
            })
        })?;
        Ok(Self {
            live: Mutex::new(live),
            map,
            house,
            target: target.to_string(),
            strategy: strategy.trim().to_string(),
            found: None,
        })
    }

    /// The container the robot should search next, or `None` once the target was found or
    /// every container was searched. Asking again before `record()` proposes the same one.
    /// Releases the GIL while the strategy decides (an LLM strategy may ask its endpoint).
    fn next_container(&mut self, py: Python<'_>) -> PyResult<Option<PyContainer>> {
        if self.found.is_some() {
            return Ok(None);
        }
        let live = self.live();
        let next = py.allow_threads(|| {
            errors::guarded("Search.next_container", || {
                live.with_dependent_mut(|_, s| s.next_container())
                    .map_err(errors::plan)
            })
        })?;
        Ok(next.map(|c| self.container(c)))
    }

    /// Records that the robot searched `container` (its id or the `Container`): `found` says
    /// whether the target was there, `objects` lists the object types it saw there (the target
    /// is added when found). Returns the length of the leg to it, metres. Raises `SearchError`
    /// for a container not in the house or already searched, or after the target was found.
    #[pyo3(signature = (container, found, objects = None))]
    fn record(
        &mut self,
        container: &Bound<'_, PyAny>,
        found: bool,
        objects: Option<Vec<String>>,
    ) -> PyResult<f64> {
        let house = self.house.get();
        let c = house.container_index(container)?;
        let id = house.scene.house.containers[c].id.clone();
        if let Some(f) = self.found {
            let at = house.scene.house.containers[f].id.clone();
            return Err(errors::search(format!(
                "the {} was already found in {at:?}; start a new Search",
                self.target
            )));
        }
        let target = ObjectType::new(self.target.clone());
        let mut seen: Vec<ObjectType> = objects
            .unwrap_or_default()
            .into_iter()
            .map(ObjectType::new)
            .collect();
        if found && !seen.contains(&target) {
            seen.push(target);
        }
        let leg = self.live().with_dependent_mut(|_, s| {
            if s.belief().is_searched(c) {
                return Err(errors::search(format!("{id:?} was already searched")));
            }
            s.record(c, seen).map_err(errors::plan)
        })?;
        if found {
            self.found = Some(c);
        }
        Ok(leg)
    }

    /// Travel distance from where the robot is to `container`, metres.
    fn distance_to(&mut self, container: &Bound<'_, PyAny>) -> PyResult<f64> {
        let c = self.house.get().container_index(container)?;
        Ok(self
            .live()
            .with_dependent_mut(|_, s| s.belief().distance_to(c)))
    }

    /// The shortest path on the grid from where the robot is to `container`'s access point, as
    /// (x, y) points in metres.
    fn path_to(&mut self, container: &Bound<'_, PyAny>) -> PyResult<Vec<(f64, f64)>> {
        let c = self.house.get().container_index(container)?;
        Ok(self.live().with_dependent_mut(|o, s| {
            o.map
                .1
                .path(s.belief().position(), Place::Container(c))
                .unwrap_or_default()
                .iter()
                .map(|p| (p.x, p.z))
                .collect()
        }))
    }

    /// Metres travelled so far (the trial's cost once it ends).
    #[getter]
    fn cost(&mut self) -> f64 {
        self.travelled()
    }

    /// The probability the strategy's likelihood source gives each container of the house (in
    /// `house.containers` order) before any search, or `None` for strategies that plan without
    /// one (`optimistic+greedy`). Releases the GIL (an LLM source may ask its endpoint).
    fn likelihoods(&mut self, py: Python<'_>) -> PyResult<Option<Vec<f64>>> {
        let live = self.live();
        let owner = live.borrow_owner();
        let Some(source) = owner.strategy.likelihood_source().cloned() else {
            return Ok(None);
        };
        let (scene, target) = (owner.scene.clone(), owner.trial.task.first().clone());
        py.allow_threads(|| {
            errors::guarded("Search.likelihoods", || {
                source
                    .likelihoods(&scene.house, &target)
                    .map(|ps| Some(ps.iter().map(|p| p.get()).collect()))
                    .map_err(errors::plan)
            })
        })
    }

    /// Ids of the containers searched, in order.
    #[getter]
    fn searched(&mut self) -> Vec<String> {
        let order = self
            .live()
            .with_dependent_mut(|_, s| s.belief().searched_in_order().to_vec());
        self.ids(&order)
    }

    /// The container where the target was found, or `None`.
    #[getter]
    fn found(&self) -> Option<PyContainer> {
        self.found.map(|c| self.container(c))
    }

    /// True once the target was found or every container was searched.
    #[getter]
    fn done(&mut self) -> bool {
        self.found.is_some()
            || self
                .live()
                .with_dependent_mut(|_, s| s.belief().unsearched_count() == 0)
    }

    /// The object type searched for.
    #[getter]
    fn target(&self) -> &str {
        &self.target
    }

    /// The strategy's spec.
    #[getter]
    fn strategy(&self) -> &str {
        &self.strategy
    }

    /// The house searched.
    #[getter]
    fn house(&self, py: Python<'_>) -> Py<House> {
        self.house.clone_ref(py)
    }

    fn __repr__(&mut self) -> String {
        let (cost, n) = self.live().with_dependent_mut(|_, s| {
            (s.belief().travelled(), s.belief().searched_in_order().len())
        });
        format!(
            "Search(house={}, target={}, strategy={}, searched={n}, cost={cost:.2})",
            crate::convert::quote(&self.house.get().scene.house.name),
            crate::convert::quote(&self.target),
            crate::convert::quote(&self.strategy)
        )
    }
}
