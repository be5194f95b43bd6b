//! The strategy registry with the LLM kinds, for commands: the experiment layer's setup under
//! the command line's options, with progress and reports on the terminal.

use std::path::Path;

use anyhow::Result;
use ferret_lab::strategies::{self, Strategies};
use ferret_llm::{FailurePolicy, LlmService};

pub use crate::args::LlmArgs;
use crate::args::PlanningArgs;

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
