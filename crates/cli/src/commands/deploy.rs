//! `ferret deploy`: a live sequential deployment. Each trial runs the strategy the selector
//! picks, then replays every other strategy on it, exactly as a robot would between trials.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Result, bail};
use ferret_lab::{DEFAULT_STRATEGIES, DeploySettings, Strategies, deploy};
use ferret_plan::{DrawMode, Protocol, Strategy, TrialsPerHouse};
use ferret_select::{DeploymentLoop, Method, ORACLE};
use ferret_world::ObjectType;
use serde::Serialize;

use super::llm_setup::LlmArgs;
use crate::args::PlanningArgs;
use crate::common::{Bars, GridArgs, HouseArgs, ProtocolArgs};
use crate::output::write_csv;

/// Run a deployment: N trials in distinct houses (random order), choosing a strategy before each
/// trial with UCB or replay selection, replaying the others after it. Writes DIR/deploy.csv.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    houses: HouseArgs,
    #[command(flatten)]
    grid: GridArgs,
    #[command(flatten)]
    planning: PlanningArgs,
    #[command(flatten)]
    llm: LlmArgs,
    #[command(flatten)]
    protocol: ProtocolArgs,
    /// Candidate strategies, comma separated (the oracle is never a candidate); for tasks,
    /// sequential/<spec> looks for one target after another with the planner of <spec>. With a
    /// --prior trained with --embeddings: model/learned (and model/learned-head,
    /// model/learned-random, model/learned-head-random), and with --fusion
    /// fused-learned/<prompt>/<llm> and fused-learned/noise.
    #[arg(long, value_delimiter = ',', default_value = DEFAULT_STRATEGIES)]
    strategies: Vec<String>,
    /// Number of trials [default: 20, or the number of types to --find].
    #[arg(long)]
    trials: Option<usize>,
    /// Selection method: `replay` or `ucb`.
    #[arg(long, default_value = "replay")]
    method: Method,
    /// Exploration constant c, metres.
    #[arg(long, default_value_t = ferret_select::DEFAULT_C)]
    c: f64,
    /// Targets drawn per house (a number or `all`); each trial of the deployment runs one of
    /// them, picked at random, in a house of its own. 1 is the paper's draw.
    #[arg(long, value_name = "N|all", default_value = "1")]
    trials_per_house: TrialsPerHouse,
    /// What to find, in order, comma separated (e.g. `Blanket,CellPhone`): trial k looks for
    /// the k-th in house k (cycling through the houses in file order), as a robot in one home
    /// would. `--trials` defaults to their number. Without it, houses are shuffled and targets
    /// drawn. Each may be a household task: `Mug+Apple` (both), `Mug|Cup` (either), with
    /// `@start`, `@room:<id>` or `@container:<id>` to bring them there (e.g.
    /// `Mug+Apple@start`).
    #[arg(long, value_delimiter = ',', value_name = "TASKS")]
    find: Vec<ferret_lab::TaskText>,
    #[command(flatten)]
    tasks: crate::args::TaskArgs,
    /// Seed of the house order and targets, and of the selector's tie breaks (its own stream,
    /// as in `ferret serve`).
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "ferret-out/deploy")]
    out: PathBuf,
}

#[derive(Serialize)]
struct DeployRow {
    k: usize,
    house: String,
    target: String,
    chosen: String,
    cost_m: f64,
    found_container: String,
    average_cost_m: f64,
    /// Replay costs of every candidate on this trial, `name=metres` separated by spaces.
    replays: String,
}

/// Runs `ferret deploy`.
pub fn run(args: Args) -> Result<ExitCode> {
    args.grid.validate()?;
    args.planning.validate()?;
    crate::common::check_distinct("--strategies", &args.strategies)?;
    let protocol = args.protocol.resolve(Protocol::FERRET)?;
    let trials = args.trials.unwrap_or(if args.find.is_empty() {
        20
    } else {
        args.find.len()
    });
    if trials == 0 {
        bail!("--trials 0: a deployment needs at least one trial");
    }
    if !args.find.is_empty() && trials > args.find.len() {
        bail!(
            "--trials {trials} but only {} types to --find: give one per trial",
            args.find.len()
        );
    }
    if !(args.c.is_finite() && args.c >= 0.0) {
        bail!("--c {}: must be a finite number ≥ 0 m", args.c);
    }
    let loaded = args.houses.load()?;
    for s in &loaded.skipped {
        eprintln!("skipped: {s}");
    }
    // Claimed before the work, so that a second run into the same directory stops at once.
    let mut out_lock = ferret_lab::files::DirLock::acquire(&args.out)?;
    let setup = Strategies::builder(&args.planning.settings(), &args.llm.settings())
        .for_specs(&args.strategies)
        .build()?;
    let candidates: Vec<Arc<dyn Strategy>> = args
        .strategies
        .iter()
        .filter(|s| s.as_str() != ORACLE)
        .map(|s| setup.registry.build(s))
        .collect::<Result<_, _>>()?;
    if candidates.len() < 2 {
        bail!("a deployment needs at least two candidate strategies");
    }
    let given_targets = !args.find.is_empty();
    if !given_targets && protocol.draw == DrawMode::Distinct && trials > loaded.scenes.len() {
        bail!(
            "{} trials need {} distinct houses; {} has {}",
            trials,
            trials,
            loaded.source,
            loaded.scenes.len()
        );
    }
    let names: Vec<String> = candidates.iter().map(|s| s.name().to_string()).collect();
    let mut deployment = DeploymentLoop::new(
        args.method,
        candidates,
        args.c,
        args.seed,
        (protocol.replay, protocol.travel_cost),
    )?;
    // A type no house holds could only end "not found" after every container of every house.
    let held: std::collections::BTreeSet<ObjectType> = loaded
        .scenes
        .iter()
        .flat_map(|s| s.truth.target_types())
        .collect();
    let find: Vec<ferret_lab::TaskText> = args
        .find
        .iter()
        .map(|task| {
            let targets = task
                .targets
                .iter()
                .map(|t| {
                    ferret_world::check_target(t.trim(), &held)
                        .map(|t| t.to_string())
                        .map_err(|e| anyhow::anyhow!("--find: {e} (in {})", loaded.source))
                })
                .collect::<Result<_>>()?;
            Ok(ferret_lab::TaskText {
                targets,
                ..task.clone()
            })
        })
        .collect::<Result<_>>()?;
    let tasks = args.tasks.tasks();
    let grid = args.grid.params_for(protocol.access);
    let settings = DeploySettings {
        trials,
        find: &find,
        tasks: tasks.as_ref(),
        per_house: args.trials_per_house,
        seed: args.seed,
        protocol: &protocol,
        grid: &grid,
    };
    let mut rows = Vec::new();
    let mut total = 0.0;
    println!(
        "{:>3}  {:<36} {:<16} {:<34} {:>8} {:>9}",
        "k", "house", "target", "chosen", "cost m", "avg m"
    );
    let scenes = &loaded.scenes;
    deploy(
        scenes,
        &mut deployment,
        &settings,
        &Bars::default(),
        &mut |t| {
            let scene = &scenes[t.house];
            total += t.step.cost;
            let row = DeployRow {
                k: t.k,
                house: scene.house.name.clone(),
                target: t.task.targets_label(),
                chosen: names[t.step.chosen].clone(),
                cost_m: t.step.cost,
                found_container: scene.house.containers[t.step.found].id.clone(),
                average_cost_m: total / t.k as f64,
                replays: names
                    .iter()
                    .zip(&t.step.replays)
                    .map(|(s, r)| format!("{s}={r:.2}"))
                    .collect::<Vec<_>>()
                    .join(" "),
            };
            println!(
                "{:>3}  {:<36} {:<16} {:<34} {:>8.2} {:>9.2}",
                row.k, row.house, row.target, row.chosen, row.cost_m, row.average_cost_m
            );
            rows.push(row);
        },
    )?;
    out_lock.used();
    std::fs::create_dir_all(&args.out)?;
    write_csv(&args.out.join("deploy.csv"), &rows)?;
    super::llm_setup::write_token_report(&setup.service, &args.out)?;
    println!("wrote {}", args.out.join("deploy.csv").display());
    Ok(ExitCode::SUCCESS)
}
