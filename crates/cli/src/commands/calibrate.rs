//! `ferret calibrate`: how good are a likelihood source's probabilities? Every (house, target,
//! container) of the houses is a pair (P_S, whether the container holds the target); each source
//! gets a Brier score, log loss, AUROC and a reliability diagram.

use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use anyhow::{Context, Result};
use ferret_lab::Strategies;
use ferret_lab::calibrate::{CalibrationSettings, DEFAULT_SOURCES, TargetCount, calibrate};
use ferret_plan::Calibration;

use crate::common::{Bars, HouseArgs};

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
    /// model/prior-raw (the uncalibrated estimate of earlier versions), model/noise (a control
    /// that knows nothing), llm+model/<prompt>/<llm> and fused/<prompt>/<llm> or fused/noise
    /// (with --fusion); with a prior trained with --embeddings, model/learned, model/learned-head,
    /// model/learned-random, model/learned-head-random and (with --fusion)
    /// fused-learned/<prompt>/<llm> and fused-learned/noise; any planner suffix is ignored: only
    /// the probabilities count.
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
    /// P_prior + b·logit P_llm + c + g·(d·logit P_llm + e), g the prior's evidence gap, by
    /// logistic regression on these houses, which should be training houses) and write the
    /// weights to FILE; `--fusion FILE` then makes `fused/<prompt>/<llm>` available to eval,
    /// calibrate, select, deploy and serve. model/noise among the sources fits the control
    /// `fused/noise` the same way: what the fit gives with a source that knows nothing. When the
    /// prior has a learned part (`prior train --embeddings`), each source is also fused with
    /// `model/learned` instead of the prior: `fused-learned/<prompt>/<llm>`, `fused-learned/noise`
    /// (its unseen view holds out the folds the learned heads were trained with).
    #[arg(long, value_name = "FILE")]
    pub fit_fusion: Option<PathBuf>,
    /// With --fit-fusion: every question is also scored by a prior that never saw its target's
    /// fold of N target types, so the fit sees questions the prior has no evidence for and the
    /// weights d and e learn how much the LLM is worth there. 0 fits on the prior as it is.
    #[arg(long, value_name = "N", default_value_t = ferret_lab::calibrate::FIT_UNSEEN_FOLDS)]
    pub fit_unseen_folds: usize,
    /// Bins of the reliability diagram.
    #[arg(long, default_value_t = 10, value_parser = clap::value_parser!(u16).range(1..=100))]
    pub bins: u16,
    /// Score one shard of the houses (`i/n`: file index i modulo n; `auto`: from a Slurm array
    /// task or a Kubernetes Indexed Job, as `eval --shard`). Its scores cover its houses only
    /// and are not merged (the scores are not sums over houses); the point is its LLM cache,
    /// <out>/llm-cache.sqlite unless --llm-cache is given: merged with `ferret merge --cache`,
    /// it answers a calibrate of all houses with --offline without asking anything again.
    #[arg(long, value_name = "i/n|auto")]
    pub shard: Option<ferret_lab::ShardSpec>,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "ferret-calibration")]
    pub out: PathBuf,
}

fn parse_targets(s: &str) -> std::result::Result<TargetCount, String> {
    s.parse()
}

/// Runs `ferret calibrate`.
pub fn run(mut args: Args) -> Result<ExitCode> {
    let started = Instant::now();
    let shard = args
        .shard
        .map(|s| s.resolve(|k| std::env::var(k).ok()))
        .transpose()?;
    if shard.is_some() && args.llm.llm_cache == std::path::Path::new(ferret_llm::DEFAULT_CACHE_PATH)
    {
        args.llm.llm_cache = args.out.join(super::eval::SHARD_CACHE);
    }
    let loaded = args
        .houses
        .load_shard(ferret_world::ContainerSet::Receptacles, shard)?;
    if let Some(sh) = shard {
        eprintln!(
            "shard {sh}: {} houses (file index mod {} = {}); its scores cover these houses only",
            loaded.scenes.len(),
            sh.count,
            sh.index
        );
    }
    for s in &loaded.skipped {
        eprintln!("skipped: {s}");
    }
    let settings = CalibrationSettings {
        sources: args.sources.clone(),
        targets_per_house: args.targets_per_house,
        seed: args.seed,
        bins: usize::from(args.bins),
        fit_fusion: args.fit_fusion.is_some(),
        fit_unseen_folds: args.fit_unseen_folds,
        holdout: args.planning.holdout_types,
    };
    if loaded.scenes.is_empty() {
        anyhow::bail!("no houses to score in {}", loaded.source);
    }
    let specs = settings.specs_to_build()?;
    // Claimed before the work, so that a second run into the same directory stops at once.
    let mut out_lock = ferret_lab::files::DirLock::acquire(&args.out)?;
    let setup = Strategies::builder(&args.planning.settings(), &args.llm.settings())
        .for_specs(&specs)
        .build()?;
    let done = calibrate(
        &loaded,
        &setup,
        &args.llm.settings(),
        &settings,
        &Bars::default(),
    )?;
    out_lock.used();
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("creating {}", args.out.display()))?;
    for e in &done.errors {
        eprintln!("error: {e}");
    }
    crate::output::write_csv(
        &args.out.join("calibration.csv"),
        &ferret_lab::calibrate::calibration_rows(&done.scored),
    )?;
    crate::output::write_bytes(&args.out.join("calibration.md"), &done.markdown)?;
    if !done.scored.is_empty() {
        for ext in ["png", "svg"] {
            crate::output::write_with_path(&args.out.join(format!("reliability.{ext}")), |p| {
                draw_reliability(&done.scored, p)
            })?;
        }
    }
    println!("{}", done.markdown);
    if let (Some(path), Some(file)) = (&args.fit_fusion, &done.fusion) {
        crate::output::write_bytes(path, file.to_json())?;
        println!("{}", ferret_lab::report::fusion_markdown(file));
        println!("wrote {}", path.display());
    }
    super::llm_setup::write_token_report(&setup.service, &args.out)?;
    super::llm_setup::check_fallback_gate(&setup.service, &args.llm)?;
    println!(
        "{} sources over {} (house, target) pairs in {:.1} s; wrote {}/{{calibration.csv,calibration.md,reliability.png,reliability.svg}}",
        done.scored.len(),
        done.trials,
        started.elapsed().as_secs_f64(),
        args.out.display()
    );
    Ok(if done.errors.is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::FAILURE
    })
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
