//! # ferret
//!
//! The command-line face of ferret: generate and check houses, draw floor plans, train priors,
//! evaluate search strategies, replay and select among them, and benchmark the planner. Each
//! subcommand lives in its own module under `commands/`; the libraries below do the work.

// The doc comments of the argument structs are the help clap prints (`[prompts]` is a TOML
// table, `<prompt>` a placeholder), not Markdown for rustdoc.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

mod args;
mod commands;
mod common;
mod output;

use clap::{Parser, Subcommand};

/// ferret: find objects in partially-known homes with LLM-informed model-based planning, and pick
/// the best prompt/LLM during deployment by offline replay.
///
/// Every command that takes houses uses generated ones (the embedded default) when given none.
#[derive(Parser, Debug)]
#[command(name = "ferret", version)]
struct Cli {
    /// More log output (-v info, -vv debug); also RUST_LOG.
    #[arg(short, long, global = true, action = clap::ArgAction::Count)]
    verbose: u8,

    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Generate houses in the ProcTHOR schema (the embedded default).
    Generate(commands::generate::Args),
    /// Check and draw houses.
    #[command(subcommand)]
    Houses(commands::houses::Command),
    /// Train a likelihood prior from houses.
    #[command(subcommand)]
    Prior(commands::prior::Command),
    /// Run every strategy on one trial per house and report costs (paper table I).
    Eval(commands::eval::Args),
    /// Score likelihood sources (uniform, prior, LLM prompts) against the ground truth: Brier,
    /// log loss, AUROC, reliability diagram.
    Calibrate(commands::calibrate::Args),
    /// Merge the run directories and LLM caches of an evaluation's shards (`eval --shard`) into
    /// the run one machine writes.
    Merge(commands::merge::Args),
    /// Replay strategies on an eval run and compare UCB with replay selection over deployments.
    Select(commands::select::Args),
    /// Run a live deployment: choose, run, replay, trial after trial.
    Deploy(commands::deploy::Args),
    /// List and ping the LLM endpoints of the configuration.
    #[command(subcommand)]
    Llm(commands::llm::Command),
    /// List prompt templates and show the exact text a prompt would send.
    #[command(subcommand)]
    Prompts(commands::prompts::Command),
    /// Check scene files (a home described for a real robot; see `ferret scene check --help`).
    #[command(subcommand)]
    Scene(commands::scene::Command),
    /// Serve the planner and strategy selection over HTTP for a real robot (docs/serve.md).
    Serve(commands::serve::Args),
    /// Measure the planner.
    #[command(subcommand)]
    Bench(commands::bench::Command),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    // A server writes to sockets whose peers may be gone (a page closed mid-stream); a write
    // to one must fail that connection, not end the process as SIGPIPE would.
    if !matches!(cli.command, Command::Serve(_) | Command::Bench(_)) {
        restore_sigpipe();
    }
    common::init_tracing(cli.verbose);
    let result = match cli.command {
        Command::Generate(args) => commands::generate::run(args),
        Command::Houses(cmd) => commands::houses::run(cmd),
        Command::Prior(cmd) => commands::prior::run(cmd),
        Command::Eval(args) => commands::eval::run(args),
        Command::Calibrate(args) => commands::calibrate::run(args),
        Command::Merge(args) => commands::merge::run(args),
        Command::Select(args) => commands::select::run(args),
        Command::Deploy(args) => commands::deploy::run(args),
        Command::Llm(cmd) => commands::llm::run(cmd),
        Command::Prompts(cmd) => commands::prompts::run(cmd),
        Command::Scene(cmd) => commands::scene::run(cmd),
        Command::Serve(args) => commands::serve::run(args),
        Command::Bench(cmd) => commands::bench::run(cmd),
    };
    match result {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {}", ferret_world::error_chain(e.as_ref()));
            if is_bad_task(&e) {
                // A task that cannot be asked is bad input, as a bad option is.
                std::process::ExitCode::from(2)
            } else {
                std::process::ExitCode::FAILURE
            }
        }
    }
}

/// Whether `e` says a household task was asked that cannot be (a target twice, a destination
/// the house does not have, ...): a usage error, as clap's are.
fn is_bad_task(e: &anyhow::Error) -> bool {
    e.chain().any(|cause| {
        cause.is::<ferret_plan::TaskError>()
            || matches!(
                cause.downcast_ref::<ferret_lab::LabError>(),
                Some(ferret_lab::LabError::Task { .. })
            )
    })
}

/// Rust ignores SIGPIPE, so `ferret houses check | head` would make every later `println!` panic
/// on the closed pipe. Restoring the default lets the process end quietly, as Unix tools do.
#[cfg(unix)]
fn restore_sigpipe() {
    // SAFETY: called in main before any other thread exists (parsing the arguments starts
    // none); SIG_DFL is a valid disposition for SIGPIPE.
    unsafe {
        libc::signal(libc::SIGPIPE, libc::SIG_DFL);
    }
}

#[cfg(not(unix))]
fn restore_sigpipe() {}
