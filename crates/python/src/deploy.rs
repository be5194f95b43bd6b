//! `ferret.Deployment`: the deployment loop `ferret deploy` and `ferret serve` run
//! (`ferret_select::DeploymentLoop`: the selector with its seeded tie-breaks, every candidate
//! replayed after a trial), fed by the `ferret.Search`es the robot drove.

use std::path::PathBuf;
use std::sync::{Mutex, MutexGuard};

use ferret_plan::{SearchProblem, hindsight_truth};
use ferret_select::{DeploymentLoop, Method};
use pyo3::prelude::*;
use pyo3::types::PyDict;

use crate::errors;
use crate::planning;
use crate::search::PySearch;
use crate::settings;

/// A deployment: `choose()` names the strategy of the next trial, the robot runs a
/// `ferret.Search` with it (one target or a household task), and `finish(search)` replays every
/// candidate on that trial (each target only where it was found) and lets the selector learn;
/// `abandon()` ends a trial that found nothing, which teaches nothing. The same strategies, method, `c` and `seed` on the same
/// trials make `ferret deploy`'s choices and costs.
#[pyclass(name = "Deployment", module = "ferret")]
pub struct PyDeployment {
    /// Behind a mutex because the selector is not `Sync`; held while a trial is replayed.
    deployment: Mutex<DeploymentLoop>,
    names: Vec<String>,
    trials: usize,
}

impl PyDeployment {
    fn deployment(&self) -> MutexGuard<'_, DeploymentLoop> {
        self.deployment.lock().unwrap_or_else(|p| p.into_inner())
    }
}

fn select_error(e: impl std::fmt::Display) -> PyErr {
    errors::config(e.to_string())
}

#[pymethods]
impl PyDeployment {
    /// A deployment over `strategies` (at least two specs, as `ferret deploy --strategies`),
    /// choosing by `method` (`"replay"` or `"ucb"`) with exploration constant `c` (metres) and
    /// tie-break `seed` (`c`'s default is `ferret deploy`'s, 5 m). Planner, prior and LLM
    /// keywords are those of `ferret.Search`, and searches given to `finish` must have been made
    /// with the same ones.
    #[new]
    #[pyo3(signature = (
        strategies, *, method = "replay", c = 5.0, seed = 0, prior = None,
        config = None, llm_cache = None, offline = false, fusion = None, max_containers = 8,
        exact_max = 16, search_cost = 0.0, protocol = "ferret"
    ))]
    fn new(
        py: Python<'_>,
        strategies: Vec<String>,
        method: &str,
        c: f64,
        seed: u64,
        prior: Option<&Bound<'_, PyAny>>,
        config: Option<PathBuf>,
        llm_cache: Option<PathBuf>,
        offline: bool,
        fusion: Option<PathBuf>,
        max_containers: usize,
        exact_max: usize,
        search_cost: f64,
        protocol: &str,
    ) -> PyResult<Self> {
        let names: Vec<String> = strategies.iter().map(|s| s.trim().to_string()).collect();
        settings::check_distinct("strategies", &names)?;
        if names.iter().any(|s| s == ferret_select::ORACLE) {
            return Err(errors::StrategyError::new_err(
                "oracle: needs the ground truth and is never a candidate of a deployment",
            ));
        }
        if names.len() < 2 {
            return Err(errors::config(format!(
                "strategies: a deployment needs at least two candidate strategies, got {}",
                names.len()
            )));
        }
        if !(c.is_finite() && c >= 0.0) {
            return Err(errors::config(format!(
                "c={c}: must be a finite number ≥ 0 m"
            )));
        }
        let method: Method = method
            .parse()
            .map_err(|e| errors::config(format!("method: {e}")))?;
        let protocol = settings::protocol(protocol)?;
        let planning = planning::Planning::new(prior, max_containers, exact_max, search_cost)?;
        let llm = settings::llm(config, llm_cache, offline, false, fusion);
        let candidates = py.allow_threads(|| {
            errors::guarded("Deployment", || {
                let setup = planning::registry(&planning, &llm, &names).map_err(errors::lab)?;
                names
                    .iter()
                    .map(|s| setup.registry.build(s).map_err(errors::plan))
                    .collect::<PyResult<Vec<_>>>()
            })
        })?;
        let deployment = DeploymentLoop::new(
            method,
            candidates,
            c,
            seed,
            (protocol.replay, protocol.travel_cost),
        )
        .map_err(select_error)?;
        Ok(Self {
            deployment: Mutex::new(deployment),
            names,
            trials: 0,
        })
    }

    /// The strategy spec of the trial in progress (chosen now if none is): the same until that
    /// trial is finished or abandoned.
    fn choose(&mut self) -> String {
        let i = self.deployment().choose();
        self.names[i].clone()
    }

    /// Ends the trial in progress with the robot's `search` (a `ferret.Search` of the chosen
    /// strategy that found its target, or whose task's goal holds): replays every candidate on
    /// it — the same task, each target only where it was found, to the same destination — and
    /// learns. A search with a destination that was not finished is finished here (its
    /// `finish()`: the way there is part of every cost). Returns each candidate's cost on this
    /// trial, metres (the chosen one's is the search's own cost).
    fn finish<'py>(
        &mut self,
        py: Python<'py>,
        search: &Bound<'py, PySearch>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let chosen = self
            .deployment()
            .live()
            .pending()
            .ok_or_else(|| errors::search("no trial in progress: call choose() first"))?;
        let mut s = search.borrow_mut();
        if s.strategy_spec() != self.names[chosen] {
            return Err(errors::search(format!(
                "the search ran {:?} but this trial's strategy is {:?}",
                s.strategy_spec(),
                self.names[chosen]
            )));
        }
        let done = s.conclude()?;
        drop(s);
        let deployment = &self.deployment;
        let replays = py.allow_threads(|| {
            errors::guarded("Deployment.finish", || {
                let mut problem = SearchProblem::new(&done.scene.house, &done.map.1, &done.trial);
                if let Some(l) = &done.legs {
                    problem = problem.with_destination(l);
                }
                let truth = hindsight_truth(&done.scene.house, &done.trial.task, &done.found_each)
                    .map_err(errors::plan)?;
                let mut deployment = deployment.lock().unwrap_or_else(|p| p.into_inner());
                let replays = deployment
                    .replays(&problem, &truth, &done.found_each, (chosen, done.cost))
                    .map_err(errors::plan)?;
                deployment
                    .learn(done.cost, &replays)
                    .map_err(select_error)?;
                Ok(replays)
            })
        })?;
        self.trials += 1;
        let out = PyDict::new(py);
        for (name, r) in self.names.iter().zip(&replays) {
            out.set_item(name, *r)?;
        }
        Ok(out)
    }

    /// Ends the trial in progress without a cost (the target was nowhere): selection learns
    /// nothing from it.
    fn abandon(&mut self) -> PyResult<()> {
        let mut deployment = self.deployment();
        if deployment.live().pending().is_none() {
            return Err(errors::search("no trial in progress: call choose() first"));
        }
        deployment.abandon().map_err(select_error)?;
        drop(deployment);
        self.trials += 1;
        Ok(())
    }

    /// The candidate strategies, in order.
    #[getter]
    fn strategies(&self) -> Vec<String> {
        self.names.clone()
    }

    /// Trials ended so far (finished or abandoned).
    #[getter]
    fn trials(&self) -> usize {
        self.trials
    }

    /// Per candidate: `strategy`, `deployed` (trials it ran), `mean_cost_m` (over them, or
    /// None), `replay_mean_m` (its real or replayed cost over all finished trials, or None) and
    /// `score` (the selection score of the next trial; lower is chosen, -inf: must be tried).
    fn stats<'py>(&self, py: Python<'py>) -> PyResult<Vec<Bound<'py, PyDict>>> {
        self.deployment()
            .live()
            .stats()
            .into_iter()
            .zip(&self.names)
            .map(|(s, name)| {
                let d = PyDict::new(py);
                d.set_item("strategy", name)?;
                d.set_item("deployed", s.deployed)?;
                d.set_item("mean_cost_m", s.mean_cost)?;
                d.set_item("replay_mean_m", s.replay_mean)?;
                d.set_item("score", s.score)?;
                Ok(d)
            })
            .collect()
    }

    fn __repr__(&self) -> String {
        format!(
            "Deployment(strategies={:?}, method={:?}, trials={})",
            self.names,
            self.deployment().live().method().name(),
            self.trials
        )
    }
}
