//! `ferret.calibrate`: how good a likelihood source's probabilities are, scored against the
//! ground truth of the houses — `ferret calibrate`'s experiment through the same call.

use std::path::PathBuf;

use ferret_lab::LoadedHouses;
use ferret_lab::calibrate::{CalibrationSettings, DEFAULT_SOURCES, TargetCount};
use ferret_lab::report::fusion_markdown;
use ferret_plan::{Calibration, FusionFile};
use ferret_world::Scene;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert;
use crate::errors;
use crate::houses::{House, scenes_of};
use crate::planning::{self, Planning};
use crate::progress;
use crate::settings;

/// The result of `ferret.calibrate`: one row per scored source (the columns of
/// `calibration.csv`), each source's reliability bins, and the fitted fusions when asked for.
#[pyclass(name = "CalibrationResult", module = "ferret", frozen)]
pub struct PyCalibration {
    scored: Vec<(String, Calibration)>,
    fusion: Option<FusionFile>,
    trials: usize,
    markdown: String,
    errors: Vec<String>,
}

#[pymethods]
impl PyCalibration {
    /// The rows: dicts with `calibration.csv`'s columns (`source`, `pairs`, `positives`,
    /// `brier`, `log_loss`, `auroc`, `mean_p_pos`, `mean_p_neg`). Each access builds a new list.
    #[getter]
    fn rows(&self, py: Python<'_>) -> PyResult<Py<PyList>> {
        convert::rows_to_py(py, &ferret_lab::calibrate::calibration_rows(&self.scored))
    }

    /// Per source, its reliability bins: dicts with `lo`, `hi`, `count`, `mean_p` and
    /// `observed` (the share of the bin's containers that hold the target).
    #[getter]
    fn reliability(&self, py: Python<'_>) -> PyResult<Py<PyDict>> {
        let out = PyDict::new(py);
        for (source, c) in &self.scored {
            out.set_item(source, convert::rows_to_py(py, &c.bins)?)?;
        }
        Ok(out.unbind())
    }

    /// (house, target) pairs scored.
    #[getter]
    fn trials(&self) -> usize {
        self.trials
    }

    /// `calibration.md`: the table of scores as Markdown, as `ferret calibrate` prints it.
    #[getter]
    fn markdown(&self) -> String {
        self.markdown.clone()
    }

    /// The fitted fusion weights as the JSON of `ferret calibrate --fit-fusion FILE` (for
    /// `fusion=` of `evaluate` and `Search`), or `None` when no fusion was fitted.
    #[getter]
    fn fusion(&self) -> Option<String> {
        self.fusion.as_ref().map(FusionFile::to_json)
    }

    /// The fitted fusions as Markdown, or `None`.
    #[getter]
    fn fusion_markdown(&self) -> Option<String> {
        self.fusion.as_ref().map(fusion_markdown)
    }

    /// One message per source or trial that failed; every other source was scored.
    #[getter]
    fn errors(&self) -> Vec<String> {
        self.errors.clone()
    }

    /// The rows as a `pandas.DataFrame` with `calibration.csv`'s columns. Needs pandas.
    fn to_pandas<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        convert::data_frame(py, "CalibrationResult", self.rows(py)?, None)
    }

    fn __len__(&self) -> usize {
        self.scored.len()
    }

    fn __repr__(&self) -> String {
        format!(
            "CalibrationResult(sources=[{}], trials={}, errors={}, fusion={})",
            self.scored
                .iter()
                .map(|(source, _)| convert::quote(source))
                .collect::<Vec<_>>()
                .join(", "),
            self.trials,
            self.errors.len(),
            if self.fusion.is_some() {
                "True"
            } else {
                "False"
            }
        )
    }
}

/// Scores likelihood sources as `ferret calibrate` does: for every house, every target type
/// present (or `targets_per_house` of them, the first the one `evaluate` draws with the same
/// `seed`) and every container, P_S(target, container) against whether the container holds the
/// target: Brier score, log loss, AUROC and `bins` reliability bins per source.
///
/// `sources` are strategy specs (a list or a comma-separated string; default
/// `"model/uniform,model/prior"`): `model/...`, `llm+model/<prompt>/<llm>` and, with `fusion`,
/// `fused/<prompt>/<llm>`; only their probabilities count. `fit_fusion=True` also fits the
/// fusion of the prior with each `llm+model` source (its JSON in `.fusion`). LLM questions go
/// through the same configuration and response cache as `evaluate`, each asked once. Releases
/// the GIL; `progress` shows progress as in `evaluate`: `True` on stderr, or a callable
/// `progress(what, done, total)`.
#[pyfunction]
#[pyo3(signature = (
    houses, sources = None, *, targets_per_house = None, seed = 0, bins = 10, fit_fusion = false,
    prior = None, max_containers = 8, exact_max = 16, search_cost = 0.0, config = None,
    llm_cache = None, offline = false, keep_going = false, fusion = None, progress = None
))]
pub fn calibrate(
    py: Python<'_>,
    houses: Vec<Py<House>>,
    sources: Option<&Bound<'_, PyAny>>,
    targets_per_house: Option<&Bound<'_, PyAny>>,
    seed: u64,
    bins: usize,
    fit_fusion: bool,
    prior: Option<&Bound<'_, PyAny>>,
    max_containers: usize,
    exact_max: usize,
    search_cost: f64,
    config: Option<PathBuf>,
    llm_cache: Option<PathBuf>,
    offline: bool,
    keep_going: bool,
    fusion: Option<PathBuf>,
    progress: Option<progress::Progress>,
) -> PyResult<PyCalibration> {
    let planning = Planning::new(prior, max_containers, exact_max, search_cost)?;
    let specs = match sources.filter(|s| !s.is_none()) {
        Some(s) => convert::spec_list(s, "sources")?,
        None => DEFAULT_SOURCES.split(',').map(String::from).collect(),
    };
    settings::check_distinct("sources", &specs)?;
    let per_house = match targets_per_house.filter(|t| !t.is_none()) {
        Some(t) => convert::count_or_all(t, "targets_per_house")?,
        None => TargetCount::All,
    };
    let settings = CalibrationSettings {
        sources: specs,
        targets_per_house: per_house,
        seed,
        bins,
        fit_fusion,
        ..CalibrationSettings::default()
    };
    let needed = settings.specs_to_build().map_err(|e| {
        errors::lab_as_keywords(
            e,
            &[
                ("--sources ", "sources "),
                ("--bins ", "bins="),
                ("--fit-fusion", "fit_fusion=True"),
            ],
        )
    })?;
    if houses.is_empty() {
        return Err(errors::config("houses: no houses to score"));
    }
    let llm = settings::llm(config, llm_cache, offline, keep_going, fusion);
    let scenes: Vec<Scene> = scenes_of(&houses).iter().map(|s| Scene::clone(s)).collect();
    let loaded = LoadedHouses {
        scenes,
        skipped: Vec::new(),
        source: "a Python list".into(),
    };
    let feedback = progress::Interruptible::new(progress);
    let done = py.allow_threads(|| {
        errors::guarded("calibrate", || {
            let setup = planning::registry(&planning, &llm, &needed).map_err(errors::lab)?;
            ferret_lab::calibrate::calibrate(&loaded, &setup, &llm, &settings, &feedback)
                .map_err(errors::lab)
        })
    });
    // The progress callable's exception (or Ctrl-C), not the stop it caused.
    if let Some(raised) = feedback.take() {
        return Err(raised);
    }
    let done = done?;
    if !done.errors.is_empty() {
        let warnings = py.import("warnings")?;
        warnings.call_method1(
            "warn",
            (format!(
                "{} failure(s); every other source was scored, the failures are in .errors: {}",
                done.errors.len(),
                done.errors.join("; ")
            ),),
        )?;
    }
    Ok(PyCalibration {
        scored: done.scored,
        fusion: done.fusion,
        trials: done.trials,
        markdown: done.markdown,
        errors: done.errors,
    })
}
