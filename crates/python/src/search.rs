//! `ferret.Search`: one trial step by step, what a robot loop drives — the plan crate's
//! `Search` under the strategy `ferret eval` and `ferret serve` build from the same spec, for
//! one target or a household task (several targets, a goal, a destination).

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ferret_plan::{DestinationLegs, Protocol, Search, SearchProblem, Strategy, Task, TrialSpec};
use ferret_world::{ObjectType, Place, Scene};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use self_cell::self_cell;

use crate::errors;
use crate::houses::{House, Map, PyContainer};
use crate::planning::{self, Planning};
use crate::settings::{self, Grid};
use crate::tasks;

/// What a search borrows from: the house, its map, the trial, the task's destination on the
/// map and the strategy.
struct Owner {
    scene: Arc<Scene>,
    map: Map,
    trial: TrialSpec,
    legs: Option<DestinationLegs>,
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
/// `record()` what was seen; repeat until the target is found (a task's goal holds) or
/// `next_container()` returns `None`, then `finish()` to bring what was found to the task's
/// destination. The robot may search another container than the one proposed. The search knows
/// no ground truth (strategies that need it, the oracle, cannot be driven this way) and starts
/// with nothing searched, as a `ferret serve` trial does; a simulated loop that answers from the
/// house's contents travels exactly what `ferret.evaluate` reports for the same house, target
/// (or task) and strategy. Not shared between threads at once (a second thread gets a
/// `RuntimeError`).
#[pyclass(name = "Search", module = "ferret")]
pub struct PySearch {
    live: Mutex<Live>,
    map: Map,
    house: Py<House>,
    /// The target types, in the task's order (one for the paper's search).
    targets: Vec<String>,
    /// The targets as `trials.csv` names them (`Mug`, `Mug+Apple`, `Mug|Cup`).
    label: String,
    strategy: String,
    /// Whether `finish()` was called: the robot went to the destination and searches no more.
    finished: bool,
}

/// What a finished search gives a deployment to replay its trial on.
pub(crate) struct Concluded {
    /// The house searched.
    pub scene: Arc<Scene>,
    /// The map it was searched on.
    pub map: Map,
    /// Its trial (the task).
    pub trial: TrialSpec,
    /// The task's destination on the map.
    pub legs: Option<DestinationLegs>,
    /// Where each target (task order) was found; `None` for targets of `any` not found.
    pub found_each: Vec<Option<usize>>,
    /// Metres travelled, the way to the destination included.
    pub cost: f64,
}

impl PySearch {
    fn live(&mut self) -> &mut Live {
        self.live.get_mut().unwrap_or_else(|p| p.into_inner())
    }

    fn container(&self, c: usize) -> PyContainer {
        self.house.get().container(c, Some(&self.map.1))
    }

    /// True for a search of one target (with or without a destination): `record(found=True)`
    /// means that target, as before tasks existed.
    fn one_target(&self) -> bool {
        self.targets.len() == 1
    }

    /// The strategy spec it runs.
    pub(crate) fn strategy_spec(&self) -> &str {
        &self.strategy
    }

    /// Metres travelled so far.
    pub(crate) fn travelled(&mut self) -> f64 {
        self.live()
            .with_dependent_mut(|_, s| s.belief().travelled())
    }

    /// Where each target (task order) was first seen.
    fn found_each(&mut self) -> Vec<Option<usize>> {
        self.live()
            .with_dependent_mut(|_, s| s.belief().found_each().to_vec())
    }

    fn goal_holds_now(&mut self) -> bool {
        self.live().with_dependent_mut(|_, s| s.goal_holds())
    }

    fn has_destination(&mut self) -> bool {
        self.live().borrow_owner().legs.is_some()
    }

    /// The search as a deployment replays it: its target found (a task's goal holding), the
    /// robot taken to the destination when it has one and was not yet (`finish()`).
    ///
    /// # Errors
    /// `SearchError` when the target was not found (the goal does not hold).
    pub(crate) fn conclude(&mut self) -> PyResult<Concluded> {
        if !self.goal_holds_now() {
            return Err(errors::search(if self.one_target() {
                "the search has not found its target: finish() needs a found target, abandon() ends a trial without one".to_string()
            } else {
                format!(
                    "the search's goal ({}) does not hold: finish() needs a search whose goal holds, abandon() ends a trial without it",
                    self.label
                )
            }));
        }
        let found_each = self.found_each();
        if self.has_destination() {
            self.finish_now();
        }
        let cost = self.travelled();
        let map = self.map.clone();
        let owner = self.live().borrow_owner();
        Ok(Concluded {
            scene: owner.scene.clone(),
            map,
            trial: owner.trial.clone(),
            legs: owner.legs.clone(),
            found_each,
            cost,
        })
    }

    /// Goes to the destination (once): the leg, metres.
    fn finish_now(&mut self) -> f64 {
        self.finished = true;
        self.live().with_dependent_mut(|_, s| s.finish())
    }

    fn ids(&self, cs: &[usize]) -> Vec<String> {
        let h = &self.house.get().scene.house;
        cs.iter()
            .filter_map(|&c| h.containers.get(c).map(|x| x.id.clone()))
            .collect()
    }

    /// A container `record` or `observe` is told was searched, and what was seen there,
    /// checked: in the house, not searched yet, the search not finished.
    fn searched_there(
        &mut self,
        container: &Bound<'_, PyAny>,
        (found, objects, found_targets): (bool, Option<Vec<String>>, Option<Vec<String>>),
    ) -> PyResult<(usize, Vec<ObjectType>)> {
        let (c, id) = {
            let house = self.house.get();
            let c = house.container_index(container)?;
            (c, house.scene.house.containers[c].id.clone())
        };
        if self.finished {
            return Err(errors::search(
                "the search was finished (finish()): start a new Search",
            ));
        }
        let seen = self.observed(found, objects, found_targets)?;
        if self
            .live()
            .with_dependent_mut(|_, s| s.belief().is_searched(c))
        {
            return Err(errors::search(format!("{id:?} was already searched")));
        }
        Ok((c, seen))
    }

    /// The object types `record` is told were seen in a container, checked: those listed in
    /// `objects`, the targets named in `found_targets`, and for one target the target itself
    /// when `found`.
    fn observed(
        &self,
        found: bool,
        objects: Option<Vec<String>>,
        found_targets: Option<Vec<String>>,
    ) -> PyResult<Vec<ObjectType>> {
        let mut seen: Vec<String> = objects.unwrap_or_default();
        let named = found_targets.unwrap_or_default();
        for (i, t) in named.iter().enumerate() {
            let t = t.trim();
            if !self.targets.iter().any(|x| x == t) {
                return Err(errors::config(format!(
                    "found_targets[{i}]: {t:?} is not a target of this search ({})",
                    self.targets.join(", ")
                )));
            }
            if !seen.iter().any(|s| s == t) {
                seen.push(t.to_string());
            }
        }
        if let [one] = self.targets.as_slice() {
            // As before tasks: `found` says the target was there.
            if found && !seen.contains(one) {
                seen.push(one.clone());
            }
        } else if found && !self.targets.iter().any(|t| seen.contains(t)) {
            return Err(errors::config(format!(
                "found=True, but no target of this search ({}) is named: list the targets seen in found_targets (or objects)",
                self.targets.join(", ")
            )));
        }
        Ok(seen.into_iter().map(ObjectType::new).collect())
    }
}

/// The task a search's arguments ask for, its targets checked against what `scene` holds.
fn task_of(
    scene: &Scene,
    names: &[String],
    as_list: bool,
    goal: ferret_plan::Goal,
    destination: Option<ferret_plan::Destination>,
) -> PyResult<Task> {
    // A target the house does not hold could only end "not found" after every container.
    let held = scene.truth.target_types();
    let mut targets = Vec::with_capacity(names.len());
    for (i, name) in names.iter().enumerate() {
        let t = ferret_world::check_target(name, &held).map_err(|e| {
            if as_list {
                errors::config(format!("target[{i}]: {e}"))
            } else {
                errors::config(e.to_string())
            }
        })?;
        targets.push(t);
    }
    Task::new(targets, goal, destination).map_err(|e| task_field_error(&e))
}

/// The checks a task makes of itself (count, repeats), on the names given.
fn check_names(names: &[String], goal: ferret_plan::Goal) -> PyResult<()> {
    Task::new(
        names.iter().map(|n| ObjectType::new(n.as_str())).collect(),
        goal,
        None,
    )
    .map(|_| ())
    .map_err(|e| task_field_error(&e))
}

/// A task's error named by this class's keywords: the task's `targets` are `target`.
fn task_field_error(e: &ferret_plan::TaskError) -> PyErr {
    let field = if e.field == "targets" {
        "target"
    } else {
        e.field
    };
    errors::config(format!("{field}: {}", e.message))
}

#[pymethods]
impl PySearch {
    /// Starts a search in `house` from its start pose with the strategy `strategy` (a spec as
    /// in `ferret eval --strategies`, e.g. `"model/prior"`, `"model/prior/exact"`,
    /// `"optimistic+greedy"`, `"sequential/model/prior"`, `"llm+model/p-yesno/<llm>"`).
    ///
    /// `target` is the object type to find, or a household task's list of 1 to 4 distinct
    /// types: `goal="all"` wants every one of them, `goal="any"` one. `destination` is where
    /// the robot brings what it found, its way there part of the cost (`finish()`): `None`,
    /// `"start"` ("bring it to me"), `"container:<id>"`, `"room:<id>"` (the room's centre), an
    /// `(x, y)` point in metres, or a `Container` of the house. One target without a
    /// destination is the paper's search, exactly as before tasks.
    ///
    /// Planner, prior, LLM and grid keywords are those of `ferret.evaluate`. Raises
    /// `StrategyError` for an unknown spec, `HouseError` for a house that cannot be mapped,
    /// `ConfigError` for a target the house's containers do not hold (naming the type most
    /// likely meant), a repeated target, more than 4, an unknown goal, or a destination the
    /// house does not have or the robot cannot reach (each naming the keyword).
    #[new]
    #[pyo3(signature = (
        house, target, strategy = "model/prior", *, goal = "all", destination = None,
        prior = None, config = None, llm_cache = None, offline = false, fusion = None,
        max_containers = 8, exact_max = 16, search_cost = 0.0, resolution = 0.05,
        robot_radius = 0.18, wall_thickness = 0.05, protocol = "ferret"
    ))]
    fn new(
        py: Python<'_>,
        house: Py<House>,
        target: &Bound<'_, PyAny>,
        strategy: &str,
        goal: &str,
        destination: Option<&Bound<'_, PyAny>>,
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
        let (names, as_list) = tasks::target_names(target)?;
        let goal = tasks::goal(goal)?;
        // How many targets, and none twice: refused before any work (the house is asked
        // whether it holds them once the strategy is known to be drivable).
        check_names(&names, goal)?;
        let grid = Grid::new(resolution, robot_radius, wall_thickness)?;
        let protocol: Protocol = settings::protocol(protocol)?;
        let planning = Planning::new(prior, max_containers, exact_max, search_cost)?;
        let llm = settings::llm(config, llm_cache, offline, false, fusion);
        let h = house.get();
        let destination = tasks::destination(h, destination)?;
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
        let task = task_of(&h.scene, &names, as_list, goal, destination)?;
        // The destination resolved once on this map; a room or point the robot cannot reach is
        // refused now rather than at the end of the search.
        let legs = task
            .destination()
            .map(|d| d.legs(&h.scene.house, &map.1))
            .transpose()
            .map_err(|e| tasks::task_error("destination", &e))?;
        // One target, goal `all`, no destination: exactly `TrialSpec::single`, the paper's trial.
        let trial = TrialSpec::of(task);
        let targets: Vec<String> = trial.task.targets().iter().map(|t| t.to_string()).collect();
        let label = trial.task.targets_label();
        let owner = Owner {
            scene: h.scene.clone(),
            map: map.clone(),
            trial,
            legs,
            strategy: built,
        };
        let live = py.allow_threads(|| {
            errors::guarded("Search", || {
                Live::try_new(owner, |o| {
                    let mut problem = SearchProblem::new(&o.scene.house, &o.map.1, &o.trial);
                    if let Some(l) = &o.legs {
                        problem = problem.with_destination(l);
                    }
                    Search::start(o.strategy.as_ref(), &problem, None)
                })
                .map_err(errors::plan)
            })
        })?;
        Ok(Self {
            live: Mutex::new(live),
            map,
            house,
            targets,
            label,
            strategy: strategy.trim().to_string(),
            finished: false,
        })
    }

    /// The container the robot should search next, or `None` once the target was found (a
    /// task's goal holds), every container was searched, or the search was finished. Asking
    /// again before `record()` proposes the same one. Releases the GIL while the strategy
    /// decides (an LLM strategy may ask its endpoint).
    ///
    /// In a team, `leaving` lists the containers teammates are on their way to (ids or
    /// `Container`s): never proposed, and planned around as if they held nothing (this robot's
    /// plan only matters where they do not); `None` when every container left is one of them.
    #[pyo3(signature = (leaving = None))]
    fn next_container(
        &mut self,
        py: Python<'_>,
        leaving: Option<Vec<Bound<'_, PyAny>>>,
    ) -> PyResult<Option<PyContainer>> {
        let others = {
            let house = self.house.get();
            leaving
                .unwrap_or_default()
                .iter()
                .map(|c| house.container_index(c))
                .collect::<PyResult<Vec<usize>>>()?
        };
        let live = self.live();
        let next = py.allow_threads(|| {
            errors::guarded("Search.next_container", || {
                live.with_dependent_mut(|_, s| s.next_container_leaving(&others))
                    .map_err(errors::plan)
            })
        })?;
        Ok(next.map(|c| self.container(c)))
    }

    /// Records what a teammate saw in `container` (arguments as `record()`): known to this
    /// robot at once, without it moving. Raises `SearchError` for a container not in the house
    /// or already searched, and after `finish()`.
    #[pyo3(signature = (container, found = false, objects = None, found_targets = None))]
    fn observe(
        &mut self,
        container: &Bound<'_, PyAny>,
        found: bool,
        objects: Option<Vec<String>>,
        found_targets: Option<Vec<String>>,
    ) -> PyResult<()> {
        let (c, seen) = self.searched_there(container, (found, objects, found_targets))?;
        self.live()
            .with_dependent_mut(|_, s| s.observe(c, seen).map_err(errors::plan))
    }

    /// Records that the robot searched `container` (its id or the `Container`) and what it saw
    /// there; returns the length of the leg to it, metres.
    ///
    /// `objects` lists the object types seen there. For one target, `found=True` says the
    /// target was there (it is added to `objects`), as always. Every target named in
    /// `found_targets` or among `objects` is found: opening a container reveals all of it, so a
    /// target seen while looking for another counts. For a task of several targets,
    /// `found=True` without naming one raises `ConfigError` (which target was it?).
    /// `found_targets` may only name the search's targets (`ConfigError` otherwise). Raises
    /// `SearchError` for a container not in the house or already searched, after the target
    /// was found (the goal holds) or after `finish()`.
    #[pyo3(signature = (container, found = false, objects = None, found_targets = None))]
    fn record(
        &mut self,
        container: &Bound<'_, PyAny>,
        found: bool,
        objects: Option<Vec<String>>,
        found_targets: Option<Vec<String>>,
    ) -> PyResult<f64> {
        // A container not in the house is refused before anything else.
        self.house.get().container_index(container)?;
        let goal_at = self.live().with_dependent_mut(|_, s| s.goal_container());
        if let Some(f) = goal_at {
            let at = self.house.get().scene.house.containers[f].id.clone();
            return Err(errors::search(if self.one_target() {
                format!(
                    "the {} was already found in {at:?}; start a new Search",
                    self.label
                )
            } else {
                format!(
                    "the goal of {} already holds (since {at:?}): call finish(), or start a new Search",
                    self.label
                )
            }));
        }
        let (c, seen) = self.searched_there(container, (found, objects, found_targets))?;
        self.live()
            .with_dependent_mut(|_, s| s.record(c, seen).map_err(errors::plan))
    }

    /// Ends the search: the robot goes from where it stands to the task's destination, and
    /// searches no more. Returns that last leg, metres (0 without a destination), which
    /// `cost` then includes; calling it again returns the same leg and adds nothing.
    fn finish(&mut self) -> f64 {
        self.finish_now()
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

    /// The way on the grid from where the robot is to the task's destination, as (x, y) points
    /// in metres; `None` for a search without a destination.
    fn path_to_destination(&mut self) -> Option<Vec<(f64, f64)>> {
        self.live().with_dependent_mut(|o, s| {
            let legs = o.legs.as_ref()?;
            Some(
                legs.path(&o.map.1, s.belief().position())
                    .unwrap_or_default()
                    .iter()
                    .map(|p| (p.x, p.z))
                    .collect(),
            )
        })
    }

    /// Where the robot brings what it found, as the (x, y) point in metres it stands at there
    /// (the start, a container's access point, a room's centre, the reachable point nearest to
    /// the one given), or `None` for a search without a destination.
    #[getter]
    fn destination(&mut self) -> Option<(f64, f64)> {
        let o = self.live().borrow_owner();
        let legs = o.legs.as_ref()?;
        legs.point(&o.map.1).map(|p| (p.x, p.z))
    }

    /// Metres travelled so far (the trial's cost once it ends), the way to the destination
    /// included once `finish()` was called.
    #[getter]
    fn cost(&mut self) -> f64 {
        self.travelled()
    }

    /// The probability the strategy's likelihood source gives each container of the house (in
    /// `house.containers` order) before any search that `target` (one of the search's targets;
    /// default its first) is there, or `None` for strategies that plan without one
    /// (`optimistic+greedy`). Releases the GIL (an LLM source may ask its endpoint).
    #[pyo3(signature = (target = None))]
    fn likelihoods(&mut self, py: Python<'_>, target: Option<&str>) -> PyResult<Option<Vec<f64>>> {
        let target = match target.map(str::trim) {
            None => None,
            Some(t) if self.targets.iter().any(|x| x == t) => Some(ObjectType::new(t)),
            Some(t) => {
                return Err(errors::config(format!(
                    "target: {t:?} is not a target of this search ({})",
                    self.targets.join(", ")
                )));
            }
        };
        let live = self.live();
        let owner = live.borrow_owner();
        let Some(source) = owner.strategy.likelihood_source().cloned() else {
            return Ok(None);
        };
        let target = target.unwrap_or_else(|| owner.trial.task.first().clone());
        let scene = owner.scene.clone();
        py.allow_threads(|| {
            errors::guarded("Search.likelihoods", || {
                source
                    .likelihoods(&scene.house, &target)
                    .map(|ps| Some(ps.iter().map(|p| p.get()).collect()))
                    .map_err(errors::plan)
            })
        })
    }

    /// Ids of the containers this robot searched, in order (not those a teammate searched and
    /// it `observe`d).
    #[getter]
    fn searched(&mut self) -> Vec<String> {
        let order = self
            .live()
            .with_dependent_mut(|_, s| s.belief().searched_in_order().to_vec());
        self.ids(&order)
    }

    /// The container where the target was found, or `None`. For a task of several targets:
    /// where its goal came to hold (the last target wanted for `all`, the first found for
    /// `any`), as `trials.csv`'s `found_container`; `found_in` says where each was.
    #[getter]
    fn found(&mut self) -> Option<PyContainer> {
        let at = self.live().with_dependent_mut(|_, s| s.goal_container());
        at.map(|c| self.container(c))
    }

    /// Each target found so far and the container it was first seen in (a dict in the task's
    /// order; targets not found are absent).
    #[getter]
    fn found_in<'py>(&mut self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let found_each = self.found_each();
        let out = PyDict::new(py);
        for (t, at) in self.targets.iter().zip(found_each) {
            if let Some(c) = at {
                out.set_item(t, self.container(c))?;
            }
        }
        Ok(out)
    }

    /// True once the task's goal holds: its target found (`all`: every target, `any`: one).
    #[getter]
    fn goal_holds(&mut self) -> bool {
        self.goal_holds_now()
    }

    /// True once the target was found (a task's goal holds), every container was searched, or
    /// the search was finished.
    #[getter]
    fn done(&mut self) -> bool {
        self.goal_holds_now()
            || self.finished
            || self
                .live()
                .with_dependent_mut(|_, s| s.belief().unsearched_count() == 0)
    }

    /// The object type searched for; for a task of several, its targets as `trials.csv`'s
    /// `target` names them (`Mug+Apple` for all, `Mug|Cup` for any).
    #[getter]
    fn target(&self) -> &str {
        &self.label
    }

    /// The target types, in the task's order (one for a search of one target).
    #[getter]
    fn targets(&self) -> Vec<String> {
        self.targets.clone()
    }

    /// `"all"` (every target wanted) or `"any"` (one of them).
    #[getter]
    fn goal(&mut self) -> &'static str {
        self.live().borrow_owner().trial.task.goal().as_str()
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
        let destination = {
            let o = self.live().borrow_owner();
            o.trial
                .task
                .destination()
                .map(|d| {
                    format!(
                        ", destination={}",
                        crate::convert::quote(&d.label(&o.scene.house))
                    )
                })
                .unwrap_or_default()
        };
        format!(
            "Search(house={}, target={}, strategy={}{destination}, searched={n}, cost={cost:.2})",
            crate::convert::quote(&self.house.get().scene.house.name),
            crate::convert::quote(&self.label),
            crate::convert::quote(&self.strategy)
        )
    }
}
