//! `ferret select`: the deployment experiment of paper section VI-C over an eval run.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::Result;
use ferret_lab::EvalRun;
use ferret_lab::selection::{select, validate};
use ferret_report::{CurvePanel, draw_choice_shares, draw_curve_panels};
use ferret_select::ExperimentOptions;
use ferret_select::{Method, PAPER_KS, choice_rows, selection_rows};

use crate::common::Bars;
use crate::output::write_csv;

/// Replay every strategy on every trial of an eval run (cached in DIR/replay.csv), then run
/// deployments — random orders of distinct houses — with UCB and with replay selection, and
/// report average cost and cumulative regret against k (paper table II and figure 4).
///
/// The replay cache is keyed to the exact run.json and trials.csv: after a new eval into the same
/// directory it is recomputed. Each house's replays are appended as soon as they finish, so an
/// interrupted select resumes where it stopped.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The output directory of `ferret eval` (trials.csv and run.json).
    #[arg(long, value_name = "DIR")]
    trials: PathBuf,
    /// Number of deployments; deployments × trials per deployment may be at most 5 000 000
    /// (every trial is kept in memory).
    #[arg(long, default_value_t = 500)]
    deployments: usize,
    /// Trials per deployment, each in a distinct house (at most the number of houses).
    #[arg(long, default_value_t = 100)]
    trials_per_deployment: usize,
    /// Exploration constant c, metres (the paper's 100 cells of 0.05 m).
    #[arg(long, default_value_t = ferret_select::DEFAULT_C)]
    c: f64,
    /// Seed of the deployment orders and tie breaks.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Make replay selection deploy every strategy once before trusting replay costs, as UCB
    /// does. By default an untried strategy's score is its replay mean (paper eq. 5 with n = 0,
    /// as in the paper's reference code), so clearly worse strategies are never deployed.
    #[arg(long)]
    replay_untried_first: bool,
    /// Output directory.
    #[arg(long, value_name = "DIR", default_value = "ferret-out/select")]
    out: PathBuf,
    #[command(flatten)]
    llm: super::llm_setup::LlmArgs,
    /// Protocol switches: by default the eval run's. `--replay` and `--draw` act here; the
    /// others decide the trials and must match the run's (a run is never mixed with another
    /// protocol's trials).
    #[command(flatten)]
    protocol: crate::common::ProtocolArgs,
}

/// Runs `ferret select`.
pub fn run(args: Args) -> Result<ExitCode> {
    let options = ExperimentOptions {
        deployments: args.deployments,
        trials_per_deployment: args.trials_per_deployment,
        c: args.c,
        seed: args.seed,
        replay_untried_first: args.replay_untried_first,
        ..ExperimentOptions::default()
    };
    // Options are checked before the run is read, so a typo is reported first.
    validate(&options)?;
    // Claimed first, so that a second run into the same directory stops at once.
    let mut out_lock = ferret_lab::files::DirLock::acquire(&args.out)?;
    let run = EvalRun::read(&args.trials)?;
    let protocol = args.protocol.resolve(run.info.protocol)?;
    let done = select(
        &run,
        &args.trials,
        &protocol,
        &args.llm.settings(),
        &options,
        &Bars::default(),
    )?;
    out_lock.used();
    if let Some(service) = &done.replay.service {
        super::llm_setup::write_token_report(service, &args.out)?;
    }
    let result = &done.result;
    std::fs::create_dir_all(&args.out)?;
    write_csv(&args.out.join("selection.csv"), &selection_rows(result))?;
    write_csv(&args.out.join("choices.csv"), &choice_rows(result))?;
    crate::output::write_bytes(&args.out.join("selection.md"), &done.markdown)?;
    draw_selection(result, &args.out)?;
    println!("{}", done.markdown);
    let choices: Vec<String> = Method::ALL
        .iter()
        .map(|m| format!("choices-{}.png", m.name()))
        .collect();
    println!(
        "wrote {}/{{selection.csv,choices.csv,selection.md,selection.png,{}}}",
        args.out.display(),
        choices.join(",")
    );
    Ok(ExitCode::SUCCESS)
}

fn draw_selection(result: &ferret_select::ExperimentResult, out: &Path) -> Result<()> {
    let ks = |v: &[f64]| {
        v.iter()
            .enumerate()
            .map(|(i, &y)| ((i + 1) as f64, y))
            .collect::<Vec<_>>()
    };
    let best = &result.strategies[result.best_strategy];
    let marks: Vec<f64> = PAPER_KS
        .iter()
        .map(|&k| k as f64)
        .filter(|&k| k <= result.trials() as f64)
        .collect();
    let curves = |curve: fn(&ferret_select::MethodSummary) -> &[f64]| {
        result
            .summaries
            .iter()
            .map(|s| (s.method.label().to_string(), ks(curve(s))))
            .collect::<Vec<_>>()
    };
    let mut average = curves(|s| &s.avg_cost);
    average.push((format!("best single: {best}"), ks(&result.best_avg_cost)));
    let panels = vec![
        CurvePanel {
            title: "Average cost of trials 1..k".into(),
            x_label: "trials k".into(),
            y_label: "average cost (m)".into(),
            series: average,
            marks_at: marks.clone(),
        },
        CurvePanel {
            title: "Cumulative regret".into(),
            x_label: "trials k".into(),
            y_label: "cumulative regret (m)".into(),
            series: curves(|s| &s.cum_regret),
            marks_at: marks,
        },
    ];
    crate::output::write_with_path(&out.join("selection.png"), |p| {
        Ok(draw_curve_panels(&panels, p)?)
    })?;
    let x: Vec<f64> = (1..=result.trials()).map(|k| k as f64).collect();
    for s in &result.summaries {
        let method = s.method;
        let shares: Vec<(String, Vec<f64>)> = result
            .strategies
            .iter()
            .enumerate()
            .map(|(i, name)| {
                (
                    name.clone(),
                    s.choice_fraction.iter().map(|f| f[i]).collect(),
                )
            })
            .collect();
        let title = format!("{}: how often each strategy is chosen", method.label());
        let path = out.join(format!("choices-{}.png", method.name()));
        crate::output::write_with_path(&path, |p| {
            Ok(draw_choice_shares(&title, "trials k", &x, &shares, p)?)
        })?;
    }
    Ok(())
}
