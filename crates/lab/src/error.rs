//! Errors of the experiment layer.

use ferret_llm::LlmError;
use ferret_plan::PlanError;
use ferret_select::SelectError;
use ferret_world::WorldError;

/// Everything that can go wrong running an experiment. Messages say what and where (file, house,
/// option); [`LabError::Context`] adds where an inner error happened, so the whole chain reads
/// as one sentence.
#[derive(Debug, thiserror::Error)]
pub enum LabError {
    /// A setting that cannot be used, named as the user gave it.
    #[error("{0}")]
    Invalid(String),
    /// A household task that cannot be asked: where it was given (a file and line, a task of a
    /// house) and which field is wrong.
    #[error("{place}: {error}")]
    Task {
        /// Where the task was given.
        place: String,
        /// Its field and what is wrong with it.
        #[source]
        error: ferret_plan::TaskError,
    },
    /// A house failed to load, map or validate.
    #[error(transparent)]
    World(#[from] WorldError),
    /// Planning, simulating or replaying failed.
    #[error(transparent)]
    Plan(#[from] PlanError),
    /// An LLM endpoint, its configuration or the response cache failed.
    #[error(transparent)]
    Llm(#[from] LlmError),
    /// An LLM endpoint failed and the run stopped; answers received are kept in the cache.
    #[error("{0}")]
    LlmStopped(String),
    /// The LLM endpoint configuration is unusable.
    #[error(transparent)]
    LlmConfig(#[from] ferret_llm::ConfigError),
    /// A selector or a selection experiment failed.
    #[error(transparent)]
    Select(#[from] SelectError),
    /// A step of the deployment loop failed.
    #[error(transparent)]
    Deployment(#[from] ferret_select::DeploymentError),
    /// The caller asked to stop ([`Feedback::cancelled`](crate::Feedback::cancelled)).
    #[error("cancelled")]
    Cancelled,
    /// A selection needs at least two candidates besides the oracle.
    #[error("selection needs at least two non-oracle strategies")]
    TooFewCandidates,
    /// Deployments of distinct houses need more houses than have a trial of every candidate.
    #[error(
        "{need} trials per deployment need {need} houses with a trial of every strategy; {have} have one"
    )]
    TooFewHouses {
        /// Houses with a trial of every candidate.
        have: usize,
        /// Houses one deployment needs.
        need: usize,
    },
    /// A file could not be read or written.
    #[error("{context}")]
    Io {
        /// What was being done, with the path.
        context: String,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A CSV file could not be read or written.
    #[error("{context}")]
    Csv {
        /// The file and row.
        context: String,
        /// The cause.
        #[source]
        source: csv::Error,
    },
    /// A JSON file could not be read or written.
    #[error("{context}")]
    Json {
        /// The file.
        context: String,
        /// The cause.
        #[source]
        source: serde_json::Error,
    },
    /// A `--shard` that cannot be used.
    #[error(transparent)]
    Shard(#[from] crate::shard::ShardError),
    /// Shards that cannot be merged.
    #[error(transparent)]
    Merge(#[from] crate::shard::MergeError),
    /// An inner error, with where it happened.
    #[error("{context}")]
    Context {
        /// Where it happened.
        context: String,
        /// The cause.
        #[source]
        source: Box<LabError>,
    },
}

/// A result of the experiment layer.
pub type Result<T, E = LabError> = std::result::Result<T, E>;

impl LabError {
    /// An I/O error with what was being done.
    pub fn io(context: impl Into<String>, source: std::io::Error) -> Self {
        Self::Io {
            context: context.into(),
            source,
        }
    }

    /// An unusable setting.
    pub fn invalid(message: impl Into<String>) -> Self {
        Self::Invalid(message.into())
    }
}

/// Adds where an error happened, as `anyhow`'s `context` does, without leaving typed errors.
pub trait Context<T> {
    /// Wraps the error with `context()`.
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T>;
}

impl<T, E: Into<LabError>> Context<T> for std::result::Result<T, E> {
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| LabError::Context {
            context: context(),
            source: Box::new(e.into()),
        })
    }
}
