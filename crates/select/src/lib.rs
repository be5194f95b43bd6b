//! Strategy selection during deployment (paper section V).
//!
//! A robot carries several strategies (policy + prompt + LLM) and must find the best one in few
//! trials. The selectors and experiments work on plain numbers: the real cost of each deployed
//! trial and the offline-replay costs of the alternatives; the deployment loop produces those
//! numbers from real strategies with the plan crate's simulator and replay.
//!
//! * [`Selector`]: one trial at a time — [`Selector::choose`] a strategy, deploy it, then
//!   [`Selector::observe`] its cost and the replay costs. Implemented by [`Ucb`] (paper eq. 2) and
//!   [`ReplaySelection`] (paper eq. 5). The same trait drives the live robot loop and the
//!   experiment, so they cannot drift apart.
//! * [`LiveDeployment`]: the selector between a robot's trials, rebuilt exactly from its stored
//!   finished trials after a restart; `ferret deploy`, `ferret serve` and the experiment all
//!   drive it. [`DeploymentLoop`]: choose → run → replay → learn with real strategies on real
//!   trials, the loop `ferret deploy` runs in simulation and `ferret serve` one step per request. [`HouseOrder`]: the houses a deployment visits.
//! * [`CostTable`]: real and replay costs of every candidate on one trial per house.
//! * [`run_experiment`]: the paper's deployment experiment (section VI-C) on a table: average cost
//!   and cumulative regret against the best single strategy, per trial count `k`.
//! * [`selection_rows`], [`choice_rows`], [`selection_table_markdown`],
//!   [`strategy_table_markdown`]: report rows and tables.

mod deployment;
mod error;
mod experiment;
mod live;
pub mod numpy;
mod order;
mod results;
mod selector;
mod table;

pub use deployment::{DeploymentError, DeploymentLoop, DeploymentStep, ReplaySettings};
pub use error::SelectError;
pub use experiment::{
    DeploymentRecord, ExperimentOptions, ExperimentResult, MAX_EXPERIMENT_TRIALS, MethodRun,
    MethodSummary, run_experiment, run_on_table,
};
pub use live::{DeploymentEvent, FinishedTrial, LiveDeployment, TrialEnd};
pub use order::HouseOrder;
pub use results::{
    ChoiceRow, PAPER_KS, SelectionRow, choice_rows, selection_rows, selection_table_markdown,
    strategy_table_markdown,
};
pub use selector::{
    DEFAULT_C, Method, ReplaySelection, Selector, SelectorVariant, StrategyStats, Ucb,
};
pub use table::{CostTable, ORACLE, REPLAY_TOLERANCE};
