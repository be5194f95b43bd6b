//! The planner and prior keywords (`prior`, `max_containers`, `exact_max`, `search_cost`) as
//! the command line checks them, and the strategy registry built from them with the LLM
//! keywords. A new function over strategies (a calibration, a selection) takes these and calls
//! [`registry`].

use std::path::PathBuf;
use std::sync::Arc;

use ferret_lab::strategies::{Strategies, needs_prior};
use ferret_lab::{LlmSettings, PlanningSettings};
use ferret_plan::Prior;
use pyo3::prelude::*;

use crate::errors;
use crate::prior::PyPrior;

/// Where the prior of `model/prior...` strategies comes from.
#[derive(Clone)]
pub enum PriorArg {
    /// A `Prior` object.
    Held(Arc<Prior>),
    /// A prior file.
    File(PathBuf),
    /// The default prior (see `Prior.default`).
    Default,
}

impl PriorArg {
    /// `None`, a `Prior` or a path.
    pub fn from_py(arg: Option<&Bound<'_, PyAny>>) -> PyResult<Self> {
        let Some(arg) = arg.filter(|a| !a.is_none()) else {
            return Ok(Self::Default);
        };
        if let Ok(p) = arg.downcast::<PyPrior>() {
            return Ok(Self::Held(p.get().inner.clone()));
        }
        if let Ok(path) = arg.extract::<PathBuf>() {
            return Ok(Self::File(path));
        }
        Err(errors::config(
            "prior: expected a ferret.Prior, a path to a prior file, or None",
        ))
    }

    /// The prior itself: the object, the file read, or the default prior trained once per
    /// process.
    pub fn resolve(&self) -> Result<Arc<Prior>, ferret_lab::LabError> {
        match self {
            Self::Held(p) => Ok(p.clone()),
            Self::File(path) => Ok(Arc::new(Prior::load(path)?)),
            Self::Default => crate::prior::default_prior(),
        }
    }
}

/// Planner and prior keywords (`prior`, `max_containers`, `exact_max`, `search_cost`), as
/// `--prior`, `--max-containers`, `--exact-max` and `--search-cost`.
#[derive(Clone)]
pub struct Planning {
    /// The planner settings, with the prior's file when one is named.
    pub settings: PlanningSettings,
    /// The prior as given: the default, a file, or a `Prior` object.
    pub prior: PriorArg,
}

impl Planning {
    /// The keywords, refused as the command line refuses them.
    pub fn new(
        prior: Option<&Bound<'_, PyAny>>,
        max_containers: usize,
        exact_max: usize,
        search_cost: f64,
    ) -> PyResult<Self> {
        let prior = PriorArg::from_py(prior)?;
        let settings = PlanningSettings {
            prior: match &prior {
                PriorArg::File(p) => Some(p.clone()),
                _ => None,
            },
            max_containers,
            exact_max,
            search_cost,
            holdout: None,
            // A learned prior finds vectors of names its file lacks through FERRET_EMBEDDINGS.
            embeddings: None,
        };
        // The command line names its options; here they are keywords.
        settings.validate().map_err(|e| {
            errors::lab_as_keywords(
                e,
                &[
                    ("--search-cost ", "search_cost="),
                    ("--max-containers ", "max_containers="),
                    ("--exact-max ", "exact_max="),
                ],
            )
        })?;
        Ok(Self { settings, prior })
    }
}

/// The full registry (built-in and LLM kinds) for `specs`, over the prior only when one of them
/// plans over it — the registry `ferret eval` builds.
pub fn registry(
    planning: &Planning,
    llm: &LlmSettings,
    specs: &[String],
) -> Result<Strategies, ferret_lab::LabError> {
    let prior = if needs_prior(specs) {
        Some(planning.prior.resolve()?)
    } else {
        None
    };
    Strategies::builder(&planning.settings, llm)
        .prior(prior)
        .build()
}
