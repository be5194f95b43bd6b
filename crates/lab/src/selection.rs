//! Strategy selection over an evaluation run (the paper's deployment experiment): every
//! strategy replayed on every trial of the run (the replay table, cached beside the run), then
//! many deployments of distinct houses, each run by every selection method.

use std::path::Path;

use ferret_plan::{DrawMode, Protocol, TrialRng, UntriedScore};
use ferret_select::{ExperimentOptions, ExperimentResult, MAX_EXPERIMENT_TRIALS, run_experiment};

use crate::error::{LabError, Result};
use crate::feedback::Feedback;
use crate::replay::{ReplayTable, replay_table};
use crate::runs::EvalRun;
use crate::strategies::LlmSettings;

/// The name of the replay cache in an evaluation run's directory.
pub const REPLAY_CACHE: &str = "replay.csv";

/// Refuses unusable experiment options, naming the command-line option, before any replay runs.
///
/// # Errors
/// No deployments or trials, more deployment trials than an experiment keeps, or a `c` that is
/// not a finite number ≥ 0.
pub fn validate(options: &ExperimentOptions) -> Result<()> {
    if options.deployments == 0 {
        return Err(LabError::invalid("--deployments 0: must be at least 1"));
    }
    if options.trials_per_deployment == 0 {
        return Err(LabError::invalid(
            "--trials-per-deployment 0: must be at least 1",
        ));
    }
    if options
        .deployments
        .checked_mul(options.trials_per_deployment)
        .is_none_or(|n| n > MAX_EXPERIMENT_TRIALS)
    {
        return Err(LabError::invalid(format!(
            "--deployments {} × --trials-per-deployment {}: at most {MAX_EXPERIMENT_TRIALS} deployment trials in all",
            options.deployments, options.trials_per_deployment
        )));
    }
    if !(options.c.is_finite() && options.c >= 0.0) {
        return Err(LabError::invalid(format!(
            "--c {}: must be a finite number ≥ 0 m",
            options.c
        )));
    }
    Ok(())
}

/// `options` with the switches `protocol` decides: drawing houses with replacement, UCB's score
/// of untried strategies, the reference code's numpy draws.
pub fn under_protocol(options: &ExperimentOptions, protocol: &Protocol) -> ExperimentOptions {
    ExperimentOptions {
        with_replacement: protocol.draw == DrawMode::Replacement,
        ucb_untried_zero: protocol.untried == UntriedScore::Zero,
        // The reference's numpy draws are draws with replacement; with distinct houses the
        // deployments keep ferret's own streams.
        reference_draws: protocol.rng == TrialRng::Python && protocol.draw == DrawMode::Replacement,
        ..*options
    }
}

/// A finished selection: the replay table it ran on and what the deployments did.
pub struct Selection {
    /// The replay table (with the LLM service, when replays asked an LLM).
    pub replay: ReplayTable,
    /// The experiment's result.
    pub result: ExperimentResult,
    /// `selection.md`: the paper's table II and the strategies' mean costs.
    pub markdown: String,
}

/// Selects over the evaluation run `run`, read from `dir`, under `protocol`: its trial
/// settings must be the run's (a run is never mixed with another protocol's trials); its replay
/// mode and house draw act here, and decide the options' protocol switches
/// ([`under_protocol`]). Replays are read from and appended to `dir/replay.csv`.
///
/// Errors: unusable settings, another protocol's trials, fewer than two candidates, too few
/// houses for deployments of distinct houses, and the errors of replaying.
pub fn select(
    run: &EvalRun,
    dir: &Path,
    protocol: &Protocol,
    llm: &LlmSettings,
    options: &ExperimentOptions,
    feedback: &dyn Feedback,
) -> Result<Selection> {
    validate(options)?;
    let info = &run.info;
    if protocol.trial_settings() != info.protocol.trial_settings() {
        return Err(LabError::invalid(format!(
            "{} was made with {}; select asks for {}: selecting over trials of another protocol \
             would mix them (run eval again instead)",
            dir.display(),
            info.protocol.trial_settings(),
            protocol.trial_settings()
        )));
    }
    let min_houses = match protocol.draw {
        DrawMode::Distinct => options.trials_per_deployment,
        DrawMode::Replacement => 0,
    };
    let replay = match replay_table(
        run,
        protocol,
        llm,
        &dir.join(REPLAY_CACHE),
        min_houses,
        feedback,
    ) {
        Ok(r) => r,
        Err(LabError::TooFewCandidates) => {
            return Err(LabError::invalid(format!(
                "selection needs at least two non-oracle strategies in {}",
                dir.display()
            )));
        }
        Err(LabError::TooFewHouses { have, need }) => {
            return Err(LabError::invalid(format!(
                "--trials-per-deployment {need}: only {have} houses of {} have a trial of every strategy",
                dir.display()
            )));
        }
        Err(e) => return Err(e),
    };
    let opts = under_protocol(options, protocol);
    let result = run_experiment(&replay.table, &opts)?;
    let markdown = crate::report::selection_markdown(
        &result,
        replay.distinct_houses,
        replay.several_per_house().then_some(replay.trials.len()),
    );
    Ok(Selection {
        replay,
        result,
        markdown,
    })
}
