//! `ferret select`: the deployment experiment of paper section VI-C over an eval run.

use std::collections::{BTreeMap, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::{Arc, Mutex};

use anyhow::{Context, Result, bail};
use ferret_plan::{
    DrawMode, ReplayMode, SearchProblem, Strategy, draw_trials_with, replay_outcome_with,
};
use ferret_report::{CurvePanel, draw_choice_shares, draw_curve_panels};
use ferret_select::{
    CostTable, ExperimentOptions, Method, ORACLE, PAPER_KS, choice_rows, run_experiment,
    selection_rows, selection_table_markdown, strategy_table_markdown,
};
use ferret_world::{Distances, Scene};
use indicatif::ParallelProgressIterator;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::eval::{RunInfo, TrialRow, write_csv};
use crate::common::{build_maps, progress};

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

/// Refuses unusable options, naming the option, before any replay runs or output is touched.
fn validate(args: &Args) -> Result<()> {
    if args.deployments == 0 {
        bail!("--deployments 0: must be at least 1");
    }
    if args.trials_per_deployment == 0 {
        bail!("--trials-per-deployment 0: must be at least 1");
    }
    let max = ferret_select::MAX_EXPERIMENT_TRIALS;
    if args
        .deployments
        .checked_mul(args.trials_per_deployment)
        .is_none_or(|n| n > max)
    {
        bail!(
            "--deployments {} × --trials-per-deployment {}: at most {max} deployment trials in all",
            args.deployments,
            args.trials_per_deployment
        );
    }
    if !(args.c.is_finite() && args.c >= 0.0) {
        bail!("--c {}: must be a finite number ≥ 0 m", args.c);
    }
    Ok(())
}

/// Runs `ferret select`.
pub fn run(args: Args) -> Result<ExitCode> {
    validate(&args)?;
    let run_json = read_input(&args.trials.join("run.json")).with_context(|| {
        format!(
            "{}: not a `ferret eval` output directory",
            args.trials.display()
        )
    })?;
    let info: RunInfo = serde_json::from_slice(&run_json).context("reading run.json")?;
    let protocol = args.protocol.resolve(info.protocol)?;
    if protocol.trial_settings() != info.protocol.trial_settings() {
        bail!(
            "{} was made with {}; select asks for {}: selecting over trials of another protocol \
             would mix them (run eval again instead)",
            args.trials.display(),
            info.protocol.trial_settings(),
            protocol.trial_settings()
        );
    }
    let trials_path = args.trials.join("trials.csv");
    let trials_csv =
        read_input(&trials_path).with_context(|| format!("reading {}", trials_path.display()))?;
    if let Some(expected) = &info.trials_sha256
        && *expected != super::eval::sha256_hex(&trials_csv)
    {
        bail!(
            "{}: trials.csv and run.json are from different runs (an eval was stopped between \
             writing them, or one file was copied from another run); run `ferret eval` into this \
             directory again",
            args.trials.display()
        );
    }
    let rows: Vec<TrialRow> = parse_csv(&trials_csv, &trials_path)?;
    // Counterfactual replays are other numbers than pessimistic ones: they are cached under a key
    // of their own (the pessimistic key is unchanged, so existing caches stay valid).
    let key = match protocol.replay {
        ReplayMode::Pessimistic => trials_key(&run_json, &trials_csv),
        ReplayMode::Counterfactual => trials_key(
            &[&run_json[..], b"\nreplay=counterfactual"].concat(),
            &trials_csv,
        ),
    };
    let candidates: Vec<String> = info
        .strategies
        .iter()
        .filter(|s| s.as_str() != ORACLE && rows.iter().any(|r| &r.strategy == *s))
        .cloned()
        .collect();
    if candidates.len() < 2 {
        bail!(
            "selection needs at least two non-oracle strategies in {}",
            args.trials.display()
        );
    }
    // Trials (house and target) that every candidate finished.
    let mut by_house: Trials<'_> = BTreeMap::new();
    for r in &rows {
        by_house
            .entry((r.house_index, r.target.clone()))
            .or_default()
            .insert(r.strategy.as_str(), r);
    }
    by_house.retain(|_, m| candidates.iter().all(|s| m.contains_key(s.as_str())));
    let replay_path = args.trials.join("replay.csv");
    let distinct_houses = by_house
        .keys()
        .map(|k| k.0)
        .collect::<std::collections::BTreeSet<_>>()
        .len();
    if protocol.draw == DrawMode::Distinct && distinct_houses < args.trials_per_deployment {
        bail!(
            "--trials-per-deployment {}: only {} houses of {} have a trial of every strategy",
            args.trials_per_deployment,
            distinct_houses,
            args.trials.display()
        );
    }
    let replays = load_or_compute_replays(
        &info,
        &args,
        &candidates,
        &by_house,
        &replay_path,
        &key,
        protocol.replay,
    )?;
    let houses: Vec<TrialId> = by_house.keys().cloned().collect();
    let s = candidates.len();
    let mut cost = Vec::with_capacity(houses.len());
    let mut replay = Vec::with_capacity(houses.len());
    for h in &houses {
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
                        .with_context(|| {
                            format!(
                                "replay.csv lacks house {}, target {}, {dj} deployed, {si}",
                                h.0, h.1
                            )
                        })?
                };
            }
        }
        replay.push(by_deployed);
    }
    // Labels must be distinct: a house with several trials is labelled per target.
    let several = houses.len() > distinct_houses;
    let labels = houses
        .iter()
        .map(|h| {
            let l = m_label(&by_house[h]);
            if several { format!("{l}/{}", h.1) } else { l }
        })
        .collect();
    let table = CostTable::new(candidates.clone(), labels, cost, replay)?;
    // One trial per house and deployment: a deployment draws distinct houses.
    let table = if several {
        table.grouped(houses.iter().map(|h| h.0).collect())?
    } else {
        table
    };
    let opts = ExperimentOptions {
        deployments: args.deployments,
        trials_per_deployment: args.trials_per_deployment,
        c: args.c,
        seed: args.seed,
        replay_untried_first: args.replay_untried_first,
        with_replacement: protocol.draw == DrawMode::Replacement,
        ucb_untried_zero: protocol.untried == ferret_plan::UntriedScore::Zero,
        // The reference's numpy draws are draws with replacement; with distinct houses the
        // deployments keep ferret's own streams.
        reference_draws: protocol.rng == ferret_plan::TrialRng::Python
            && protocol.draw == DrawMode::Replacement,
    };
    let result = run_experiment(&table, &opts)?;
    std::fs::create_dir_all(&args.out)?;
    write_csv(&args.out.join("selection.csv"), &selection_rows(&result))?;
    write_csv(&args.out.join("choices.csv"), &choice_rows(&result))?;
    let ks: Vec<usize> = PAPER_KS
        .iter()
        .copied()
        .filter(|&k| k <= result.trials())
        .collect();
    let md = format!(
        "# Strategy selection\n\n{} deployments × {} trials over {} houses{}, c = {} m, seed {}.\n\n{}\n{}",
        opts.deployments,
        opts.trials_per_deployment,
        distinct_houses,
        if several {
            format!(
                " ({} trials; one per house in each deployment)",
                houses.len()
            )
        } else {
            String::new()
        },
        opts.c,
        opts.seed,
        selection_table_markdown(&result, &ks),
        strategy_table_markdown(&result)
    );
    crate::output::write_bytes(&args.out.join("selection.md"), &md)?;
    draw_selection(&result, &args.out)?;
    println!("{md}");
    println!(
        "wrote {}/{{selection.csv,choices.csv,selection.md,selection.png,choices-ucb.png,choices-replay.png}}",
        args.out.display()
    );
    Ok(ExitCode::SUCCESS)
}

fn m_label(m: &HashMap<&str, &TrialRow>) -> String {
    m.values()
        .next()
        .map(|r| r.house.clone())
        .unwrap_or_default()
}

/// Parses serde rows from the CSV text of `path`; errors name the file and line.
fn parse_csv<T: for<'de> Deserialize<'de>>(bytes: &[u8], path: &Path) -> Result<Vec<T>> {
    let mut r = csv::Reader::from_reader(bytes);
    r.deserialize()
        .enumerate()
        .map(|(i, row)| row.with_context(|| format!("{}: row {}", path.display(), i + 2)))
        .collect()
}

/// An eval output file, through the bounded reader every input goes through.
fn read_input(path: &Path) -> std::io::Result<Vec<u8>> {
    ferret_world::input::read_file(path, MAX_RUN_FILE_BYTES)
}

/// Largest eval output read (trials.csv of a very large run is tens of megabytes).
const MAX_RUN_FILE_BYTES: u64 = 1 << 30;

/// The identity of an eval run's trials: SHA-256 of run.json and trials.csv. Replays are only
/// valid for the exact trials they were computed on.
fn trials_key(run_json: &[u8], trials_csv: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    let mut h = Sha256::new();
    for part in [run_json, trials_csv] {
        h.update((part.len() as u64).to_le_bytes());
        h.update(part);
    }
    format!("{:x}", h.finalize())
}

/// A trial of an eval run: house index and target.
type TrialId = (usize, String);

/// The rows of every trial, by strategy.
type Trials<'a> = BTreeMap<TrialId, HashMap<&'a str, &'a TrialRow>>;

/// House index, target, deployed strategy, replayed strategy.
type ReplayKey = (usize, String, String, String);

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
    let mut w = csv::WriterBuilder::new()
        .has_headers(false)
        .from_writer(Vec::new());
    for r in rows {
        w.serialize(r)?;
    }
    Ok(w.into_inner().map_err(|e| e.into_error())?)
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
    crate::output::write_atomic(path, |w| {
        writeln!(w, "{CACHE_KEY_PREFIX}{key}")?;
        w.write_all(CACHE_HEADER.as_bytes())?;
        w.write_all(&body)?;
        Ok(())
    })
}

fn load_or_compute_replays(
    info: &RunInfo,
    args: &Args,
    candidates: &[String],
    by_house: &Trials<'_>,
    path: &Path,
    key: &str,
    mode: ReplayMode,
) -> Result<HashMap<ReplayKey, f64>> {
    let read = match read_input(path) {
        Ok(text) => {
            let read = parse_replay_cache(&text, key, candidates, by_house);
            if let Some(why) = &read.stale {
                eprintln!("{}: {why}; replaying again", path.display());
            }
            const SHOWN: usize = 10;
            for d in read.dropped.iter().take(SHOWN) {
                eprintln!("{}: {d}; row dropped and replayed again", path.display());
            }
            if read.dropped.len() > SHOWN {
                eprintln!(
                    "{}: {} more rows dropped",
                    path.display(),
                    read.dropped.len() - SHOWN
                );
            }
            Some(read)
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
        Err(e) => return Err(e).with_context(|| format!("reading {}", path.display())),
    };
    let needs_rewrite = read
        .as_ref()
        .is_none_or(|r| r.stale.is_some() || !r.dropped.is_empty());
    let mut known = read.map(|r| r.known).unwrap_or_default();
    if needs_rewrite {
        rewrite_replay_cache(path, key, &known)?;
    }
    let missing = |h: &TrialId| {
        candidates.iter().any(|j| {
            candidates
                .iter()
                .any(|i| i != j && !known.contains_key(&(h.0, h.1.clone(), j.clone(), i.clone())))
        })
    };
    let todo: Vec<usize> = by_house
        .keys()
        .filter(|h| missing(h))
        .map(|h| h.0)
        .collect::<std::collections::BTreeSet<_>>()
        .into_iter()
        .collect();
    if todo.is_empty() {
        return Ok(known);
    }
    eprintln!(
        "replaying {} strategies on {} houses (cached in {})",
        candidates.len(),
        todo.len(),
        path.display()
    );
    let loaded = info.house_args().load_for(info.protocol.containers)?;
    let scenes: Vec<Scene> = loaded
        .scenes
        .into_iter()
        .filter(|s| todo.contains(&s.house.index))
        .collect();
    let maps = build_maps(&scenes, &info.grid_args().params_for(info.protocol.access));
    let setup = super::llm_setup::full_registry(&info.planning, &args.llm, candidates)?;
    let strategies: Vec<Arc<dyn Strategy>> = candidates
        .iter()
        .map(|s| setup.registry.build(s))
        .collect::<Result<_, _>>()?;
    // Each house's replays are appended as soon as they finish, so that a killed run keeps them.
    let cache = Mutex::new(
        std::fs::OpenOptions::new()
            .append(true)
            .open(path)
            .with_context(|| format!("opening {}", path.display()))?,
    );
    let bar = progress(scenes.len(), "replays");
    let results: Vec<Result<Vec<ReplayRow>>> = scenes
        .par_iter()
        .zip(maps.par_iter())
        .progress_with(bar.clone())
        .map(|(scene, map)| {
            let (_, distances) = map.as_ref().map_err(|e| anyhow::anyhow!("{e}"))?;
            let trials: Vec<(&String, &HashMap<&str, &TrialRow>)> = by_house
                .iter()
                .filter(|(k, _)| k.0 == scene.house.index)
                .map(|(k, m)| (&k.1, m))
                .collect();
            let rows = replay_house(scene, distances, &strategies, &trials, info, mode)?;
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
                .with_context(|| format!("appending to {}", path.display()))?;
            Ok(rows)
        })
        .collect();
    bar.finish_and_clear();
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
            Err(e) => errors.push(format!("{e:#}")),
        }
    }
    super::llm_setup::write_token_report(&setup.service, &args.out)?;
    if !errors.is_empty() {
        bail!(
            "{} house(s) could not be replayed; the others are cached in {}:\n{}",
            errors.len(),
            path.display(),
            errors.join("\n")
        );
    }
    Ok(known)
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
    let drawn = draw_trials_with(
        house,
        &scene.truth,
        info.seed,
        info.reveal_fraction,
        info.trials_per_house,
        &info.protocol,
    )?;
    let mut out = Vec::new();
    for (target, rows) in trials {
        let Some(trial) = drawn.iter().find(|t| t.target.as_str() == target.as_str()) else {
            bail!(
                "{}: trials.csv has target {target}, the run's seed does not draw it; was run.json edited?",
                house.name
            );
        };
        replay_trial(
            scene,
            distances,
            strategies,
            rows,
            trial,
            (mode, info.protocol.travel_cost),
            &mut out,
        )?;
    }
    Ok(out)
}

/// The replay costs of every strategy on one trial, for every deployed strategy.
fn replay_trial(
    scene: &Scene,
    distances: &Distances,
    strategies: &[Arc<dyn Strategy>],
    rows: &HashMap<&str, &TrialRow>,
    trial: &ferret_plan::TrialSpec,
    (mode, travel): (ReplayMode, ferret_plan::TravelCost),
    out: &mut Vec<ReplayRow>,
) -> Result<()> {
    let house = &scene.house;
    for deployed in strategies {
        let row = rows
            .get(deployed.name())
            .with_context(|| format!("{}: no trial of {}", house.name, deployed.name()))?;
        if row.target != trial.target.as_str() {
            bail!(
                "{}: trials.csv says target {}, the run's seed draws {}; was run.json edited?",
                house.name,
                row.target,
                trial.target
            );
        }
        let found = house
            .container_index(&row.found_container)
            .with_context(|| {
                format!(
                    "{}: found container `{}` is not in the house",
                    house.name, row.found_container
                )
            })?;
        for s in strategies {
            if s.name() == deployed.name() {
                continue;
            }
            let c = replay_outcome_with(
                mode,
                s.as_ref(),
                &SearchProblem::new(house, distances, trial),
                &scene.truth,
                found,
            )?
            .reported_cost(house, distances, travel)?;
            out.push(ReplayRow {
                house_index: house.index,
                target: trial.target.to_string(),
                deployed: deployed.name().to_string(),
                strategy: s.name().to_string(),
                replay_cost_m: c,
            });
        }
    }
    Ok(())
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
    let panels = vec![
        CurvePanel {
            title: "Average cost of trials 1..k".into(),
            x_label: "trials k".into(),
            y_label: "average cost (m)".into(),
            series: vec![
                (Method::Ucb.label().into(), ks(&result.ucb.avg_cost)),
                (
                    Method::ReplaySelection.label().into(),
                    ks(&result.replay.avg_cost),
                ),
                (format!("best single: {best}"), ks(&result.best_avg_cost)),
            ],
            marks_at: marks.clone(),
        },
        CurvePanel {
            title: "Cumulative regret".into(),
            x_label: "trials k".into(),
            y_label: "cumulative regret (m)".into(),
            series: vec![
                (Method::Ucb.label().into(), ks(&result.ucb.cum_regret)),
                (
                    Method::ReplaySelection.label().into(),
                    ks(&result.replay.cum_regret),
                ),
            ],
            marks_at: marks,
        },
    ];
    crate::output::write_with_path(&out.join("selection.png"), |p| {
        Ok(draw_curve_panels(&panels, p)?)
    })?;
    let x: Vec<f64> = (1..=result.trials()).map(|k| k as f64).collect();
    for method in Method::ALL {
        let s = result.summary(method);
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
