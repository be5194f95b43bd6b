//! Python exceptions from the typed errors of the crates below: one class per kind of mistake,
//! with the message the command line prints for the same error.

use std::panic::{AssertUnwindSafe, catch_unwind};

use ferret_lab::LabError;
use ferret_plan::PlanError;
use ferret_world::{WorldError, error_chain};
use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::prelude::*;

create_exception!(
    ferret,
    FerretError,
    PyException,
    "Base class of every error ferret raises."
);
create_exception!(
    ferret,
    HouseError,
    FerretError,
    "A house file, scene file or asset database that cannot be read, or a house that cannot be mapped; the message names the file, the house index and the field."
);
create_exception!(
    ferret,
    StrategyError,
    FerretError,
    "A strategy spec that names no known strategy, or a strategy that cannot be built."
);
create_exception!(
    ferret,
    PriorError,
    FerretError,
    "A prior file that cannot be read or written."
);
create_exception!(
    ferret,
    ConfigError,
    FerretError,
    "An unusable setting: a keyword argument, a protocol, grid or planner option, or the LLM endpoint configuration."
);
create_exception!(
    ferret,
    LlmError,
    FerretError,
    "An LLM endpoint or the LLM response cache failed."
);
create_exception!(
    ferret,
    SearchError,
    FerretError,
    "A search cannot go on: a container that is not in the house or was already searched, or a policy that failed to choose."
);

/// Adds the exception classes to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("FerretError", py.get_type::<FerretError>())?;
    m.add("HouseError", py.get_type::<HouseError>())?;
    m.add("StrategyError", py.get_type::<StrategyError>())?;
    m.add("PriorError", py.get_type::<PriorError>())?;
    m.add("ConfigError", py.get_type::<ConfigError>())?;
    m.add("LlmError", py.get_type::<LlmError>())?;
    m.add("SearchError", py.get_type::<SearchError>())?;
    Ok(())
}

/// The exception class of an error, by the kind of its innermost typed cause.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Ferret,
    House,
    Strategy,
    Prior,
    Config,
    Llm,
    Search,
}

impl Kind {
    fn err(self, message: String) -> PyErr {
        match self {
            Kind::Ferret => FerretError::new_err(message),
            Kind::House => HouseError::new_err(message),
            Kind::Strategy => StrategyError::new_err(message),
            Kind::Prior => PriorError::new_err(message),
            Kind::Config => ConfigError::new_err(message),
            Kind::Llm => LlmError::new_err(message),
            Kind::Search => SearchError::new_err(message),
        }
    }
}

fn lab_kind(e: &LabError) -> Kind {
    match e {
        LabError::Context { source, .. } => lab_kind(source),
        LabError::Invalid(_) => Kind::Config,
        LabError::World(_) => Kind::House,
        LabError::Plan(p) => plan_kind(p),
        LabError::Llm(_) | LabError::LlmStopped(_) => Kind::Llm,
        LabError::LlmConfig(_) => Kind::Config,
        _ => Kind::Ferret,
    }
}

fn plan_kind(e: &PlanError) -> Kind {
    match e {
        PlanError::UnknownStrategy { .. } => Kind::Strategy,
        PlanError::Prior { .. } | PlanError::Learned { .. } => Kind::Prior,
        PlanError::Fusion { .. } => Kind::Config,
        // An LLM-backed source or policy fails with the LLM's error inside.
        PlanError::Likelihood { error, .. } | PlanError::Policy { error, .. }
            if error.downcast_ref::<ferret_llm::LlmError>().is_some() =>
        {
            Kind::Llm
        }
        _ => Kind::Search,
    }
}

/// The exception of an experiment-layer error, with the command line's message.
pub fn lab(e: LabError) -> PyErr {
    lab_kind(&e).err(error_chain(&e))
}

/// The same, with the command line's option names in the message written as the keywords
/// that set them (`("--c ", "c=")`).
pub fn lab_as_keywords(e: LabError, keywords: &[(&str, &str)]) -> PyErr {
    let mut message = error_chain(&e);
    for (option, keyword) in keywords {
        message = message.replace(option, keyword);
    }
    lab_kind(&e).err(message)
}

/// The exception of a planning error.
pub fn plan(e: PlanError) -> PyErr {
    plan_kind(&e).err(error_chain(&e))
}

/// The exception of a house error.
pub fn world(e: WorldError) -> PyErr {
    HouseError::new_err(error_chain(&e))
}

/// An unusable keyword argument, named as the caller wrote it.
pub fn config(message: impl Into<String>) -> PyErr {
    ConfigError::new_err(message.into())
}

/// A search step that cannot be taken.
pub fn search(message: impl Into<String>) -> PyErr {
    SearchError::new_err(message.into())
}

/// Runs Rust work so that a panic in it (a bug, never an input) becomes a `FerretError` naming
/// it instead of unwinding into the interpreter.
pub fn guarded<T>(what: &str, f: impl FnOnce() -> PyResult<T>) -> PyResult<T> {
    match catch_unwind(AssertUnwindSafe(f)) {
        Ok(r) => r,
        Err(panic) => {
            let why = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_else(|| "unknown cause".to_string());
            Err(FerretError::new_err(format!(
                "{what}: internal error (please report it): {why}"
            )))
        }
    }
}
