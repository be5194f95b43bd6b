//! `ferret.select`: UCB and replay selection over an evaluation run — `ferret select`'s
//! deployment experiment through the same call, with the same replay cache beside the run.

use std::path::PathBuf;

use ferret_lab::EvalRun;
use ferret_lab::selection::validate;
use ferret_plan::{DrawMode, ReplayMode};
use ferret_select::{ExperimentOptions, ExperimentResult, choice_rows, selection_rows};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert;
use crate::errors;
use crate::progress;
use crate::settings;

/// The result of `ferret.select`: per method and trial count k, the average cost and the
/// cumulative regret against the best single strategy (the rows of `selection.csv`), how often
/// each strategy was chosen (`choices.csv`), and the tables of `selection.md`.
#[pyclass(name = "SelectionResult", module = "ferret", frozen)]
pub struct PySelection {
    result: ExperimentResult,
    markdown: String,
}

#[pymethods]
impl PySelection {
    /// The candidate strategies, in the run's order (the oracle is never one).
    #[getter]
    fn strategies(&self) -> Vec<String> {
        self.result.strategies.clone()
    }

    /// The best single strategy: the lowest mean cost over the run's houses.
    #[getter]
    fn best_strategy(&self) -> String {
        self.result.strategies[self.result.best_strategy].clone()
    }

    /// Each candidate's mean cost over the run's houses, metres.
    #[getter]
    fn mean_costs(&self, py: Python<'_>) -> PyResult<Py<PyDict>> {
        let out = PyDict::new(py);
        for (s, m) in self.result.strategies.iter().zip(&self.result.mean_costs) {
            out.set_item(s, m)?;
        }
        Ok(out.unbind())
    }

    /// The selection methods that ran, by name (`ucb`, `replay`).
    #[getter]
    fn methods(&self) -> Vec<String> {
        self.result
            .summaries
            .iter()
            .map(|s| s.method.name().to_string())
            .collect()
    }

    /// Per method name, its curves against k (index k − 1): `avg_cost`, `cum_regret`,
    /// `paper_regret` (the paper's figure 4), metres; and `best_avg_cost`, the best single
    /// strategy's average cost, under the key `"best"`.
    #[getter]
    fn curves(&self, py: Python<'_>) -> PyResult<Py<PyDict>> {
        let out = PyDict::new(py);
        for s in &self.result.summaries {
            let d = PyDict::new(py);
            d.set_item("avg_cost", s.avg_cost.clone())?;
            d.set_item("cum_regret", s.cum_regret.clone())?;
            d.set_item("paper_regret", s.paper_regret.clone())?;
            out.set_item(s.method.name(), d)?;
        }
        let best = PyDict::new(py);
        best.set_item("avg_cost", self.result.best_avg_cost.clone())?;
        out.set_item("best", best)?;
        Ok(out.unbind())
    }

    /// The rows of `selection.csv`: dicts with `method`, `k`, `avg_cost`, `cum_regret`,
    /// `paper_regret` (metres), `best_avg_cost` and `best_fraction` (the share of deployments
    /// that chose the best single strategy at k). Each access builds a new list.
    #[getter]
    fn rows(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        convert::rows_to_py(py, &selection_rows(&self.result))
    }

    /// The rows of `choices.csv`: per method, trial k and strategy, the share of deployments
    /// that chose it.
    #[getter]
    fn choices(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        convert::rows_to_py(py, &choice_rows(&self.result))
    }

    /// `selection.md`: the paper's table II at its k and the strategies' mean costs.
    #[getter]
    fn markdown(&self) -> String {
        self.markdown.clone()
    }

    /// Deployments run.
    #[getter]
    fn deployments(&self) -> usize {
        self.result.deployments.len()
    }

    /// Trials per deployment.
    #[getter]
    fn trials_per_deployment(&self) -> usize {
        self.result.trials()
    }

    /// The rows of `selection.csv` as a `pandas.DataFrame`. Needs pandas.
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        convert::data_frame(py, "SelectionResult", self.rows(py)?, None)
    }

    fn __repr__(&self) -> String {
        format!(
            "SelectionResult(methods=[{}], deployments={}, trials_per_deployment={}, best_strategy={})",
            self.methods()
                .iter()
                .map(|m| convert::quote(m))
                .collect::<Vec<_>>()
                .join(", "),
            self.deployments(),
            self.trials_per_deployment(),
            convert::quote(&self.best_strategy())
        )
    }
}

/// The command line's options in selection errors, as this function's keywords.
const KEYWORDS: &[(&str, &str)] = &[
    ("--deployments ", "deployments="),
    ("--trials-per-deployment ", "trials_per_deployment="),
    ("--c ", "c="),
];

/// Runs the deployment experiment over the evaluation run in `trials` (a directory written by
/// `ferret eval` or `Evaluation.save`), as `ferret select --trials` does: every strategy is
/// replayed on every trial of the run (cached in `trials/replay.csv`, so a second call replays
/// nothing), then `deployments` deployments of `trials_per_deployment` distinct houses each run
/// with every selection method, exploration constant `c` metres, tie breaks and house orders
/// from `seed`.
///
/// `replay` (`"pessimistic"` or `"counterfactual"`) and `draw` (`"distinct"` or
/// `"replacement"`) override the run's protocol; every other protocol setting is the run's.
/// Replays of LLM strategies ask through `config` and `llm_cache` as `evaluate` does. Releases
/// the GIL; `progress` shows progress as in `evaluate`: `True` on stderr, or a callable
/// `progress(what, done, total)`.
#[pyfunction]
#[pyo3(signature = (
    trials, *, deployments = 500, trials_per_deployment = 100, c = 5.0, seed = 0,
    replay_untried_first = false, replay = None, draw = None, config = None, llm_cache = None,
    offline = false, keep_going = false, fusion = None, progress = None
))]
pub fn select(
    py: Python<'_>,
    trials: PathBuf,
    deployments: usize,
    trials_per_deployment: usize,
    c: f64,
    seed: u64,
    replay_untried_first: bool,
    replay: Option<&str>,
    draw: Option<&str>,
    config: Option<PathBuf>,
    llm_cache: Option<PathBuf>,
    offline: bool,
    keep_going: bool,
    fusion: Option<PathBuf>,
    progress: Option<progress::Progress>,
) -> PyResult<PySelection> {
    let options = ExperimentOptions {
        deployments,
        trials_per_deployment,
        c,
        seed,
        replay_untried_first,
        ..ExperimentOptions::default()
    };
    validate(&options).map_err(|e| errors::lab_as_keywords(e, KEYWORDS))?;
    let replay = replay
        .map(|r| {
            r.parse::<ReplayMode>()
                .map_err(|e| errors::config(format!("replay={r:?}: {e}")))
        })
        .transpose()?;
    let draw = draw
        .map(|d| {
            d.parse::<DrawMode>()
                .map_err(|e| errors::config(format!("draw={d:?}: {e}")))
        })
        .transpose()?;
    let llm = settings::llm(config, llm_cache, offline, keep_going, fusion);
    let feedback = progress::Interruptible::new(progress);
    let done = py.allow_threads(|| {
        errors::guarded("select", || {
            let run = EvalRun::read(&trials).map_err(errors::lab)?;
            let mut protocol = run.info.protocol;
            if let Some(r) = replay {
                protocol.replay = r;
            }
            if let Some(d) = draw {
                protocol.draw = d;
            }
            ferret_lab::selection::select(&run, &trials, &protocol, &llm, &options, &feedback)
                .map_err(|e| errors::lab_as_keywords(e, KEYWORDS))
        })
    });
    // The progress callable's exception (or Ctrl-C), not the stop it caused.
    if let Some(raised) = feedback.take() {
        return Err(raised);
    }
    let done = done?;
    Ok(PySelection {
        result: done.result,
        markdown: done.markdown,
    })
}
