//! Errors of the select crate.

use thiserror::Error;

/// Everything that can go wrong when building a cost table, a selector or an experiment.
///
/// Indices in the variants are 0-based positions in the [`CostTable`](crate::CostTable)
/// (houses, strategies) so that callers can map them back to names.
#[derive(Debug, Clone, PartialEq, Error)]
#[non_exhaustive]
pub enum SelectError {
    /// A live deployment cannot be rebuilt from its stored trials, or is used out of order.
    #[error("live deployment: {0}")]
    Live(String),
    /// A cost table or selector needs at least one candidate strategy.
    #[error("no candidate strategies")]
    NoStrategies,
    /// A cost table needs at least one house.
    #[error("no houses in the cost table")]
    NoHouses,
    /// Two candidate strategies share a name.
    #[error("strategy `{0}` is listed twice")]
    DuplicateStrategy(String),
    /// Two houses share a label; trials would be ambiguous.
    #[error("house `{0}` is listed twice")]
    DuplicateHouse(String),
    /// `oracle` is a lower bound that knows the answer; it must never be a candidate.
    #[error("`oracle` cannot be a candidate strategy")]
    OracleCandidate,
    /// A row of the table has the wrong number of entries.
    #[error("{what}: expected {expected} entries, found {found}")]
    Shape {
        /// Which part of the table, e.g. "cost rows" or "replay costs of house 3, deployed 1".
        what: String,
        /// Number of entries required.
        expected: usize,
        /// Number of entries given.
        found: usize,
    },
    /// A real cost is NaN or infinite.
    #[error("cost of strategy {strategy} on house {house} is not finite ({value})")]
    NonFiniteCost {
        /// House index.
        house: usize,
        /// Strategy index.
        strategy: usize,
        /// The offending value.
        value: f64,
    },
    /// A replay cost is NaN or infinite.
    #[error(
        "replay cost of strategy {strategy} on house {house} with {deployed} deployed is not finite ({value})"
    )]
    NonFiniteReplay {
        /// House index.
        house: usize,
        /// Strategy that was deployed.
        deployed: usize,
        /// Strategy that was replayed.
        strategy: usize,
        /// The offending value.
        value: f64,
    },
    /// Replaying the deployed strategy must give its own real cost.
    #[error(
        "replay of deployed strategy {strategy} on house {house} is {replay}, but its cost is {cost}"
    )]
    ReplayOfDeployed {
        /// House index.
        house: usize,
        /// The deployed (and replayed) strategy.
        strategy: usize,
        /// Its real cost.
        cost: f64,
        /// Its replay cost.
        replay: f64,
    },
    /// A strategy index outside `0..strategies`.
    #[error("strategy index {index} out of range (there are {strategies} strategies)")]
    StrategyOutOfRange {
        /// The index given.
        index: usize,
        /// Number of strategies.
        strategies: usize,
    },
    /// A cost handed to [`Selector::observe`](crate::Selector::observe) is NaN or infinite.
    #[error("observed cost of strategy {strategy} is not finite ({value})")]
    NonFiniteObservation {
        /// Strategy whose (real or replay) cost it is.
        strategy: usize,
        /// The offending value.
        value: f64,
    },
    /// A house index outside `0..houses`.
    #[error("house index {index} out of range (there are {houses} houses)")]
    HouseOutOfRange {
        /// The index given.
        index: usize,
        /// Number of houses.
        houses: usize,
    },
    /// A deployment draws houses without replacement, so it cannot be longer than the table.
    #[error("{trials} trials per deployment, but only {houses} distinct houses")]
    TooManyTrials {
        /// Trials per deployment requested.
        trials: usize,
        /// Houses available.
        houses: usize,
    },
    /// An option is out of its domain (zero deployments, negative `c`, ...).
    #[error("invalid option {name}: {reason}")]
    InvalidOption {
        /// Option name as the CLI spells it.
        name: &'static str,
        /// Why it was rejected.
        reason: String,
    },
}
