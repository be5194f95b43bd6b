//! Keyword arguments several functions share — grid, planner and prior, LLM — turned into the
//! experiment layer's settings and checked with the command line's rules, and the strategy
//! registry built from them. A new function over strategies (a calibration, a selection) takes
//! these and calls [`registry`].

use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use ferret_lab::strategies::{Strategies, default_prior, needs_prior};
use ferret_lab::{LlmSettings, PlanningSettings};
use ferret_plan::{Prior, Protocol, ProtocolName};
use ferret_world::GridParams;
use pyo3::prelude::*;

use crate::errors;
use crate::prior::PyPrior;

/// Occupancy-grid options (`resolution`, `robot_radius`, `wall_thickness`), as `--resolution`,
/// `--robot-radius` and `--wall-thickness`.
#[derive(Clone, Copy, Debug)]
pub struct Grid {
    /// Cell size, metres.
    pub resolution: f64,
    /// Robot radius by which obstacles are inflated, metres.
    pub robot_radius: f64,
    /// Thickness given to walls, metres.
    pub wall_thickness: f64,
}

impl Grid {
    /// The options, refused as the command line refuses them, named as keywords.
    pub fn new(resolution: f64, robot_radius: f64, wall_thickness: f64) -> PyResult<Self> {
        let min = GridParams::MIN_RESOLUTION;
        if !(resolution.is_finite() && resolution >= min) {
            return Err(errors::config(format!(
                "resolution={resolution}: the cell size must be a finite number ≥ {min} m"
            )));
        }
        for (name, value) in [
            ("robot_radius", robot_radius),
            ("wall_thickness", wall_thickness),
        ] {
            if !(value.is_finite() && value >= 0.0) {
                return Err(errors::config(format!(
                    "{name}={value}: must be a finite number ≥ 0 m"
                )));
            }
        }
        Ok(Self {
            resolution,
            robot_radius,
            wall_thickness,
        })
    }

    /// The grid parameters with access points chosen by `protocol`.
    pub fn params(&self, protocol: &Protocol) -> GridParams {
        GridParams {
            resolution: self.resolution,
            robot_radius: self.robot_radius,
            wall_thickness: self.wall_thickness,
            access: protocol.access,
        }
    }
}

/// The command line's defaults. The keyword defaults in the functions' signatures are the same
/// numbers written out (a signature shows only literals to Python); the tests compare them with
/// `ferret eval --help`.
impl Default for Grid {
    fn default() -> Self {
        let d = GridParams::default();
        Self {
            resolution: d.resolution,
            robot_radius: d.robot_radius,
            wall_thickness: d.wall_thickness,
        }
    }
}

/// A protocol by name, `"ferret"` or `"paper"`, as `--protocol`.
pub fn protocol(name: &str) -> PyResult<Protocol> {
    name.parse::<ProtocolName>()
        .map(Protocol::named)
        .map_err(|e| errors::config(format!("protocol={name:?}: {e}")))
}

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
            Self::Default => default(),
        }
    }
}

/// The prior `ferret eval` uses when given none, trained on first use and kept: it depends on
/// nothing but constants.
pub fn default() -> Result<Arc<Prior>, ferret_lab::LabError> {
    static DEFAULT: Mutex<Option<Arc<Prior>>> = Mutex::new(None);
    let mut held = DEFAULT.lock().unwrap_or_else(|p| p.into_inner());
    if let Some(p) = held.as_ref() {
        return Ok(p.clone());
    }
    let (houses, seed) = ferret_lab::strategies::DEFAULT_PRIOR_HOUSES;
    let p = Arc::new(default_prior(houses, seed)?);
    *held = Some(p.clone());
    Ok(p)
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

/// LLM keywords (`config`, `llm_cache`, `offline`, `keep_going`, `fusion`), as `--config`,
/// `--llm-cache`, `--offline`, `--keep-going` and `--fusion`.
pub fn llm(
    config: Option<PathBuf>,
    llm_cache: Option<PathBuf>,
    offline: bool,
    keep_going: bool,
    fusion: Option<PathBuf>,
) -> LlmSettings {
    let defaults = LlmSettings::default();
    LlmSettings {
        config,
        llm_cache: llm_cache.unwrap_or(defaults.llm_cache),
        offline,
        keep_going,
        max_fallback_share: None,
        fusion,
    }
}

/// Refuses a spec given twice, as `--strategies a,b,a` is refused.
pub fn check_distinct(name: &str, specs: &[String]) -> PyResult<()> {
    ferret_lab::strategies::check_distinct(name, specs).map_err(errors::lab)
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
