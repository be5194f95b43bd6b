//! # ferret-lab
//!
//! The experiment layer between the libraries ({world, plan, llm, select}) and ferret's faces
//! (the command line, the HTTP service, Python): it owns what an experiment is made of, and the
//! faces parse their input, call it and print what it returns. Its modules stack in layers,
//! each using only those below it. At the bottom, depending on no other module: a run's rows
//! and cost unit ([`rows`]), shards and their records ([`shard`]), errors ([`error`]), progress
//! without printing ([`feedback`]), atomic output files ([`files`]) and paired statistics
//! ([`paired`]). Above them, the figures of a run ([`summary`]) and every Markdown report,
//! rendered in one place ([`report`]); then the setup of an experiment: where houses come from
//! and their maps ([`houses`]), word vectors for the learned likelihood ([`language`]), and the
//! strategies with the LLM service behind them, built by one builder ([`strategies`]). On those
//! stand the run files `trials.csv` and `run.json` ([`runs`]) and the merge of shards' runs
//! ([`merge`](mod@merge)); at the top, the work itself: evaluation of strategies on the same
//! trials through one [`EvalContext`] ([`evaluate`](mod@evaluate)), an evaluation run into its
//! directory ([`eval_run`]), calibration of likelihood sources ([`calibrate`]), the replay table
//! behind selection with its resumable cache ([`replay`]), selection over an evaluation run
//! ([`selection`]), and batch deployments in simulation ([`deploy`](mod@deploy)).
//!
//! An evaluation of two strategies on three generated houses, one trial each:
//!
//! ```
//! # fn main() -> ferret_lab::Result<()> {
//! use ferret_lab::{
//!     EvalContext, HouseInput, LlmSettings, PlanningSettings, Silent, Strategies, TrialDraw,
//! };
//! use ferret_plan::{Protocol, TrialsPerHouse};
//! use ferret_world::GridParams;
//!
//! let scenes = ferret_world::generate::default_scenes(3, 0)?;
//! let specs = vec!["optimistic+greedy".to_string(), "model/uniform".to_string()];
//! // No LLM strategy runs, so the response cache is never opened.
//! let llm = LlmSettings::default();
//! let planning = PlanningSettings::default();
//! let setup = Strategies::builder(&planning, &llm).for_specs(&specs).build()?;
//! let draw = TrialDraw {
//!     seed: 0,
//!     reveal_fraction: 0.0,
//!     per_house: TrialsPerHouse::One,
//!     protocol: &Protocol::FERRET,
//!     holdout: None,
//!     tasks: None,
//!     team: None,
//! };
//! let grid = GridParams::default();
//! let run = EvalContext::new(&setup, &specs, &draw, &grid, &llm, &Silent)
//!     .collect(HouseInput::Scenes(&scenes))?;
//!
//! // Three trials, each run by both strategies, every target found at a finite, positive cost.
//! let ev = &run.evaluation;
//! assert!(ev.errors.is_empty(), "{:?}", ev.errors);
//! assert_eq!((ev.houses_run, ev.trials_run), (3, 3));
//! assert_eq!(ev.rows.len(), 3 * specs.len());
//! assert!(ev.rows.iter().all(|r| r.found && r.cost_m.is_finite() && r.cost_m > 0.0));
//! // The same trial for every strategy: each house's target is the same in both rows.
//! for pair in ev.rows.chunks(2) {
//!     assert_eq!((pair[0].house_index, &pair[0].target), (pair[1].house_index, &pair[1].target));
//! }
//! # Ok(())
//! # }
//! ```

pub mod calibrate;
pub mod deploy;
pub mod error;
pub mod eval_run;
pub mod evaluate;
pub mod feedback;
pub mod files;
pub mod houses;
pub mod language;
pub mod merge;
pub mod paired;
pub mod replay;
pub mod report;
pub mod rows;
pub mod runs;
pub mod selection;
pub mod shard;
pub mod strategies;
pub mod summary;
pub mod tasks;

pub use deploy::{DeploySettings, DeployedTrial, deploy, house_order};
pub use error::{LabError, Result};
pub use eval_run::{EvalDone, EvalJob, ShownHouse, check_team};
pub use evaluate::{
    EvalContext, Evaluation, EvaluationTotals, HouseInput, HouseOutcome, SpecEvaluation, TrialDraw,
    default_batch, evaluate, team_paths, team_row, trial_row,
};
pub use feedback::{Feedback, Silent};
pub use ferret_select::HouseOrder;
pub use houses::{
    HouseEvent, HouseSource, HouseStream, LoadedHouses, Mapped, OpenSource, build_maps,
};
pub use merge::{MergedRun, merge_runs};
pub use rows::{CELL_M, TrialRow};
pub use runs::{EvalRun, RunInfo, RunWriter, WrittenRun, sha256_hex};
pub use shard::{MergeError, Shard, ShardError, ShardSpec};
pub use strategies::{
    DEFAULT_STRATEGIES, LlmSettings, PlanningSettings, Strategies, StrategiesBuilder,
};
pub use summary::{CostTable, PairedRow, SummaryRow, paired_comparisons, summarize};
pub use tasks::{Deliver, TaskLine, TaskText, Tasks, read_task_file, task_of_row};
