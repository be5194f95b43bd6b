//! `ferret.evaluate`: every strategy on the same trials of every house — `ferret eval`'s
//! experiment through the same experiment-layer calls, so the rows are `trials.csv`'s rows.

use std::path::PathBuf;
use std::sync::Arc;

use ferret_lab::eval_run::check_listed_tasks_in;
use ferret_lab::runs::{EvalRun, ReportView, RunInfo, RunWriter};
use ferret_lab::shard::{SHARD_RULE, Shard, ShardRecord};
use ferret_lab::{CELL_M, TrialRow};
use ferret_lab::{DEFAULT_STRATEGIES, EvalContext, HouseInput, Tasks, TrialDraw};
use ferret_plan::TrialsPerHouse;
use ferret_world::Scene;
use pyo3::prelude::*;
use pyo3::types::PyList;

use crate::convert;
use crate::errors;
use crate::houses::{House, scenes_of};
use crate::planning::{self, Planning, PriorArg};
use crate::progress;
use crate::settings::{self, Grid};

/// The result of `ferret.evaluate`: one row per trial and strategy that finished, houses in
/// order, each a dict with exactly the columns of `ferret eval`'s `trials.csv`.
#[pyclass(name = "Evaluation", module = "ferret", frozen)]
pub struct PyEvaluation {
    rows: Vec<TrialRow>,
    errors: Vec<String>,
    houses_run: usize,
    trials_run: usize,
    strategies: Vec<String>,
    /// What `run.json` says of this evaluation, or why it cannot say it.
    run_info: Result<RunInfo, String>,
    /// Where the houses came from, as `summary.md` names it.
    source: String,
    /// Indices of the houses evaluated.
    houses: Vec<usize>,
    /// Whether rows carry costs in grid cells.
    cells: bool,
    /// The shard this evaluation ran (`shard=(i, n)`), recorded by `save` for `ferret.merge`.
    shard: Option<Shard>,
    /// House or trial failures.
    failures: usize,
}

#[pymethods]
impl PyEvaluation {
    /// The rows: dicts with `trials.csv`'s columns (`house`, `house_index`, `target`,
    /// `strategy`, `cost_m`, `searches`, `found`, `found_container`, `searched`,
    /// `goal_containers`, `cost_cells` with `cells=True`, and for household tasks `goal`,
    /// `destination`, `found_each` and `delivery_m`). A new list on every access: keep it in a
    /// variable rather than indexing `rows` in a loop.
    #[getter]
    fn rows(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        convert::rows_to_py(py, &self.rows)
    }

    /// The column names of the rows, in order (`trials.csv`'s header).
    #[getter]
    fn columns(&self, py: Python<'_>) -> PyResult<Vec<String>> {
        let first = convert::rows_to_py(py, &self.rows[..self.rows.len().min(1)])?;
        match first.bind(py).iter().next() {
            Some(row) => row.downcast::<pyo3::types::PyDict>()?.keys().extract(),
            None => Ok(Vec::new()),
        }
    }

    /// One message per house or trial that failed (a house without a map or a target, a
    /// strategy that failed); every finished trial is in `rows`.
    #[getter]
    fn errors(&self) -> Vec<String> {
        self.errors.clone()
    }

    /// Houses with a map and a target.
    #[getter]
    fn houses_run(&self) -> usize {
        self.houses_run
    }

    /// Trials (house and target) drawn on those houses.
    #[getter]
    fn trials_run(&self) -> usize {
        self.trials_run
    }

    /// The strategies evaluated, in order.
    #[getter]
    fn strategies(&self) -> Vec<String> {
        self.strategies.clone()
    }

    /// Per strategy: trials, mean, median and spread of the cost, as the rows of `ferret eval`'s
    /// `summary.csv` (dicts with its columns).
    fn summary(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        convert::rows_to_py(py, &ferret_lab::summarize(&self.rows, &self.strategies))
    }

    /// The rows as a `pandas.DataFrame` with `trials.csv`'s columns. Needs pandas, which ferret
    /// does not install (`pip install pandas`).
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        convert::data_frame(py, "Evaluation", self.rows(py)?, Some(self.columns(py)?))
    }

    /// Writes the files `ferret eval` writes into `dir` (created if missing): `trials.csv`
    /// with these rows, `summary.csv`, `paired.csv` (each strategy against the best, and against
    /// each of `paired_against`; not for a shard, whose comparisons `merge` makes over all
    /// shards), `summary.md`, and `run.json`, which names the houses' source, the prior, the
    /// planner, grid and protocol settings and the household tasks, so that `ferret.select(dir)` and
    /// `ferret select --trials dir` can replay the run. Possible when the houses come from one
    /// `load_houses` or `generate_houses` call and the prior is the default or a file; raises
    /// `ConfigError` saying why otherwise.
    #[pyo3(signature = (dir, *, paired_against = None))]
    fn save(
        &self,
        py: Python<'_>,
        dir: PathBuf,
        paired_against: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<()> {
        let info = self.run_info.clone().map_err(errors::config)?;
        let against = match paired_against.filter(|s| !s.is_none()) {
            Some(s) => convert::spec_list(s, "paired_against")?,
            None => Vec::new(),
        };
        if let Some(s) = against.iter().find(|s| !self.strategies.contains(s)) {
            return Err(errors::config(format!(
                "paired_against: {s:?} is not one of the evaluation's strategies"
            )));
        }
        let mut info = info;
        info.shard = self.shard.map(|sh| ShardRecord {
            index: sh.index,
            count: sh.count,
            rule: SHARD_RULE.into(),
            houses: self.houses.clone(),
            houses_run: self.houses_run,
            trials_run: self.trials_run,
            failures: self.failures,
            paired_against: against.clone(),
            cells: self.cells,
            show_house: None,
        });
        py.allow_threads(|| {
            std::fs::create_dir_all(&dir).map_err(|e| {
                errors::FerretError::new_err(format!("creating {}: {e}", dir.display()))
            })?;
            // Through the writer `ferret eval` streams its rows into, so that the files are the
            // same; the rows already carry their cost in cells when asked for.
            let mut writer = RunWriter::create(&dir, false).map_err(errors::lab)?;
            for r in &self.rows {
                writer.push(r).map_err(errors::lab)?;
            }
            writer
                .finish(
                    info,
                    &ReportView {
                        source: &self.source,
                        houses: &self.houses,
                        houses_run: self.houses_run,
                        trials_run: self.trials_run,
                        paired_against: &against,
                        cells: self.cells,
                    },
                )
                .map_err(errors::lab)?;
            Ok(())
        })
    }

    fn __len__(&self) -> usize {
        self.rows.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "Evaluation(rows={}, houses_run={}, trials_run={}, errors={}, strategies=[{}])",
            self.rows.len(),
            self.houses_run,
            self.trials_run,
            self.errors.len(),
            self.strategies
                .iter()
                .map(|s| convert::quote(s))
                .collect::<Vec<_>>()
                .join(", ")
        )
    }
}

/// Evaluates strategies on houses as `ferret eval` does: the same trials (targets drawn by
/// `seed`) for every strategy, in parallel over houses, with the GIL released; the same houses,
/// strategies, seed and options give the very costs of `ferret eval`'s `trials.csv`.
///
/// `strategies` (a list or a comma-separated string; default `DEFAULT_STRATEGIES`) are specs as
/// in `ferret eval --strategies`. `prior` is a `Prior`, a prior file, or `None` for the default
/// prior. `protocol` is `"ferret"` or `"paper"` (houses of ProcTHOR files must then be loaded
/// with `containers="furniture"`, as `ferret eval --protocol paper` reads them). LLM strategies
/// use the endpoint configuration `config` (default `ferret.toml` when present) and the SQLite
/// response cache `llm_cache`; their questions are asked before the trials run.
///
/// `progress` shows how far the work is: `True` prints a line per step to stderr (`houses:
/// 40/150 (3.2 s)`, redrawn in place on a terminal), a callable is called as
/// `progress(what, done, total)` with the step's name (`"houses"`, `"LLM questions"`), the
/// items done and the step's length (0 while unknown) — at each step's start and end and at
/// most every hundredth of it in between — and `None` or `False` (the default) shows nothing.
/// An exception the callable raises stops the evaluation and is raised by `evaluate`.
///
/// Household tasks replace the one target of each trial, as with `ferret eval --task` and
/// `--tasks`: `task="all:3"` (or `"any:2"`) draws per house a task of that many distinct types
/// present (from `seed`; `trials_per_house` of them, each another set), every one wanted or any
/// one, and `deliver` brings what each found to `"start"`, `"room:<RoomType>"` (the centre of
/// the house's first room of that type, e.g. `"room:Kitchen"`) or `"container:<ObjectType>"`
/// (e.g. `"container:Sofa"`), its way there part of the cost. `tasks` lists the trials
/// instead: the path of a tasks file (CSV `house,targets,goal,destination`, as `--tasks` reads
/// it) or a list of dicts such as `{"house": 0, "targets": ["Mug", "Apple"], "goal": "all",
/// "destination": "start"}` (`goal` defaults to `"all"`; `destination` is `"start"`,
/// `"container:<id>"`, `"room:<id>"`, an `(x, y)` point in metres, or absent); every listed
/// task is checked against its house before anything runs. Rows of tasks have the columns
/// `goal`, `destination`, `found_each` and `delivery_m` too, and `target` is the targets joined
/// by `+` (all) or `|` (any). Bad tasks raise `ConfigError` naming the keyword and the field.
///
/// `robots=N` (1 to 4) runs every trial with a team, as `ferret eval --robots` does:
/// `starts="together"` (every robot at the house's start) or `"spread"` (the others on
/// reachable floor drawn from `seed`); `cost_m` is then the makespan and the rows have
/// `robots`, `total_travel_m` and `searched_by` too. Strategies `independent/<spec>` and
/// `split/<spec>` share the work otherwise than a plain spec, which coordinates its robots.
///
/// `shard=(i, n)` runs only the houses whose file index is i
/// modulo n (as `ferret eval --shard i/n`): exactly the trials one machine runs on them; `save`
/// records the shard, and `ferret.merge` joins the shards' directories into the run of all
/// houses. Raises `FerretError` when no trial finished.
#[pyfunction]
#[pyo3(signature = (
    houses, strategies = None, *, prior = None, seed = 0, trials_per_house = None,
    reveal_fraction = 0.0, task = None, deliver = None, tasks = None, protocol = "ferret",
    cells = false, max_containers = 8, exact_max = 16, search_cost = 0.0, config = None,
    llm_cache = None, offline = false, keep_going = false, fusion = None, resolution = 0.05,
    robot_radius = 0.18, wall_thickness = 0.05, progress = None, shard = None, robots = None,
    starts = "together"
))]
pub fn evaluate(
    py: Python<'_>,
    houses: Vec<Py<House>>,
    strategies: Option<&Bound<'_, PyAny>>,
    prior: Option<&Bound<'_, PyAny>>,
    seed: u64,
    trials_per_house: Option<&Bound<'_, PyAny>>,
    reveal_fraction: f64,
    task: Option<&str>,
    deliver: Option<&str>,
    tasks: Option<&Bound<'_, PyAny>>,
    protocol: &str,
    cells: bool,
    max_containers: usize,
    exact_max: usize,
    search_cost: f64,
    config: Option<PathBuf>,
    llm_cache: Option<PathBuf>,
    offline: bool,
    keep_going: bool,
    fusion: Option<PathBuf>,
    resolution: f64,
    robot_radius: f64,
    wall_thickness: f64,
    progress: Option<progress::Progress>,
    shard: Option<(usize, usize)>,
    robots: Option<usize>,
    starts: &str,
) -> PyResult<PyEvaluation> {
    // Every argument is checked before any work, as the command line checks its options.
    let grid = Grid::new(resolution, robot_radius, wall_thickness)?;
    let planning = Planning::new(prior, max_containers, exact_max, search_cost)?;
    if !(0.0..=1.0).contains(&reveal_fraction) {
        return Err(errors::config(format!(
            "reveal_fraction={reveal_fraction}: must be a fraction between 0 and 1"
        )));
    }
    let specs = match strategies.filter(|s| !s.is_none()) {
        Some(s) => convert::spec_list(s, "strategies")?,
        None => DEFAULT_STRATEGIES.split(',').map(String::from).collect(),
    };
    settings::check_distinct("strategies", &specs)?;
    let per_house = match trials_per_house.filter(|t| !t.is_none()) {
        Some(t) => convert::count_or_all(t, "trials_per_house")?,
        None => TrialsPerHouse::One,
    };
    let tasks = crate::tasks::eval_tasks(task, deliver, tasks)?;
    if let (Some(Tasks::Drawn { shape, .. }), TrialsPerHouse::All) = (&tasks, per_house) {
        // Every set of targets would be far too many trials; the draw would refuse each house.
        return Err(errors::config(format!(
            "trials_per_house=\"all\": with task={:?}, give a number of tasks per house",
            shape.to_string()
        )));
    }
    let protocol = settings::protocol(protocol)?;
    let starts: ferret_plan::TeamStarts = starts
        .parse()
        .map_err(|e: String| errors::config(format!("starts={starts:?}: {e}")))?;
    let team = match robots {
        Some(n) => Some(
            ferret_plan::TeamSettings::new(n, starts)
                .map_err(|e| errors::config(format!("robots={n}: {e}")))?,
        ),
        None if starts != ferret_plan::TeamStarts::Together => {
            return Err(errors::config(format!(
                "starts={:?}: only with robots=",
                starts.to_string()
            )));
        }
        None => None,
    };
    ferret_lab::check_team(team, &protocol).map_err(errors::lab)?;
    let shard = shard
        .map(|(i, n)| Shard::new(i, n))
        .transpose()
        .map_err(|e| errors::config(format!("shard: {e}")))?;
    if houses.is_empty() {
        return Err(errors::config("houses: no houses to evaluate"));
    }
    let grid_params = grid.params(&protocol);
    let draw = TrialDraw {
        seed,
        reveal_fraction,
        per_house,
        protocol: &protocol,
        holdout: None,
        tasks: tasks.as_ref(),
        team,
    };
    // Listed tasks are checked against every house given (a shard's too: the tasks of the
    // other shards' houses must fit them as well), as `ferret eval --tasks` checks its file
    // before anything runs.
    if let Some(Tasks::Listed { .. }) = &tasks {
        let scenes = scenes_of(&houses);
        let source = houses
            .first()
            .map(|h| h.get().origin.describe())
            .unwrap_or_default();
        py.allow_threads(|| {
            errors::guarded("evaluate", || {
                check_listed_tasks_in(
                    scenes.iter().map(|s| Ok(s.as_ref())),
                    &source,
                    &draw,
                    &grid_params,
                )
                .map_err(|e| errors::config(format!("tasks: {}", ferret_world::error_chain(&e))))
            })
        })?;
    }
    let houses: Vec<Py<House>> = match shard {
        Some(sh) => {
            let kept: Vec<Py<House>> = houses
                .into_iter()
                .filter(|h| sh.contains(h.get().scene.house.index))
                .collect();
            if kept.is_empty() {
                return Err(errors::config(format!(
                    "shard={sh}: no house has a file index that is {} modulo {}; use fewer shards",
                    sh.index, sh.count
                )));
            }
            kept
        }
        None => houses,
    };
    for h in &houses {
        let h = h.get();
        if let Some(read) = h.read_with
            && read != protocol.containers
        {
            return Err(errors::config(format!(
                "{}: read with containers=\"{read}\", but this protocol's container set is \"{}\": load the houses with containers=\"{}\"",
                h.scene.house.name, protocol.containers, protocol.containers
            )));
        }
    }
    let run_info = run_info(&houses, &planning, &grid, &draw, &specs);
    let source = houses
        .first()
        .map(|h| h.get().origin.describe())
        .unwrap_or_default();
    let llm = settings::llm(config, llm_cache, offline, keep_going, fusion);
    let scenes: Vec<Scene> = scenes_of(&houses).iter().map(|s| Scene::clone(s)).collect();
    let house_indices: Vec<usize> = scenes.iter().map(|s| s.house.index).collect();
    let params = grid_params;
    let feedback = progress::Interruptible::new(progress);
    let outcome = py.allow_threads(|| {
        errors::guarded("evaluate", || {
            let setup = planning::registry(&planning, &llm, &specs).map_err(errors::lab)?;
            let run = EvalContext::new(&setup, &specs, &draw, &params, &llm, &feedback)
                .collect(HouseInput::Scenes(&scenes))
                .map_err(errors::lab)?;
            Ok(run.evaluation)
        })
    });
    // Ctrl-C: the interrupt, not the stop it caused.
    if let Some(interrupt) = feedback.take() {
        return Err(interrupt);
    }
    let outcome = outcome?;
    if outcome.rows.is_empty() {
        return Err(errors::FerretError::new_err(format!(
            "no trial finished{}",
            if outcome.errors.is_empty() {
                String::new()
            } else {
                format!(":\n  {}", outcome.errors.join("\n  "))
            }
        )));
    }
    if !outcome.errors.is_empty() {
        let warnings = py.import("warnings")?;
        warnings.call_method1(
            "warn",
            (format!(
                "{} trial(s) failed; every finished trial is in the rows, the failures in .errors: {}",
                outcome.errors.len(),
                outcome.errors.join("; ")
            ),),
        )?;
    }
    let mut rows = outcome.rows;
    if cells {
        for r in &mut rows {
            r.cost_cells = Some(r.cost_m / CELL_M);
        }
    }
    let failures = outcome.errors.len();
    Ok(PyEvaluation {
        rows,
        errors: outcome.errors,
        houses_run: outcome.houses_run,
        trials_run: outcome.trials_run,
        strategies: specs,
        run_info,
        source,
        houses: house_indices,
        cells,
        shard,
        failures,
    })
}

/// What `run.json` says of an evaluation of `houses` under these settings: one house source,
/// and a prior that a file names (paths made absolute, since the run may be replayed from
/// another working directory).
fn run_info(
    houses: &[Py<House>],
    planning: &Planning,
    grid: &Grid,
    draw: &TrialDraw<'_>,
    strategies: &[String],
) -> Result<RunInfo, String> {
    let Some(first) = houses.first().map(|h| h.get().origin.clone()) else {
        return Err("no houses".into());
    };
    if houses.iter().any(|h| !Arc::ptr_eq(&h.get().origin, &first)) {
        return Err(
            "the houses come from several load_houses or generate_houses calls; run.json names one source of houses"
                .into(),
        );
    }
    if let PriorArg::Held(_) = planning.prior {
        return Err(
            "prior is a Prior object, which run.json cannot name: save it (prior.save(path)) and pass prior=path"
                .into(),
        );
    }
    let absolute = |p: &Option<PathBuf>| -> Result<Option<PathBuf>, String> {
        p.as_ref()
            .map(|p| std::path::absolute(p).map_err(|e| format!("{}: {e}", p.display())))
            .transpose()
    };
    let mut planning_settings = planning.settings.clone();
    planning_settings.prior = absolute(&planning_settings.prior)?;
    Ok(RunInfo {
        houses: absolute(&first.houses)?,
        range: first.range.as_ref().map(ToString::to_string),
        asset_db: absolute(&first.asset_db)?,
        generate: first.generate,
        house_seed: first.house_seed,
        grid: [grid.resolution, grid.robot_radius, grid.wall_thickness],
        planning: planning_settings,
        seed: draw.seed,
        reveal_fraction: draw.reveal_fraction,
        trials_per_house: draw.per_house,
        protocol: *draw.protocol,
        tasks: draw.tasks.cloned(),
        team: draw.team,
        strategies: strategies.to_vec(),
        trials_sha256: None,
        shard: None,
        merged_from: Vec::new(),
    })
}

/// Merges the run directories of an evaluation's shards (`Evaluation.save` of
/// `evaluate(..., shard=(i, n))`, or `ferret eval --shard`) into `out`, as `ferret merge`
/// does: trials.csv in the one-machine order (the very file one machine writes), summary,
/// paired comparisons and run.json listing the shards. `caches` (default: each directory's
/// `llm-cache.sqlite` that exists) are merged into `cache_out` (default
/// `out/llm-cache.sqlite`). Returns a dict: `rows`, `houses`, `cache_answers` and `conflicts`
/// (one message per key two caches answer differently; the first answer is kept). Raises
/// `ConfigError` naming the directories for shards of different settings, overlaps and gaps.
#[pyfunction]
#[pyo3(signature = (runs, out, *, caches = None, cache_out = None))]
pub fn merge(
    py: Python<'_>,
    runs: Vec<PathBuf>,
    out: PathBuf,
    caches: Option<Vec<PathBuf>>,
    cache_out: Option<PathBuf>,
) -> PyResult<Py<pyo3::types::PyDict>> {
    const SHARD_CACHE: &str = "llm-cache.sqlite";
    let caches: Vec<PathBuf> = caches.unwrap_or_else(|| {
        runs.iter()
            .map(|d| d.join(SHARD_CACHE))
            .filter(|p| p.is_file())
            .collect()
    });
    let cache_out = cache_out.unwrap_or_else(|| out.join(SHARD_CACHE));
    let (rows, houses, answers, conflicts) = py.allow_threads(|| -> PyResult<_> {
        let shards = runs
            .iter()
            .map(|d| Ok((d.clone(), EvalRun::read(d)?)))
            .collect::<ferret_lab::Result<Vec<_>>>()
            .map_err(errors::lab)?;
        let merged = ferret_lab::merge_runs(&shards).map_err(|e| errors::config(e.to_string()))?;
        std::fs::create_dir_all(&out).map_err(|e| {
            errors::FerretError::new_err(format!("creating {}: {e}", out.display()))
        })?;
        merged.write_all(&out).map_err(errors::lab)?;
        let mut conflicts = Vec::new();
        let mut answers = 0;
        if !caches.is_empty() {
            let cache_err = |e: ferret_llm::CacheError| errors::FerretError::new_err(e.to_string());
            let target = ferret_llm::ResponseCache::open(&cache_out).map_err(cache_err)?;
            for c in &caches {
                let other = ferret_llm::ResponseCache::open(c).map_err(cache_err)?;
                let m = target.merge_from(&other).map_err(cache_err)?;
                conflicts.extend(m.conflicts.iter().map(ToString::to_string));
            }
            answers = target.len().map_err(cache_err)?;
        }
        Ok((
            merged.run.rows.len(),
            merged.houses.len(),
            answers,
            conflicts,
        ))
    })?;
    let d = pyo3::types::PyDict::new(py);
    d.set_item("rows", rows)?;
    d.set_item("houses", houses)?;
    d.set_item("cache_answers", answers)?;
    d.set_item("conflicts", conflicts)?;
    Ok(d.unbind())
}
