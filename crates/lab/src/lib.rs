//! # ferret-lab
//!
//! The experiment layer between the libraries ({world, plan, llm, select}) and ferret's
//! faces (the command line, the HTTP service, Python). It owns what an experiment is made of:
//! where houses come from and their maps ([`houses`]), strategy setup without a command line
//! ([`strategies`]), evaluation of strategies on the same trials ([`evaluate`](mod@evaluate)), the run files
//! `trials.csv` and `run.json` ([`runs`]), summaries ([`summary`]) and the paired statistics behind them ([`paired`]),
//! calibration of likelihood sources ([`calibrate`]), word vectors for the learned likelihood
//! ([`language`]), the replay table behind selection with its
//! resumable cache ([`replay`]), selection over an evaluation run ([`selection`]), sharded evaluation and its merge
//! ([`shard`]), batch
//! deployments in simulation with their house order ([`deploy`](mod@deploy)), atomic
//! output files ([`files`]), and how long work reports progress without printing
//! ([`feedback`]). Faces parse their input, call these functions and print what they return.

pub mod calibrate;
pub mod deploy;
pub mod error;
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

pub use deploy::{DeploySettings, DeployedTrial, deploy, house_order};
pub use error::{LabError, Result};
pub use evaluate::{
    Evaluation, EvaluationTotals, HouseOutcome, SpecEvaluation, TrialDraw, default_batch, evaluate,
    evaluate_source_each, evaluate_specs, evaluate_specs_each, trial_row,
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
    DEFAULT_STRATEGIES, LlmSettings, PlanningSettings, Strategies, full_registry,
    full_registry_with,
};
pub use summary::{CostTable, PairedRow, SummaryRow, paired_comparisons, summarize};
