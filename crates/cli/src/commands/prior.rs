//! `ferret prior train`: learn P(target | container type, room type) from training houses.

use std::path::PathBuf;
use std::process::ExitCode;

use anyhow::Result;
use ferret_plan::Prior;

use crate::common::HouseArgs;

/// Train and inspect likelihood priors.
#[derive(clap::Subcommand, Debug)]
pub enum Command {
    /// Learn a prior from training houses. Several files may be given as `--houses A --also B`.
    Train(TrainArgs),
}

/// Arguments of `prior train`.
#[derive(clap::Args, Debug)]
pub struct TrainArgs {
    #[command(flatten)]
    houses: HouseArgs,
    /// More training files (whole files), e.g. smallhouse-train1000 plus oneroom-train500.
    #[arg(long, value_name = "PATH")]
    also: Vec<PathBuf>,
    /// Which top-level objects of the training houses are containers: train with the set the
    /// evaluation will use (`furniture` for `--protocol paper`), so that every container type
    /// it meets has been seen.
    #[arg(long, value_name = "receptacles|furniture", default_value_t)]
    containers: ferret_world::ContainerSet,
    /// Smoothing weight toward the back-off estimate (pseudo-containers).
    #[arg(long, default_value_t = 2.0)]
    smoothing: f64,
    /// Folds of the cross-fitting that calibrates the prior's probabilities on its own training
    /// houses (Platt scaling, recorded in the file); 0 leaves them as counted. Fewer than two
    /// houses per fold also leaves them as counted.
    #[arg(long, value_name = "N", default_value_t = ferret_plan::CALIBRATION_FOLDS)]
    calibration_folds: usize,
    /// Output JSON file.
    #[arg(long, value_name = "FILE")]
    out: PathBuf,
}

/// Runs a `prior` subcommand.
pub fn run(cmd: Command) -> Result<ExitCode> {
    match cmd {
        Command::Train(args) => train(args),
    }
}

fn train(args: TrainArgs) -> Result<ExitCode> {
    let mut loaded = args.houses.load_for(args.containers)?;
    for path in &args.also {
        let more = HouseArgs {
            houses: Some(path.clone()),
            range: None,
            ..args.houses.clone()
        }
        .load_for(args.containers)?;
        loaded.scenes.extend(more.scenes);
        loaded.skipped.extend(more.skipped);
    }
    for s in &loaded.skipped {
        eprintln!("skipped: {s}");
    }
    if !(args.smoothing.is_finite() && args.smoothing >= 0.0) {
        anyhow::bail!(
            "--smoothing {}: must be a finite number ≥ 0",
            args.smoothing
        );
    }
    let prior = Prior::train_with(&loaded.scenes, args.smoothing, args.calibration_folds);
    crate::output::write_with_path(&args.out, |p| Ok(prior.save(p)?))?;
    let calibration = match &prior.calibration {
        Some(c) => format!(
            "calibrated by {}-fold cross-fitting on {} questions: logit P = {:.3}·logit P_counts {:+.3}",
            c.folds, c.pairs, c.a, c.c
        ),
        None => "not calibrated (too few houses, or --calibration-folds 0)".to_string(),
    };
    println!(
        "trained a prior on {} houses ({} containers), {calibration}, and wrote {}",
        prior.houses,
        prior.container_count(),
        args.out.display()
    );
    Ok(ExitCode::SUCCESS)
}
