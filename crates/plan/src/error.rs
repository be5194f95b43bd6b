//! Errors of the plan crate.

/// A boxed error from an extension (an LLM client, a file reader).
pub type BoxError = Box<dyn std::error::Error + Send + Sync + 'static>;

/// Everything that can go wrong planning, simulating or replaying.
#[derive(Debug, thiserror::Error)]
pub enum PlanError {
    /// A strategy spec string does not name a known strategy.
    #[error("unknown strategy `{spec}`: {reason}")]
    UnknownStrategy {
        /// The spec as given.
        spec: String,
        /// Why it was not understood, with the accepted forms.
        reason: String,
    },
    /// A likelihood source failed.
    #[error("likelihood source {source_name}: {error}")]
    Likelihood {
        /// The source's name.
        source_name: String,
        /// The cause.
        #[source]
        error: BoxError,
    },
    /// A team that cannot work: no robots or too many, robots on different trials, a start
    /// the house's start cannot reach.
    #[error("{house}: team: {message}")]
    Team {
        /// The house's name.
        house: String,
        /// What is wrong.
        message: String,
    },
    /// A policy failed to choose.
    #[error("policy {policy}: {error}")]
    Policy {
        /// The policy's name.
        policy: String,
        /// The cause.
        #[source]
        error: BoxError,
    },
    /// A policy chose a container that does not exist or was already searched.
    #[error("policy {policy} chose container {container}, which is {why}")]
    BadChoice {
        /// The policy's name.
        policy: String,
        /// The container index.
        container: usize,
        /// `already searched` or `not in the house`.
        why: &'static str,
    },
    /// The number of probabilities does not match the number of containers.
    #[error("likelihood source {source_name} gave {got} probabilities for {expected} containers")]
    LikelihoodCount {
        /// The source's name.
        source_name: String,
        /// Containers in the house.
        expected: usize,
        /// Probabilities given.
        got: usize,
    },
    /// A house has no container holding any small object, so no trial can be drawn.
    #[error("{house}: no container holds a small object; no target can be drawn")]
    NoTarget {
        /// The house label.
        house: String,
    },
    /// A house has fewer target types than a task asks for.
    #[error(
        "{house}: {have} target type(s), a task of {want} targets cannot be drawn {tasks} time(s)"
    )]
    TooFewTargets {
        /// The house label.
        house: String,
        /// Target types in the house.
        have: usize,
        /// Targets per task.
        want: usize,
        /// Tasks asked for.
        tasks: usize,
    },
    /// A fusion file could not be read.
    #[error("fusion file {path}: {message}")]
    Fusion {
        /// The file.
        path: String,
        /// What is wrong.
        message: String,
    },
    /// A learned likelihood could not be trained.
    #[error("learned likelihood: {message}")]
    Learned {
        /// What went wrong.
        message: String,
    },
    /// A prior file could not be read or written.
    #[error("prior {path}: {message}")]
    Prior {
        /// The file.
        path: String,
        /// What went wrong.
        message: String,
    },
    /// A trial's reported cost cannot be measured as asked.
    #[error("{house}: {message}")]
    TravelCost {
        /// The house label.
        house: String,
        /// Why.
        message: String,
    },
    /// A task that cannot be asked, or a destination the map cannot serve.
    #[error(transparent)]
    Task(#[from] crate::task::TaskError),
    /// A trial to replay is inconsistent with its house.
    #[error("replay on {house}: {message}")]
    Replay {
        /// The house label.
        house: String,
        /// What is wrong.
        message: String,
    },
}
