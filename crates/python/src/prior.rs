//! `ferret.Prior`: the learned P(target | container type, room type) that `model/prior`
//! strategies plan over.

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ferret_plan::Prior;
use ferret_world::ObjectType;
use pyo3::prelude::*;

use crate::errors;
use crate::houses::{House, scenes_of};

/// A likelihood prior: the chance that a container of some type, in a room of some type, holds
/// an object type, learned from training houses. Immutable; shared without copying.
#[pyclass(name = "Prior", module = "ferret", frozen)]
pub struct PyPrior {
    /// The prior, shared with every strategy built from it.
    pub inner: Arc<Prior>,
}

#[pymethods]
impl PyPrior {
    /// Learns a prior from training houses (their contents are what training reads), as
    /// `ferret prior train`. `smoothing` is the weight (pseudo-containers) toward the back-off
    /// estimate. With `embeddings` (a folder, as `--embeddings`: `scripts/embeddings.sh install`
    /// prints one), also the learned likelihood that `model/learned` plans over, with
    /// `learned_folds` folds of held-out types and `learned_seed` its heads' seed. Releases the
    /// GIL while it trains.
    #[staticmethod]
    #[pyo3(signature = (houses, smoothing = 2.0, embeddings = None, learned_folds = 5, learned_seed = 0))]
    fn train(
        py: Python<'_>,
        houses: Vec<Py<House>>,
        smoothing: f64,
        embeddings: Option<PathBuf>,
        learned_folds: usize,
        learned_seed: u64,
    ) -> PyResult<Self> {
        if !(smoothing.is_finite() && smoothing >= 0.0) {
            return Err(errors::config(format!(
                "smoothing={smoothing}: must be a finite number ≥ 0"
            )));
        }
        let scenes = scenes_of(&houses);
        let mut notes = Vec::new();
        let prior = py.allow_threads(|| {
            errors::guarded("Prior.train", || {
                let prior = Prior::train(scenes.iter().map(|s| s.as_ref()), smoothing);
                let Some(dir) = &embeddings else {
                    return Ok(prior);
                };
                let table = ferret_lab::language::open_embeddings(dir).map_err(errors::lab)?;
                let wordnet = ferret_lab::language::LazyWordNet::new(None);
                let owned: Vec<ferret_world::Scene> =
                    scenes.iter().map(|s| s.as_ref().clone()).collect();
                let settings = ferret_plan::LearnedSettings {
                    folds: learned_folds,
                    seed: learned_seed,
                    ..Default::default()
                };
                let source = ferret_lab::language::NameSource {
                    embeddings: &table,
                    wordnet: &wordnet,
                    knowledge: None,
                };
                ferret_lab::language::train_learned(&owned, &prior, &source, &settings)
                    .map(|(p, report)| {
                        notes = report.notes;
                        p
                    })
                    .map_err(errors::lab)
            })
        })?;
        // A word read otherwise than spelt (a base form, a WordNet hypernym, left out) is said
        // as a Python warning, once per name, so that a typo never trains in silence.
        for note in notes {
            PyErr::warn(
                py,
                &py.get_type::<pyo3::exceptions::PyUserWarning>(),
                &std::ffi::CString::new(note).unwrap_or_default(),
                1,
            )?;
        }
        Ok(Self {
            inner: Arc::new(prior),
        })
    }

    /// Reads a prior written by `Prior.save` or `ferret prior train --out`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let prior = py
            .allow_threads(|| Prior::load(&path))
            .map_err(errors::plan)?;
        Ok(Self {
            inner: Arc::new(prior),
        })
    }

    /// The prior `ferret eval` uses when given none: trained on 500 generated houses of seed
    /// 1000003 (never the evaluation houses) with smoothing 2. Trained once per process.
    #[staticmethod]
    fn default(py: Python<'_>) -> PyResult<Self> {
        let inner = py.allow_threads(|| {
            errors::guarded("Prior.default", || default_prior().map_err(errors::lab))
        })?;
        Ok(Self { inner })
    }

    /// The embeddings the learned likelihood was trained with (e.g. `glove-6b-50d`), or None
    /// for a prior of counts only.
    #[getter]
    fn learned(&self) -> Option<String> {
        self.inner.learned().map(|l| l.embedding.clone())
    }

    /// Writes the prior as JSON (the file `ferret eval --prior` reads).
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        let inner = self.inner.clone();
        py.allow_threads(|| inner.save(&path)).map_err(errors::plan)
    }

    /// The probability that a container of type `container` (in a room of type `room`, when
    /// known) holds an object of type `target`, given that the house holds one, calibrated: what
    /// `model/prior` plans with.
    #[pyo3(signature = (target, container, room = None))]
    fn probability(&self, target: &str, container: &str, room: Option<&str>) -> f64 {
        self.inner
            .probability(&ObjectType::new(target), &ObjectType::new(container), room)
            .get()
    }

    /// Number of training houses.
    #[getter]
    fn houses(&self) -> usize {
        self.inner.houses
    }

    /// Number of training containers.
    #[getter]
    fn containers(&self) -> u32 {
        self.inner.container_count()
    }

    /// The smoothing weight it was trained with.
    #[getter]
    fn smoothing(&self) -> f64 {
        self.inner.smoothing
    }

    fn __eq__(&self, other: &Bound<'_, PyAny>) -> bool {
        other
            .downcast::<PyPrior>()
            .is_ok_and(|o| *o.get().inner == *self.inner)
    }

    fn __repr__(&self) -> String {
        format!(
            "Prior(houses={}, containers={}, smoothing={:?})",
            self.inner.houses,
            self.inner.container_count(),
            self.inner.smoothing
        )
    }
}

/// The prior `ferret eval` uses when given none, trained on first use and kept: it depends on
/// nothing but constants.
pub fn default_prior() -> Result<Arc<Prior>, ferret_lab::LabError> {
    static DEFAULT: Mutex<Option<Arc<Prior>>> = Mutex::new(None);
    let mut held = DEFAULT.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(p) = held.as_ref() {
        return Ok(p.clone());
    }
    let (houses, seed) = ferret_lab::strategies::DEFAULT_PRIOR_HOUSES;
    let p = Arc::new(ferret_lab::strategies::default_prior(houses, seed)?);
    *held = Some(p.clone());
    Ok(p)
}
