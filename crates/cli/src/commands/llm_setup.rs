//! What the commands that may ask an LLM print after a run: the token report and the answer
//! warnings on the terminal, and the fallback gate under the command line's options.

use std::path::Path;

use anyhow::Result;
use ferret_lab::strategies;
use ferret_llm::LlmService;

pub use crate::args::LlmArgs;

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
