//! LLM options shared by every command that builds strategies, and the full strategy registry
//! (built-in kinds plus the LLM crate's `llm+model` and `llm-direct`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Result;
use ferret_llm::{LlmConfig, LlmOptions, LlmService, prefetch_probabilities, register_strategies};
use ferret_plan::StrategyRegistry;
use ferret_world::{House, ObjectType};

use super::eval::PlanningArgs;

/// Where LLM endpoints and cached answers live.
#[derive(clap::Args, Clone, Debug)]
pub struct LlmArgs {
    /// Endpoint configuration (TOML, see ferret.example.toml); `ferret.toml` in the working
    /// directory when present.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// The response cache (SQLite). Every answer is stored before it is used, so an interrupted
    /// run loses nothing and a rerun asks nothing twice.
    #[arg(long, value_name = "FILE", default_value = ferret_llm::DEFAULT_CACHE_PATH)]
    pub llm_cache: PathBuf,
    /// Answer LLM queries from the cache only; a missing answer is an error naming the prompt.
    #[arg(long)]
    pub offline: bool,
}

/// Strategies and the LLM service behind the LLM ones.
pub struct Strategies {
    /// Every kind: built-in and LLM.
    pub registry: StrategyRegistry,
    /// The LLM service (endpoints, cache, accounting).
    pub service: Arc<LlmService>,
}

/// Built-in strategies plus the LLM kinds, for the strategies `specs` will build. The LLM service opens its cache only when an LLM is
/// first asked, so runs without LLM strategies touch no cache file.
pub fn full_registry(
    planning: &PlanningArgs,
    llm: &LlmArgs,
    specs: &[String],
) -> Result<Strategies> {
    let mut registry = planning.registry(specs)?;
    let config = LlmConfig::load_default(llm.config.as_deref())?;
    let service = Arc::new(LlmService::new(
        config,
        LlmOptions {
            cache_path: Some(llm.llm_cache.clone()),
            offline: llm.offline,
        },
    )?);
    register_strategies(
        &mut registry,
        service.clone(),
        planning.planner_config(),
        planning.exact_max,
    );
    Ok(Strategies { registry, service })
}

/// Asks every probability question of the `llm+model` strategies concurrently before trials run,
/// so trials answer from the cache. Failures are printed; trials of the failed LLMs then fail
/// one by one and are reported, while all others run.
pub fn prefetch(
    service: &Arc<LlmService>,
    specs: &[String],
    trials: &[(&House, &ObjectType)],
) -> Result<()> {
    if !specs.iter().any(|s| s.starts_with(ferret_llm::LLM_MODEL)) {
        return Ok(());
    }
    let summary = prefetch_probabilities(service, specs, trials)?;
    eprintln!(
        "LLM questions: {} distinct ({} cached, {} asked now, {} skipped after a failure)",
        summary.distinct, summary.cached, summary.asked, summary.skipped
    );
    for f in &summary.failures {
        eprintln!("LLM failure: {f}");
    }
    Ok(())
}

/// Prints the token report (paper table V) and writes `tokens.csv`, when any LLM was used.
pub fn write_token_report(service: &LlmService, dir: &Path) -> Result<()> {
    let report = service.report();
    if report.rows.is_empty() {
        return Ok(());
    }
    println!("{report}");
    // Also in the run's summary, beside the cost table (the paper's table V).
    let summary = dir.join("summary.md");
    if summary.exists() {
        let mut md = std::fs::read_to_string(&summary)?;
        md.push_str(&format!("\n## LLM tokens and cost\n\n```\n{report}```\n"));
        crate::output::write_bytes(&summary, md)?;
    }
    std::fs::create_dir_all(dir)?;
    crate::output::write_atomic(&dir.join("tokens.csv"), |w| Ok(report.write_csv(w)?))?;
    Ok(())
}
