//! `ferret eval`: one trial per house, every strategy on it; costs, summary tables and pictures.

use std::collections::{BTreeMap, HashMap};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use ferret_plan::{
    CandidateLimit, PlannerConfig, Prior, Protocol, SearchProblem, Strategy, StrategyRegistry,
    TrialOutcome, TrialSpec, TrialsPerHouse, draw_trials_with, run_trial,
};
use ferret_report::{
    TrajectoryOptions, TrajectoryPanel, ViolinOptions, draw_trajectories, draw_violins,
};
use ferret_world::{Distances, Scene};
use indicatif::ParallelProgressIterator;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::common::{GridArgs, HouseArgs, Mapped, ProtocolArgs, build_maps, progress};

/// The strategies evaluated when none are named.
pub const DEFAULT_STRATEGIES: &str =
    "optimistic+greedy,model/uniform,model/prior,model/prior/exact,oracle";

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
    /// Strategies, comma separated: optimistic+greedy, model/uniform, model/prior,
    /// model/prior/exact, model/prior/k<N>, oracle (a model spec ending in /authors plans with the
    /// paper reference code's cost), and with an LLM configuration
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
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "ferret-out")]
    pub out: PathBuf,
}

/// Planner and prior options shared by `eval`, `select` and `deploy`.
#[derive(clap::Args, Clone, Debug, Serialize, Deserialize)]
pub struct PlanningArgs {
    /// A prior from `ferret prior train`. Without it, model/prior uses a prior trained on 500
    /// generated houses (seed 1000003, never the evaluation houses).
    #[arg(long, value_name = "FILE")]
    pub prior: Option<PathBuf>,
    /// Containers the planner considers per decision in model strategies without a limit suffix:
    /// the 2 nearest plus the most likely, as in the paper (K = 8).
    #[arg(long, value_name = "K", default_value_t = 8)]
    pub max_containers: usize,
    /// Largest exact problem for `/exact` strategies, at most 22 (2^n·n memory: 16 → 8 MB,
    /// 20 → 160 MB).
    #[arg(long, value_name = "N", default_value_t = 16)]
    pub exact_max: usize,
    /// Search cost R per container, metres (0 in the paper).
    #[arg(long, value_name = "M", default_value_t = 0.0)]
    pub search_cost: f64,
}

impl PlanningArgs {
    /// Refuses unusable planner options, naming the option, before any output is touched.
    pub fn validate(&self) -> Result<()> {
        if !(self.search_cost.is_finite() && self.search_cost >= 0.0) {
            anyhow::bail!(
                "--search-cost {}: must be a finite number ≥ 0 m",
                self.search_cost
            );
        }
        if self.max_containers == 0 {
            anyhow::bail!("--max-containers 0: the planner needs at least one container");
        }
        let max = ferret_plan::planner::MAX_EXACT;
        if !(1..=max).contains(&self.exact_max) {
            anyhow::bail!(
                "--exact-max {}: must be between 1 and {max}",
                self.exact_max
            );
        }
        Ok(())
    }

    /// The prior these arguments name, or the default one.
    pub fn prior(&self) -> Result<Prior> {
        match &self.prior {
            Some(p) => Ok(Prior::load(p)?),
            None => super::prior::default_prior(500, 1_000_003),
        }
    }

    /// The planner settings of model strategies without a limit suffix.
    pub fn planner_config(&self) -> PlannerConfig {
        PlannerConfig {
            search_cost: self.search_cost,
            limit: CandidateLimit::Paper {
                k: self.max_containers.max(1),
            },
            cost: ferret_plan::CostModel::Paper,
        }
    }

    /// The prior, when one of `specs` plans over it (`model/prior...`, `fused/...`): loaded, or
    /// the default one trained. `None` when none does.
    pub fn prior_for(&self, specs: &[String]) -> Result<Option<Arc<Prior>>> {
        let needs_prior = specs
            .iter()
            .any(|s| s.starts_with("model/prior") || s.starts_with("fused/"));
        Ok(if needs_prior {
            Some(Arc::new(self.prior()?))
        } else {
            None
        })
    }

    /// The registry of built-in strategies under these settings over `prior`.
    pub fn registry_with(&self, prior: Option<Arc<Prior>>) -> StrategyRegistry {
        StrategyRegistry::builtin(prior, self.planner_config(), self.exact_max)
    }
}

/// One row of `trials.csv`.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct TrialRow {
    /// House label.
    pub house: String,
    /// House index in its file.
    pub house_index: usize,
    /// Target object type.
    pub target: String,
    /// Strategy spec.
    pub strategy: String,
    /// Distance travelled, metres.
    pub cost_m: f64,
    /// Containers searched.
    pub searches: usize,
    /// Whether the target was found.
    pub found: bool,
    /// Id of the container where it was found.
    pub found_container: String,
    /// Ids of the containers searched, in order, space separated.
    pub searched: String,
    /// Number of containers holding the target.
    pub goal_containers: usize,
    /// Distance travelled in the paper's 0.05 m grid cells, with `--cells` only (absent
    /// otherwise, so the default file is as before).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub cost_cells: Option<f64>,
}

/// The paper's unit of cost: a grid cell of 0.05 m (its table I is in these cells).
pub const CELL_M: f64 = 0.05;

/// What `select` needs to rebuild the houses and strategies of an eval run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunInfo {
    /// `--houses`.
    pub houses: Option<PathBuf>,
    /// `--range`.
    pub range: Option<String>,
    /// `--asset-db`.
    pub asset_db: Option<PathBuf>,
    /// `--generate`.
    pub generate: usize,
    /// `--house-seed`.
    pub house_seed: u64,
    /// Grid resolution, robot radius, wall thickness.
    pub grid: [f64; 3],
    /// Planner settings.
    pub planning: PlanningArgs,
    /// Trial seed.
    pub seed: u64,
    /// Reveal fraction.
    pub reveal_fraction: f64,
    /// Trials per house; left out of run.json when 1, so single-trial runs read as before.
    #[serde(default, skip_serializing_if = "is_one_per_house")]
    pub trials_per_house: TrialsPerHouse,
    /// The protocol; left out of run.json when it is ferret's, so default runs read as before.
    #[serde(default, skip_serializing_if = "is_ferret_protocol")]
    pub protocol: Protocol,
    /// Strategies in order.
    pub strategies: Vec<String>,
    /// SHA-256 of the trials.csv written with this file, so that a trials.csv of another run
    /// beside it (an eval stopped between the two) is recognised.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trials_sha256: Option<String>,
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    format!("{:x}", Sha256::digest(bytes))
}

fn is_ferret_protocol(p: &Protocol) -> bool {
    *p == Protocol::FERRET
}

fn is_one_per_house(t: &TrialsPerHouse) -> bool {
    *t == TrialsPerHouse::One
}

impl RunInfo {
    /// House arguments that load the same houses.
    pub fn house_args(&self) -> HouseArgs {
        HouseArgs {
            houses: self.houses.clone(),
            range: self.range.as_ref().and_then(|r| r.parse().ok()),
            asset_db: self.asset_db.clone(),
            skip_invalid: true,
            generate: self.generate,
            house_seed: self.house_seed,
        }
    }

    /// Grid arguments that build the same maps.
    pub fn grid_args(&self) -> GridArgs {
        GridArgs {
            resolution: self.grid[0],
            robot_radius: self.grid[1],
            wall_thickness: self.grid[2],
        }
    }
}

/// Per-strategy statistics for `summary.csv`.
#[derive(Clone, Debug, Serialize)]
pub struct SummaryRow {
    /// Strategy spec.
    pub strategy: String,
    /// Trials run.
    pub trials: usize,
    /// Mean cost, metres.
    pub mean_m: f64,
    /// Median cost, metres.
    pub median_m: f64,
    /// Half-width of the 95 % confidence interval of the mean (normal approximation).
    pub ci95_m: f64,
    /// Improvement of the mean over optimistic+greedy, percent (positive = cheaper), on the
    /// paired trials only.
    pub improvement_pct: Option<f64>,
    /// Trials in the comparison with optimistic+greedy: the houses where every summarized
    /// strategy finished, so that a strategy is never credited for skipping hard houses.
    pub paired_trials: usize,
    /// Mean cost in 0.05 m cells (`--cells` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_cells: Option<f64>,
    /// Median cost in 0.05 m cells (`--cells` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub median_cells: Option<f64>,
    /// Half-width of the 95 % interval in 0.05 m cells (`--cells` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ci95_cells: Option<f64>,
}

impl SummaryRow {
    /// Fills in the costs in 0.05 m cells.
    pub fn with_cells(self) -> Self {
        Self {
            mean_cells: Some(self.mean_m / CELL_M),
            median_cells: Some(self.median_m / CELL_M),
            ci95_cells: Some(self.ci95_m / CELL_M),
            ..self
        }
    }
}

/// Each strategy's mean cost as the reference code averages its table: 500 runs of 100 houses
/// drawn with replacement by numpy's legacy generator (`seed(s)`, shuffle, `choice`) from the
/// houses in file order, i.e. a mean weighted by how often each house is drawn. Houses a
/// strategy has no trial on are left out of its weights. `(strategy, metres)` in `order`.
pub fn reference_means(
    rows: &[TrialRow],
    order: &[String],
    houses: &[usize],
) -> Vec<(String, f64)> {
    let counts = ferret_select::numpy::reference_draw_counts(houses.len(), 500, 100);
    let weight: HashMap<usize, f64> = houses
        .iter()
        .zip(&counts)
        .map(|(&h, &c)| (h, c as f64))
        .collect();
    order
        .iter()
        .filter_map(|s| {
            let (sum, total) = rows
                .iter()
                .filter(|r| &r.strategy == s)
                .filter_map(|r| weight.get(&r.house_index).map(|w| (w * r.cost_m, *w)))
                .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            (total > 0.0).then(|| (s.clone(), sum / total))
        })
        .collect()
}

/// [`reference_means`] as Markdown, in metres and cells.
fn reference_means_markdown(means: &[(String, f64)]) -> String {
    let mut md = String::from(
        "\n## As the reference code averages\n\nEach mean weighted by how often 500 seeded runs of 100 draws with replacement (numpy's legacy generator, as the reference's results script) pick each house.\n\n| strategy | mean cost (m) | mean cost (cells) |\n|---|---:|---:|\n",
    );
    for (s, m) in means {
        md.push_str(&format!("| {s} | {m:.2} | {:.1} |\n", m / CELL_M));
    }
    md
}

/// The summary in 0.05 m cells as Markdown: the paper's unit, for comparison with its table I.
pub fn cells_markdown(summary: &[SummaryRow]) -> String {
    let mut md = String::from(
        "\n## In the paper's unit\n\nThe same costs in grid cells of 0.05 m (metres / 0.05), the unit of the paper's table I.\n\n| strategy | trials | mean cost (cells) | 95 % CI | median (cells) |\n|---|---:|---:|---:|---:|\n",
    );
    for r in summary {
        md.push_str(&format!(
            "| {} | {} | {:.1} | ±{:.1} | {:.1} |\n",
            r.strategy,
            r.trials,
            r.mean_m / CELL_M,
            r.ci95_m / CELL_M,
            r.median_m / CELL_M
        ));
    }
    md
}

/// Runs `ferret eval`.
pub fn run(args: Args) -> Result<ExitCode> {
    let started = Instant::now();
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
    let loaded = args.houses.load_for(protocol.containers)?;
    for s in &loaded.skipped {
        eprintln!("skipped: {s}");
    }
    if loaded.scenes.is_empty() {
        anyhow::bail!("no houses to evaluate in {}", loaded.source);
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
    let strategies: Vec<Arc<dyn Strategy>> = args
        .strategies
        .iter()
        .map(|s| setup.registry.build(s))
        .collect::<Result<_, _>>()?;
    let maps = build_maps(&loaded.scenes, &args.grid.params_for(protocol.access));
    let targets: Vec<(&ferret_world::House, ferret_world::ObjectType)> = loaded
        .scenes
        .iter()
        .zip(&maps)
        .filter(|(_, m)| m.is_ok())
        .flat_map(|(s, _)| {
            draw_trials_with(
                &s.house,
                &s.truth,
                args.seed,
                args.reveal_fraction,
                args.trials_per_house,
                &protocol,
            )
            .unwrap_or_default()
            .into_iter()
            .map(|t| (&s.house, t.target))
        })
        .collect();
    let pairs: Vec<(&ferret_world::House, &ferret_world::ObjectType)> =
        targets.iter().map(|(h, t)| (*h, t)).collect();
    let dropped = super::llm_setup::prefetch(&setup.service, &args.llm, &args.strategies, &pairs)?;
    let strategies: Vec<Arc<dyn Strategy>> = strategies
        .into_iter()
        .filter(|s| !dropped.iter().any(|d| d == s.name()))
        .collect();
    let outcome = evaluate(
        &loaded.scenes,
        &maps,
        &strategies,
        args.seed,
        args.reveal_fraction,
        args.trials_per_house,
        &protocol,
    );
    for e in &outcome.errors {
        eprintln!("error: {e}");
    }
    if outcome.rows.is_empty() {
        anyhow::bail!(
            "no trial finished; {} was left as it was",
            args.out.display()
        );
    }
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let mut rows = outcome.rows.clone();
    if args.cells {
        for r in &mut rows {
            r.cost_cells = Some(r.cost_m / CELL_M);
        }
    }
    let trials_csv = crate::output::csv_bytes(&rows)?;
    crate::output::write_bytes(&args.out.join("trials.csv"), &trials_csv)?;
    let mut summary = summarize(&outcome.rows, &args.strategies);
    if args.cells {
        summary = summary.into_iter().map(SummaryRow::with_cells).collect();
    }
    write_csv(&args.out.join("summary.csv"), &summary)?;
    let paired = paired_comparisons(
        &outcome.rows,
        &args.strategies,
        &args.paired_against,
        args.seed,
    );
    write_csv(&args.out.join("paired.csv"), &paired)?;
    let md = summary_markdown(
        &summary,
        &loaded.source,
        outcome.houses_run,
        args.trials_per_house,
        outcome.trials_run,
    ) + &if args.cells {
        cells_markdown(&summary)
    } else {
        String::new()
    } + &if protocol.rng == ferret_plan::TrialRng::Python
        && args.trials_per_house == TrialsPerHouse::One
    {
        let houses: Vec<usize> = loaded.scenes.iter().map(|s| s.house.index).collect();
        reference_means_markdown(&reference_means(&outcome.rows, &args.strategies, &houses))
    } else {
        String::new()
    } + &paired_markdown(&paired);
    crate::output::write_bytes(&args.out.join("summary.md"), &md)?;
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
        planning: args.planning.clone(),
        seed: args.seed,
        reveal_fraction: args.reveal_fraction,
        trials_per_house: args.trials_per_house,
        protocol,
        strategies: args.strategies.clone(),
        trials_sha256: Some(sha256_hex(&trials_csv)),
    };
    crate::output::write_bytes(
        &args.out.join("run.json"),
        serde_json::to_string_pretty(&info)?,
    )?;
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

/// Rows and errors of an evaluation.
pub struct Evaluation {
    /// One row per house × strategy that finished.
    pub rows: Vec<TrialRow>,
    /// One message per house or trial that failed.
    pub errors: Vec<String>,
    /// Houses with a map and a target.
    pub houses_run: usize,
    /// Trials (house and target) drawn on those houses.
    pub trials_run: usize,
}

/// Runs every strategy on the trials of every house (`per_house` of them), in parallel over
/// houses.
pub fn evaluate(
    scenes: &[Scene],
    maps: &[Mapped],
    strategies: &[Arc<dyn Strategy>],
    seed: u64,
    reveal_fraction: f64,
    per_house: TrialsPerHouse,
    protocol: &Protocol,
) -> Evaluation {
    let bar = progress(scenes.len(), "trials");
    let by_house: Vec<(Vec<TrialRow>, Vec<String>, usize)> = scenes
        .par_iter()
        .zip(maps.par_iter())
        .progress_with(bar.clone())
        .map(|(scene, map)| {
            let (_, distances) = match map {
                Ok(m) => m,
                Err(e) => return (vec![], vec![e.to_string()], 0),
            };
            let trials = match draw_trials_with(
                &scene.house,
                &scene.truth,
                seed,
                reveal_fraction,
                per_house,
                protocol,
            ) {
                Ok(t) => t,
                Err(e) => return (vec![], vec![e.to_string()], 0),
            };
            let mut rows = Vec::new();
            let mut errors = Vec::new();
            for trial in &trials {
                for s in strategies {
                    let run = run_trial(
                        s.as_ref(),
                        &SearchProblem::new(&scene.house, distances, trial),
                        &scene.truth,
                    )
                    .and_then(|out| {
                        let cost =
                            out.reported_cost(&scene.house, distances, protocol.travel_cost)?;
                        Ok(TrialOutcome { cost, ..out })
                    });
                    match run {
                        Ok(out) => rows.push(row(scene, trial, &out)),
                        // The target is named only when a house has several trials, so that
                        // single-trial messages read as before.
                        Err(e) if trials.len() > 1 => errors.push(format!(
                            "{}: {}: {}: {e}",
                            scene.house.name,
                            trial.target,
                            s.name()
                        )),
                        Err(e) => errors.push(format!("{}: {}: {e}", scene.house.name, s.name())),
                    }
                }
            }
            (rows, errors, trials.len())
        })
        .collect();
    bar.finish_and_clear();
    let mut ev = Evaluation {
        rows: vec![],
        errors: vec![],
        houses_run: 0,
        trials_run: 0,
    };
    for (rows, errors, trials) in by_house {
        ev.rows.extend(rows);
        ev.errors.extend(errors);
        ev.houses_run += usize::from(trials > 0);
        ev.trials_run += trials;
    }
    ev
}

fn row(scene: &Scene, trial: &TrialSpec, out: &TrialOutcome) -> TrialRow {
    let house = &scene.house;
    let id = |c: usize| {
        house
            .containers
            .get(c)
            .map_or_else(|| c.to_string(), |x| x.id.clone())
    };
    TrialRow {
        house: house.name.clone(),
        house_index: house.index,
        target: trial.target.to_string(),
        strategy: out.strategy.clone(),
        cost_m: out.cost,
        searches: out.searched.len(),
        found: out.found.is_some(),
        found_container: out.found.map(id).unwrap_or_default(),
        searched: out
            .searched
            .iter()
            .map(|&c| id(c))
            .collect::<Vec<_>>()
            .join(" "),
        goal_containers: scene.truth.goal_containers(&trial.target).len(),
        cost_cells: None,
    }
}

pub use crate::output::write_csv;

/// A trial's identity across strategies: house index and target. Two strategies' rows with the
/// same key ran the same trial, so their costs pair.
pub type TrialKey<'a> = (usize, &'a str);

/// Each strategy's cost per trial.
fn costs_by_trial(rows: &[TrialRow]) -> BTreeMap<&str, BTreeMap<TrialKey<'_>, f64>> {
    let mut by: BTreeMap<&str, BTreeMap<TrialKey<'_>, f64>> = BTreeMap::new();
    for r in rows {
        by.entry(r.strategy.as_str())
            .or_default()
            .insert((r.house_index, r.target.as_str()), r.cost_m);
    }
    by
}

/// Mean, median, 95 % CI and improvement over optimistic+greedy, per strategy in `order`. The
/// improvement compares means over the paired trials only: the trials (house and target) that
/// every strategy of `order` that finished any trial finished.
pub fn summarize(rows: &[TrialRow], order: &[String]) -> Vec<SummaryRow> {
    let mut by: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    let by_house = costs_by_trial(rows);
    for r in rows {
        by.entry(r.strategy.as_str()).or_default().push(r.cost_m);
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let compared: Vec<&BTreeMap<TrialKey<'_>, f64>> = order
        .iter()
        .filter_map(|s| by_house.get(s.as_str()))
        .collect();
    let paired: Vec<TrialKey<'_>> = compared
        .first()
        .map(|first| {
            first
                .keys()
                .copied()
                .filter(|h| compared.iter().all(|m| m.contains_key(h)))
                .collect()
        })
        .unwrap_or_default();
    let paired_mean = |s: &str| {
        let m = by_house.get(s)?;
        let v: Vec<f64> = paired.iter().filter_map(|h| m.get(h).copied()).collect();
        (!v.is_empty()).then(|| mean(&v))
    };
    let greedy = paired_mean("optimistic+greedy");
    order
        .iter()
        .filter_map(|s| by.get(s.as_str()).map(|v| (s, v)))
        .map(|(s, v)| {
            let m = mean(v);
            let mut sorted = v.clone();
            sorted.sort_by(f64::total_cmp);
            let n = sorted.len();
            let median = if n % 2 == 1 {
                sorted[n / 2]
            } else {
                (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
            };
            let var = if n > 1 {
                v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1) as f64
            } else {
                0.0
            };
            SummaryRow {
                strategy: s.clone(),
                trials: n,
                mean_m: m,
                median_m: median,
                ci95_m: 1.96 * (var / n as f64).sqrt(),
                improvement_pct: greedy
                    .filter(|g| *g > 0.0)
                    .zip(paired_mean(s))
                    .map(|(g, m)| 100.0 * (g - m) / g),
                paired_trials: paired.len(),
                mean_cells: None,
                median_cells: None,
                ci95_cells: None,
            }
        })
        .collect()
}

/// Bootstrap resamples of the paired confidence intervals: enough that the interval's ends move
/// by less than a hundredth of a metre between seeds on 150 trials.
pub const PAIRED_RESAMPLES: usize = 10_000;

/// One row of `paired.csv`: a strategy against a reference on the trials both finished.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairedRow {
    /// The strategy compared against.
    pub reference: String,
    /// Why it is the reference: `first` (the first strategy named), `best` (the lowest mean
    /// on the paired trials, the oracle excepted) or `named` (given with `--paired-against`).
    pub role: &'static str,
    /// The strategy.
    pub strategy: String,
    /// Trials (house and target) both finished.
    pub pairs: usize,
    /// Mean of cost(strategy) − cost(reference), metres; negative = the strategy is cheaper.
    pub mean_diff_m: f64,
    /// Lower end of the 95 % bootstrap interval of the mean difference, metres.
    pub ci95_low_m: f64,
    /// Upper end of that interval, metres.
    pub ci95_high_m: f64,
    /// Two-sided Wilcoxon signed-rank p-value; empty when every pair ties.
    pub wilcoxon_p: Option<f64>,
    /// Trials where the strategy is cheaper.
    pub wins: usize,
    /// Trials within a nanometre.
    pub ties: usize,
    /// Trials where the strategy costs more.
    pub losses: usize,
}

/// Every strategy of `order` against the first one, and against the best (lowest mean over the
/// trials every strategy finished; the oracle is a bound, never the best) when that is another
/// strategy, then against each of `named` that is neither. Pairs are the trials (house and
/// target) both strategies of a comparison finished. `seed` seeds the bootstrap, so the table is
/// reproducible.
pub fn paired_comparisons(
    rows: &[TrialRow],
    order: &[String],
    named: &[String],
    seed: u64,
) -> Vec<PairedRow> {
    let by = costs_by_trial(rows);
    let present: Vec<&str> = order
        .iter()
        .map(String::as_str)
        .filter(|s| by.contains_key(s))
        .collect();
    let Some(&first) = present.first() else {
        return Vec::new();
    };
    let common: Vec<TrialKey<'_>> = by[first]
        .keys()
        .copied()
        .filter(|k| present.iter().all(|s| by[s].contains_key(k)))
        .collect();
    let best = present
        .iter()
        .copied()
        .filter(|s| *s != "oracle" && !common.is_empty())
        .map(|s| (s, common.iter().map(|k| by[s][k]).sum::<f64>()))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(s, _)| s);
    let mut references = vec![(first, "first")];
    if let Some(b) = best.filter(|b| *b != first) {
        references.push((b, "best"));
    }
    for n in named {
        if let Some(&n) = present.iter().find(|s| **s == n.as_str())
            && !references.iter().any(|(r, _)| *r == n)
        {
            references.push((n, "named"));
        }
    }
    let mut out = Vec::new();
    for (reference, role) in references {
        for &s in present.iter().filter(|s| **s != reference) {
            let keys: Vec<&TrialKey<'_>> = by[s]
                .keys()
                .filter(|k| by[reference].contains_key(*k))
                .collect();
            let a: Vec<f64> = keys.iter().map(|k| by[s][*k]).collect();
            let b: Vec<f64> = keys.iter().map(|k| by[reference][*k]).collect();
            let Some(c) = ferret_report::paired::compare_paired(&a, &b, PAIRED_RESAMPLES, seed)
            else {
                continue;
            };
            out.push(PairedRow {
                reference: reference.to_string(),
                role,
                strategy: s.to_string(),
                pairs: c.n,
                mean_diff_m: c.mean_diff,
                ci95_low_m: c.ci95.0,
                ci95_high_m: c.ci95.1,
                wilcoxon_p: c.wilcoxon.map(|w| w.p),
                wins: c.wins,
                ties: c.ties,
                losses: c.losses,
            });
        }
    }
    out
}

/// A p-value as people read it: three decimals, two significant digits below 0.001, and
/// `< 1e-6` below that.
fn format_p(p: Option<f64>) -> String {
    match p {
        None => "–".into(),
        Some(p) if p < 1e-6 => "< 1e-6".into(),
        Some(p) if p < 0.001 => format!("{p:.1e}"),
        Some(p) => format!("{p:.3}"),
    }
}

/// The paired comparisons as Markdown, one table per reference; empty without comparisons.
pub fn paired_markdown(paired: &[PairedRow]) -> String {
    if paired.is_empty() {
        return String::new();
    }
    let mut md = format!(
        "\n## Paired comparisons\n\nPairs are the trials (house and target) both strategies finished. Difference = strategy − reference, metres (negative: the strategy is cheaper); 95 % CI of its mean by bootstrap ({PAIRED_RESAMPLES} resamples); p from the two-sided Wilcoxon signed-rank test; wins / ties / losses count the trials where the strategy is cheaper / equal / dearer.\n"
    );
    let mut current: Option<(&str, &str)> = None;
    for r in paired {
        if current != Some((r.reference.as_str(), r.role)) {
            current = Some((r.reference.as_str(), r.role));
            let why = match r.role {
                "first" => "the first strategy",
                "best" => "the lowest mean, oracle excepted",
                _ => "named with --paired-against",
            };
            md.push_str(&format!(
                "\nAgainst {} ({why}):\n\n| strategy | pairs | mean difference (m) | 95 % CI (m) | Wilcoxon p | wins / ties / losses |\n|---|---:|---:|---:|---:|---:|\n",
                r.reference
            ));
        }
        md.push_str(&format!(
            "| {} | {} | {:+.2} | [{:+.2}, {:+.2}] | {} | {} / {} / {} |\n",
            r.strategy,
            r.pairs,
            r.mean_diff_m,
            r.ci95_low_m,
            r.ci95_high_m,
            format_p(r.wilcoxon_p),
            r.wins,
            r.ties,
            r.losses
        ));
    }
    md
}

/// The paper's table I as Markdown; `trials` trials were drawn on `houses` houses.
pub fn summary_markdown(
    summary: &[SummaryRow],
    source: &str,
    houses: usize,
    per_house: TrialsPerHouse,
    trials: usize,
) -> String {
    let drawn = match per_house {
        TrialsPerHouse::One => "one trial per house".to_string(),
        TrialsPerHouse::Count(n) => {
            format!("{trials} trials, up to {n} distinct targets per house")
        }
        TrialsPerHouse::All => format!("{trials} trials, every target type of each house"),
    };
    let mut md = format!(
        "# Navigation cost per strategy\n\n{houses} houses from {source}; {drawn}, the same for every strategy.\n\n"
    );
    md.push_str(
        "| strategy | trials | mean cost (m) | 95 % CI | median (m) | cost vs optimistic+greedy |\n",
    );
    md.push_str("|---|---:|---:|---:|---:|---:|\n");
    for r in summary {
        let imp = r
            .improvement_pct
            // Shown as a change of cost, so that lower reads as better (−52.8 % = 52.8 % cheaper);
            // `0.0 - p` keeps the reference's own row at +0.0 rather than −0.0.
            .map_or_else(|| "–".to_string(), |p| format!("{:+.1} %", 0.0 - p));
        md.push_str(&format!(
            "| {} | {} | {:.2} | ±{:.2} | {:.2} | {} |\n",
            r.strategy, r.trials, r.mean_m, r.ci95_m, r.median_m, imp
        ));
    }
    let short: Vec<String> = summary
        .iter()
        .filter(|r| r.trials < trials)
        .map(|r| format!("{} finished {} of {trials}", r.strategy, r.trials))
        .collect();
    if !short.is_empty() {
        md.push_str(&format!(
            "\n**Failed trials:** {}. Means and medians cover each strategy's own trials; \"cost vs optimistic+greedy\" compares only the {} paired trials (houses where every strategy finished).\n",
            short.join("; "),
            summary.first().map_or(0, |r| r.paired_trials)
        ));
    }
    md
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

#[cfg(test)]
mod tests {
    use super::*;

    fn trial(house_index: usize, strategy: &str, cost_m: f64) -> TrialRow {
        TrialRow {
            house: format!("h#{house_index}"),
            house_index,
            target: "Apple".into(),
            strategy: strategy.into(),
            cost_m,
            searches: 1,
            found: true,
            found_container: "1|0".into(),
            searched: "1|0".into(),
            goal_containers: 1,
            cost_cells: None,
        }
    }

    #[test]
    fn reference_means_weight_houses_by_the_reference_draws() {
        // Houses 10, 11, 12 in file order; strategy b lacks house 12.
        let rows = vec![
            trial(10, "a", 1.0),
            trial(11, "a", 2.0),
            trial(12, "a", 4.0),
            trial(10, "b", 3.0),
            trial(11, "b", 3.0),
        ];
        let order = vec!["a".to_string(), "b".to_string(), "c".to_string()];
        let means = reference_means(&rows, &order, &[10, 11, 12]);
        let w = ferret_select::numpy::reference_draw_counts(3, 500, 100);
        let w: Vec<f64> = w.into_iter().map(|c| c as f64).collect();
        assert_eq!(means.len(), 2, "no rows, no mean for c");
        let a = (w[0] + 2.0 * w[1] + 4.0 * w[2]) / (w[0] + w[1] + w[2]);
        assert!((means[0].1 - a).abs() < 1e-12);
        // Unequal weights: the weighted mean is not the plain one.
        assert!((a - 7.0 / 3.0).abs() > 1e-6);
        assert!((means[1].1 - 3.0).abs() < 1e-12);
    }

    #[test]
    fn the_summary_table_shows_a_cheaper_strategy_as_a_lower_cost() {
        let order = vec!["optimistic+greedy".to_string(), "model/x".to_string()];
        let rows = vec![
            trial(0, "optimistic+greedy", 10.0),
            trial(0, "model/x", 4.0),
        ];
        let summary = summarize(&rows, &order);
        assert!((summary[1].improvement_pct.unwrap_or_default() - 60.0).abs() < 1e-9);
        let md = summary_markdown(&summary, "test", 1, TrialsPerHouse::One, 1);
        assert!(
            md.contains("| model/x | 1 | 4.00 | ±0.00 | 4.00 | -60.0 % |"),
            "{md}"
        );
        assert!(
            md.contains("| optimistic+greedy | 1 | 10.00 | ±0.00 | 10.00 | +0.0 % |"),
            "{md}"
        );
    }

    #[test]
    fn strategies_with_failed_trials_are_compared_on_paired_trials_only() {
        let order = vec!["optimistic+greedy".to_string(), "model/x".to_string()];
        // Greedy finished all four houses; model/x failed on house 3, the most expensive one.
        let mut rows: Vec<TrialRow> = [10.0, 20.0, 30.0, 100.0]
            .iter()
            .enumerate()
            .map(|(h, &c)| trial(h, "optimistic+greedy", c))
            .collect();
        rows.extend(
            [9.0, 18.0, 27.0]
                .iter()
                .enumerate()
                .map(|(h, &c)| trial(h, "model/x", c)),
        );
        let summary = summarize(&rows, &order);
        assert_eq!(summary[0].trials, 4);
        assert_eq!(summary[1].trials, 3);
        assert!((summary[0].mean_m - 40.0).abs() < 1e-12);
        assert!((summary[1].mean_m - 18.0).abs() < 1e-12);
        // Over the three paired houses greedy averages 20 m, model/x 18 m: 10 % cheaper, not the
        // 55 % that comparing 18 m with greedy's 40 m over all four houses would claim.
        assert!((summary[1].improvement_pct.unwrap() - 10.0).abs() < 1e-9);
        assert!(summary[0].improvement_pct.unwrap().abs() < 1e-9);
        assert_eq!(summary[1].paired_trials, 3);
        let md = summary_markdown(&summary, "test houses", 4, TrialsPerHouse::One, 4);
        // In cells: 18 m is 360 cells of 0.05 m.
        let cells = cells_markdown(&summary);
        assert!(cells.contains("| model/x | 3 | 360.0 | ±"), "{cells}");
        let with = summary[1].clone().with_cells();
        assert!((with.median_cells.unwrap() - 360.0).abs() < 1e-9);
        assert!((with.ci95_cells.unwrap() - with.ci95_m * 20.0).abs() < 1e-9);
        assert!(md.contains("model/x finished 3 of 4"), "{md}");
        assert!(md.contains("only the 3 paired trials"), "{md}");
        assert!(!md.contains("optimistic+greedy finished"), "{md}");
        // Complete runs carry no note.
        let complete = summarize(&rows[..4], &order[..1]);
        assert!(
            !summary_markdown(&complete, "test houses", 4, TrialsPerHouse::One, 4)
                .contains("Failed trials")
        );
    }

    #[test]
    fn paired_comparisons_pair_by_house_and_target_against_first_and_best() {
        let order: Vec<String> = ["optimistic+greedy", "model/x", "model/y", "oracle"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let mut rows = Vec::new();
        // Two targets in each of three houses; model/x saves 2 m on every trial, model/y 1 m on
        // all but one (a tie), the oracle 5 m. model/x also has a trial no other strategy ran.
        for h in 0..3 {
            for (t, target) in ["Apple", "Book"].iter().enumerate() {
                let g = 10.0 + 3.0 * h as f64 + t as f64;
                let mut push = |s: &str, c: f64| {
                    let mut r = trial(h, s, c);
                    r.target = target.to_string();
                    rows.push(r);
                };
                push("optimistic+greedy", g);
                push("model/x", g - 2.0);
                push("model/y", if h == 0 && t == 0 { g } else { g - 1.0 });
                push("oracle", g - 5.0);
            }
        }
        let mut extra = trial(9, "model/x", 1.0);
        extra.target = "Cup".into();
        rows.push(extra);
        let paired = paired_comparisons(&rows, &order, &[], 0);
        // Against greedy: x, y, oracle; against the best (model/x): greedy, y, oracle.
        assert_eq!(paired.len(), 6);
        let x = &paired[0];
        assert_eq!(
            (x.role, x.strategy.as_str(), x.pairs),
            ("first", "model/x", 6)
        );
        assert!((x.mean_diff_m + 2.0).abs() < 1e-12);
        assert!((x.ci95_low_m + 2.0).abs() < 1e-12 && (x.ci95_high_m + 2.0).abs() < 1e-12);
        assert_eq!((x.wins, x.ties, x.losses), (6, 0, 0));
        // Six equal differences tie in rank: the normal approximation, z = (0 − 10.5 + 0.5)/√(22.75
        // − 210/48) = −2.33285 → p = 0.0196562 (Python: math.erfc(2.33285 / math.sqrt(2))).
        assert!(
            (x.wilcoxon_p.unwrap() - 0.019_656_157).abs() < 1e-8,
            "{:?}",
            x.wilcoxon_p
        );
        let y = &paired[1];
        assert_eq!((y.wins, y.ties, y.losses), (5, 1, 0));
        assert!((y.mean_diff_m + 5.0 / 6.0).abs() < 1e-12);
        assert_eq!(paired[3].role, "best");
        assert_eq!(paired[3].reference, "model/x");
        assert_eq!(paired[3].strategy, "optimistic+greedy");
        assert!((paired[3].mean_diff_m - 2.0).abs() < 1e-12);
        assert_eq!(paired[5].strategy, "oracle");
        let md = paired_markdown(&paired);
        assert!(
            md.contains("Against optimistic+greedy (the first strategy)"),
            "{md}"
        );
        assert!(
            md.contains("Against model/x (the lowest mean, oracle excepted)"),
            "{md}"
        );
        assert!(md.contains("| model/y | 6 | -0.83 | [-1.00, "), "{md}");
        assert!(
            md.contains("| optimistic+greedy | 6 | +2.00 | [+2.00, +2.00] | 0.020 | 0 / 0 / 6 |"),
            "{md}"
        );
        assert!(md.contains("| 5 / 1 / 0 |"), "{md}");
        // The same seed gives the same table.
        assert_eq!(
            paired_markdown(&paired_comparisons(&rows, &order, &[], 0)),
            md
        );
        // A named reference adds its own table; the first, the best and strategies that ran no
        // trial add nothing twice.
        let named: Vec<String> = ["model/y", "model/x", "optimistic+greedy", "model/z"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let with = paired_comparisons(&rows, &order, &named, 0);
        assert_eq!(with.len(), 9);
        assert_eq!(&with[..6], &paired[..]);
        let y: Vec<(&str, &str, &str)> = with[6..]
            .iter()
            .map(|r| (r.role, r.reference.as_str(), r.strategy.as_str()))
            .collect();
        assert_eq!(
            y,
            [
                ("named", "model/y", "optimistic+greedy"),
                ("named", "model/y", "model/x"),
                ("named", "model/y", "oracle")
            ]
        );
        assert!((with[7].mean_diff_m + 7.0 / 6.0).abs() < 1e-12);
        assert!(
            paired_markdown(&with).contains("Against model/y (named with --paired-against)"),
            "{}",
            paired_markdown(&with)
        );
    }
}
