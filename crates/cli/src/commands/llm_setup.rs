//! The strategy registry with the LLM kinds, for commands: the experiment layer's setup under
//! the command line's options, with progress and reports on the terminal.

use std::path::Path;
use std::sync::Arc;

use anyhow::Result;
use ferret_lab::strategies::{self, Strategies};
use ferret_llm::{FailurePolicy, LlmService};
use ferret_world::{House, ObjectType};

pub use crate::args::LlmArgs;
use crate::args::PlanningArgs;
use crate::common::Bars;

/// Built-in strategies plus the LLM kinds, for the strategies `specs` will build.
pub fn full_registry(
    planning: &PlanningArgs,
    llm: &LlmArgs,
    specs: &[String],
) -> Result<Strategies> {
    Ok(strategies::full_registry(
        &planning.settings(),
        &llm.settings(),
        specs,
    )?)
}

/// The same, with what a failed LLM endpoint means for later questions.
pub fn full_registry_with(
    planning: &PlanningArgs,
    llm: &LlmArgs,
    specs: &[String],
    on_failure: FailurePolicy,
) -> Result<Strategies> {
    Ok(strategies::full_registry_with(
        &planning.settings(),
        &llm.settings(),
        specs,
        on_failure,
    )?)
}

/// Asks every probability question before trials run, with a progress bar; returns the
/// strategies to drop under `--keep-going` (see [`ferret_lab::strategies::prefetch`]).
pub fn prefetch(
    service: &Arc<LlmService>,
    llm: &LlmArgs,
    specs: &[String],
    trials: &[(&House, &ObjectType)],
) -> Result<Vec<String>> {
    Ok(strategies::prefetch(
        service,
        &llm.settings(),
        specs,
        trials,
        &Bars::default(),
    )?)
}

/// Fails when `--max-fallback-share` is set and an LLM strategy's fallback share exceeds it.
pub fn check_fallback_gate(service: &LlmService, llm: &LlmArgs) -> Result<()> {
    Ok(strategies::check_fallback_gate(service, &llm.settings())?)
}

/// Prints the token report (paper table V) and writes `tokens.csv`, when any LLM was used.
pub fn write_token_report(service: &LlmService, dir: &Path) -> Result<()> {
    if let Some(files) = strategies::write_token_files(service, dir)? {
        println!("{}", files.report);
        for (strategy, w) in &files.warnings {
            eprintln!("WARNING: {strategy}: {w}");
        }
    }
    Ok(())
}
