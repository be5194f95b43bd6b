//! `ferret calibrate`: how good are a likelihood source's probabilities? Every (house, target,
//! container) of the houses is a pair (P_S, whether the container holds the target); each source
//! gets a Brier score, log loss, AUROC and a reliability diagram.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use ferret_plan::{Calibration, LikelihoodSource, draw_trial};
use ferret_world::{House, ObjectType, Scene};
use indicatif::ParallelProgressIterator;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::Serialize;

use crate::common::{HouseArgs, progress};

/// The sources scored when none are named.
pub const DEFAULT_SOURCES: &str = "model/uniform,model/prior";

/// Score likelihood sources against the ground truth: for every house, every target type present
/// (or `--targets-per-house N` of them) and every container, compare P_S(target, container) with
/// whether the container holds the target. Writes `calibration.csv`, `calibration.md` and a
/// reliability diagram (`reliability.png`, `reliability.svg`). LLM questions go through the same
/// response cache as `eval`, each asked at most once.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    pub houses: HouseArgs,
    #[command(flatten)]
    pub planning: super::eval::PlanningArgs,
    #[command(flatten)]
    pub llm: super::llm_setup::LlmArgs,
    /// Likelihood sources as strategy specs, comma separated: model/uniform, model/prior, and
    /// llm+model/<prompt>/<llm> (any planner suffix is ignored: only the probabilities count).
    #[arg(long, value_delimiter = ',', default_value = DEFAULT_SOURCES)]
    pub sources: Vec<String>,
    /// Targets per house: `all` (every small-object type present) or a number N. With N, the
    /// first is the target `eval --seed` draws, so an eval with the same seed reuses its answers.
    #[arg(long, value_name = "N|all", default_value = "all", value_parser = parse_targets)]
    pub targets_per_house: TargetCount,
    /// Seed of the target choice (with `--targets-per-house N`).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Bins of the reliability diagram.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u16).range(1..=100))]
    pub bins: u16,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "ferret-calibration")]
    pub out: PathBuf,
}

/// How many targets per house.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TargetCount {
    /// Every target type present.
    All,
    /// At most this many.
    N(usize),
}

fn parse_targets(s: &str) -> std::result::Result<TargetCount, String> {
    if s.eq_ignore_ascii_case("all") {
        return Ok(TargetCount::All);
    }
    match s.parse::<usize>() {
        Ok(0) | Err(_) => Err(format!("`{s}` is neither `all` nor a positive number")),
        Ok(n) => Ok(TargetCount::N(n)),
    }
}

/// One row of `calibration.csv`.
#[derive(Clone, Debug, Serialize)]
pub struct CalibrationRow {
    /// The source's spec.
    pub source: String,
    /// (house, target, container) pairs.
    pub pairs: u64,
    /// Pairs whose container holds the target.
    pub positives: u64,
    /// Brier score.
    pub brier: f64,
    /// Log loss.
    pub log_loss: f64,
    /// AUROC (empty without both classes).
    pub auroc: Option<f64>,
    /// Mean P_S of holders.
    pub mean_p_pos: Option<f64>,
    /// Mean P_S of non-holders.
    pub mean_p_neg: Option<f64>,
}

/// The targets scored in one house: with `N`, the eval's target first, then others in a seeded
/// order.
pub fn targets_for(scene: &Scene, count: TargetCount, seed: u64) -> Vec<ObjectType> {
    let all: Vec<ObjectType> = scene.truth.target_types().into_iter().collect();
    match count {
        TargetCount::All => all,
        TargetCount::N(n) => {
            let first = draw_trial(&scene.house, &scene.truth, seed, 0.0)
                .ok()
                .map(|t| t.target);
            let mut rest: Vec<ObjectType> = all
                .into_iter()
                .filter(|t| Some(t) != first.as_ref())
                .collect();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                seed ^ (scene.house.index as u64).wrapping_mul(0x2545_F491_4F6C_DD1D),
            );
            rest.shuffle(&mut rng);
            first.into_iter().chain(rest).take(n).collect()
        }
    }
}

/// Runs `ferret calibrate`.
pub fn run(args: Args) -> Result<ExitCode> {
    let started = Instant::now();
    let loaded = args.houses.load()?;
    for s in &loaded.skipped {
        eprintln!("skipped: {s}");
    }
    if loaded.scenes.is_empty() {
        anyhow::bail!("no houses to score in {}", loaded.source);
    }
    if args.sources.is_empty() {
        anyhow::bail!("--sources names no source");
    }
    let setup = super::llm_setup::full_registry(&args.planning, &args.llm, &args.sources)?;
    let mut sources: Vec<(String, Arc<dyn LikelihoodSource>)> = Vec::new();
    for spec in &args.sources {
        let strategy = setup.registry.build(spec)?;
        let source = strategy.likelihood_source().cloned().with_context(|| {
            format!("{spec} plans over no likelihood source (use model/... or llm+model/...)")
        })?;
        sources.push((spec.clone(), source));
    }
    let trials: Vec<(&House, ObjectType, &Scene)> = loaded
        .scenes
        .iter()
        .flat_map(|s| {
            targets_for(s, args.targets_per_house, args.seed)
                .into_iter()
                .map(move |t| (&s.house, t, s))
        })
        .collect();
    if trials.is_empty() {
        anyhow::bail!("no house in {} holds a target object", loaded.source);
    }
    let pairs: Vec<(&House, &ObjectType)> = trials.iter().map(|(h, t, _)| (*h, t)).collect();
    let dropped = super::llm_setup::prefetch(&setup.service, &args.llm, &args.sources, &pairs)?;
    sources.retain(|(spec, _)| !dropped.contains(spec));

    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    let mut rows = Vec::new();
    let mut scored = Vec::new();
    let mut errors = Vec::new();
    for (spec, source) in &sources {
        let bar = progress(trials.len(), "calibrating");
        let per_trial: Vec<std::result::Result<Vec<(f64, bool)>, String>> = trials
            .par_iter()
            .progress_with(bar.clone())
            .map(|(house, target, scene)| {
                let p = source
                    .likelihoods(house, target)
                    .map_err(|e| format!("{spec}: {}: {e}", house.name))?;
                Ok(p.iter()
                    .enumerate()
                    .map(|(c, p)| (p.get(), scene.truth.holds(c, target)))
                    .collect())
            })
            .collect();
        bar.finish_and_clear();
        let mut all = Vec::new();
        for r in per_trial {
            match r {
                Ok(v) => all.extend(v),
                Err(e) => errors.push(e),
            }
        }
        let Some(c) = Calibration::score(&all, usize::from(args.bins)) else {
            errors.push(format!("{spec}: no pairs scored"));
            continue;
        };
        rows.push(CalibrationRow {
            source: spec.clone(),
            pairs: c.pairs,
            positives: c.positives,
            brier: c.brier,
            log_loss: c.log_loss,
            auroc: c.auroc,
            mean_p_pos: c.mean_p_pos,
            mean_p_neg: c.mean_p_neg,
        });
        scored.push((spec.clone(), c));
    }
    for e in &errors {
        eprintln!("error: {e}");
    }
    super::eval::write_csv(&args.out.join("calibration.csv"), &rows)?;
    let md = calibration_markdown(
        &scored,
        &loaded.source,
        loaded.scenes.len(),
        trials.len(),
        args.targets_per_house,
    );
    crate::output::write_bytes(&args.out.join("calibration.md"), &md)?;
    if !scored.is_empty() {
        for ext in ["png", "svg"] {
            crate::output::write_with_path(&args.out.join(format!("reliability.{ext}")), |p| {
                draw_reliability(&scored, p)
            })?;
        }
    }
    println!("{md}");
    super::llm_setup::write_token_report(&setup.service, &args.out)?;
    super::llm_setup::check_fallback_gate(&setup.service, &args.llm)?;
    println!(
        "{} sources over {} (house, target) pairs in {:.1} s; wrote {}/{{calibration.csv,calibration.md,reliability.png,reliability.svg}}",
        scored.len(),
        trials.len(),
        started.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(if errors.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
}

/// The table of scores as Markdown.
pub fn calibration_markdown(
    scored: &[(String, Calibration)],
    source: &str,
    houses: usize,
    trials: usize,
    targets: TargetCount,
) -> String {
    let per_house = match targets {
        TargetCount::All => "every target type present".to_string(),
        TargetCount::N(n) => format!("up to {n} target types"),
    };
    let mut md = format!(
        "# Calibration of likelihood sources\n\n{houses} houses from {source}, {per_house} per house ({trials} house–target pairs), every container: P_S(target, container) against whether it holds the target. Brier and log loss: lower is better; AUROC: 0.5 is chance.\n\n"
    );
    md.push_str("| source | pairs | holders | Brier | log loss | AUROC | mean p (holders) | mean p (others) |\n");
    md.push_str("|---|---:|---:|---:|---:|---:|---:|---:|\n");
    let opt =
        |v: Option<f64>, digits: usize| v.map_or_else(|| "–".into(), |v| format!("{v:.digits$}"));
    for (name, c) in scored {
        md.push_str(&format!(
            "| {name} | {} | {} | {:.4} | {:.4} | {} | {} | {} |\n",
            c.pairs,
            c.positives,
            c.brier,
            c.log_loss,
            opt(c.auroc, 3),
            opt(c.mean_p_pos, 3),
            opt(c.mean_p_neg, 3),
        ));
    }
    md
}

/// The reliability diagram: for each source, the observed rate of holders against the mean
/// probability in each bin, beside the diagonal of perfect calibration.
fn draw_reliability(scored: &[(String, Calibration)], out: &std::path::Path) -> Result<()> {
    let mut series: Vec<(String, Vec<(f64, f64)>)> = scored
        .iter()
        .map(|(name, c)| {
            (
                name.clone(),
                c.bins.iter().map(|b| (b.mean_p, b.observed)).collect(),
            )
        })
        .collect();
    series.push(("perfectly calibrated".into(), vec![(0.0, 0.0), (1.0, 1.0)]));
    // A marker on every bin's point, so a source whose probabilities fall in one bin (uniform)
    // still shows.
    let marks_at: Vec<f64> = scored
        .iter()
        .flat_map(|(_, c)| c.bins.iter().map(|b| b.mean_p))
        .collect();
    let panel = ferret_report::CurvePanel {
        title: "Reliability: observed rate of holders against P_S".into(),
        x_label: "mean P_S in bin".into(),
        y_label: "share of containers holding the target".into(),
        series,
        marks_at,
    };
    ferret_report::draw_curve_panels(std::slice::from_ref(&panel), out)?;
    Ok(())
}
