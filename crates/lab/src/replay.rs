//! The replay table behind strategy selection: what every candidate would have cost on every
//! trial of an evaluation run where each other candidate was deployed. Replays are cached in
//! `replay.csv` beside the run, keyed to the run's exact files; each house's replays are
//! appended as soon as they finish, so an interrupted computation resumes where it stopped.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::io::Write;
use std::path::Path;
use std::sync::{Arc, Mutex};

use ferret_llm::LlmService;
use ferret_plan::{
    PlanError, Protocol, ReplayMode, SearchProblem, Strategy, replay_outcome_with,
    replay_team_cost_with,
};
use ferret_select::{CostTable, ORACLE};
use ferret_world::{Distances, Scene};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::error::{LabError, Result};
use crate::evaluate::{HouseTeam, TrialDraw};
use crate::feedback::Feedback;
use crate::houses::{Mapped, build_maps};
use crate::rows::TrialRow;
use crate::runs::{EvalRun, RunInfo, read_run_file};
use crate::strategies::{LlmSettings, Strategies};

/// One row of `replay.csv`: the replay cost of `strategy` on the trial of `house_index` and
/// `target` where `deployed` was run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ReplayRow {
    /// House index.
    pub house_index: usize,
    /// Target of the trial (a house has several trials under `--trials-per-house`).
    pub target: String,
    /// The deployed strategy.
    pub deployed: String,
    /// The replayed strategy.
    pub strategy: String,
    /// Replay cost, metres.
    pub replay_cost_m: f64,
}

/// The identity of an eval run's trials: SHA-256 of run.json and trials.csv. Replays are only
/// valid for the exact trials they were computed on.
pub fn trials_key(run_json: &[u8], trials_csv: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    for part in [run_json, trials_csv] {
        h.update((part.len() as u64).to_le_bytes());
        h.update(part);
    }
    format!("{:x}", h.finalize())
}

/// A trial of an eval run: house index and target.
pub type TrialId = (usize, String);

/// The rows of every trial, by strategy.
pub type Trials<'a> = BTreeMap<TrialId, HashMap<&'a str, &'a TrialRow>>;

/// House index, target, deployed strategy, replayed strategy.
pub type ReplayKey = (usize, String, String, String);

/// First line of replay.csv: the trials the cache belongs to (see [`trials_key`]).
const CACHE_KEY_PREFIX: &str = "# ferret replay cache for trials sha256:";

/// The header of replay.csv after the key line.
const CACHE_HEADER: &str = "house_index,target,deployed,strategy,replay_cost_m\n";

/// What a replay cache held that can be used, and why the rest cannot.
#[derive(Debug, Default)]
struct CacheRead {
    /// Usable replay costs.
    known: HashMap<ReplayKey, f64>,
    /// Why the file as a whole was set aside (other trials, no key), if it was.
    stale: Option<String>,
    /// One message per dropped row, naming its line.
    dropped: Vec<String>,
}

/// Reads the text of a replay cache for the trials `key`. Rows are kept only when they name a
/// house of `houses`, two different `candidates`, and a finite cost ≥ 0; a key given twice is
/// dropped altogether (which copy is right cannot be told); a last line without its newline was
/// cut by an interrupted write and is dropped. Dropped rows are replayed again.
fn parse_replay_cache(
    text: &[u8],
    key: &str,
    candidates: &[String],
    houses: &Trials<'_>,
) -> CacheRead {
    let mut read = CacheRead::default();
    let (first, rest) = match text.iter().position(|&b| b == b'\n') {
        Some(i) => (&text[..i], &text[i + 1..]),
        None => (text, &text[text.len()..]),
    };
    let first = String::from_utf8_lossy(first);
    match first.strip_prefix(CACHE_KEY_PREFIX) {
        Some(k) if k.trim() == key => {}
        Some(_) => {
            read.stale =
                Some("it was computed for other trials (run.json or trials.csv changed)".into());
            return read;
        }
        None => {
            read.stale = Some("it does not say which trials it was computed for".into());
            return read;
        }
    }
    let complete = text.ends_with(b"\n");
    let mut reader = csv::ReaderBuilder::new().flexible(true).from_reader(rest);
    let headers = match reader.headers() {
        Ok(h) if h.iter().eq(CACHE_HEADER.trim_end().split(',')) => h.clone(),
        _ => {
            read.stale = Some("its header is not the replay header".into());
            return read;
        }
    };
    let mut rows: Vec<(u64, ReplayRow)> = Vec::new();
    let mut records = reader.records().peekable();
    while let Some(record) = records.next() {
        let is_last = records.peek().is_none();
        // The key line comes before the CSV text.
        let line = |r: &csv::StringRecord| r.position().map_or(0, |p| p.line() + 1);
        let record = match record {
            Ok(r) => r,
            Err(e) => {
                let at = e.position().map_or(0, |p| p.line() + 1);
                read.dropped.push(format!("line {at}: {e}"));
                continue;
            }
        };
        let at = line(&record);
        if is_last && !complete {
            read.dropped
                .push(format!("line {at}: cut short by an interrupted write"));
            continue;
        }
        let row: ReplayRow = match record.deserialize(Some(&headers)) {
            Ok(r) => r,
            Err(e) => {
                read.dropped.push(format!("line {at}: {e}"));
                continue;
            }
        };
        let why = if !houses.contains_key(&(row.house_index, row.target.clone())) {
            Some(format!(
                "house {}, target {} has no trial of every strategy in trials.csv",
                row.house_index, row.target
            ))
        } else if !candidates.contains(&row.deployed) {
            Some(format!("unknown deployed strategy `{}`", row.deployed))
        } else if !candidates.contains(&row.strategy) {
            Some(format!("unknown strategy `{}`", row.strategy))
        } else if row.deployed == row.strategy {
            Some(format!("`{}` replayed on its own trial", row.strategy))
        } else if !(row.replay_cost_m.is_finite() && row.replay_cost_m >= 0.0) {
            Some(format!(
                "replay cost {} is not a finite number ≥ 0",
                row.replay_cost_m
            ))
        } else {
            None
        };
        match why {
            Some(why) => read.dropped.push(format!("line {at}: {why}")),
            None => rows.push((at, row)),
        }
    }
    let mut lines: HashMap<ReplayKey, Vec<u64>> = HashMap::new();
    for (at, r) in &rows {
        lines
            .entry((
                r.house_index,
                r.target.clone(),
                r.deployed.clone(),
                r.strategy.clone(),
            ))
            .or_default()
            .push(*at);
    }
    for (at, r) in rows {
        let k = (r.house_index, r.target, r.deployed, r.strategy);
        match lines.get(&k) {
            Some(l) if l.len() > 1 => read.dropped.push(format!(
                "line {at}: house {}, target {}, {} deployed, {} is also on line(s) {}",
                k.0,
                k.1,
                k.2,
                k.3,
                l.iter()
                    .filter(|&&x| x != at)
                    .map(u64::to_string)
                    .collect::<Vec<_>>()
                    .join(", ")
            )),
            _ => {
                read.known.insert(k, r.replay_cost_m);
            }
        }
    }
    read
}

/// Serializes replay rows as CSV lines without a header.
fn replay_lines(rows: &[ReplayRow]) -> Result<Vec<u8>> {
    let csv_error = |source| LabError::Csv {
        context: "writing replay rows".into(),
        source,
    };
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(Vec::new());
    for r in rows {
        w.serialize(r).map_err(csv_error)?;
    }
    w.into_inner()
        .map_err(|e| LabError::io("writing replay rows", e.into_error()))
}

/// Rewrites the replay cache whole (atomically): key line, header and `known`.
fn rewrite_replay_cache(path: &Path, key: &str, known: &HashMap<ReplayKey, f64>) -> Result<()> {
    let mut all: Vec<ReplayRow> = known
        .iter()
        .map(|((h, t, d, s), c)| ReplayRow {
            house_index: *h,
            target: t.clone(),
            deployed: d.clone(),
            strategy: s.clone(),
            replay_cost_m: *c,
        })
        .collect();
    all.sort_by(|a, b| {
        (a.house_index, &a.target, &a.deployed, &a.strategy).cmp(&(
            b.house_index,
            &b.target,
            &b.deployed,
            &b.strategy,
        ))
    });
    let body = replay_lines(&all)?;
    crate::files::write_atomic(path, |w| {
        writeln!(w, "{CACHE_KEY_PREFIX}{key}")?;
        w.write_all(CACHE_HEADER.as_bytes())?;
        w.write_all(&body)
    })
    .map_err(|e| LabError::io(format!("writing {}", path.display()), e))
}

/// The trial draw an evaluation run used.
fn run_draw(info: &RunInfo) -> TrialDraw<'_> {
    TrialDraw {
        seed: info.seed,
        reveal_fraction: info.reveal_fraction,
        per_house: info.trials_per_house,
        protocol: &info.protocol,
        holdout: info.planning.holdout,
        tasks: info.tasks.as_ref(),
        team: None,
    }
}

/// The replay table of an evaluation run, ready for a selection experiment.
pub struct ReplayTable {
    /// Costs and replay costs, houses labelled by name (and target, with several per house).
    pub table: CostTable,
    /// The candidate strategies, in the run's order (the oracle is never one).
    pub candidates: Vec<String>,
    /// The trials (house index and target) every candidate finished, in order.
    pub trials: Vec<TrialId>,
    /// Distinct houses among them.
    pub distinct_houses: usize,
    /// The LLM service used for replays that had to be computed, for its token report.
    pub service: Option<Arc<LlmService>>,
}

impl ReplayTable {
    /// Whether some house has more than one trial (deployments then draw one per house).
    pub fn several_per_house(&self) -> bool {
        self.trials.len() > self.distinct_houses
    }
}

/// The replay table of `run` under `protocol` (whose trial settings must be the run's; its
/// replay mode decides what a replay assumes), read from the cache at `cache` where it holds
/// them and computed (and appended to it) where not. With `min_houses`, fails before any replay
/// when fewer houses have a trial of every candidate.
pub fn replay_table(
    run: &EvalRun,
    protocol: &Protocol,
    llm: &LlmSettings,
    cache: &Path,
    min_houses: usize,
    feedback: &dyn Feedback,
) -> Result<ReplayTable> {
    let info = &run.info;
    let rows = &run.rows;
    // Counterfactual replays are other numbers than pessimistic ones: they are cached under a
    // key of their own (the pessimistic key stays the plain one, so existing caches stay valid).
    let key = match protocol.replay {
        ReplayMode::Pessimistic => trials_key(&run.run_json, &run.trials_csv),
        ReplayMode::Counterfactual => trials_key(
            &[&run.run_json[..], b"\nreplay=counterfactual"].concat(),
            &run.trials_csv,
        ),
    };
    let candidates: Vec<String> = info
        .strategies
        .iter()
        .filter(|s| s.as_str() != ORACLE && rows.iter().any(|r| &r.strategy == *s))
        .cloned()
        .collect();
    if candidates.len() < 2 {
        return Err(LabError::TooFewCandidates);
    }
    // Trials (house and target) that every candidate finished.
    let mut by_house: Trials<'_> = BTreeMap::new();
    for r in rows {
        by_house
            .entry((r.house_index, r.target.clone()))
            .or_default()
            .insert(r.strategy.as_str(), r);
    }
    by_house.retain(|_, m| candidates.iter().all(|s| m.contains_key(s.as_str())));
    let distinct_houses = by_house.keys().map(|k| k.0).collect::<BTreeSet<_>>().len();
    if distinct_houses < min_houses {
        return Err(LabError::TooFewHouses {
            have: distinct_houses,
            need: min_houses,
        });
    }
    let (replays, service) = ReplayJob {
        info,
        llm,
        candidates: &candidates,
        by_house: &by_house,
        cache,
        key: &key,
        mode: protocol.replay,
        feedback,
    }
    .load_or_compute()?;
    let trials: Vec<TrialId> = by_house.keys().cloned().collect();
    let s = candidates.len();
    let mut cost = Vec::with_capacity(trials.len());
    let mut replay = Vec::with_capacity(trials.len());
    for h in &trials {
        let m = &by_house[h];
        cost.push(
            candidates
                .iter()
                .map(|c| m[c.as_str()].cost_m)
                .collect::<Vec<_>>(),
        );
        let mut by_deployed = vec![vec![0.0; s]; s];
        for (j, dj) in candidates.iter().enumerate() {
            for (i, si) in candidates.iter().enumerate() {
                by_deployed[j][i] = if i == j {
                    m[si.as_str()].cost_m
                } else {
                    *replays
                        .get(&(h.0, h.1.clone(), dj.clone(), si.clone()))
                        .ok_or_else(|| {
                            LabError::invalid(format!(
                                "replay.csv lacks house {}, target {}, {dj} deployed, {si}",
                                h.0, h.1
                            ))
                        })?
                };
            }
        }
        replay.push(by_deployed);
    }
    // Labels must be distinct: a house with several trials is labelled per target.
    let several = trials.len() > distinct_houses;
    let labels = trials
        .iter()
        .map(|h| {
            let l = by_house[h]
                .values()
                .next()
                .map(|r| r.house.clone())
                .unwrap_or_default();
            if several { format!("{l}/{}", h.1) } else { l }
        })
        .collect();
    let table = CostTable::new(candidates.clone(), labels, cost, replay)?;
    // One trial per house and deployment: a deployment draws distinct houses.
    let table = if several {
        table.grouped(trials.iter().map(|h| h.0).collect())?
    } else {
        table
    };
    Ok(ReplayTable {
        table,
        candidates,
        trials,
        distinct_houses,
        service,
    })
}

/// Replay costs by key, and the LLM service that computed any new ones (to write its token use).
type LoadedReplays = (HashMap<ReplayKey, f64>, Option<Arc<LlmService>>);

/// The replays a run's replay table needs: its candidates on the trials every one finished,
/// cached at `cache` under `key` (the run's identity and replay mode).
struct ReplayJob<'a> {
    info: &'a RunInfo,
    llm: &'a LlmSettings,
    candidates: &'a [String],
    by_house: &'a Trials<'a>,
    cache: &'a Path,
    key: &'a str,
    mode: ReplayMode,
    feedback: &'a dyn Feedback,
}

impl ReplayJob<'_> {
    /// The replay costs: those the cache holds, and the missing ones computed (and appended).
    fn load_or_compute(&self) -> Result<LoadedReplays> {
        let mut known = self.read_cache()?;
        let todo = self.houses_missing(&known);
        if todo.is_empty() {
            return Ok((known, None));
        }
        self.feedback.note(&format!(
            "replaying {} strategies on {} houses (cached in {})",
            self.candidates.len(),
            todo.len(),
            self.cache.display()
        ));
        let service = self.replay_houses(&todo, &mut known)?;
        Ok((known, Some(service)))
    }

    /// The cache's replays of this run; a cache of another run, or rows that do not fit this
    /// one, are noted and the cache rewritten without them.
    fn read_cache(&self) -> Result<HashMap<ReplayKey, f64>> {
        let path = self.cache;
        let read = match read_run_file(path) {
            Ok(text) => {
                let read = parse_replay_cache(&text, self.key, self.candidates, self.by_house);
                self.note_dropped(&read);
                Some(read)
            }
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
            Err(e) => return Err(LabError::io(format!("reading {}", path.display()), e)),
        };
        let needs_rewrite = read
            .as_ref()
            .is_none_or(|r| r.stale.is_some() || !r.dropped.is_empty());
        let known = read.map(|r| r.known).unwrap_or_default();
        if needs_rewrite {
            rewrite_replay_cache(path, self.key, &known)?;
        }
        Ok(known)
    }

    /// Says why the cache, or some of its rows, are replayed again (the first few rows only).
    fn note_dropped(&self, read: &CacheRead) {
        const SHOWN: usize = 10;
        let path = self.cache.display();
        if let Some(why) = &read.stale {
            self.feedback
                .note(&format!("{path}: {why}; replaying again"));
        }
        for d in read.dropped.iter().take(SHOWN) {
            self.feedback
                .note(&format!("{path}: {d}; row dropped and replayed again"));
        }
        if read.dropped.len() > SHOWN {
            self.feedback.note(&format!(
                "{path}: {} more rows dropped",
                read.dropped.len() - SHOWN
            ));
        }
    }

    /// Indices of the houses with a trial some pair of candidates has no replay for, in order.
    fn houses_missing(&self, known: &HashMap<ReplayKey, f64>) -> Vec<usize> {
        let candidates = self.candidates;
        let missing = |h: &TrialId| {
            candidates.iter().any(|j| {
                candidates.iter().any(|i| {
                    i != j && !known.contains_key(&(h.0, h.1.clone(), j.clone(), i.clone()))
                })
            })
        };
        self.by_house
            .keys()
            .filter(|h| missing(h))
            .map(|h| h.0)
            .collect::<BTreeSet<_>>()
            .into_iter()
            .collect()
    }

    /// Replays every candidate on the houses `todo`, in parallel, adding their costs to `known`
    /// and appending each house's new rows to the cache as soon as it finishes, so that a killed
    /// run keeps them. Returns the LLM service the replays used.
    fn replay_houses(
        &self,
        todo: &[usize],
        known: &mut HashMap<ReplayKey, f64>,
    ) -> Result<Arc<LlmService>> {
        let (info, feedback, path) = (self.info, self.feedback, self.cache);
        let loaded = info.house_source().load_for(info.protocol.containers)?;
        let scenes: Vec<Scene> = loaded
            .scenes
            .into_iter()
            .filter(|s| todo.contains(&s.house.index))
            .collect();
        let maps = build_maps(&scenes, &info.grid_params(info.protocol.access), feedback);
        let setup = Strategies::builder(&info.planning, self.llm)
            .for_specs(self.candidates)
            .build()?;
        let strategies: Vec<Arc<dyn Strategy>> = self
            .candidates
            .iter()
            .map(|s| setup.registry.build(s))
            .collect::<Result<_, _>>()?;
        let cache = Mutex::new(
            std::fs::OpenOptions::new()
                .append(true)
                .open(path)
                .map_err(|e| LabError::io(format!("opening {}", path.display()), e))?,
        );
        feedback.begin("replays", scenes.len());
        let known_before: &HashMap<ReplayKey, f64> = known;
        let results: Vec<Result<Vec<ReplayRow>>> = scenes
            .par_iter()
            .zip(maps.par_iter())
            .map(|(scene, map)| {
                let r = self.replay_and_append(scene, map, &strategies, known_before, &cache);
                feedback.tick();
                r
            })
            .collect();
        feedback.end();
        let mut errors = Vec::new();
        for r in results {
            match r {
                Ok(rows) => {
                    for r in rows {
                        known.insert(
                            (r.house_index, r.target, r.deployed, r.strategy),
                            r.replay_cost_m,
                        );
                    }
                }
                Err(e) => errors.push(ferret_world::error_chain(&e)),
            }
        }
        if !errors.is_empty() {
            return Err(LabError::invalid(format!(
                "{} house(s) could not be replayed; the others are cached in {}:\n{}",
                errors.len(),
                path.display(),
                errors.join("\n")
            )));
        }
        Ok(setup.service)
    }

    /// One house's replays, its rows the cache lacks appended to `cache`.
    fn replay_and_append(
        &self,
        scene: &Scene,
        map: &Mapped,
        strategies: &[Arc<dyn Strategy>],
        known: &HashMap<ReplayKey, f64>,
        cache: &Mutex<std::fs::File>,
    ) -> Result<Vec<ReplayRow>> {
        let (_, distances) = map.as_ref().map_err(|e| LabError::invalid(e.to_string()))?;
        let trials: Vec<(&String, &HashMap<&str, &TrialRow>)> = self
            .by_house
            .iter()
            .filter(|(k, _)| k.0 == scene.house.index)
            .map(|(k, m)| (&k.1, m))
            .collect();
        let rows = replay_house(scene, distances, strategies, &trials, self.info, self.mode)?;
        // A house is replayed whole; rows already cached are not written twice.
        let new: Vec<ReplayRow> = rows
            .iter()
            .filter(|r| {
                !known.contains_key(&(
                    r.house_index,
                    r.target.clone(),
                    r.deployed.clone(),
                    r.strategy.clone(),
                ))
            })
            .cloned()
            .collect();
        let lines = replay_lines(&new)?;
        let mut file = cache.lock().unwrap_or_else(|p| p.into_inner());
        file.write_all(&lines)
            .and_then(|()| file.flush())
            .map_err(|e| LabError::io(format!("appending to {}", self.cache.display()), e))?;
        Ok(rows)
    }
}

/// The replay costs of every strategy on one house's trials (`trials`: target and the rows of
/// its trial), for every deployed strategy. The trials are drawn again from the run's settings,
/// and each must be one the run drew.
pub fn replay_house(
    scene: &Scene,
    distances: &Distances,
    strategies: &[Arc<dyn Strategy>],
    trials: &[(&String, &HashMap<&str, &TrialRow>)],
    info: &RunInfo,
    mode: ReplayMode,
) -> Result<Vec<ReplayRow>> {
    let house = &scene.house;
    let drawn = run_draw(info).trials(scene)?;
    // A team's trials are replayed by the same team, from the same starts.
    let team = match info.team {
        Some(t) => {
            let grid = distances.grid().ok_or_else(|| {
                LabError::invalid(format!("{}: a team's replay needs a grid", house.name))
            })?;
            Some(HouseTeam::new(house, (grid, distances), t, info.seed)?)
        }
        None => None,
    };
    let mut out = Vec::new();
    for (target, rows) in trials {
        let Some(trial) = drawn
            .iter()
            .find(|t| t.task.targets_label() == target.as_str())
        else {
            return Err(LabError::invalid(format!(
                "{}: trials.csv has target {target}, the run's seed does not draw it; was run.json edited?",
                house.name
            )));
        };
        replay_trial(
            (scene, distances, team.as_ref()),
            strategies,
            rows,
            trial,
            (mode, info.protocol.travel_cost),
            &mut out,
        )?;
    }
    Ok(out)
}

/// The replay costs of every strategy on one trial, for every deployed strategy (run by
/// `team` when the trial was a team's: its makespan).
fn replay_trial(
    (scene, distances, team): (&Scene, &Distances, Option<&HouseTeam>),
    strategies: &[Arc<dyn Strategy>],
    rows: &HashMap<&str, &TrialRow>,
    trial: &ferret_plan::TrialSpec,
    (mode, travel): (ReplayMode, ferret_plan::TravelCost),
    out: &mut Vec<ReplayRow>,
) -> Result<()> {
    let house = &scene.house;
    let legs = trial
        .task
        .destination()
        .map(|d| d.legs(house, distances))
        .transpose()
        .map_err(PlanError::Task)?;
    let team_legs = team
        .map(|t| t.legs(house, &trial.task))
        .transpose()
        .map_err(PlanError::Task)?;
    let team_problems = match (team, &team_legs) {
        (Some(t), Some(l)) => Some(t.problems(house, trial, l)),
        _ => None,
    };
    for deployed in strategies {
        let row = rows.get(deployed.name()).ok_or_else(|| {
            LabError::invalid(format!("{}: no trial of {}", house.name, deployed.name()))
        })?;
        let label = trial.task.targets_label();
        if row.target != label {
            return Err(LabError::invalid(format!(
                "{}: trials.csv says target {}, the run's seed draws {label}; was run.json edited?",
                house.name, row.target
            )));
        }
        let found_each = found_each(house, row)?;
        let mut problem = SearchProblem::new(house, distances, trial);
        if let Some(l) = legs.as_ref() {
            problem = problem.with_destination(l);
        }
        for s in strategies {
            if s.name() == deployed.name() {
                continue;
            }
            let c = match &team_problems {
                Some(problems) => {
                    replay_team_cost_with(mode, s.as_ref(), problems, &scene.truth, &found_each)?
                }
                None => replay_outcome_with(mode, s.as_ref(), &problem, &scene.truth, &found_each)?
                    .reported_cost(house, distances, travel)?,
            };
            out.push(ReplayRow {
                house_index: house.index,
                target: label.clone(),
                deployed: deployed.name().to_string(),
                strategy: s.name().to_string(),
                replay_cost_m: c,
            });
        }
    }
    Ok(())
}

/// Where each target of a row's trial was found (task order): the row's `found_each` in a run
/// of tasks, its found container otherwise.
fn found_each(house: &ferret_world::House, row: &TrialRow) -> Result<Vec<Option<usize>>> {
    let index = |id: &str| {
        house.container_index(id).ok_or_else(|| {
            LabError::invalid(format!(
                "{}: found container `{id}` is not in the house",
                house.name
            ))
        })
    };
    match &row.found_each {
        Some(each) => each
            .split_whitespace()
            .map(|id| {
                if id == "-" {
                    Ok(None)
                } else {
                    index(id).map(Some)
                }
            })
            .collect(),
        None => Ok(vec![Some(index(&row.found_container)?)]),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    const KEY: &str = "0123abcd";

    fn trial(house_index: usize, strategy: &str) -> TrialRow {
        TrialRow {
            house: format!("h#{house_index}"),
            house_index,
            target: "Apple".into(),
            strategy: strategy.into(),
            cost_m: 1.0,
            searches: 1,
            found: true,
            found_container: "1|0".into(),
            searched: "1|0".into(),
            goal_containers: 1,
            cost_cells: None,
            goal: None,
            destination: None,
            found_each: None,
            delivery_m: None,
            robots: None,
            total_travel_m: None,
            searched_by: None,
        }
    }

    fn candidates() -> Vec<String> {
        vec!["a".into(), "b".into(), "c".into()]
    }

    /// Every (house, deployed, replayed) row of 4 houses and strategies a, b, c, with a cost
    /// that tells them apart.
    fn valid_rows() -> Vec<ReplayRow> {
        let c = candidates();
        let mut rows = Vec::new();
        for h in 0..4 {
            for (j, d) in c.iter().enumerate() {
                for (i, s) in c.iter().enumerate() {
                    if i != j {
                        rows.push(ReplayRow {
                            house_index: h,
                            target: "Apple".into(),
                            deployed: d.clone(),
                            strategy: s.clone(),
                            replay_cost_m: (10 * h + 3 * j + i) as f64 + 0.5,
                        });
                    }
                }
            }
        }
        rows
    }

    fn line_of(r: &ReplayRow) -> String {
        format!(
            "{},{},{},{},{}",
            r.house_index, r.target, r.deployed, r.strategy, r.replay_cost_m
        )
    }

    /// A corruption of one row: the row's text, and whether it is dropped for itself (as
    /// opposed to only making its key a duplicate).
    fn corrupt(kind: u8, r: &ReplayRow) -> String {
        let (h, t, d, s) = (r.house_index, &r.target, &r.deployed, &r.strategy);
        match kind {
            0 => format!("{h},{t},{d},{s},-1.5"),
            1 => format!("{h},{t},{d},{s},NaN"),
            2 => format!("{h},{t},{d},{s},inf"),
            3 => format!("{h},{t},{d},zzz,2.0"),
            4 => format!("{h},{t},zzz,{s},2.0"),
            5 => format!("99,{t},{d},{s},2.0"),
            6 => format!("{h},{t},{d},{d},2.0"),
            7 => format!("{h},{t},{d},{s}"),
            _ => format!("{h},{t},{d},{s},twelve"),
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

        /// Corrupt rows (bad costs, unknown strategies or houses, self replays, short rows,
        /// duplicates, a line cut by a kill) are dropped with their line number; every other
        /// row is kept with its exact cost.
        #[test]
        fn corrupt_replay_rows_are_dropped_with_their_line(
            edits in proptest::collection::btree_map(0usize..36, 0u8..10, 0..8),
            cut in any::<bool>(),
        ) {
            let rows = valid_rows();
            // Each line's text and, when it is a good row, its key and cost.
            let mut lines: Vec<(String, Option<(ReplayKey, f64)>)> = Vec::new();
            for (i, r) in rows.iter().enumerate() {
                let key = (
                    r.house_index,
                    r.target.clone(),
                    r.deployed.clone(),
                    r.strategy.clone(),
                );
                let good = (line_of(r), Some((key, r.replay_cost_m)));
                match edits.get(&i) {
                    // Kind 9: the row twice.
                    Some(9) => {
                        lines.push(good.clone());
                        lines.push(good);
                    }
                    Some(&k) => lines.push((corrupt(k, r), None)),
                    None => lines.push(good),
                }
            }
            let mut text = format!("{CACHE_KEY_PREFIX}{KEY}\n{CACHE_HEADER}");
            for (l, _) in &lines {
                text.push_str(l);
                text.push('\n');
            }
            if cut {
                // Killed while appending the last row: its newline never made it.
                text.pop();
                if let Some(last) = lines.last_mut() {
                    last.1 = None;
                }
            }
            // Line numbers: 1 is the key, 2 the header. A key on two good lines drops both.
            let mut count: HashMap<ReplayKey, usize> = HashMap::new();
            for (_, good) in &lines {
                if let Some((k, _)) = good {
                    *count.entry(k.clone()).or_default() += 1;
                }
            }
            let mut expected: HashMap<ReplayKey, f64> = HashMap::new();
            let mut bad_lines = Vec::new();
            for (n, (_, good)) in lines.iter().enumerate() {
                match good {
                    Some((k, c)) if count[k] == 1 => {
                        expected.insert(k.clone(), *c);
                    }
                    _ => bad_lines.push(n as u64 + 3),
                }
            }
            let trials: Vec<TrialRow> = (0..4)
                .flat_map(|h| candidates().into_iter().map(move |s| trial(h, &s)))
                .collect();
            let mut houses: Trials<'_> = BTreeMap::new();
            for t in &trials {
                houses
                    .entry((t.house_index, t.target.clone()))
                    .or_default()
                    .insert(t.strategy.as_str(), t);
            }
            let read = parse_replay_cache(text.as_bytes(), KEY, &candidates(), &houses);
            prop_assert!(read.stale.is_none());
            prop_assert_eq!(&read.known, &expected);
            let mut reported: Vec<u64> = read
                .dropped
                .iter()
                .map(|m| {
                    m.strip_prefix("line ")
                        .and_then(|m| m.split(':').next())
                        .and_then(|n| n.parse().ok())
                        .unwrap_or(0)
                })
                .collect();
            reported.sort_unstable();
            prop_assert_eq!(reported, bad_lines);
        }
    }

    #[test]
    fn a_cache_of_other_trials_or_without_key_is_stale() {
        let houses = BTreeMap::new();
        let other = format!("{CACHE_KEY_PREFIX}ffff\n{CACHE_HEADER}");
        let read = parse_replay_cache(other.as_bytes(), KEY, &candidates(), &houses);
        assert!(read.stale.unwrap().contains("other trials"));
        // The format before the key line.
        let old = format!("{CACHE_HEADER}0,a,b,1.0\n");
        let read = parse_replay_cache(old.as_bytes(), KEY, &candidates(), &houses);
        assert!(read.stale.is_some() && read.known.is_empty());
    }

    #[test]
    fn the_trials_key_changes_with_either_file() {
        let k = trials_key(b"{run}", b"trials");
        assert_eq!(k.len(), 64);
        assert_ne!(k, trials_key(b"{run}", b"trials2"));
        assert_ne!(k, trials_key(b"{run2}", b"trials"));
        // The length prefix keeps the boundary between the files.
        assert_ne!(trials_key(b"ab", b"c"), trials_key(b"a", b"bc"));
    }
}
