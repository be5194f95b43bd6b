//! An evaluation run into its directory, as `ferret eval` runs it: the options checked before
//! anything is read or written, the directory claimed, the houses read and evaluated batch by
//! batch with their rows streamed to `trials.csv`, and `run.json` and the report written. A
//! face draws the pictures and prints what [`EvalJob::run`] returns.

use std::path::Path;

use ferret_plan::{Destination, Protocol, TeamSettings, TrialSpec, TrialsPerHouse};
use ferret_world::{ContainerSet, Distances, GridParams, Scene};

use crate::error::{LabError, Result};
use crate::evaluate::{
    EvalContext, EvaluationTotals, HouseInput, TrialDraw, check_holdout_has_trials,
};
use crate::feedback::Feedback;
use crate::files::DirLock;
use crate::houses::{HouseEvent, HouseSource};
use crate::rows::TrialRow;
use crate::runs::{ReportView, RunInfo, RunWriter, WrittenRun};
use crate::shard::{SHARD_RULE, Shard, ShardRecord};
use crate::strategies::{LlmSettings, PlanningSettings, Strategies, check_distinct};
use crate::tasks::Tasks;

/// An evaluation run: which houses, strategies and trials, and where its files go.
#[derive(Clone, Copy, Debug)]
pub struct EvalJob<'a> {
    /// Where the houses come from.
    pub source: &'a HouseSource,
    /// The grid of the maps (its access rule is the protocol's).
    pub grid: GridParams,
    /// Planner and prior settings.
    pub planning: &'a PlanningSettings,
    /// LLM endpoints, cache and what a failed endpoint means.
    pub llm: &'a LlmSettings,
    /// The strategies, in order.
    pub specs: &'a [String],
    /// Seed of the trials.
    pub seed: u64,
    /// Fraction of non-goal containers revealed as searched before each trial.
    pub reveal_fraction: f64,
    /// Trials per house.
    pub trials_per_house: TrialsPerHouse,
    /// Household tasks instead of one target per trial.
    pub tasks: Option<&'a Tasks>,
    /// A team of robots on every trial instead of one.
    pub team: Option<TeamSettings>,
    /// The protocol the trials follow.
    pub protocol: &'a Protocol,
    /// Costs in grid cells too.
    pub cells: bool,
    /// More references for the paired comparisons, each one of `specs`.
    pub paired_against: &'a [String],
    /// The house whose trajectories are shown; the first where every strategy finished when
    /// `None`.
    pub show_house: Option<usize>,
    /// The shard of the houses to run; all of them when `None`.
    pub shard: Option<Shard>,
    /// The run directory.
    pub out: &'a Path,
}

/// The house whose trajectories are drawn: the first (in house order) where every strategy that
/// ran finished a trial, or the one asked for; all of it that the picture needs.
pub struct ShownHouse {
    /// The house.
    pub scene: Scene,
    /// Its distances (and routes).
    pub distances: Distances,
    /// Its rows.
    pub rows: Vec<TrialRow>,
}

/// A finished evaluation run, its files written.
pub struct EvalDone {
    /// run.json, the report and the rows' costs, as written.
    pub written: WrittenRun,
    /// The strategies that ran, the failures and the houses.
    pub totals: EvaluationTotals,
    /// Rows of trials.csv.
    pub rows: usize,
    /// The house to draw, when there is one (never for a shard: its merge draws it).
    pub shown: Option<ShownHouse>,
    /// The strategies and the LLM service, for its token report.
    pub setup: Strategies,
}

impl EvalJob<'_> {
    /// Refuses options that cannot be used, before anything is read or written.
    pub fn validate(&self) -> Result<()> {
        if !(0.0..=1.0).contains(&self.reveal_fraction) {
            return Err(LabError::invalid(format!(
                "--reveal-fraction {}: must be a fraction between 0 and 1",
                self.reveal_fraction
            )));
        }
        check_distinct("--strategies", self.specs)?;
        check_team(self.team, self.protocol)?;
        if let Some(s) = self.paired_against.iter().find(|s| !self.specs.contains(s)) {
            return Err(LabError::invalid(format!(
                "--paired-against {s}: not one of --strategies"
            )));
        }
        Ok(())
    }

    /// Runs the evaluation into [`out`](Self::out): `trials.csv` as houses finish (only their
    /// costs stay in memory, and of the maps only the shown house's), then `run.json`,
    /// `summary.csv`, `summary.md` and (not for a shard) `paired.csv`. Failures of houses or
    /// trials go to `feedback` as notes (`error: …`); every finished trial is written.
    ///
    /// Errors: unusable options, a `show_house` the source does not hold, a held-out fold with
    /// no trial, a directory another run holds, the errors of evaluating, no houses, and no
    /// trial finished (the directory is then left as it was).
    pub fn run(&self, feedback: &dyn Feedback) -> Result<EvalDone> {
        self.validate()?;
        let protocol = self.protocol;
        let open = self.source.open(protocol.containers, self.shard)?;
        // A shard draws no pictures and may not hold the house: the merge draws it. Only that
        // house is read here; the others are read once, by the run.
        if let Some(i) = self.show_house
            && self.shard.is_none()
            && !has_house(self.source, protocol.containers, i)?
        {
            return Err(LabError::invalid(format!(
                "--show-house {i}: no house with that index in {}",
                self.source.describe()
            )));
        }
        let setup = Strategies::builder(self.planning, self.llm)
            .for_specs(self.specs)
            .build()?;
        let draw = TrialDraw {
            seed: self.seed,
            reveal_fraction: self.reveal_fraction,
            per_house: self.trials_per_house,
            protocol,
            holdout: self.planning.holdout,
            tasks: self.tasks,
            team: self.team,
        };
        check_holdout_has_trials(&open, &draw)?;
        let grid = GridParams {
            access: protocol.access,
            ..self.grid
        };
        check_listed_tasks(self.source, &draw, &grid)?;
        // Claimed before the evaluation, so that a second run into the same directory stops at
        // once rather than after its work, its files then replacing this one's.
        let mut out_lock = DirLock::acquire(self.out)?;
        let mut writer = RunWriter::create(self.out, self.cells)?;
        let mut shown: Option<ShownHouse> = None;
        let context = EvalContext::new(&setup, self.specs, &draw, &grid, self.llm, feedback);
        let totals = context.run(HouseInput::Source(&open), &mut |h| {
            if self.shard.is_none()
                && shown.is_none()
                && self.show_house.is_none_or(|i| h.scene.house.index == i)
                && h.every_strategy_finished()
                && let Ok((_, distances)) = h.map
            {
                shown = Some(ShownHouse {
                    scene: h.scene.clone(),
                    distances: distances.clone(),
                    rows: h.rows.clone(),
                });
            }
            for r in &h.rows {
                writer.push(r)?;
            }
            Ok(())
        })?;
        self.check_ran(&totals, feedback)?;
        if writer.rows() == 0 {
            return Err(LabError::invalid(format!(
                "no trial finished; {} was left as it was",
                self.out.display()
            )));
        }
        out_lock.used();
        let rows = writer.rows();
        let source = self.source.describe();
        let written = writer.finish(
            self.run_info(&totals),
            &ReportView {
                source: &source,
                houses: &totals.houses,
                houses_run: totals.houses_run,
                trials_run: totals.trials_run,
                paired_against: self.paired_against,
                cells: self.cells,
            },
        )?;
        Ok(EvalDone {
            written,
            totals,
            rows,
            shown,
            setup,
        })
    }

    /// Says which houses a shard ran, refuses a run without houses, and notes every failure.
    fn check_ran(&self, totals: &EvaluationTotals, feedback: &dyn Feedback) -> Result<()> {
        if let Some(sh) = self.shard {
            feedback.note(&format!(
                "shard {sh}: {} houses (file index mod {} = {})",
                totals.houses.len(),
                sh.count,
                sh.index
            ));
        }
        if totals.houses.is_empty() {
            return Err(LabError::invalid(match self.shard {
                Some(sh) => format!(
                    "shard {sh}: no house of {} has a file index that is {} modulo {}; use fewer shards",
                    self.source.describe(),
                    sh.index,
                    sh.count
                ),
                None => format!("no houses to evaluate in {}", self.source.describe()),
            }));
        }
        for e in &totals.errors {
            feedback.note(&format!("error: {e}"));
        }
        Ok(())
    }

    /// What `run.json` records of this run.
    fn run_info(&self, totals: &EvaluationTotals) -> RunInfo {
        let source = self.source;
        RunInfo {
            houses: source.houses.clone(),
            range: source.range.as_ref().map(ToString::to_string),
            asset_db: source.asset_db.clone(),
            generate: source.generate,
            house_seed: source.house_seed,
            grid: [
                self.grid.resolution,
                self.grid.robot_radius,
                self.grid.wall_thickness,
            ],
            planning: self.planning.clone(),
            seed: self.seed,
            reveal_fraction: self.reveal_fraction,
            trials_per_house: self.trials_per_house,
            protocol: *self.protocol,
            tasks: self.tasks.cloned(),
            team: self.team,
            strategies: self.specs.to_vec(),
            trials_sha256: None,
            shard: self.shard.map(|sh| ShardRecord {
                index: sh.index,
                count: sh.count,
                rule: SHARD_RULE.into(),
                houses: totals.houses.clone(),
                houses_run: totals.houses_run,
                trials_run: totals.trials_run,
                failures: totals.errors.len(),
                paired_against: self.paired_against.to_vec(),
                cells: self.cells,
                show_house: self.show_house,
            }),
            merged_from: Vec::new(),
        }
    }
}

/// Refuses a team under a protocol whose cost a team cannot have: a team's makespan is plain
/// metres, the soft travel cost measures one robot's legs.
pub fn check_team(team: Option<TeamSettings>, protocol: &Protocol) -> Result<()> {
    match team {
        Some(t) if protocol.travel_cost != ferret_world::TravelCost::Plain => {
            Err(LabError::invalid(format!(
                "a team of {} robots: a team's makespan is measured in plain metres, and this protocol's soft travel cost measures one robot's legs (use a protocol with the plain travel cost)",
                t.robots
            )))
        }
        _ => Ok(()),
    }
}

/// Refuses, before anything runs, a list of tasks that does not fit its houses: a house the
/// source does not hold, a target of `all` no container of its house holds, a container or
/// room its house does not have, a point off the floor the robot reaches. Reads every house
/// of the source once (see [`check_listed_tasks_in`]).
pub fn check_listed_tasks(
    source: &HouseSource,
    draw: &TrialDraw<'_>,
    grid: &GridParams,
) -> Result<()> {
    let Some(Tasks::Listed { .. }) = draw.tasks else {
        return Ok(());
    };
    let open = source.open(draw.protocol.containers, None)?;
    // Skipped (invalid) houses hold no task: a line naming one is a house the source does not
    // hold, as before.
    let scenes = open.houses()?.filter_map(|event| match event {
        Ok(HouseEvent::Scene(scene)) => Some(Ok(scene)),
        Ok(HouseEvent::Skipped(_)) => None,
        Err(e) => Some(Err(e)),
    });
    check_listed_tasks_in(scenes, &source.describe(), draw, grid)
}

/// [`check_listed_tasks`] over houses already read (`scenes`, in any order; `source` names
/// them in the error for a house that is not among them): for a face that holds its houses in
/// memory. Maps only the houses with a destination in a room or at a point.
pub fn check_listed_tasks_in<S: std::borrow::Borrow<Scene>>(
    scenes: impl IntoIterator<Item = Result<S>>,
    source: &str,
    draw: &TrialDraw<'_>,
    grid: &GridParams,
) -> Result<()> {
    let Some(tasks @ Tasks::Listed { lines }) = draw.tasks else {
        return Ok(());
    };
    let wanted = tasks.listed_houses();
    let mut seen = std::collections::BTreeSet::new();
    for scene in scenes {
        let scene = scene?;
        let scene: &Scene = std::borrow::Borrow::borrow(&scene);
        let index = scene.house.index;
        if !wanted.contains(&index) {
            continue;
        }
        seen.insert(index);
        let trials = draw.trials(scene)?;
        let spot = |t: &&TrialSpec| {
            matches!(
                t.task.destination(),
                Some(Destination::Room { .. } | Destination::Point { .. })
            )
        };
        if trials.iter().any(|t| spot(&t)) {
            let (_, distances) = ferret_world::distance::build(&scene.house, grid)?;
            for (k, t) in trials.iter().filter(spot).enumerate() {
                if let Some(d) = t.task.destination() {
                    d.legs(&scene.house, &distances)
                        .map_err(|error| LabError::Task {
                            place: format!("house {index}, task {}", k + 1),
                            error,
                        })?;
                }
            }
        }
    }
    if let Some((k, line)) = lines
        .iter()
        .enumerate()
        .find(|(_, l)| !seen.contains(&l.house))
    {
        return Err(LabError::Task {
            place: format!("task {}", k + 1),
            error: ferret_plan::TaskError::new(
                "house",
                format!("no house {} in {source}", line.house),
            ),
        });
    }
    Ok(())
}

/// Whether `source` holds a valid house of index `i` (inside its range), reading that house
/// alone. Errors of the file other than the range are the file's.
fn has_house(source: &HouseSource, containers: ContainerSet, i: usize) -> Result<bool> {
    if source.range.is_some_and(|r| !r.contains(i)) {
        return Ok(false);
    }
    let one = HouseSource {
        range: Some(ferret_world::procthor::HouseRange::single(i)),
        ..source.clone()
    };
    match one.load_for(containers) {
        Ok(loaded) => Ok(loaded.scenes.iter().any(|s| s.house.index == i)),
        Err(LabError::World(ferret_world::WorldError::Range { .. })) => Ok(false),
        Err(e) => Err(e),
    }
}
