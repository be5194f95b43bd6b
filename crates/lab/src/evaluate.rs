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
use crate::houses::{Mapped, build_maps};
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
        scenes
            .iter()
            .zip(maps)
            .filter(|(_, m)| m.is_ok())
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
    /// Every house's map (or why it has none), in the houses' order.
    pub maps: Vec<Mapped>,
    /// The strategies that ran, in the order of the specs: those of an LLM that failed are left
    /// out under `keep_going`.
    pub strategies: Vec<Arc<dyn Strategy>>,
    /// The rows and errors.
    pub evaluation: Evaluation,
}

/// Evaluates the strategies `specs` of `setup` on `scenes` mapped on `grid`, as `ferret eval`
/// does: the strategies built, the maps built, every LLM question of the drawn trials asked
/// before the trials run (through the response cache), then [`evaluate`].
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
    let built: Vec<Arc<dyn Strategy>> = specs
        .iter()
        .map(|s| setup.registry.build(s))
        .collect::<std::result::Result<_, _>>()?;
    let maps = build_maps(scenes, grid, feedback);
    let targets = draw.targets(scenes, &maps);
    let pairs: Vec<(&House, &ObjectType)> = targets.iter().map(|(h, t)| (*h, t)).collect();
    let dropped = prefetch(&setup.service, llm, specs, &pairs, feedback)?;
    let strategies: Vec<Arc<dyn Strategy>> = built
        .into_iter()
        .filter(|s| !dropped.iter().any(|d| d == s.name()))
        .collect();
    let evaluation = evaluate(scenes, &maps, &strategies, draw, feedback);
    Ok(SpecEvaluation {
        maps,
        strategies,
        evaluation,
    })
}

fn evaluate_house(
    scene: &Scene,
    map: &Mapped,
    strategies: &[Arc<dyn Strategy>],
    draw: &TrialDraw<'_>,
) -> (Vec<TrialRow>, Vec<String>, usize) {
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
