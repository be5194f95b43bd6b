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
//!
//! A robot's search, step by step: the strategy names the next container, the robot searches it
//! and reports what it saw, until the target turns up.
//!
//! ```
//! use ferret_plan::{PlannerConfig, Search, SearchProblem, StrategyRegistry, draw_trial};
//! use ferret_world::{GridParams, distance, generate};
//!
//! let scene = generate::default_scenes(1, 3)?.remove(0);
//! let (_, distances) = distance::build(&scene.house, &GridParams::default())?;
//! let trial = draw_trial(&scene.house, &scene.truth, 0, 0.0)?;
//! let problem = SearchProblem::new(&scene.house, &distances, &trial);
//! // Without a prior file, `model/uniform`: the exact planner over equal probabilities.
//! let registry = StrategyRegistry::builtin(None, PlannerConfig::default(), 16);
//! let strategy = registry.build("model/uniform")?;
//! let mut search = Search::start(strategy.as_ref(), &problem, None)?;
//! let mut found = false;
//! while let Some(c) = search.next_container()? {
//!     // A real robot drives to container `c` here; the ground truth stands in for its camera.
//!     let seen: Vec<_> = scene.truth.contents(c).iter().map(|o| o.object_type.clone()).collect();
//!     found = seen.contains(trial.task.first());
//!     search.record(c, seen)?;
//!     if found {
//!         break;
//!     }
//! }
//! assert!(found, "every drawn target is in some container");
//! assert!(search.belief().travelled() > 0.0);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```
//!
//! The exact planner on its own: the order of candidates that minimises the expected distance
//! travelled before the target is found (paper eq. 3).
//!
//! ```
//! use ferret_plan::{Probability, TourProblem, solve_brute_force, solve_exact};
//!
//! // A likely container 10 m away and an unlikely one 4 m away, 10 m apart.
//! let problem = TourProblem {
//!     from_robot: vec![10.0, 4.0],
//!     between: vec![0.0, 10.0, 10.0, 0.0],
//!     p: vec![Probability::new(0.9).ok_or("p")?, Probability::new(0.1).ok_or("p")?],
//!     search_cost: 0.0,
//!     leg_extra: vec![],
//!     final_leg: vec![],
//! };
//! let (plan, _) = solve_exact(&problem).ok_or("too large")?;
//! // The far, likely one first: 10 + 0.1·10 = 11 m expected, against 4 + 0.9·10 = 13 m.
//! assert_eq!(plan.order, [0, 1]);
//! assert!((plan.expected_cost - 11.0).abs() < 1e-9);
//! assert_eq!(plan.order, solve_brute_force(&problem).order);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

pub mod belief;
pub mod calibration;
pub mod error;
pub mod fusion;
pub mod holdout;
pub mod learned;
pub mod likelihood;
pub mod logistic;
pub mod plan_memo;
pub mod planner;
pub mod policy;
pub mod prior;
pub mod probability;
pub mod problem;
pub mod protocol;
pub mod pyrandom;
pub mod replay;
pub mod replay_memo;
pub mod strategy;
pub mod task;
pub mod task_table;
pub mod team;
pub mod trial;

pub use belief::Belief;
pub use calibration::{Calibration, ReliabilityBin};
pub use error::{BoxError, PlanError};
pub use fusion::{
    Fused, FusionBase, FusionFile, FusionFit, FusionSample, FusionWeights, TrainingScore,
    prior_fingerprint,
};
pub use holdout::HoldOut;
pub use learned::{Embedder, Learned, LearnedKind, LearnedSettings, LearnedSource, NameVectors};
pub use likelihood::{Evidence, LikelihoodSource, Noise, OracleLikelihood, Uniform};
pub use plan_memo::PlanMemo;
pub use planner::{Plan, TourProblem, solve_brute_force, solve_exact};
pub use policy::{
    CandidateLimit, CostModel, Greedy, Oracle, Planner, PlannerConfig, Policy, Sequential,
    oracle_route,
};
pub use prior::{CALIBRATION_FOLDS, Prior, PriorCalibration, RawPrior};
pub use probability::Probability;
pub use problem::{SearchProblem, TrialSpec};
pub use protocol::{
    AccessRule, ContainerSet, DrawMode, InitialBelief, Protocol, ProtocolName, ReplayMode,
    TargetSet, TravelCost, TrialRng, TrialSettings, UntriedScore,
};
pub use replay::{
    hindsight_truth, replay_cost, replay_cost_with, replay_costs, replay_outcome_with,
    replay_team_cost_with, replay_team_costs,
};
pub use replay_memo::ReplayMemo;
pub use strategy::{
    INDEPENDENT, ModelStrategy, SEQUENTIAL, SPLIT, SequentialStrategy, Strategy, StrategyRegistry,
    StrategySpec, TeamStrategy, Teamwork, TrialContext, planned_spec, task_likelihoods,
};
pub use task::{Destination, DestinationLegs, Goal, MAX_TARGETS, Task, TaskError};
pub use task_table::{TaskProblem, TaskSolution, solve_task};
pub use team::{
    MAX_ROBOTS, RobotRun, TeamOutcome, TeamSettings, TeamStarts, draw_starts, run_team,
    split_rooms, team_destinations, team_distances,
};
pub use trial::{
    Search, TaskShape, TrialOutcome, TrialsPerHouse, draw_tasks, draw_trial, draw_trials,
    draw_trials_with, python_seed, run_trial,
};
