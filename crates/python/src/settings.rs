//! Keyword arguments several functions share — grid, protocol, LLM, lists of specs — turned
//! into the experiment layer's settings and checked with the command line's rules (the planner
//! and prior keywords, and the strategy registry built from them, are in
//! [`planning`](crate::planning)).

use std::path::PathBuf;

use ferret_lab::LlmSettings;
use ferret_plan::{Protocol, ProtocolName};
use ferret_world::GridParams;
use pyo3::prelude::*;

use crate::errors;

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
