//! # ferret-python
//!
//! ferret's Python package (`import ferret`): a thin face over the experiment layer that owns
//! the conversion between Python and ferret's types — houses loaded or generated
//! ([`houses`]), priors ([`prior`]), a search driven step by step ([`search`]), evaluations
//! with `trials.csv`'s rows ([`evaluate`]), calibration of likelihood sources ([`calibrate`]),
//! selection over an evaluation run ([`select`]), a live deployment's selector ([`deploy`]),
//! household tasks from Python's arguments ([`tasks`]), the keyword arguments they share
//! ([`settings`], and the planner's and prior's with the strategy registry: [`planning`]), progress on stderr ([`progress`]) and exception classes carrying the command
//! line's messages ([`errors`]). It plans, simulates and evaluates nothing itself: every call
//! goes to the crates `ferret eval` and `ferret serve` use.

use pyo3::prelude::*;

pub mod calibrate;
pub mod convert;
pub mod deploy;
pub mod errors;
pub mod evaluate;
pub mod houses;
pub mod planning;
pub mod prior;
pub mod progress;
pub mod search;
pub mod select;
pub mod settings;
pub mod tasks;

/// The extension module `ferret._ferret`, re-exported by the `ferret` package.
#[pymodule]
fn _ferret(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::register(m)?;
    m.add_class::<houses::House>()?;
    m.add_class::<houses::PyContainer>()?;
    m.add_class::<houses::PyRoom>()?;
    m.add_class::<houses::PyObject_>()?;
    m.add_class::<prior::PyPrior>()?;
    m.add_class::<search::PySearch>()?;
    m.add_class::<evaluate::PyEvaluation>()?;
    m.add_class::<calibrate::PyCalibration>()?;
    m.add_class::<select::PySelection>()?;
    m.add_class::<deploy::PyDeployment>()?;
    m.add_function(wrap_pyfunction!(houses::load_houses, m)?)?;
    m.add_function(wrap_pyfunction!(houses::generate_houses, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::evaluate, m)?)?;
    m.add_function(wrap_pyfunction!(evaluate::merge, m)?)?;
    m.add_function(wrap_pyfunction!(calibrate::calibrate, m)?)?;
    m.add_function(wrap_pyfunction!(select::select, m)?)?;
    m.add("DEFAULT_STRATEGIES", ferret_lab::DEFAULT_STRATEGIES)?;
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    Ok(())
}
