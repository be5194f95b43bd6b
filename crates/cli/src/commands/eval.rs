//! `ferret eval`: one trial per house, every strategy on it; costs, summary tables and pictures.

use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use anyhow::Result;
use ferret_lab::{CostTable, EvalJob, ShownHouse, TrialRow};
use ferret_plan::{Destination, Goal, Protocol, Task, TrialOutcome, TrialsPerHouse};
use ferret_report::{
    TrajectoryOptions, TrajectoryPanel, ViolinOptions, draw_trajectories, draw_violins,
};
use ferret_world::{Distances, Scene};

pub use crate::args::PlanningArgs;
use crate::common::{Bars, GridArgs, HouseArgs, ProtocolArgs};
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
    #[command(flatten)]
    pub tasks: crate::args::TaskArgs,
    #[command(flatten)]
    pub team: crate::args::TeamArgs,
    /// Strategies, comma separated: optimistic+greedy, model/uniform, model/prior (calibrated),
    /// model/prior-raw (the uncalibrated estimate of earlier versions), model/noise (a control
    /// that knows nothing), each with /exact, /exact<N> or /k<N>, oracle (a model spec ending in
    /// /authors plans with the paper reference code's cost), fused/noise[/exact] (with
    /// --fusion: the control of every fused row), and with an LLM configuration
    /// llm+model/<prompt>/<llm>[/exact], fused/<prompt>/<llm>[/exact] (with --fusion) and
    /// llm-direct/p-direct/<llm> (prompts: p-yesno, p-choice, p-batch, p-context-a,
    /// p-context-b, p-minimal, p-direct, or a template path); with --task, also
    /// sequential/<spec> (the planner of <spec> looking for one target after another); with
    /// --robots, independent/<spec> (each robot blind to the others) and split/<spec> (the
    /// rooms divided among the robots), a plain spec coordinating its robots. With a prior
    /// trained with --embeddings (see docs/learned.md): model/learned, model/learned-head and
    /// their controls model/learned-random and model/learned-head-random, and with --fusion
    /// fused-learned/<prompt>/<llm> and fused-learned/noise.
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
    /// House (index) whose trajectories are drawn; the first house when not given. Shards draw
    /// no pictures: they record it for `ferret merge`, which draws them.
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
    let protocol = args.protocol.resolve(Protocol::FERRET)?;
    let tasks = args.tasks.tasks();
    let (source, planning, llm) = (
        args.houses.source(),
        args.planning.settings(),
        args.llm.settings(),
    );
    let done = EvalJob {
        source: &source,
        grid: args.grid.params(),
        planning: &planning,
        llm: &llm,
        specs: &args.strategies,
        seed: args.seed,
        reveal_fraction: args.reveal_fraction,
        trials_per_house: args.trials_per_house,
        tasks: tasks.as_ref(),
        team: args.team.team(),
        protocol: &protocol,
        cells: args.cells,
        paired_against: &args.paired_against,
        show_house: args.show_house,
        shard,
        out: &args.out,
    }
    .run(&Bars::default())?;
    let names: Vec<String> = done
        .totals
        .strategies
        .iter()
        .map(|s| s.name().to_string())
        .collect();
    let pictures = if shard.is_some() {
        Vec::new()
    } else {
        draw_pictures(
            &Pictures {
                team: args.team.team(),
                out: &args.out,
                strategies: &args.strategies,
                ran: &names,
                houses: done.totals.houses.len(),
                seed: args.seed,
            },
            &done.written.costs,
            done.shown.as_ref(),
        )?
    };
    if shard.is_none() && done.shown.is_none() {
        no_trajectories(args.show_house);
    }
    println!("{}", done.written.report.markdown);
    super::llm_setup::write_token_report(&done.setup.service, &args.out)?;
    super::llm_setup::check_fallback_gate(&done.setup.service, &args.llm)?;
    println!(
        "{} trials on {} houses in {:.1} s; wrote {}/{{trials.csv,summary.csv,summary.md{},run.json{}}}",
        done.rows,
        done.totals.houses_run,
        started.elapsed().as_secs_f64(),
        args.out.display(),
        if shard.is_some() { "" } else { ",paired.csv" },
        pictures.iter().map(|p| format!(",{p}")).collect::<String>()
    );
    let failed = done.totals.errors.len();
    if failed == 0 {
        Ok(ExitCode::SUCCESS)
    } else {
        eprintln!("{failed} trial(s) failed; every finished trial was written");
        Ok(ExitCode::FAILURE)
    }
}

/// What the pictures of a run need besides its costs and the shown house.
pub struct Pictures<'a> {
    /// The run directory.
    pub out: &'a Path,
    /// The strategies asked for, in order (the violins').
    pub strategies: &'a [String],
    /// The strategies that ran (the trajectory panels').
    pub ran: &'a [String],
    /// Houses evaluated (the violin plot's title).
    pub houses: usize,
    /// The trial seed (the violins' jitter, and a team's starts).
    pub seed: u64,
    /// The team of every trial, in a run of teams.
    pub team: Option<ferret_plan::TeamSettings>,
}

/// Says why trajectories.png was not drawn: no house where every strategy finished (or not
/// the `--show-house` one). A house whose trial could not be drawn has already been reported.
pub fn no_trajectories(show_house: Option<usize>) {
    match show_house {
        Some(i) => eprintln!(
            "--show-house {i}: not every strategy finished a trial on that house; trajectories.png not drawn"
        ),
        None => eprintln!("no house where every strategy finished; trajectories.png not drawn"),
    }
}

/// Draws `costs.png` and `trajectories.png` (of `shown`, when there is one); returns the names
/// of the pictures drawn. `ferret eval` and `ferret merge` draw through here, so a merged run's pictures are
/// one machine's.
pub fn draw_pictures(
    p: &Pictures<'_>,
    costs: &CostTable,
    shown: Option<&ShownHouse>,
) -> Result<Vec<&'static str>> {
    let mut drawn = Vec::new();
    let series: Vec<(String, Vec<f64>)> = p
        .strategies
        .iter()
        .map(|s| (s.clone(), costs.costs_of(s)))
        .filter(|(_, v): &(String, Vec<f64>)| !v.is_empty())
        .collect();
    if !series.is_empty() {
        let opts = ViolinOptions {
            title: format!("Navigation cost per strategy ({} houses)", p.houses),
            seed: p.seed,
            ..ViolinOptions::default()
        };
        crate::output::write_with_path(&p.out.join("costs.png"), |path| {
            Ok(draw_violins(&series, &opts, path)?)
        })?;
        drawn.push("costs.png");
    }
    if let Some(h) = shown {
        crate::output::write_with_path(&p.out.join("trajectories.png"), |path| {
            let team = p.team.map(|t| (t, p.seed));
            draw_house_trajectories(&h.scene, &h.distances, p.ran, &h.rows, team, path)
        })?;
        drawn.push("trajectories.png");
    }
    Ok(drawn)
}

/// Draws every strategy's trajectory on one house side by side, from the trials already run
/// (`rows`): nothing is run again, so no LLM is asked twice. A task's panels mark the
/// containers holding each target and the destination, and its route ends there. A team's
/// panels (`team`: the run's team and seed) draw each robot's way in its own colour.
pub fn draw_house_trajectories(
    scene: &Scene,
    distances: &Distances,
    strategies: &[String],
    rows: &[TrialRow],
    team: Option<(ferret_plan::TeamSettings, u64)>,
    out: &Path,
) -> Result<()> {
    let house = &scene.house;
    // With several trials per house, the panels show the house's first trial.
    let Some(shown) = rows
        .iter()
        .find(|r| r.house_index == house.index && r.house == house.name)
    else {
        anyhow::bail!("no trial on {} to draw", house.name);
    };
    let task = ferret_lab::task_of_row(shown, house)?;
    let legs = task
        .destination()
        .map(|d| d.legs(house, distances))
        .transpose()?;
    // Every container holding a target, and which of them.
    let holds = |c: usize| -> Vec<String> {
        task.targets()
            .iter()
            .filter(|t| scene.truth.holds(c, t))
            .map(|t| t.words())
            .collect()
    };
    let goals: Vec<usize> = (0..house.containers.len())
        .filter(|&c| !holds(c).is_empty())
        .collect();
    let goal_labels: Vec<String> = if task.targets().len() > 1 {
        goals.iter().map(|&c| holds(c).join(", ")).collect()
    } else {
        Vec::new()
    };
    let mut panels = Vec::new();
    for s in strategies {
        let Some(row) = rows.iter().find(|r| {
            r.house_index == house.index
                && r.house == house.name
                && &r.strategy == s
                && r.target == shown.target
        }) else {
            continue;
        };
        let searched: Vec<usize> = row
            .searched
            .split_whitespace()
            .filter_map(|id| house.container_index(id))
            .collect();
        let o = TrialOutcome {
            strategy: row.strategy.clone(),
            task: task.clone(),
            cost: row.cost_m,
            searched: searched.clone(),
            found: house.container_index(&row.found_container),
            found_each: Vec::new(),
            delivery: row.delivery_m.unwrap_or(0.0),
            delivered_to: legs.as_ref().and_then(|l| l.place()),
        };
        let (path, team_paths, searched_by) = match team {
            Some((t, seed)) => {
                let mut paths = ferret_lab::team_paths(scene, distances, t, seed, row)?;
                let first = if paths.is_empty() {
                    Vec::new()
                } else {
                    paths.remove(0)
                };
                let by = row
                    .searched_by
                    .as_deref()
                    .unwrap_or_default()
                    .split_whitespace()
                    .filter_map(|r| r.parse().ok())
                    .collect();
                (first, paths, by)
            }
            None => (
                o.trajectory(distances, legs.as_ref()).unwrap_or_default(),
                Vec::new(),
                Vec::new(),
            ),
        };
        panels.push(TrajectoryPanel {
            title: match team {
                Some((t, _)) => format!("{s} ({} robots)", t.robots),
                None => s.clone(),
            },
            cost_m: o.cost,
            path,
            searched,
            goals: goals.clone(),
            goal_labels: goal_labels.clone(),
            destination: legs.as_ref().and_then(|l| l.point(distances)),
            color: None,
            team_paths,
            searched_by,
        });
    }
    let what = task_words(&task);
    let opts = TrajectoryOptions {
        title: Some(match task.destination() {
            Some(d) => format!(
                "Bringing {what} to {} in {}",
                destination_words(d, house),
                scene.house.name
            ),
            None => format!("Finding {what} in {}", scene.house.name),
        }),
        ..TrajectoryOptions::default()
    };
    draw_trajectories(&scene.house, &panels, &opts, out)?;
    Ok(())
}

/// "a mug", "a mug and an apple", "a mug or a cup".
fn task_words(task: &Task) -> String {
    let words: Vec<String> = task
        .targets()
        .iter()
        .map(|t| {
            let w = t.words();
            let article = if w.starts_with(['a', 'e', 'i', 'o', 'u']) {
                "an"
            } else {
                "a"
            };
            format!("{article} {w}")
        })
        .collect();
    let join = match task.goal() {
        Goal::All => " and ",
        Goal::Any => " or ",
    };
    match words.split_last() {
        Some((last, rest)) if !rest.is_empty() => format!("{}{join}{last}", rest.join(", ")),
        _ => words.join(""),
    }
}

/// "the start", "the kitchen", "the sofa", "(1.5, 2.0)".
fn destination_words(d: &Destination, house: &ferret_world::House) -> String {
    match d {
        Destination::Start => "the start".into(),
        Destination::Container { index } => house.containers.get(*index).map_or_else(
            || "a container".into(),
            |c| format!("the {}", c.object_type.words()),
        ),
        Destination::Room { index } => house.rooms.get(*index).map_or_else(
            || "a room".into(),
            |r| format!("the {}", r.room_type.words()),
        ),
        Destination::Point { x, z } => format!("({x:.1}, {z:.1})"),
    }
}
