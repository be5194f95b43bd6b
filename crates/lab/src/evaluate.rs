//! Evaluation: every strategy on the same trials of every house, in parallel over houses.

use std::sync::Arc;

use ferret_plan::{
    HoldOut, Protocol, SearchProblem, Strategy, TrialOutcome, TrialSpec, TrialsPerHouse,
    draw_trials_with, run_trial,
};
use ferret_world::{GridParams, House, ObjectType, Scene};
use rayon::prelude::*;

use crate::error::Result;
use crate::feedback::Feedback;
use crate::houses::Mapped;
use crate::runs::TrialRow;
use crate::strategies::{LlmSettings, Strategies, prefetch};

/// How trials are drawn on each house: the same for every strategy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TrialDraw<'a> {
    /// Seed of the targets (and of revealed containers).
    pub seed: u64,
    /// Fraction of non-goal containers revealed as searched before each trial.
    pub reveal_fraction: f64,
    /// Trials per house.
    pub per_house: TrialsPerHouse,
    /// The protocol the trials follow.
    pub protocol: &'a Protocol,
    /// With one held-out fold, only the trials whose target is of that fold's types are run
    /// (drawn as without hold-out, then kept or not, so they are a subset of the run without).
    pub holdout: Option<HoldOut>,
}

impl TrialDraw<'_> {
    /// The trials of one house.
    pub fn trials(&self, scene: &Scene) -> Result<Vec<TrialSpec>, ferret_plan::PlanError> {
        let mut trials = draw_trials_with(
            &scene.house,
            &scene.truth,
            self.seed,
            self.reveal_fraction,
            self.per_house,
            self.protocol,
        )?;
        if let Some(h) = self.holdout {
            trials.retain(|t| h.includes_target(&t.target));
        }
        Ok(trials)
    }

    /// Every house's targets, for the houses that have a map: what LLM strategies will be asked
    /// about (see [`prefetch`]).
    pub fn targets<'s>(
        &self,
        scenes: &'s [Scene],
        maps: &[Mapped],
    ) -> Vec<(&'s House, ObjectType)> {
        let mapped: Vec<bool> = maps.iter().map(Result::is_ok).collect();
        self.targets_where(scenes, &mapped)
    }

    /// [`targets`](Self::targets) of the houses whose `mapped` entry is true.
    pub fn targets_where<'s>(
        &self,
        scenes: &'s [Scene],
        mapped: &[bool],
    ) -> Vec<(&'s House, ObjectType)> {
        scenes
            .iter()
            .zip(mapped)
            .filter(|(_, m)| **m)
            .flat_map(|(s, _)| {
                self.trials(s)
                    .unwrap_or_default()
                    .into_iter()
                    .map(|t| (&s.house, t.target))
            })
            .collect()
    }
}

/// Rows and errors of an evaluation.
#[derive(Clone, Debug, Default)]
pub struct Evaluation {
    /// One row per trial × strategy that finished, houses in order.
    pub rows: Vec<TrialRow>,
    /// One message per house or trial that failed.
    pub errors: Vec<String>,
    /// Houses with a map and a target.
    pub houses_run: usize,
    /// Trials (house and target) drawn on those houses.
    pub trials_run: usize,
}

/// Runs every strategy on the trials of every house, in parallel over houses. A house without a
/// map or without a trial, and a trial that fails, become messages in
/// [`Evaluation::errors`]; every finished trial is kept.
pub fn evaluate(
    scenes: &[Scene],
    maps: &[Mapped],
    strategies: &[Arc<dyn Strategy>],
    draw: &TrialDraw<'_>,
    feedback: &dyn Feedback,
) -> Evaluation {
    feedback.begin("trials", scenes.len());
    let by_house: Vec<(Vec<TrialRow>, Vec<String>, usize)> = scenes
        .par_iter()
        .zip(maps.par_iter())
        .map(|(scene, map)| {
            let r = evaluate_house(scene, map, strategies, draw);
            feedback.tick();
            r
        })
        .collect();
    feedback.end();
    let mut ev = Evaluation::default();
    for (rows, errors, trials) in by_house {
        ev.rows.extend(rows);
        ev.errors.extend(errors);
        ev.houses_run += usize::from(trials > 0);
        ev.trials_run += trials;
    }
    ev
}

/// An evaluation of strategy specs, with what it was run on.
pub struct SpecEvaluation {
    /// The strategies that ran, in the order of the specs: those of an LLM that failed are left
    /// out under `keep_going`.
    pub strategies: Vec<Arc<dyn Strategy>>,
    /// The rows and errors.
    pub evaluation: Evaluation,
}

/// Evaluates the strategies `specs` of `setup` on `scenes` mapped on `grid`, keeping every row:
/// [`evaluate_specs_each`] collecting what it hands over.
///
/// Errors: a spec the registry cannot build, and the errors of prefetching LLM answers.
pub fn evaluate_specs(
    scenes: &[Scene],
    setup: &Strategies,
    specs: &[String],
    draw: &TrialDraw<'_>,
    grid: &GridParams,
    llm: &LlmSettings,
    feedback: &dyn Feedback,
) -> Result<SpecEvaluation> {
    let mut rows = Vec::new();
    let run = evaluate_specs_each(scenes, setup, specs, draw, grid, llm, feedback, &mut |h| {
        rows.extend(h.rows);
        Ok(())
    })?;
    Ok(SpecEvaluation {
        strategies: run.strategies,
        evaluation: Evaluation {
            rows,
            errors: run.errors,
            houses_run: run.houses_run,
            trials_run: run.trials_run,
        },
    })
}

/// One house evaluated, as [`evaluate_specs_each`] hands it over. Its map is dropped when the
/// callback returns: a caller that needs it later (to draw the house) clones it.
pub struct HouseOutcome<'a> {
    /// The house.
    pub scene: &'a Scene,
    /// Its map, or why it has none.
    pub map: &'a Mapped,
    /// One row per trial and strategy that finished, in the one-machine order.
    pub rows: Vec<TrialRow>,
    /// One message per failure on this house.
    pub errors: &'a [String],
    /// Trials (house and target) drawn on it.
    pub trials: usize,
    /// The strategies that ran, by name, in the order of the specs.
    pub strategies: &'a [String],
}

impl HouseOutcome<'_> {
    /// Whether every strategy that ran finished a trial here (a house that can show every
    /// trajectory).
    pub fn every_strategy_finished(&self) -> bool {
        self.map.is_ok()
            && self
                .strategies
                .iter()
                .all(|s| self.rows.iter().any(|r| &r.strategy == s))
    }
}

/// What an evaluation handed house by house leaves besides its rows.
#[derive(Clone, Default)]
pub struct EvaluationTotals {
    /// The strategies that ran, in the order of the specs.
    pub strategies: Vec<Arc<dyn Strategy>>,
    /// One message per house or trial that failed, houses in order.
    pub errors: Vec<String>,
    /// Houses with a map and a target.
    pub houses_run: usize,
    /// Trials (house and target) drawn on those houses.
    pub trials_run: usize,
}

/// Houses mapped and evaluated at once per worker thread: what bounds the maps in memory. A
/// batch ends when its slowest house does, so batches much larger than the threads keep every
/// thread busy most of the time.
const HOUSES_PER_THREAD_IN_FLIGHT: usize = 8;

/// Evaluates the strategies `specs` of `setup` on `scenes` mapped on `grid`, as `ferret eval`
/// does, handing each house's rows to `each` in house order as houses finish: the strategies
/// built, every LLM question of the drawn trials asked before the trials run (through the
/// response cache), then the houses mapped and run in parallel a batch at a time. Only a batch's
/// maps and rows are in memory at once, so a caller that writes the rows out (a [`RunWriter`])
/// runs any number of houses in the same memory.
///
/// [`RunWriter`]: crate::runs::RunWriter
///
/// Errors: a spec the registry cannot build, the errors of prefetching LLM answers, and the
/// first error of `each` (which stops the evaluation).
#[allow(clippy::too_many_arguments)]
pub fn evaluate_specs_each(
    scenes: &[Scene],
    setup: &Strategies,
    specs: &[String],
    draw: &TrialDraw<'_>,
    grid: &GridParams,
    llm: &LlmSettings,
    feedback: &dyn Feedback,
    each: &mut dyn FnMut(HouseOutcome<'_>) -> Result<()>,
) -> Result<EvaluationTotals> {
    let built: Vec<Arc<dyn Strategy>> = specs
        .iter()
        .map(|s| setup.registry.build(s))
        .collect::<std::result::Result<_, _>>()?;
    let dropped = if crate::strategies::asks_llm(specs) {
        // The questions are asked for the houses that have a map, all at once; the maps are
        // built again with their batch rather than all kept.
        feedback.begin("maps", scenes.len());
        let mapped: Vec<bool> = scenes
            .par_iter()
            .map(|s| {
                let ok = ferret_world::distance::build(&s.house, grid).is_ok();
                feedback.tick();
                ok
            })
            .collect();
        feedback.end();
        let targets = draw.targets_where(scenes, &mapped);
        let pairs: Vec<(&House, &ObjectType)> = targets.iter().map(|(h, t)| (*h, t)).collect();
        prefetch(&setup.service, llm, specs, &pairs, feedback)?
    } else {
        Vec::new()
    };
    let strategies: Vec<Arc<dyn Strategy>> = built
        .into_iter()
        .filter(|s| !dropped.iter().any(|d| d == s.name()))
        .collect();
    let names: Vec<String> = strategies.iter().map(|s| s.name().to_string()).collect();
    let mut totals = EvaluationTotals {
        strategies: strategies.clone(),
        ..EvaluationTotals::default()
    };
    let batch = (rayon::current_num_threads() * HOUSES_PER_THREAD_IN_FLIGHT).max(1);
    feedback.begin("houses", scenes.len());
    for chunk in scenes.chunks(batch) {
        let done: Vec<(Mapped, HouseRun)> = chunk
            .par_iter()
            .map(|scene| {
                let map = ferret_world::distance::build(&scene.house, grid);
                let r = evaluate_house(scene, &map, &strategies, draw);
                feedback.tick();
                (map, r)
            })
            .collect();
        for (scene, (map, (rows, errors, trials))) in chunk.iter().zip(done) {
            totals.houses_run += usize::from(trials > 0);
            totals.trials_run += trials;
            let r = each(HouseOutcome {
                scene,
                map: &map,
                rows,
                errors: &errors,
                trials,
                strategies: &names,
            });
            totals.errors.extend(errors);
            if let Err(e) = r {
                feedback.end();
                return Err(e);
            }
        }
    }
    feedback.end();
    Ok(totals)
}

/// One house's rows, failure messages and trials drawn.
type HouseRun = (Vec<TrialRow>, Vec<String>, usize);

fn evaluate_house(
    scene: &Scene,
    map: &Mapped,
    strategies: &[Arc<dyn Strategy>],
    draw: &TrialDraw<'_>,
) -> HouseRun {
    let (_, distances) = match map {
        Ok(m) => m,
        Err(e) => return (vec![], vec![e.to_string()], 0),
    };
    let trials = match draw.trials(scene) {
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
                let cost = out.reported_cost(&scene.house, distances, draw.protocol.travel_cost)?;
                Ok(TrialOutcome { cost, ..out })
            });
            match run {
                Ok(out) => rows.push(trial_row(scene, trial, &out)),
                // The target is named only when a house has several trials: with one, the house
                // says which trial it was.
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
}

/// The `trials.csv` row of a finished trial.
pub fn trial_row(scene: &Scene, trial: &TrialSpec, out: &TrialOutcome) -> TrialRow {
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
