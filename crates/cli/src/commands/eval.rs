//! `ferret eval`: one trial per house, every strategy on it; costs, summary tables and pictures.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::Result;
use ferret_lab::runs::{CELL_M, EvalRun, ReportView, RunInfo, TrialRow};
use ferret_lab::shard::{SHARD_RULE, ShardRecord};
use ferret_lab::{SpecEvaluation, TrialDraw, evaluate_specs};
use ferret_plan::{Protocol, Strategy, TrialOutcome, TrialSpec, TrialsPerHouse};
use ferret_report::{
    TrajectoryOptions, TrajectoryPanel, ViolinOptions, draw_trajectories, draw_violins,
};
use ferret_world::{Distances, Scene};

pub use crate::args::PlanningArgs;
use crate::common::{Bars, GridArgs, HouseArgs, Mapped, ProtocolArgs};
pub use ferret_lab::DEFAULT_STRATEGIES;

/// A shard's LLM cache, in its run directory unless --llm-cache says otherwise.
pub const SHARD_CACHE: &str = "llm-cache.sqlite";

/// Run every strategy on one trial per house (same target and start for all strategies) and
/// report costs: `trials.csv`, `summary.csv`, `summary.md` (the paper's table I), a violin plot of
/// costs (`costs.png`) and trajectories on one house (`trajectories.png`).
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub houses: HouseArgs,
    #[command(flatten)]
    pub grid: GridArgs,
    #[command(flatten)]
    pub planning: PlanningArgs,
    #[command(flatten)]
    pub llm: super::llm_setup::LlmArgs,
    #[command(flatten)]
    pub protocol: ProtocolArgs,
    /// Strategies, comma separated: optimistic+greedy, model/uniform, model/prior (calibrated),
    /// model/prior-raw (the uncalibrated estimate of earlier versions), model/noise (a control
    /// that knows nothing), each with /exact, /exact<N> or /k<N>, oracle (a model spec ending in
    /// /authors plans with the paper reference code's cost), fused/noise[/exact] (with
    /// --fusion: the control of every fused row), and with an LLM configuration
    /// llm+model/<prompt>/<llm>[/exact], fused/<prompt>/<llm>[/exact] (with --fusion) and
    /// llm-direct/p-direct/<llm> (prompts: p-yesno, p-choice, p-batch, p-context-a,
    /// p-context-b, p-minimal, p-direct, or a template path).
    #[arg(long, value_delimiter = ',', default_value = DEFAULT_STRATEGIES)]
    pub strategies: Vec<String>,
    /// Seed of the trials (targets drawn per house).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fraction of non-goal containers revealed as searched before each trial.
    #[arg(long, default_value_t = 0.0)]
    pub reveal_fraction: f64,
    /// Trials per house, each with a distinct target and the same for every strategy: a number,
    /// or `all` for every target type present. 1 draws one target per house as the paper does.
    #[arg(long, value_name = "N|all", default_value = "1")]
    pub trials_per_house: TrialsPerHouse,
    /// Also report costs in the paper's unit, grid cells of 0.05 m (metres / 0.05): a
    /// `cost_cells` column in trials.csv, `*_cells` columns in summary.csv and a table in cells
    /// in summary.md.
    #[arg(long)]
    pub cells: bool,
    /// More references for the paired comparisons in summary.md and paired.csv, comma
    /// separated, each one of --strategies (e.g. `model/prior`, to see what an LLM adds to the
    /// prior). Every strategy is always compared with the first one and with the best.
    #[arg(long, value_delimiter = ',', value_name = "STRATEGY")]
    pub paired_against: Vec<String>,
    /// House (index) whose trajectories are drawn; the first house when not given.
    #[arg(long)]
    pub show_house: Option<usize>,
    /// Run one shard of the houses: `i/n` runs the houses whose index in their file is i modulo
    /// n (0 ≤ i < n), `auto` reads the shard from a Slurm array task (SLURM_ARRAY_TASK_ID,
    /// SLURM_ARRAY_TASK_COUNT) or a Kubernetes Indexed Job (JOB_COMPLETION_INDEX with
    /// FERRET_SHARD_COUNT). The trials are exactly those one machine runs on these houses; give
    /// every shard its own --out, and `ferret merge` makes the one-machine run of all of them.
    /// The LLM cache defaults to <out>/llm-cache.sqlite, one per shard (SQLite is not safe on
    /// network file systems); `ferret merge` merges them too.
    #[arg(long, value_name = "i/n|auto")]
    pub shard: Option<ferret_lab::ShardSpec>,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "ferret-out")]
    pub out: PathBuf,
}

/// Runs `ferret eval`.
pub fn run(mut args: Args) -> Result<ExitCode> {
    let started = Instant::now();
    let shard = args
        .shard
        .map(|s| s.resolve(|k| std::env::var(k).ok()))
        .transpose()?;
    if shard.is_some() && args.llm.llm_cache == Path::new(ferret_llm::DEFAULT_CACHE_PATH) {
        args.llm.llm_cache = args.out.join(SHARD_CACHE);
    }
    // Every option is checked before anything is loaded or written, so a typo never replaces a
    // previous run's results.
    args.grid.validate()?;
    args.planning.validate()?;
    if !(0.0..=1.0).contains(&args.reveal_fraction) {
        anyhow::bail!(
            "--reveal-fraction {}: must be a fraction between 0 and 1",
            args.reveal_fraction
        );
    }
    crate::common::check_distinct("--strategies", &args.strategies)?;
    if let Some(s) = args
        .paired_against
        .iter()
        .find(|s| !args.strategies.contains(s))
    {
        anyhow::bail!("--paired-against {s}: not one of --strategies");
    }
    let protocol = args.protocol.resolve(Protocol::FERRET)?;
    let loaded = args.houses.load_shard(protocol.containers, shard)?;
    if let Some(sh) = shard {
        eprintln!(
            "shard {sh}: {} houses (file index mod {} = {})",
            loaded.scenes.len(),
            sh.count,
            sh.index
        );
    }
    for s in &loaded.skipped {
        eprintln!("skipped: {s}");
    }
    if loaded.scenes.is_empty() {
        match shard {
            Some(sh) => anyhow::bail!(
                "shard {sh}: no house of {} has a file index that is {} modulo {}; use fewer shards",
                loaded.source,
                sh.index,
                sh.count
            ),
            None => anyhow::bail!("no houses to evaluate in {}", loaded.source),
        }
    }
    if let Some(i) = args.show_house
        && !loaded.scenes.iter().any(|s| s.house.index == i)
    {
        anyhow::bail!(
            "--show-house {i}: no house with that index in {}",
            loaded.source
        );
    }
    let setup = super::llm_setup::full_registry(&args.planning, &args.llm, &args.strategies)?;
    let draw = TrialDraw {
        seed: args.seed,
        reveal_fraction: args.reveal_fraction,
        per_house: args.trials_per_house,
        protocol: &protocol,
        holdout: args.planning.holdout_types,
    };
    // Claimed before the evaluation, so that a second run into the same directory stops at
    // once rather than after its work, its files then replacing this one's.
    let mut out_lock = ferret_lab::files::DirLock::acquire(&args.out)?;
    let SpecEvaluation {
        maps,
        strategies,
        evaluation: outcome,
    } = evaluate_specs(
        &loaded.scenes,
        &setup,
        &args.strategies,
        &draw,
        &args.grid.params_for(protocol.access),
        &args.llm.settings(),
        &Bars::default(),
    )?;
    for e in &outcome.errors {
        eprintln!("error: {e}");
    }
    if outcome.rows.is_empty() {
        anyhow::bail!(
            "no trial finished; {} was left as it was",
            args.out.display()
        );
    }
    out_lock.used();
    let mut rows = outcome.rows.clone();
    if args.cells {
        for r in &mut rows {
            r.cost_cells = Some(r.cost_m / CELL_M);
        }
    }
    let info = RunInfo {
        houses: args.houses.houses.clone(),
        range: args.houses.range.as_ref().map(ToString::to_string),
        asset_db: args.houses.asset_db.clone(),
        generate: args.houses.generate,
        house_seed: args.houses.house_seed,
        grid: [
            args.grid.resolution,
            args.grid.robot_radius,
            args.grid.wall_thickness,
        ],
        planning: args.planning.settings(),
        seed: args.seed,
        reveal_fraction: args.reveal_fraction,
        trials_per_house: args.trials_per_house,
        protocol,
        strategies: args.strategies.clone(),
        trials_sha256: None,
        shard: shard.map(|sh| ShardRecord {
            index: sh.index,
            count: sh.count,
            rule: SHARD_RULE.into(),
            houses: loaded.scenes.iter().map(|s| s.house.index).collect(),
            houses_run: outcome.houses_run,
            trials_run: outcome.trials_run,
            failures: outcome.errors.len(),
            paired_against: args.paired_against.clone(),
            cells: args.cells,
        }),
        merged_from: Vec::new(),
    };
    let run = EvalRun::new(info, rows)?;
    let houses: Vec<usize> = loaded.scenes.iter().map(|s| s.house.index).collect();
    let report = run.report(&ReportView {
        source: &loaded.source,
        houses: &houses,
        houses_run: outcome.houses_run,
        trials_run: outcome.trials_run,
        paired_against: &args.paired_against,
        cells: args.cells,
    });
    run.write_all(&args.out, &report)?;
    let md = report.markdown;
    let pictures = draw_pictures(&args, &loaded.scenes, &maps, &strategies, &outcome.rows)?;
    println!("{md}");
    super::llm_setup::write_token_report(&setup.service, &args.out)?;
    super::llm_setup::check_fallback_gate(&setup.service, &args.llm)?;
    println!(
        "{} trials on {} houses in {:.1} s; wrote {}/{{trials.csv,summary.csv,summary.md,paired.csv,run.json{}}}",
        outcome.rows.len(),
        outcome.houses_run,
        started.elapsed().as_secs_f64(),
        args.out.display(),
        pictures.iter().map(|p| format!(",{p}")).collect::<String>()
    );
    if outcome.errors.is_empty() {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!(
            "{} trial(s) failed; every finished trial was written",
            outcome.errors.len()
        );
        Ok(ExitCode::FAILURE)
    }
}

/// Draws `costs.png` and `trajectories.png`; returns the names of the pictures drawn.
fn draw_pictures(
    args: &Args,
    scenes: &[Scene],
    maps: &[Mapped],
    strategies: &[Arc<dyn Strategy>],
    rows: &[TrialRow],
) -> Result<Vec<&'static str>> {
    let mut drawn = Vec::new();
    let series: Vec<(String, Vec<f64>)> = args
        .strategies
        .iter()
        .map(|s| {
            (
                s.clone(),
                rows.iter()
                    .filter(|r| &r.strategy == s)
                    .map(|r| r.cost_m)
                    .collect(),
            )
        })
        .filter(|(_, v): &(String, Vec<f64>)| !v.is_empty())
        .collect();
    if !series.is_empty() {
        let opts = ViolinOptions {
            title: format!("Navigation cost per strategy ({} houses)", scenes.len()),
            seed: args.seed,
            ..ViolinOptions::default()
        };
        crate::output::write_with_path(&args.out.join("costs.png"), |p| {
            Ok(draw_violins(&series, &opts, p)?)
        })?;
        drawn.push("costs.png");
    }
    // Only a house where every strategy finished its trial can show all trajectories; one whose
    // trial could not be drawn has already been reported.
    let finished = |index: usize| {
        strategies.iter().all(|s| {
            rows.iter()
                .any(|r| r.house_index == index && r.strategy == s.name())
        })
    };
    let pick = scenes.iter().zip(maps).position(|(s, m)| {
        m.is_ok() && args.show_house.is_none_or(|i| s.house.index == i) && finished(s.house.index)
    });
    match (pick, args.show_house) {
        (Some(i), _) => {
            if let Ok((_, distances)) = &maps[i] {
                crate::output::write_with_path(&args.out.join("trajectories.png"), |p| {
                    draw_house_trajectories(&scenes[i], distances, strategies, rows, p)
                })?;
                drawn.push("trajectories.png");
            }
        }
        (None, Some(i)) => eprintln!(
            "--show-house {i}: not every strategy finished a trial on that house; trajectories.png not drawn"
        ),
        (None, None) => {
            eprintln!("no house where every strategy finished; trajectories.png not drawn")
        }
    }
    Ok(drawn)
}

/// Draws every strategy's trajectory on one house side by side, from the trials already run
/// (`rows`): nothing is run again, so no LLM is asked twice.
pub fn draw_house_trajectories(
    scene: &Scene,
    distances: &Distances,
    strategies: &[Arc<dyn Strategy>],
    rows: &[TrialRow],
    out: &Path,
) -> Result<()> {
    let house = &scene.house;
    let mut panels = Vec::new();
    let mut target = None;
    // With several trials per house, the panels show the house's first trial.
    let shown = rows
        .iter()
        .find(|r| r.house_index == house.index && r.house == house.name)
        .map(|r| r.target.as_str());
    for s in strategies {
        let Some(row) = rows.iter().find(|r| {
            r.house_index == house.index
                && r.house == house.name
                && r.strategy == s.name()
                && Some(r.target.as_str()) == shown
        }) else {
            continue;
        };
        let searched: Vec<usize> = row
            .searched
            .split_whitespace()
            .filter_map(|id| house.container_index(id))
            .collect();
        let target_type = ferret_world::ObjectType::new(row.target.clone());
        let o = TrialOutcome {
            strategy: row.strategy.clone(),
            target: target_type.clone(),
            cost: row.cost_m,
            searched: searched.clone(),
            found: house.container_index(&row.found_container),
        };
        panels.push(TrajectoryPanel {
            title: s.name().to_string(),
            cost_m: o.cost,
            path: o.trajectory(distances).unwrap_or_default(),
            searched,
            goals: scene.truth.goal_containers(&target_type),
            color: None,
        });
        target = Some(target_type);
    }
    let Some(target) = target else {
        anyhow::bail!("no trial on {} to draw", house.name);
    };
    let trial = TrialSpec {
        target,
        revealed: Vec::new(),
    };
    let opts = TrajectoryOptions {
        title: Some(format!(
            "Finding a {} in {}",
            trial.target.words(),
            scene.house.name
        )),
        ..TrajectoryOptions::default()
    };
    draw_trajectories(&scene.house, &panels, &opts, out)?;
    Ok(())
}
