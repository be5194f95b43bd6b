//! # ferret-plan
//!
//! Object search as planning (paper section IV): the robot's [`Belief`], likelihood sources that
//! give `P_S(target, container)` ([`LikelihoodSource`]: a learned and calibrated [`Prior`],
//! [`Uniform`], the [`Noise`] control, the oracle; target types a prior must not have seen,
//! [`HoldOut`]), policies that map a belief to the next container ([`Policy`]: the exact expected-cost
//! [`Planner`], the optimistic greedy baseline, the oracle), named [`Strategy`]s built from spec
//! strings through a [`StrategyRegistry`], a trial step by step ([`Search`], what a robot loop
//! drives), the trial simulator built on it ([`run_trial`]) and offline replay
//! ([`replay_cost`]), the [`Calibration`] of a likelihood source against the ground truth, and
//! the [`Fused`] source that combines the prior with another by fitted [`FusionWeights`].
//! It depends only on the world crate; LLM-backed sources and policies plug in
//! from the llm crate through the same traits.

pub mod belief;
pub mod calibration;
pub mod error;
pub mod fusion;
pub mod holdout;
pub mod likelihood;
pub mod logistic;
pub mod planner;
pub mod policy;
pub mod probability;
pub mod protocol;
pub mod pyrandom;
pub mod replay;
pub mod strategy;
pub mod trial;

pub use belief::Belief;
pub use calibration::{Calibration, ReliabilityBin};
pub use error::{BoxError, PlanError};
pub use fusion::{
    Fused, FusionFile, FusionFit, FusionSample, FusionWeights, TrainingScore, prior_fingerprint,
};
pub use holdout::HoldOut;
pub use likelihood::{
    CALIBRATION_FOLDS, LikelihoodSource, Noise, OracleLikelihood, Prior, PriorCalibration,
    RawPrior, Uniform,
};
pub use planner::{Plan, TourProblem, solve_brute_force, solve_exact};
pub use policy::{CandidateLimit, CostModel, Greedy, Oracle, Planner, PlannerConfig, Policy};
pub use probability::Probability;
pub use protocol::{
    AccessRule, ContainerSet, DrawMode, InitialBelief, Protocol, ProtocolName, ReplayMode,
    TargetSet, TravelCost, TrialRng, TrialSettings, UntriedScore,
};
pub use replay::{
    hindsight_truth, replay_cost, replay_cost_with, replay_costs, replay_outcome_with,
};
pub use strategy::{ModelStrategy, Strategy, StrategyRegistry, StrategySpec, TrialContext};
pub use trial::{
    Search, SearchProblem, TrialOutcome, TrialSpec, TrialsPerHouse, draw_trial, draw_trials,
    draw_trials_with, python_seed, run_trial,
};
