//! Evaluation: every strategy on the same trials of every house, in parallel over houses —
//! [`EvalContext`] for strategy specs, houses in memory or read from a source batch by batch,
//! and [`evaluate`] for strategies already built on houses already mapped.

use std::sync::Arc;

use ferret_plan::{
    HoldOut, Protocol, SearchProblem, Strategy, TeamOutcome, TeamSettings, TrialOutcome, TrialSpec,
    TrialsPerHouse, draw_starts, draw_trials_with, run_team, run_trial, team_destinations,
    team_distances,
};
use ferret_world::{GridParams, House, ObjectType, Scene};
use rayon::prelude::*;

use crate::error::Result;
use crate::feedback::Feedback;
use crate::houses::{HouseEvent, HouseStream, Mapped, OpenSource, build_maps};
use crate::rows::TrialRow;
use crate::strategies::{LlmSettings, Strategies, add_summary, prefetch_outcome, prefetch_quiet};
use crate::tasks::Tasks;
use ferret_llm::{PrefetchSummary, Prefetched};

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
    /// (drawn as without hold-out, then kept or not, so they are a subset of the run without);
    /// a task is run when one of its targets is.
    pub holdout: Option<HoldOut>,
    /// Household tasks instead of one target per trial.
    pub tasks: Option<&'a Tasks>,
    /// A team of robots on every trial instead of one robot (the rows then have the team's
    /// columns, and their cost is the makespan).
    pub team: Option<TeamSettings>,
}

impl TrialDraw<'_> {
    /// The trials of one house.
    ///
    /// Errors: what drawing refuses (a house without targets, too few for a task, a
    /// destination it does not have), and listed tasks that do not fit the house.
    pub fn trials(&self, scene: &Scene) -> Result<Vec<TrialSpec>> {
        let mut trials = match self.tasks {
            None => draw_trials_with(
                &scene.house,
                &scene.truth,
                self.seed,
                self.reveal_fraction,
                self.per_house,
                self.protocol,
            )?,
            Some(tasks) => tasks.trials(
                scene,
                (self.seed, self.reveal_fraction),
                self.per_house,
                self.protocol,
            )?,
        };
        if let Some(h) = self.holdout {
            trials.retain(|t| t.task.targets().iter().any(|x| h.includes_target(x)));
        }
        Ok(trials)
    }

    /// Every house's targets, for the houses that have a map: what LLM strategies will be asked
    /// about (see [`prefetch`](crate::strategies::prefetch)).
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
                    .flat_map(|t| t.task.targets().to_vec())
                    .map(|t| (&s.house, t))
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

/// An evaluation of strategy specs that kept every row ([`EvalContext::collect`]).
pub struct SpecEvaluation {
    /// The strategies that ran, in the order of the specs: those of an LLM that failed are left
    /// out under `keep_going`.
    pub strategies: Vec<Arc<dyn Strategy>>,
    /// The rows and errors.
    pub evaluation: Evaluation,
}

/// One house evaluated, as [`EvalContext::run`] hands it over. Its map is dropped when the
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
    /// Indices of the houses evaluated (valid, whether mapped or not), in order: a report's
    /// house list, 8 bytes a house.
    pub houses: Vec<usize>,
    /// Why each skipped house was skipped, in order (each also went to
    /// [`Feedback::note`] as `skipped: …` when it was read).
    pub skipped: Vec<String>,
}

/// Houses mapped and evaluated at once per worker thread: what bounds the maps in memory. A
/// batch ends when its slowest house does, so batches much larger than the threads keep every
/// thread busy most of the time.
const HOUSES_PER_THREAD_IN_FLIGHT: usize = 8;

/// Houses read, mapped and run at once by an [`EvalContext`] on the current thread pool: a few
/// per worker thread.
pub fn default_batch() -> usize {
    (rayon::current_num_threads() * HOUSES_PER_THREAD_IN_FLIGHT).max(1)
}

/// Where an evaluation's houses come from: already in memory, or read from a source batch by
/// batch (see [`EvalContext::run`]).
#[derive(Clone, Copy)]
pub enum HouseInput<'a> {
    /// Houses in memory.
    Scenes(&'a [Scene]),
    /// Houses read from an opened source as the run goes.
    Source(&'a OpenSource<'a>),
}

/// Everything an evaluation of strategy specs runs with, as `ferret eval` runs it: the
/// strategies and the LLM service behind them, which of them run, how trials are drawn, the
/// grid of the maps, what a failed LLM means, how many houses are in flight at once, and where
/// progress goes. Every evaluation of specs goes through one of these (an example is in the
/// [crate documentation](crate)).
#[derive(Clone, Copy)]
pub struct EvalContext<'a> {
    /// The registry that builds `specs`, and the LLM service behind LLM strategies.
    pub setup: &'a Strategies,
    /// The strategies to run, in order.
    pub specs: &'a [String],
    /// How each house's trials are drawn.
    pub draw: &'a TrialDraw<'a>,
    /// The grid every house is mapped on.
    pub grid: &'a GridParams,
    /// What a failed LLM means (`keep_going`), and the LLM settings of the run.
    pub llm: &'a LlmSettings,
    /// Houses read, mapped and run at once (at least one); [`default_batch`] unless set. The
    /// rows do not depend on it.
    pub batch: usize,
    /// Where progress and remarks go.
    pub feedback: &'a dyn Feedback,
}

impl<'a> EvalContext<'a> {
    /// A context of [`default_batch`] houses in flight.
    pub fn new(
        setup: &'a Strategies,
        specs: &'a [String],
        draw: &'a TrialDraw<'a>,
        grid: &'a GridParams,
        llm: &'a LlmSettings,
        feedback: &'a dyn Feedback,
    ) -> Self {
        Self {
            setup,
            specs,
            draw,
            grid,
            llm,
            batch: default_batch(),
            feedback,
        }
    }

    /// The same, `batch` houses at a time.
    pub fn with_batch(self, batch: usize) -> Self {
        Self { batch, ..self }
    }

    /// Evaluates the strategies on `houses`, handing each house's rows to `each` in house order
    /// as houses finish. The houses are read [`batch`](Self::batch) at a time: the batch's
    /// houses read, mapped, their LLM questions asked (through the response cache) and their
    /// trials run in parallel, then the batch is dropped. Memory thus holds one batch of houses,
    /// maps and rows however many houses there are, and a caller that writes the rows out (a
    /// [`RunWriter`]) runs any number of houses in the same memory.
    ///
    /// With `keep_going` and an LLM strategy, the questions of every house are asked first, in
    /// a pass of their own over the houses (batch by batch as well), so that the strategies of
    /// an LLM that fails are left out of every house, not only of those after the failure.
    /// Skipped houses go to the feedback as notes (`skipped: …`) as they are read.
    ///
    /// [`RunWriter`]: crate::runs::RunWriter
    ///
    /// Errors: a spec the registry cannot build, the errors of reading the houses (an invalid
    /// house without `skip_invalid` stops the run there), of prefetching LLM answers, and the
    /// first error of `each` (which stops the evaluation).
    pub fn run(
        &self,
        houses: HouseInput<'_>,
        each: &mut dyn FnMut(HouseOutcome<'_>) -> Result<()>,
    ) -> Result<EvaluationTotals> {
        match houses {
            HouseInput::Scenes(scenes) => {
                let open = || -> Result<HouseStream<'_>> {
                    Ok(Box::new(
                        scenes
                            .iter()
                            .map(|s| Ok(HouseEvent::Scene(Box::new(s.clone())))),
                    ))
                };
                self.run_batches_of(
                    &Houses {
                        open: &open,
                        len_hint: scenes.len(),
                    },
                    each,
                )
            }
            HouseInput::Source(source) => {
                let open = || source.houses();
                self.run_batches_of(
                    &Houses {
                        open: &open,
                        len_hint: source.len_hint(),
                    },
                    each,
                )
            }
        }
    }

    /// [`run`](Self::run), keeping every row.
    ///
    /// Errors: those of [`run`](Self::run).
    pub fn collect(&self, houses: HouseInput<'_>) -> Result<SpecEvaluation> {
        let mut rows = Vec::new();
        let run = self.run(houses, &mut |h| {
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
}

/// With one held-out fold (`--holdout-types K/N`), refuses a run none of whose trials has a
/// target of that fold: it would plan nothing and fail at its end. The houses are read once
/// more for it (as far as the first such trial); with every fold, or none, nothing is read.
pub fn check_holdout_has_trials(source: &OpenSource<'_>, draw: &TrialDraw<'_>) -> Result<()> {
    let Some(holdout) = draw.holdout.filter(|h| h.fold().is_some()) else {
        return Ok(());
    };
    for event in source.houses()? {
        if let HouseEvent::Scene(scene) = event?
            && draw.trials(&scene).is_ok_and(|t| !t.is_empty())
        {
            return Ok(());
        }
    }
    Err(crate::LabError::invalid(format!(
        "--holdout-types {holdout}: no trial of these houses has a target of that fold's types, so nothing would run; take another fold, or every fold (`--holdout-types {}`)",
        holdout.folds()
    )))
}

/// Houses that can be read from the start as often as needed.
struct Houses<'a, 'h> {
    open: &'a dyn Fn() -> Result<HouseStream<'h>>,
    /// What a progress bar's length starts at (0: unknown).
    len_hint: usize,
}

/// Up to `n` houses of `stream` (fewer at its end), skipped ones handed to `skipped`.
fn next_batch(
    stream: &mut HouseStream<'_>,
    n: usize,
    skipped: &mut dyn FnMut(String),
) -> Result<Vec<Scene>> {
    let mut batch = Vec::with_capacity(n.min(1024));
    while batch.len() < n {
        match stream.next() {
            Some(event) => match event? {
                HouseEvent::Scene(scene) => batch.push(*scene),
                HouseEvent::Skipped(why) => skipped(why),
            },
            None => break,
        }
    }
    Ok(batch)
}

/// Asks the LLM questions of a batch's mapped houses.
fn prefetch_batch(
    ctx: &EvalContext<'_>,
    scenes: &[Scene],
    maps: &[Mapped],
    before: &mut Prefetched,
) -> Result<PrefetchSummary> {
    let targets = ctx.draw.targets(scenes, maps);
    let pairs: Vec<(&House, &ObjectType)> = targets.iter().map(|(h, t)| (*h, t)).collect();
    prefetch_quiet(&ctx.setup.service, ctx.specs, &pairs, before)
}

/// The strategies an evaluation runs: built from the specs, less those of an LLM that failed.
struct Running<'a> {
    strategies: &'a [Arc<dyn Strategy>],
    names: &'a [String],
}

impl EvalContext<'_> {
    fn run_batches_of(
        &self,
        houses: &Houses<'_, '_>,
        each: &mut dyn FnMut(HouseOutcome<'_>) -> Result<()>,
    ) -> Result<EvaluationTotals> {
        let (specs, llm, feedback) = (self.specs, self.llm, self.feedback);
        let service = &self.setup.service;
        let built: Vec<Arc<dyn Strategy>> = specs
            .iter()
            .map(|s| self.setup.registry.build(s))
            .collect::<std::result::Result<_, _>>()?;
        let asks = crate::strategies::asks_llm(specs);
        let mut asked = PrefetchSummary::default();
        // Under --keep-going a failed LLM's strategies leave every house, so every question is
        // asked before the first trial; otherwise a failure stops the run and each batch asks
        // its own.
        let ask_first = asks && llm.keep_going;
        let dropped = if ask_first {
            feedback.begin("LLM questions", houses.len_hint);
            let all = self.ask_every_batch(houses, &mut asked);
            feedback.end();
            all?;
            prefetch_outcome(service, llm, specs, &asked, feedback)?
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
        // Questions already asked by earlier batches, so that each is asked and counted once.
        let mut prefetched = Prefetched::default();
        feedback.begin("houses", houses.len_hint);
        let result = self.run_batches(
            houses,
            each,
            &Running {
                strategies: &strategies,
                names: &names,
            },
            (asks && !ask_first).then_some((&mut asked, &mut prefetched)),
            &mut totals,
        );
        feedback.end();
        result?;
        if asks && !ask_first {
            prefetch_outcome(service, llm, specs, &asked, feedback)?;
        }
        Ok(totals)
    }

    /// Asks the questions of every house, batch by batch, adding to `asked`, before any trial
    /// runs.
    fn ask_every_batch(&self, houses: &Houses<'_, '_>, asked: &mut PrefetchSummary) -> Result<()> {
        let batch = self.batch.max(1);
        // Questions already asked by earlier batches, so that each is asked and counted once.
        let mut prefetched = Prefetched::default();
        let mut stream = (houses.open)()?;
        let mut read = 0;
        loop {
            let scenes = next_batch(&mut stream, batch, &mut |_| {})?;
            if scenes.is_empty() {
                return Ok(());
            }
            read += scenes.len();
            self.feedback.set_len(houses.len_hint.max(read));
            let maps = build_maps(&scenes, self.grid, &crate::feedback::Silent);
            let summary = prefetch_batch(self, &scenes, &maps, &mut prefetched);
            self.feedback.set_done(read);
            add_summary(asked, summary?);
        }
    }

    /// The run proper: batch after batch, each read, mapped, asked (with `ask`: the sum it adds
    /// to and the questions earlier batches asked) and run, its houses handed to `each`.
    fn run_batches(
        &self,
        houses: &Houses<'_, '_>,
        each: &mut dyn FnMut(HouseOutcome<'_>) -> Result<()>,
        running: &Running<'_>,
        mut ask: Option<(&mut PrefetchSummary, &mut Prefetched)>,
        totals: &mut EvaluationTotals,
    ) -> Result<()> {
        let (feedback, draw, grid) = (self.feedback, self.draw, self.grid);
        let strategies = running.strategies;
        let batch = self.batch.max(1);
        let mut stream = (houses.open)()?;
        loop {
            if feedback.cancelled() {
                return Err(crate::LabError::Cancelled);
            }
            let scenes = next_batch(&mut stream, batch, &mut |why| {
                feedback.note(&format!("skipped: {why}"));
                totals.skipped.push(why);
            })?;
            if scenes.is_empty() {
                break;
            }
            let read = totals.houses.len() + scenes.len();
            feedback.set_len(houses.len_hint.max(read));
            totals.houses.extend(scenes.iter().map(|s| s.house.index));
            let done: Vec<(Mapped, HouseRun)> = if let Some((sum, before)) = ask.as_mut() {
                // The questions wait for the batch's maps (only mapped houses are asked about),
                // so the maps are built first and the trials run after.
                let maps = build_maps(&scenes, grid, &crate::feedback::Silent);
                add_summary(sum, prefetch_batch(self, &scenes, &maps, before)?);
                if !self.setup.service.failed_llms().is_empty() {
                    // Without --keep-going a failed LLM stops the run; the outcome says why.
                    prefetch_outcome(&self.setup.service, self.llm, self.specs, sum, feedback)?;
                }
                scenes
                    .par_iter()
                    .zip(maps)
                    .map(|(scene, map)| {
                        let r = evaluate_house(scene, &map, strategies, draw);
                        feedback.tick();
                        (map, r)
                    })
                    .collect()
            } else {
                scenes
                    .par_iter()
                    .map(|scene| {
                        let map = ferret_world::distance::build(&scene.house, grid);
                        let r = evaluate_house(scene, &map, strategies, draw);
                        feedback.tick();
                        (map, r)
                    })
                    .collect()
            };
            for (scene, (map, (rows, errors, trials))) in scenes.iter().zip(done) {
                totals.houses_run += usize::from(trials > 0);
                totals.trials_run += trials;
                let r = each(HouseOutcome {
                    scene,
                    map: &map,
                    rows,
                    errors: &errors,
                    trials,
                    strategies: running.names,
                });
                totals.errors.extend(errors);
                r?;
            }
        }
        Ok(())
    }
}

/// One house's rows, failure messages and trials drawn.
type HouseRun = (Vec<TrialRow>, Vec<String>, usize);

fn evaluate_house(
    scene: &Scene,
    map: &Mapped,
    strategies: &[Arc<dyn Strategy>],
    draw: &TrialDraw<'_>,
) -> HouseRun {
    let (grid, distances) = match map {
        Ok(m) => m,
        Err(e) => return (vec![], vec![e.to_string()], 0),
    };
    let trials = match draw.trials(scene) {
        Ok(t) => t,
        Err(e) => return (vec![], vec![e.to_string()], 0),
    };
    if let Some(team) = draw.team {
        return evaluate_team(scene, (grid, distances), strategies, draw, team, trials);
    }
    // A house's trials run in parallel too: houses differ in cost by far more than their
    // trials do, so a batch no longer waits for its one slow house on one thread. Collected in
    // order, the rows are those of one trial after another.
    let tasks = draw.tasks.is_some();
    let several = trials.len() > 1;
    let runs: Vec<std::result::Result<TrialRow, String>> = trials
        .par_iter()
        .flat_map_iter(|trial| {
            // The target is named only when a house has several trials: with one, the house
            // says which trial it was.
            let failed = move |s: &str, e: &dyn std::fmt::Display| {
                if several {
                    format!(
                        "{}: {}: {s}: {e}",
                        scene.house.name,
                        trial.task.targets_label()
                    )
                } else {
                    format!("{}: {s}: {e}", scene.house.name)
                }
            };
            // A destination resolved once for every strategy of the trial.
            let legs = trial
                .task
                .destination()
                .map(|d| d.legs(&scene.house, distances))
                .transpose();
            strategies.iter().map(move |s| {
                let legs = legs.as_ref().map_err(|e| failed(s.name(), e))?;
                let mut problem = SearchProblem::new(&scene.house, distances, trial);
                if let Some(l) = legs {
                    problem = problem.with_destination(l);
                }
                run_trial(s.as_ref(), &problem, &scene.truth)
                    .and_then(|out| {
                        let cost =
                            out.reported_cost(&scene.house, distances, draw.protocol.travel_cost)?;
                        Ok(TrialOutcome { cost, ..out })
                    })
                    .map(|out| trial_row(scene, trial, &out, tasks))
                    .map_err(|e| failed(s.name(), &e))
            })
        })
        .collect();
    house_run(runs, trials.len())
}

/// A house's rows and failures, in the order of its trials' runs.
fn house_run(runs: Vec<std::result::Result<TrialRow, String>>, trials: usize) -> HouseRun {
    let (ok, failed): (Vec<_>, Vec<_>) = runs.into_iter().partition(|r| r.is_ok());
    (
        ok.into_iter().filter_map(|r| r.ok()).collect(),
        failed.into_iter().filter_map(|r| r.err()).collect(),
        trials,
    )
}

/// A house's team: each robot's start and its distances, drawn and measured once for the house
/// (the starts from the run's seed), shared by its evaluation and its replays.
pub(crate) struct HouseTeam {
    starts: Vec<ferret_world::grid::Cell>,
    robots: Vec<ferret_world::Distances>,
    grid_start: ferret_world::grid::Cell,
}

impl HouseTeam {
    /// The team of `team` robots in `house` on `grid` (`distances` from the house's start).
    ///
    /// # Errors
    /// A start the house's start cannot reach.
    pub(crate) fn new(
        house: &House,
        (grid, distances): (&ferret_world::OccupancyGrid, &ferret_world::Distances),
        team: TeamSettings,
        seed: u64,
    ) -> std::result::Result<Self, ferret_plan::PlanError> {
        let starts = draw_starts(house, grid, team.robots, team.starts, seed);
        let robots = team_distances(house, grid, distances, &starts)?;
        Ok(Self {
            starts,
            robots,
            grid_start: grid.start_cell(),
        })
    }

    /// The task's destination on each robot's map.
    pub(crate) fn legs(
        &self,
        house: &House,
        task: &ferret_plan::Task,
    ) -> std::result::Result<Vec<Option<ferret_plan::DestinationLegs>>, ferret_plan::TaskError>
    {
        team_destinations(house, task, &self.robots, self.grid_start, &self.starts)
    }

    /// Each robot's search problem of `trial`, with `legs` from [`legs`](Self::legs).
    pub(crate) fn problems<'a>(
        &'a self,
        house: &'a House,
        trial: &'a TrialSpec,
        legs: &'a [Option<ferret_plan::DestinationLegs>],
    ) -> Vec<SearchProblem<'a>> {
        self.robots
            .iter()
            .zip(legs)
            .map(|(d, l)| {
                let p = SearchProblem::new(house, d, trial);
                match l {
                    Some(l) => p.with_destination(l),
                    None => p,
                }
            })
            .collect()
    }
}

/// [`evaluate_house`] with a team on every trial: the robots' starts drawn and their distances
/// measured once for the house, each trial run by [`run_team`].
fn evaluate_team(
    scene: &Scene,
    (grid, distances): (&ferret_world::OccupancyGrid, &ferret_world::Distances),
    strategies: &[Arc<dyn Strategy>],
    draw: &TrialDraw<'_>,
    team: TeamSettings,
    trials: Vec<TrialSpec>,
) -> HouseRun {
    let house = &scene.house;
    let members = match HouseTeam::new(house, (grid, distances), team, draw.seed) {
        Ok(t) => t,
        Err(e) => return (vec![], vec![e.to_string()], 0),
    };
    let tasks = draw.tasks.is_some();
    let runs: Vec<std::result::Result<TrialRow, String>> = trials
        .par_iter()
        .flat_map_iter(|trial| {
            let failed = move |s: &str, e: &dyn std::fmt::Display| {
                format!("{}: {}: {s}: {e}", house.name, trial.task.targets_label())
            };
            let legs = members.legs(house, &trial.task);
            let members = &members;
            strategies.iter().map(move |s| {
                let legs = legs.as_ref().map_err(|e| failed(s.name(), e))?;
                let problems = members.problems(house, trial, legs);
                run_team(s.as_ref(), &problems, &scene.truth)
                    .map(|out| team_row(scene, trial, &out, tasks))
                    .map_err(|e| failed(s.name(), &e))
            })
        })
        .collect();
    house_run(runs, trials.len())
}

/// Each robot's way on the floor in a team's row, first robot first: from its own start (the
/// run's starts drawn again from `seed`) through the containers it searched, in order. The way
/// a robot was on when the trial ended, and the way to a destination, are not in the row.
///
/// # Errors
/// A row that is not a team's, distances that came from no grid, starts the house's start
/// cannot reach.
pub fn team_paths(
    scene: &Scene,
    distances: &ferret_world::Distances,
    team: TeamSettings,
    seed: u64,
    row: &TrialRow,
) -> Result<Vec<Vec<ferret_world::Point>>> {
    let house = &scene.house;
    let by: Vec<usize> = row
        .searched_by
        .as_deref()
        .ok_or_else(|| {
            crate::LabError::invalid(format!("{}: the row is not a team's", house.name))
        })?
        .split_whitespace()
        .map(|r| r.parse::<usize>())
        .collect::<std::result::Result<_, _>>()
        .map_err(|e| crate::LabError::invalid(format!("{}: searched_by: {e}", house.name)))?;
    let grid = distances.grid().ok_or_else(|| {
        crate::LabError::invalid(format!("{}: a team's paths need a grid", house.name))
    })?;
    let starts = draw_starts(house, grid, team.robots, team.starts, seed);
    let robots = team_distances(house, grid, distances, &starts)?;
    let searched: Vec<usize> = row
        .searched
        .split_whitespace()
        .filter_map(|id| house.container_index(id))
        .collect();
    Ok(robots
        .iter()
        .enumerate()
        .map(|(r, d)| {
            let visits: Vec<ferret_world::Place> = std::iter::once(ferret_world::Place::Start)
                .chain(
                    searched
                        .iter()
                        .zip(&by)
                        .filter(|(_, b)| **b == r)
                        .map(|(&c, _)| ferret_world::Place::Container(c)),
                )
                .collect();
            visits
                .windows(2)
                .filter_map(|w| d.path(w[0], w[1]))
                .flatten()
                .collect()
        })
        .collect())
}

/// The `trials.csv` row of a team's trial: [`trial_row`] of its outcome (the cost is the
/// makespan) with the team's columns.
pub fn team_row(scene: &Scene, trial: &TrialSpec, out: &TeamOutcome, tasks: bool) -> TrialRow {
    TrialRow {
        robots: Some(out.robots.len()),
        total_travel_m: Some(out.total_travel),
        searched_by: Some(
            out.searched_by
                .iter()
                .map(ToString::to_string)
                .collect::<Vec<_>>()
                .join(" "),
        ),
        ..trial_row(scene, trial, &out.trial, tasks)
    }
}

/// The `trials.csv` row of a finished trial; with `tasks`, the task's columns too (every row of
/// a run of tasks has them, none of a run of single targets).
pub fn trial_row(scene: &Scene, trial: &TrialSpec, out: &TrialOutcome, tasks: bool) -> TrialRow {
    let house = &scene.house;
    let id = |c: usize| {
        house
            .containers
            .get(c)
            .map_or_else(|| c.to_string(), |x| x.id.clone())
    };
    let task = &trial.task;
    let holding = |c: usize| task.targets().iter().any(|t| scene.truth.holds(c, t));
    TrialRow {
        house: house.name.clone(),
        house_index: house.index,
        target: task.targets_label(),
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
        goal_containers: (0..house.containers.len()).filter(|&c| holding(c)).count(),
        cost_cells: None,
        goal: tasks.then(|| task.goal().to_string()),
        destination: tasks.then(|| {
            task.destination()
                .map(|d| d.label(house))
                .unwrap_or_default()
        }),
        found_each: tasks.then(|| {
            out.found_each
                .iter()
                .map(|f| f.map_or_else(|| "-".to_string(), id))
                .collect::<Vec<_>>()
                .join(" ")
        }),
        delivery_m: tasks.then_some(out.delivery),
        robots: None,
        total_travel_m: None,
        searched_by: None,
    }
}
