//! `ferret llm list` and `ferret llm ping NAME`: the configured LLM endpoints, and one tiny live
//! request to check that an endpoint answers.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use ferret_llm::{ChatMessage, EndpointClient, LlmConfig};

/// LLM endpoints.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// List the endpoints of the config: model, URL, whether the API key is set, limits, prices.
    List(ListArgs),
    /// Send one tiny request to an endpoint (never from the cache) and print latency and reply.
    Ping(PingArgs),
}

/// `ferret llm list`.
#[derive(clap::Args, Debug)]
pub struct ListArgs {
    /// Endpoint configuration (TOML); `ferret.toml` in the working directory when present.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
}

/// `ferret llm ping NAME`.
#[derive(clap::Args, Debug)]
pub struct PingArgs {
    /// The endpoint's name in the config.
    pub name: String,
    /// Endpoint configuration (TOML); `ferret.toml` in the working directory when present.
    #[arg(long, value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// What to ask.
    #[arg(long, default_value = "Reply with the single word: pong")]
    pub message: String,
    /// Seconds to wait for the answer (or the endpoint's own timeout, if shorter). One attempt:
    /// a check, not a run, so a server that accepts and never answers is reported quickly.
    #[arg(long, value_name = "SECS", default_value_t = 30.0)]
    pub timeout: f64,
}

/// Runs `ferret llm ...`.
pub fn run(cmd: Command) -> Result<ExitCode> {
    match cmd {
        Command::List(args) => list(&args),
        Command::Ping(args) => ping(&args),
    }
}

fn load(config: Option<&std::path::Path>) -> Result<LlmConfig> {
    let c = LlmConfig::load_default(config)?;
    if c.endpoints.is_empty() {
        anyhow::bail!(
            "no LLM endpoints configured: pass --config FILE or create ferret.toml with [llm.<name>] tables (see ferret.example.toml)"
        );
    }
    Ok(c)
}

fn list(args: &ListArgs) -> Result<ExitCode> {
    let config = load(args.config.as_deref())?;
    println!("endpoints in {}:", config.file.display());
    println!(
        "{:<18} {:<26} {:<56} {:<28} {:>5} {:>8} {:>9} {:>9}",
        "name", "model", "base_url", "api key", "conc.", "timeout", "$/M in", "$/M out"
    );
    for name in config.endpoints.keys() {
        let endpoint = config.endpoint(name)?;
        let c = &endpoint.config;
        // Only the variable's name and whether it is set: never the key.
        let key = match &c.api_key_env {
            None => "none".to_string(),
            Some(var) if endpoint.has_key() => format!("${var} (set)"),
            Some(var) => format!("${var} (NOT SET)"),
        };
        println!(
            "{:<18} {:<26} {:<56} {:<28} {:>5} {:>7}s {:>9.3} {:>9.3}",
            name,
            c.model,
            c.normalized_base_url(),
            key,
            c.concurrency,
            c.timeout_secs,
            c.price_input_per_mtok,
            c.price_output_per_mtok
        );
    }
    for (name, path) in &config.prompts {
        println!("prompt {name}: {}", path.display());
    }
    Ok(ExitCode::SUCCESS)
}

fn ping(args: &PingArgs) -> Result<ExitCode> {
    let config = load(args.config.as_deref())?;
    let endpoint = config.endpoint(&args.name)?;
    let cost_of = endpoint.config.clone();
    let client = EndpointClient::new(endpoint)?;
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .context("starting the async runtime")?;
    if !(args.timeout.is_finite() && args.timeout > 0.0 && args.timeout <= 86_400.0) {
        anyhow::bail!(
            "--timeout {}: must be a number of seconds in (0, 86400]",
            args.timeout
        );
    }
    let started = Instant::now();
    let reply = rt.block_on(client.complete_once(
        &ferret_llm::Request::plain(vec![ChatMessage::user(args.message.clone())]),
        std::time::Duration::from_secs_f64(args.timeout),
    ))?;
    let total = started.elapsed();
    let u = reply.usage;
    println!(
        "{} ({}) answered in {:.0} ms",
        args.name,
        cost_of.model,
        reply.latency.as_secs_f64() * 1000.0
    );
    if reply.attempts > 1 {
        println!(
            "after {} attempts, {:.0} ms in all",
            reply.attempts,
            total.as_secs_f64() * 1000.0
        );
    }
    // The model's text may hold terminal escape sequences.
    println!("reply: {}", ferret_llm::printable(reply.text.trim()));
    println!(
        "tokens: {} in{}, {} out; cost ${:.6}",
        u.prompt_tokens,
        u.cached_tokens
            .map(|c| format!(" ({c} cached)"))
            .unwrap_or_default(),
        u.completion_tokens,
        cost_of.cost_usd(
            u.prompt_tokens,
            u.cached_tokens.unwrap_or(0),
            u.completion_tokens
        )
    );
    Ok(ExitCode::SUCCESS)
}
