//! LLM options shared by every command that builds strategies, and the full strategy registry
//! (built-in kinds plus the LLM crate's `llm+model` and `llm-direct`).

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::Result;
use ferret_llm::{
    FailurePolicy, LlmConfig, LlmOptions, LlmService, prefetch_probabilities, register_fused,
    register_strategies,
};
use ferret_plan::StrategyRegistry;
use ferret_plan::{FusionFile, Prior};
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
    /// When an LLM endpoint fails (after its retries), go on without the strategies that use it
    /// instead of stopping the run. Answers already received stay in the cache either way.
    #[arg(long)]
    pub keep_going: bool,
    /// Exit with an error when an LLM strategy's share of answers that could not be read (after
    /// re-asks) exceeds this fraction, e.g. 0.02. Results are written first.
    #[arg(long, value_name = "SHARE", value_parser = parse_share)]
    pub max_fallback_share: Option<f64>,
    /// Fusion weights from `ferret calibrate --fit-fusion`: makes `fused/<prompt>/<llm>`
    /// available, the prior and the LLM's likelihoods combined as fitted on training houses.
    #[arg(long, value_name = "FILE")]
    pub fusion: Option<PathBuf>,
}

fn parse_share(s: &str) -> std::result::Result<f64, String> {
    let v: f64 = s
        .parse()
        .map_err(|e| format!("`{s}` is not a number: {e}"))?;
    if (0.0..=1.0).contains(&v) {
        Ok(v)
    } else {
        Err(format!("{v} is not a share between 0 and 1"))
    }
}

/// Strategies and the LLM service behind the LLM ones.
pub struct Strategies {
    /// Every kind: built-in and LLM.
    pub registry: StrategyRegistry,
    /// The LLM service (endpoints, cache, accounting).
    pub service: Arc<LlmService>,
    /// The prior, when a strategy plans over it.
    pub prior: Option<Arc<Prior>>,
}

/// Built-in strategies plus the LLM kinds, for the strategies `specs` will build. The LLM service opens its cache only when an LLM is
/// first asked, so runs without LLM strategies touch no cache file.
pub fn full_registry(
    planning: &PlanningArgs,
    llm: &LlmArgs,
    specs: &[String],
) -> Result<Strategies> {
    full_registry_with(planning, llm, specs, FailurePolicy::StopForRun)
}

/// The same, with what a failed LLM endpoint means for later questions (batch commands stop
/// asking it; the server pauses and asks again).
pub fn full_registry_with(
    planning: &PlanningArgs,
    llm: &LlmArgs,
    specs: &[String],
    on_failure: FailurePolicy,
) -> Result<Strategies> {
    let prior = planning.prior_for(specs)?;
    let mut registry = planning.registry_with(prior.clone());
    let fusion = match &llm.fusion {
        Some(path) => Some((
            path.display().to_string(),
            Arc::new(FusionFile::load(path)?),
        )),
        None => None,
    };
    let config = LlmConfig::load_default(llm.config.as_deref())?;
    let service = Arc::new(LlmService::new(
        config,
        LlmOptions {
            cache_path: Some(llm.llm_cache.clone()),
            offline: llm.offline,
            on_failure,
        },
    )?);
    register_strategies(
        &mut registry,
        service.clone(),
        planning.planner_config(),
        planning.exact_max,
    );
    register_fused(
        &mut registry,
        service.clone(),
        prior.clone(),
        fusion,
        planning.planner_config(),
        planning.exact_max,
    );
    Ok(Strategies {
        registry,
        service,
        prior,
    })
}

/// Asks every probability question of the `llm+model` strategies concurrently before trials run,
/// with a progress bar, so trials answer from the cache. When an endpoint fails (after its
/// retries), the run stops with the endpoint's error, or, with `--keep-going`, goes on without the
/// strategies of `specs` that use a failed LLM: those are returned, for the caller to drop. An
/// offline miss is not an endpoint failure: the trials that need it fail and are reported.
pub fn prefetch(
    service: &Arc<LlmService>,
    llm: &LlmArgs,
    specs: &[String],
    trials: &[(&House, &ObjectType)],
) -> Result<Vec<String>> {
    let asks = |s: &String| {
        s.split('/')
            .next()
            .is_some_and(ferret_llm::asks_probabilities)
    };
    if !specs.iter().any(asks) {
        return Ok(Vec::new());
    }
    let bar = crate::common::progress(0, "LLM questions");
    let summary = prefetch_probabilities(service, specs, trials, &|done, total| {
        bar.set_length(total as u64);
        bar.set_position(done as u64);
    })?;
    bar.finish_and_clear();
    eprintln!(
        "LLM questions: {} distinct ({} cached, {} asked now, {} skipped after a failure)",
        summary.distinct, summary.cached, summary.asked, summary.skipped
    );
    let down = service.failed_llms();
    if down.is_empty() {
        for f in &summary.failures {
            eprintln!("LLM failure: {f}");
        }
        return Ok(Vec::new());
    }
    let reasons: Vec<String> = down.iter().map(|(_, why)| why.clone()).collect();
    if !llm.keep_going {
        anyhow::bail!(
            "{}\nanswers received so far are kept in the response cache; rerun to resume, or pass --keep-going to run the other strategies",
            reasons.join("\n")
        );
    }
    let dropped: Vec<String> = specs
        .iter()
        .filter(|s| {
            ferret_plan::StrategySpec::parse(s)
                .ok()
                .and_then(|spec| ferret_llm::LlmSpec::parse(&spec))
                .and_then(|p| p.ok())
                .is_some_and(|p| down.iter().any(|(name, _)| *name == p.llm))
        })
        .cloned()
        .collect();
    for r in &reasons {
        eprintln!("error: {r}");
    }
    eprintln!(
        "--keep-going: going on without {} (their LLM failed)",
        dropped.join(", ")
    );
    Ok(dropped)
}

/// Warnings for LLM strategies whose answers mostly fell back or collapsed into one value, by
/// strategy.
pub fn answer_warnings(service: &LlmService) -> Vec<(String, String)> {
    service
        .report()
        .rows
        .iter()
        .filter_map(|r| r.warning().map(|w| (r.strategy.clone(), w)))
        .collect()
}

/// Fails when `--max-fallback-share` is set and an LLM strategy's fallback share exceeds it.
pub fn check_fallback_gate(service: &LlmService, llm: &LlmArgs) -> Result<()> {
    let Some(max) = llm.max_fallback_share else {
        return Ok(());
    };
    let over: Vec<String> = service
        .report()
        .rows
        .iter()
        .filter_map(|r| {
            let share = r.answers.fallback_share()?;
            (share > max).then(|| {
                format!(
                    "{}: {:.1} % of {} answers fell back",
                    r.strategy,
                    100.0 * share,
                    r.answers.answers()
                )
            })
        })
        .collect();
    if over.is_empty() {
        Ok(())
    } else {
        anyhow::bail!(
            "fallback share above --max-fallback-share {max}:\n  {}",
            over.join("\n  ")
        )
    }
}

/// Prints the token report (paper table V) and writes `tokens.csv`, when any LLM was used.
pub fn write_token_report(service: &LlmService, dir: &Path) -> Result<()> {
    let report = service.report();
    if report.rows.is_empty() {
        return Ok(());
    }
    println!("{report}");
    let warnings = answer_warnings(service);
    for (strategy, w) in &warnings {
        eprintln!("WARNING: {strategy}: {w}");
    }
    // Also in the run's summary, beside the cost table (the paper's table V), with the answer
    // classes and a mark on every row whose answers say little.
    let summary = dir.join("summary.md");
    if summary.exists() {
        let md = ferret_world::input::read_text(&summary, ferret_world::input::MAX_INPUT_BYTES)?;
        let mut md = mark_rows(&md, &warnings);
        md.push_str(&format!("\n## LLM tokens and cost\n\n```\n{report}```\n"));
        md.push_str(&answers_markdown(&report));
        if !warnings.is_empty() {
            md.push_str("\n## Warnings\n\n");
            for (strategy, w) in &warnings {
                md.push_str(&format!("- ⚠ `{strategy}`: {w}\n"));
            }
        }
        crate::output::write_bytes(&summary, md)?;
    }
    std::fs::create_dir_all(dir)?;
    crate::output::write_atomic(&dir.join("tokens.csv"), |w| Ok(report.write_csv(w)?))?;
    Ok(())
}

/// `| strategy |` table rows of strategies with a warning get a ⚠ after the name.
fn mark_rows(md: &str, warnings: &[(String, String)]) -> String {
    md.lines()
        .map(|line| {
            match warnings
                .iter()
                .find(|(s, _)| line.starts_with(&format!("| {s} |")))
            {
                Some((s, _)) => line.replacen(&format!("| {s} |"), &format!("| {s} ⚠ |"), 1),
                None => line.to_string(),
            }
        })
        .collect::<Vec<_>>()
        .join("\n")
        + if md.ends_with('\n') { "\n" } else { "" }
}

/// How each LLM strategy's answers were read: the class of every first answer, re-asks,
/// fallbacks, log-probabilities, and the most common probability.
pub fn answers_markdown(report: &ferret_llm::TokenReport) -> String {
    use ferret_llm::AnswerClass;
    let rows: Vec<_> = report
        .rows
        .iter()
        .filter(|r| r.answers.answers() > 0)
        .collect();
    if rows.is_empty() {
        return String::new();
    }
    let mut md = String::from(
        "\n## LLM answers\n\nClass of each distinct question's first answer (P-BATCH: of each place's percentage); unusable ones (several numbers, none, the worked example echoed, no allowed word, a place left out) are asked again, then fall back to 0.01. \"logprobs missing\": read from the text although log-probabilities were wanted (P-YESNO and P-CHOICE: the word with the endpoint's `word_answer_mass`).\n\n| strategy | answers |",
    );
    for c in AnswerClass::ALL {
        md.push_str(&format!(" {} |", c.label()));
    }
    md.push_str(
        " re-asked | fell back | from logprobs | logprobs missing | most common p |\n|---|---:|",
    );
    for _ in AnswerClass::ALL {
        md.push_str("---:|");
    }
    md.push_str("---:|---:|---:|---:|---:|\n");
    for r in rows {
        let a = &r.answers;
        let mut line = format!("| {} | {} |", r.strategy, a.answers());
        for c in AnswerClass::ALL {
            line.push_str(&format!(" {} |", a.class(c)));
        }
        let common = r.most_common_probability().map_or_else(
            || "–".into(),
            |(v, share)| format!("{:.1} % ({:.0} %)", 100.0 * v, 100.0 * share),
        );
        let direct = if a.direct_answers > 0 {
            format!(" ({} P-DIRECT unmatched)", a.direct_fallbacks)
        } else {
            String::new()
        };
        line.push_str(&format!(
            " {} | {}{} | {} | {} | {} |\n",
            a.reasked,
            a.fallbacks(),
            direct,
            a.logprob_used,
            a.logprob_missing,
            common
        ));
        md.push_str(&line);
    }
    md
}
