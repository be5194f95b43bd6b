//! `ferret calibrate`: how good are a likelihood source's probabilities? Every (house, target,
//! container) of the houses is a pair (P_S, whether the container holds the target); each source
//! gets a Brier score, log loss, AUROC and a reliability diagram.

use std::path::PathBuf;
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result};
use ferret_plan::{
    Calibration, FusionFile, FusionFit, FusionWeights, LikelihoodSource, TrainingScore, draw_trial,
    prior_fingerprint,
};
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
    /// Likelihood sources as strategy specs, comma separated: model/uniform, model/prior,
    /// llm+model/<prompt>/<llm> and fused/<prompt>/<llm> (with --fusion); any planner suffix is
    /// ignored: only the probabilities count.
    #[arg(long, value_delimiter = ',', default_value = DEFAULT_SOURCES)]
    pub sources: Vec<String>,
    /// Targets per house: `all` (every small-object type present) or a number N. With N, the
    /// first is the target `eval --seed` draws, so an eval with the same seed reuses its answers.
    #[arg(long, value_name = "N|all", default_value = "all", value_parser = parse_targets)]
    pub targets_per_house: TargetCount,
    /// Seed of the target choice (with `--targets-per-house N`).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fit the fusion of the prior with each LLM source among `--sources` (logit P = a·logit
    /// P_prior + b·logit P_llm + c, by logistic regression on these houses, which should be
    /// training houses) and write the weights to FILE; `--fusion FILE` then makes
    /// `fused/<prompt>/<llm>` available to eval, calibrate, select, deploy and serve.
    #[arg(long, value_name = "FILE")]
    pub fit_fusion: Option<PathBuf>,
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
    let fitted: Vec<String> = if args.fit_fusion.is_some() {
        let fit: Vec<String> = args
            .sources
            .iter()
            .filter(|s| s.starts_with(&format!("{}/", ferret_llm::LLM_MODEL)))
            .cloned()
            .collect();
        if fit.is_empty() {
            anyhow::bail!(
                "--fit-fusion: --sources names no llm+model/<prompt>/<llm> source to fuse with the prior"
            );
        }
        fit
    } else {
        Vec::new()
    };
    // The prior is needed to fit a fusion even when it is not scored itself.
    let mut needed = args.sources.clone();
    if !fitted.is_empty() {
        needed.push("model/prior".into());
    }
    let setup = super::llm_setup::full_registry(&args.planning, &args.llm, &needed)?;
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
    let holds: Vec<Vec<bool>> = trials
        .iter()
        .map(|(house, target, scene)| {
            (0..house.containers.len())
                .map(|c| scene.truth.holds(c, target))
                .collect()
        })
        .collect();
    // Each source's probabilities per trial (None where it failed), kept for the fusion fit.
    let mut per_source: Vec<(String, Vec<Option<Vec<f64>>>)> = Vec::new();
    for (spec, source) in &sources {
        let probabilities = source_probabilities(spec, source.as_ref(), &trials, &mut errors);
        let all: Vec<(f64, bool)> = probabilities
            .iter()
            .zip(&holds)
            .filter_map(|(p, h)| p.as_ref().map(|p| p.iter().copied().zip(h.iter().copied())))
            .flatten()
            .collect();
        per_source.push((spec.clone(), probabilities));
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
    let fusion = match &args.fit_fusion {
        None => None,
        Some(path) => {
            let prior = setup
                .prior
                .clone()
                .context("--fit-fusion needs the prior")?;
            let prior_p = source_probabilities("model/prior", prior.as_ref(), &trials, &mut errors);
            let trained_on = format!(
                "{} houses from {}, {} ({} house–target pairs)",
                loaded.scenes.len(),
                loaded.source,
                match args.targets_per_house {
                    TargetCount::All => "every target type present".to_string(),
                    TargetCount::N(n) => format!("up to {n} target types per house"),
                },
                trials.len()
            );
            let mut fits = Vec::new();
            for (spec, probabilities) in per_source.iter().filter(|(s, _)| fitted.contains(s)) {
                match fit_fusion(spec, &prior, &prior_p, probabilities, &holds, &trained_on) {
                    Ok(f) => fits.push(f),
                    Err(e) => errors.push(format!("--fit-fusion: {spec}: {e}")),
                }
            }
            Some((path.clone(), FusionFile::new(fits)))
        }
    };
    for e in &errors {
        eprintln!("error: {e}");
    }
    crate::output::write_csv(&args.out.join("calibration.csv"), &rows)?;
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
    if let Some((path, file)) = &fusion {
        crate::output::write_bytes(path, file.to_json())?;
        println!("{}", fusion_markdown(file));
        println!("wrote {}", path.display());
    }
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

/// The probabilities `source` gives on every trial; a failure is recorded in `errors` and
/// leaves that trial's entry `None`.
fn source_probabilities(
    spec: &str,
    source: &dyn LikelihoodSource,
    trials: &[(&House, ObjectType, &Scene)],
    errors: &mut Vec<String>,
) -> Vec<Option<Vec<f64>>> {
    let bar = progress(trials.len(), "calibrating");
    let per_trial: Vec<std::result::Result<Vec<f64>, String>> = trials
        .par_iter()
        .progress_with(bar.clone())
        .map(|(house, target, _)| {
            source
                .likelihoods(house, target)
                .map(|p| p.iter().map(|p| p.get()).collect())
                .map_err(|e| format!("{spec}: {}: {e}", house.name))
        })
        .collect();
    bar.finish_and_clear();
    per_trial
        .into_iter()
        .map(|r| r.map_err(|e| errors.push(e)).ok())
        .collect()
}

/// The fusion of the prior with the LLM source `spec`, fitted on every trial both answered.
fn fit_fusion(
    spec: &str,
    prior: &ferret_plan::Prior,
    prior_p: &[Option<Vec<f64>>],
    llm_p: &[Option<Vec<f64>>],
    holds: &[Vec<bool>],
    trained_on: &str,
) -> Result<FusionFit> {
    let samples: Vec<(f64, f64, bool)> = prior_p
        .iter()
        .zip(llm_p)
        .zip(holds)
        .filter_map(|((p, l), h)| Some((p.as_ref()?, l.as_ref()?, h)))
        .flat_map(|(p, l, h)| p.iter().zip(l).zip(h).map(|((&p, &l), &h)| (p, l, h)))
        .collect();
    let weights = FusionWeights::fit(&samples)
        .context("the fit needs containers that hold the target and ones that do not")?;
    let score = |f: &dyn Fn(&(f64, f64, bool)) -> f64| -> Result<TrainingScore> {
        let pairs: Vec<(f64, bool)> = samples.iter().map(|s| (f(s), s.2)).collect();
        let c = Calibration::score(&pairs, 10).context("no pairs")?;
        Ok(TrainingScore {
            brier: c.brier,
            auroc: c.auroc,
        })
    };
    let parsed = ferret_plan::StrategySpec::parse(spec)?;
    let llm = ferret_llm::LlmSpec::parse(&parsed).context("not an LLM source")??;
    Ok(FusionFit {
        source: format!("{}/{}", llm.prompt, llm.llm),
        weights,
        prior: prior_fingerprint(prior),
        trained_on: trained_on.to_string(),
        pairs: samples.len() as u64,
        positives: samples.iter().filter(|s| s.2).count() as u64,
        prior_score: score(&|s| s.0)?,
        source_score: score(&|s| s.1)?,
        fused_score: score(&|s| weights.fuse(s.0, s.1))?,
    })
}

/// The fitted fusions as Markdown.
pub fn fusion_markdown(file: &FusionFile) -> String {
    let mut md = String::from(
        "## Fusion with the prior (logit P = a·logit P_prior + b·logit P_llm + c)\n\n| source | a | b | c | pairs | Brier prior / LLM / fused | AUROC prior / LLM / fused |\n|---|---:|---:|---:|---:|---|---|\n",
    );
    let auroc = |a: Option<f64>| a.map_or_else(|| "–".into(), |a| format!("{a:.3}"));
    for f in &file.fits {
        md.push_str(&format!(
            "| {} | {:.3} | {:.3} | {:.3} | {} | {:.4} / {:.4} / {:.4} | {} / {} / {} |\n",
            f.source,
            f.weights.a,
            f.weights.b,
            f.weights.c,
            f.pairs,
            f.prior_score.brier,
            f.source_score.brier,
            f.fused_score.brier,
            auroc(f.prior_score.auroc),
            auroc(f.source_score.auroc),
            auroc(f.fused_score.auroc),
        ));
    }
    md
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
