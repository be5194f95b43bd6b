//! `ferret deploy`: a live sequential deployment. Each trial runs the strategy the selector
//! picks, then replays every other strategy on it, exactly as a robot would between trials.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;

use anyhow::{Result, bail};
use ferret_plan::{
    DrawMode, Protocol, Strategy, TrialSpec, TrialsPerHouse, draw_trials_with, replay_costs,
    run_trial,
};
use ferret_select::{LiveDeployment, Method, ORACLE};
use ferret_world::ObjectType;
use rand::seq::SliceRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::Serialize;

use super::eval::{DEFAULT_STRATEGIES, PlanningArgs, write_csv};
use super::llm_setup::{LlmArgs, full_registry};
use crate::common::{GridArgs, HouseArgs, ProtocolArgs};

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
    /// Candidate strategies, comma separated (the oracle is never a candidate).
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
    /// Object types to find, in order, comma separated (e.g. `Blanket,CellPhone`): trial k looks
    /// for the k-th in house k (cycling through the houses in file order), as a robot in one home
    /// would. `--trials` defaults to their number. Without it, houses are shuffled and targets
    /// drawn.
    #[arg(long, value_delimiter = ',', value_name = "TYPES")]
    find: Vec<String>,
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
    let setup = full_registry(&args.planning, &args.llm, &args.strategies)?;
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
    let mut rng = ChaCha8Rng::seed_from_u64(args.seed);
    let order: Vec<usize> = if given_targets {
        (0..trials).map(|k| k % loaded.scenes.len()).collect()
    } else {
        match protocol.draw {
            DrawMode::Distinct => {
                let mut order: Vec<usize> = (0..loaded.scenes.len()).collect();
                order.shuffle(&mut rng);
                order
            }
            DrawMode::Replacement => (0..trials)
                .map(|_| rng.random_range(0..loaded.scenes.len()))
                .collect(),
        }
    };
    let mut deployment = LiveDeployment::new(args.method, candidates.len(), args.c, args.seed)?;
    let params = args.grid.params_for(protocol.access);
    let mut rows = Vec::new();
    let mut total = 0.0;
    println!(
        "{:>3}  {:<36} {:<16} {:<34} {:>8} {:>9}",
        "k", "house", "target", "chosen", "cost m", "avg m"
    );
    for (k, &h) in order.iter().take(trials).enumerate() {
        let scene = &loaded.scenes[h];
        let (_, distances) = match ferret_world::distance::build(&scene.house, &params) {
            Ok(m) => m,
            Err(e) => {
                eprintln!("skipping {}: {e}", scene.house.name);
                continue;
            }
        };
        let trial = if given_targets {
            let target = ObjectType::new(args.find[k].trim());
            if scene.truth.goal_containers(&target).is_empty() {
                bail!(
                    "{}: no container holds {target}, so trial {} cannot end",
                    scene.house.name,
                    k + 1
                );
            }
            TrialSpec {
                target,
                revealed: Vec::new(),
            }
        } else {
            let mut drawn = draw_trials_with(
                &scene.house,
                &scene.truth,
                args.seed,
                0.0,
                args.trials_per_house,
                &protocol,
            )?;
            // One trial is the paper's draw; the generator is touched only when there is a
            // choice, so single-target deployments are as before.
            let pick = match args.trials_per_house {
                TrialsPerHouse::One => 0,
                _ => rng.random_range(0..drawn.len()),
            };
            drawn.swap_remove(pick)
        };
        let i = deployment.choose();
        let outcome = run_trial(
            candidates[i].as_ref(),
            &scene.house,
            &scene.truth,
            &distances,
            &trial,
        )?;
        // The selector learns from the cost the protocol reports (soft under the reference's
        // rules); the strategies themselves planned on plain distances either way.
        let cost = outcome.reported_cost(&scene.house, &distances, protocol.travel_cost)?;
        let Some(found) = outcome.found else {
            bail!(
                "{}: the target {} was not found",
                scene.house.name,
                trial.target
            );
        };
        let replays = replay_costs(
            protocol.replay,
            protocol.travel_cost,
            &candidates,
            i,
            cost,
            &scene.house,
            &scene.truth,
            &distances,
            &trial,
            found,
        )?;
        deployment.finish(cost, &replays)?;
        total += cost;
        let row = DeployRow {
            k: k + 1,
            house: scene.house.name.clone(),
            target: trial.target.to_string(),
            chosen: candidates[i].name().to_string(),
            cost_m: cost,
            found_container: scene.house.containers[found].id.clone(),
            average_cost_m: total / (k + 1) as f64,
            replays: candidates
                .iter()
                .zip(&replays)
                .map(|(s, r)| format!("{}={r:.2}", s.name()))
                .collect::<Vec<_>>()
                .join(" "),
        };
        println!(
            "{:>3}  {:<36} {:<16} {:<34} {:>8.2} {:>9.2}",
            row.k, row.house, row.target, row.chosen, row.cost_m, row.average_cost_m
        );
        rows.push(row);
    }
    std::fs::create_dir_all(&args.out)?;
    write_csv(&args.out.join("deploy.csv"), &rows)?;
    super::llm_setup::write_token_report(&setup.service, &args.out)?;
    println!("wrote {}", args.out.join("deploy.csv").display());
    Ok(ExitCode::SUCCESS)
}
