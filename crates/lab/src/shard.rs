//! Sharded evaluation: which houses a shard runs, what it records, and the merge of shards'
//! runs into the run one machine would have written.
//!
//! **The rule.** Shard `i` of `n` runs the houses whose index in their file satisfies
//! `index mod n = i` ([`Shard::contains`]). The index is the house's line in its file (or its
//! place among generated houses), so the rule needs nothing but the house itself: no count of
//! the file's houses, no hash whose value could change between machines or language versions,
//! and a house keeps its shard when `--range` or invalid houses change which others are
//! loaded. Striding rather than contiguous blocks also spreads houses of every kind over all
//! shards, so one shard does not draw all the large houses of a file sorted by size.
//!
//! **Why the shards' trials are the one-machine trials.** Every draw of a trial (target,
//! revealed containers, the paper's initial belief, under both `--rng ferret` and
//! `--rng python`) is seeded from the trial seed and the house's index alone
//! ([`ferret_plan::draw_trials_with`]); no stream runs across houses. A shard therefore draws
//! exactly the trials one machine draws for its houses, and nothing about the shard enters them.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::runs::{EvalRun, ReportView, RunInfo, RunReport, TrialRow, WrittenRun};

/// One shard of an evaluation: `index` of `count` (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub struct Shard {
    /// This shard, `0..count`.
    pub index: usize,
    /// How many shards the houses are split into.
    pub count: usize,
}

/// The rule's name as run.json records it.
pub const SHARD_RULE: &str = "house_index mod count";

impl Shard {
    /// Shard `index` of `count`; an error unless `index < count`.
    pub fn new(index: usize, count: usize) -> Result<Self, ShardError> {
        if count == 0 || index >= count {
            return Err(ShardError::OutOfRange { index, count });
        }
        Ok(Self { index, count })
    }

    /// Whether the house with file index `house_index` belongs to this shard.
    pub fn contains(&self, house_index: usize) -> bool {
        house_index % self.count == self.index
    }

    /// The shard of `count` that runs the house with file index `house_index`.
    pub fn of_house(house_index: usize, count: usize) -> usize {
        house_index % count.max(1)
    }
}

impl std::fmt::Display for Shard {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl std::str::FromStr for Shard {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || ShardError::Syntax(s.to_string());
        let (i, n) = s.trim().split_once('/').ok_or_else(bad)?;
        let i = digits(i).ok_or_else(bad)?;
        let n = digits(n).ok_or_else(bad)?;
        Self::new(i, n)
    }
}

/// A number written as decimal digits only: `+1`, ` 1` and `1 ` (which `usize`'s own parsing or
/// a trim would take) are refused, since a batch system never writes them and a mistyped
/// variable should not run a shard.
fn digits(s: &str) -> Option<usize> {
    if s.is_empty() || !s.bytes().all(|b| b.is_ascii_digit()) {
        return None;
    }
    s.parse().ok()
}

/// `--shard` as given: a fixed shard, or `auto` (from the batch system's environment).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ShardSpec {
    /// `i/n`.
    Fixed(Shard),
    /// From `SLURM_ARRAY_TASK_ID`/`SLURM_ARRAY_TASK_COUNT` or `JOB_COMPLETION_INDEX` with
    /// [`SHARD_COUNT_VAR`]; see [`ShardSpec::resolve`].
    Auto,
}

/// The variable that gives the shard count beside a Kubernetes Indexed Job's
/// `JOB_COMPLETION_INDEX` (Kubernetes passes the index only; the manifest's `completions` is
/// the count, set here too).
pub const SHARD_COUNT_VAR: &str = "FERRET_SHARD_COUNT";

impl std::str::FromStr for ShardSpec {
    type Err = ShardError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        if s.trim() == "auto" {
            Ok(Self::Auto)
        } else {
            s.parse().map(Self::Fixed)
        }
    }
}

impl ShardSpec {
    /// The shard, reading the environment through `var` for `auto`: a Slurm array task
    /// (`SLURM_ARRAY_TASK_ID` − `SLURM_ARRAY_TASK_MIN`, of `SLURM_ARRAY_TASK_COUNT`, so that
    /// `--array=1-3` works as `--array=0-2` does), else a Kubernetes Indexed Job
    /// (`JOB_COMPLETION_INDEX` of [`SHARD_COUNT_VAR`]).
    pub fn resolve(&self, var: impl Fn(&str) -> Option<String>) -> Result<Shard, ShardError> {
        if let Self::Fixed(s) = self {
            return Ok(*s);
        }
        let num = |name: &str| -> Result<Option<usize>, ShardError> {
            match var(name) {
                None => Ok(None),
                Some(v) => digits(&v).map(Some).ok_or_else(|| {
                    ShardError::Env(format!("{name}={v:?} is not a number (digits only)"))
                }),
            }
        };
        if var("SLURM_ARRAY_TASK_ID").is_some() && var("JOB_COMPLETION_INDEX").is_some() {
            return Err(ShardError::Env(
                "--shard auto: both a Slurm array task (SLURM_ARRAY_TASK_ID) and a Kubernetes \
                 Indexed Job (JOB_COMPLETION_INDEX) are in the environment, so the shard is \
                 ambiguous: unset one, or give --shard i/n"
                    .into(),
            ));
        }
        if let Some(id) = num("SLURM_ARRAY_TASK_ID")? {
            let count = num("SLURM_ARRAY_TASK_COUNT")?.ok_or_else(|| {
                ShardError::Env(
                    "SLURM_ARRAY_TASK_ID is set but SLURM_ARRAY_TASK_COUNT is not".into(),
                )
            })?;
            let min = num("SLURM_ARRAY_TASK_MIN")?.unwrap_or(0);
            let index = id.checked_sub(min).ok_or_else(|| {
                ShardError::Env(format!(
                    "SLURM_ARRAY_TASK_ID {id} is below SLURM_ARRAY_TASK_MIN {min}"
                ))
            })?;
            // An array with a step (--array=0-10:2) or a list has ids that are not 0..count.
            return Shard::new(index, count).map_err(|_| {
                ShardError::Env(format!(
                    "array task {id} (min {min}) of {count} is not one of 0..{count} after the \
                     minimum is taken off: submit a contiguous array such as --array=0-{}",
                    count.saturating_sub(1)
                ))
            });
        }
        if let Some(index) = num("JOB_COMPLETION_INDEX")? {
            let count = num(SHARD_COUNT_VAR)?.ok_or_else(|| {
                ShardError::Env(format!(
                    "JOB_COMPLETION_INDEX is set but {SHARD_COUNT_VAR} is not: set it to the \
                     Job's completions"
                ))
            })?;
            return Shard::new(index, count);
        }
        Err(ShardError::Env(format!(
            "--shard auto: neither a Slurm array task (SLURM_ARRAY_TASK_ID and \
             SLURM_ARRAY_TASK_COUNT) nor a Kubernetes Indexed Job (JOB_COMPLETION_INDEX and \
             {SHARD_COUNT_VAR}) is in the environment; give --shard i/n"
        )))
    }
}

/// A `--shard` that cannot be used.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum ShardError {
    /// Not `i/n` nor `auto`.
    #[error("--shard {0:?}: expected i/n (e.g. 0/3) or `auto`")]
    Syntax(String),
    /// `i` not below `n`.
    #[error(
        "--shard {index}/{count}: the shard must be one of 0..{count} (and the count at least 1)"
    )]
    OutOfRange {
        /// The index given.
        index: usize,
        /// The count given.
        count: usize,
    },
    /// `auto` found no usable environment.
    #[error("{0}")]
    Env(String),
}

/// What a shard's run.json records besides the run's settings: enough for [`merge_runs`] to
/// check the shards and to write the report one machine writes.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ShardRecord {
    /// This shard.
    pub index: usize,
    /// Of how many.
    pub count: usize,
    /// The rule, [`SHARD_RULE`].
    pub rule: String,
    /// File indices of the houses this shard loaded (valid houses of the run's source in it).
    pub houses: Vec<usize>,
    /// Houses with at least one trial.
    pub houses_run: usize,
    /// Trials (house and target) drawn.
    pub trials_run: usize,
    /// House or trial failures (their messages went to the shard's log).
    #[serde(default)]
    pub failures: usize,
    /// The report's extra references (`--paired-against`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub paired_against: Vec<String>,
    /// Whether costs in grid cells were asked for (`--cells`).
    #[serde(default)]
    pub cells: bool,
    /// The house whose trajectories the merged run shows (`--show-house`): shards draw no
    /// pictures, the merge draws them once.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub show_house: Option<usize>,
}

/// One shard of a merged run, as the merged run.json lists it.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MergedShard {
    /// The shard's run directory, as given to the merge.
    pub dir: PathBuf,
    /// Its index.
    pub index: usize,
    /// Its houses.
    pub houses: usize,
    /// Its trials.csv's rows.
    pub rows: usize,
    /// Its trials.csv's SHA-256.
    pub trials_sha256: String,
}

/// Why shards cannot be merged. Every message names the directories concerned.
#[derive(Debug, thiserror::Error)]
pub enum MergeError {
    /// Nothing to merge.
    #[error("no run directories to merge")]
    Empty,
    /// A run directory that is not a shard.
    #[error("{}: not a shard's run (its run.json has no `shard`); run `ferret eval --shard i/n` into it", dir.display())]
    NotShard {
        /// The directory.
        dir: PathBuf,
    },
    /// Two shards ran with different settings.
    #[error("{} and {} ran with different settings ({fields}); shards of one run must share every option but --shard and --out", first.display(), other.display())]
    Settings {
        /// The first shard given.
        first: PathBuf,
        /// The one that differs.
        other: PathBuf,
        /// The settings that differ.
        fields: String,
    },
    /// Two directories hold the same shard, or share a house.
    #[error("{} and {} overlap: {what}", first.display(), other.display())]
    Overlap {
        /// One directory.
        first: PathBuf,
        /// The other.
        other: PathBuf,
        /// What they share.
        what: String,
    },
    /// Shards missing.
    #[error("shards missing: {missing} of {count} (given: {given})")]
    Gap {
        /// The missing shard indices.
        missing: String,
        /// The count.
        count: usize,
        /// The directories given, with their shards.
        given: String,
    },
    /// A shard holds a house or trial that its rule does not give it.
    #[error("{}: {message}", dir.display())]
    Inconsistent {
        /// The directory.
        dir: PathBuf,
        /// What is wrong.
        message: String,
    },
}

/// The shards merged: the run one machine writes, and what its report needs.
#[derive(Clone, Debug)]
pub struct MergedRun {
    /// The merged run (rows in the one-machine order; run.json lists the shards).
    pub run: EvalRun,
    /// File indices of every shard's houses, in order.
    pub houses: Vec<usize>,
    /// Houses with a trial, over all shards.
    pub houses_run: usize,
    /// Trials drawn, over all shards.
    pub trials_run: usize,
    /// Failures, over all shards.
    pub failures: usize,
    /// The shards' `--paired-against`.
    pub paired_against: Vec<String>,
    /// The shards' `--cells`.
    pub cells: bool,
    /// The shards' `--show-house`.
    pub show_house: Option<usize>,
}

impl MergedRun {
    /// The merged run's report (summary, paired comparisons, `summary.md`), the same a
    /// one-machine `ferret eval` writes, and every file of it written into `dir` through the one
    /// run writer.
    ///
    /// # Errors
    /// A file that cannot be written.
    pub fn write_all(&self, dir: &Path) -> crate::Result<RunReport> {
        let source = self.run.info.house_source().describe();
        let report = self.run.report(&ReportView {
            source: &source,
            houses: &self.houses,
            houses_run: self.houses_run,
            trials_run: self.trials_run,
            paired_against: &self.paired_against,
            cells: self.cells,
        });
        self.run.write_all(dir, &report)?;
        Ok(report)
    }
}

/// The settings of a run that must agree between shards: run.json without the fields that
/// differ by shard. Compared as JSON, so that a new setting is compared without a change here.
fn settings(info: &RunInfo) -> serde_json::Map<String, serde_json::Value> {
    let mut v = match serde_json::to_value(info) {
        Ok(serde_json::Value::Object(m)) => m,
        _ => serde_json::Map::new(),
    };
    for k in ["trials_sha256", "shard", "merged_from"] {
        v.remove(k);
    }
    if let Some(s) = &info.shard {
        v.insert("shard count".into(), s.count.into());
        v.insert("paired_against".into(), s.paired_against.clone().into());
        v.insert("cells".into(), s.cells.into());
        v.insert("show_house".into(), s.show_house.into());
    }
    v
}

fn differing(
    a: &serde_json::Map<String, serde_json::Value>,
    b: &serde_json::Map<String, serde_json::Value>,
) -> Vec<String> {
    let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
    keys.sort();
    keys.dedup();
    keys.into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| {
            let show = |m: &serde_json::Map<String, serde_json::Value>| {
                m.get(k)
                    .map_or_else(|| "absent".to_string(), |v| v.to_string())
            };
            format!("{k}: {} vs {}", show(a), show(b))
        })
        .collect()
}

/// Merges the shards' runs `shards` (each with its directory) into one run: the same settings
/// checked in every shard, every shard `0..count` present exactly once, no house in two of
/// them, rows ordered as one machine orders them (houses in file order; within a house, the
/// shard's own order, which is one machine's). The merged run.json is a shard's without
/// `shard`, with `merged_from` listing the shards.
pub fn merge_runs(shards: &[(PathBuf, EvalRun)]) -> Result<MergedRun, MergeError> {
    let infos: Vec<(&Path, &RunInfo)> =
        shards.iter().map(|(d, r)| (d.as_path(), &r.info)).collect();
    let records = check_shards(&infos)?;
    for &(pos, rec) in &records {
        let (dir, run) = &shards[pos];
        let houses = sorted(&rec.houses);
        if let Some(r) = run
            .rows
            .iter()
            .find(|r| houses.binary_search(&r.house_index).is_err())
        {
            return Err(not_loaded(dir, r));
        }
    }
    // Concatenated shard by shard, then a stable sort by house: a house's rows stay in its
    // shard's order, which is the one-machine order within a house.
    let mut rows: Vec<TrialRow> = records
        .iter()
        .flat_map(|&(pos, _)| shards[pos].1.rows.iter().cloned())
        .collect();
    rows.sort_by_key(|r| r.house_index);
    let counts: Vec<usize> = records
        .iter()
        .map(|&(pos, _)| shards[pos].1.rows.len())
        .collect();
    let m = merged_parts(&infos, &records, &counts);
    let first_dir = &shards[0].0;
    Ok(MergedRun {
        houses: m.houses,
        houses_run: m.houses_run,
        trials_run: m.trials_run,
        failures: m.failures,
        paired_against: m.paired_against,
        cells: m.cells,
        show_house: m.show_house,
        run: EvalRun::new(m.info, rows).map_err(|e| MergeError::Inconsistent {
            dir: first_dir.clone(),
            message: e.to_string(),
        })?,
    })
}

fn sorted(houses: &[usize]) -> Vec<usize> {
    let mut h = houses.to_vec();
    h.sort_unstable();
    h
}

fn not_loaded(dir: &Path, r: &TrialRow) -> MergeError {
    MergeError::Inconsistent {
        dir: dir.to_path_buf(),
        message: format!(
            "trials.csv has a trial of house {} ({}), which the shard did not load",
            r.house_index, r.house
        ),
    }
}

/// Checks that `shards` (directory and run.json) are the shards of one run: the same settings,
/// every shard `0..count` exactly once, every house in its shard by the rule and in one shard
/// only. Returns each shard's position in `shards` with its record, in shard order.
fn check_shards<'a>(
    shards: &[(&'a Path, &'a RunInfo)],
) -> Result<Vec<(usize, &'a ShardRecord)>, MergeError> {
    let (first_dir, first) = shards.first().ok_or(MergeError::Empty)?;
    let base = settings(first);
    let mut records: Vec<(usize, &ShardRecord)> = Vec::new();
    let dir_of = |pos: usize| shards[pos].0.to_path_buf();
    for (pos, (dir, info)) in shards.iter().enumerate() {
        let rec = info.shard.as_ref().ok_or_else(|| MergeError::NotShard {
            dir: dir.to_path_buf(),
        })?;
        let diff = differing(&base, &settings(info));
        if !diff.is_empty() {
            return Err(MergeError::Settings {
                first: first_dir.to_path_buf(),
                other: dir.to_path_buf(),
                fields: diff.join("; "),
            });
        }
        if let Some((other, _)) = records.iter().find(|(_, r)| r.index == rec.index) {
            return Err(MergeError::Overlap {
                first: dir_of(*other),
                other: dir.to_path_buf(),
                what: format!("both are shard {}/{}", rec.index, rec.count),
            });
        }
        let shard = Shard {
            index: rec.index,
            count: rec.count,
        };
        if let Some(h) = rec.houses.iter().copied().find(|&h| !shard.contains(h)) {
            return Err(MergeError::Inconsistent {
                dir: dir.to_path_buf(),
                message: format!(
                    "house {h} is not in shard {}/{} by the rule {SHARD_RULE}",
                    rec.index, rec.count
                ),
            });
        }
        for (other, r) in &records {
            if let Some(h) = rec.houses.iter().find(|h| r.houses.contains(h)) {
                return Err(MergeError::Overlap {
                    first: dir_of(*other),
                    other: dir.to_path_buf(),
                    what: format!("both ran house {h}"),
                });
            }
        }
        records.push((pos, rec));
    }
    let count = records[0].1.count;
    let missing: Vec<String> = (0..count)
        .filter(|i| !records.iter().any(|(_, r)| r.index == *i))
        .map(|i| i.to_string())
        .collect();
    if !missing.is_empty() {
        return Err(MergeError::Gap {
            missing: missing.join(", "),
            count,
            given: records
                .iter()
                .map(|(pos, r)| format!("{} = {}/{}", shards[*pos].0.display(), r.index, r.count))
                .collect::<Vec<_>>()
                .join(", "),
        });
    }
    records.sort_by_key(|(_, r)| r.index);
    Ok(records)
}

/// What a merged run says besides its rows.
struct MergedParts {
    info: RunInfo,
    houses: Vec<usize>,
    houses_run: usize,
    trials_run: usize,
    failures: usize,
    paired_against: Vec<String>,
    cells: bool,
    show_house: Option<usize>,
}

/// The merged run.json (without the rows' hash) and totals of checked shards, `rows[i]` being
/// the row count of `records[i]`'s trials.csv.
fn merged_parts(
    shards: &[(&Path, &RunInfo)],
    records: &[(usize, &ShardRecord)],
    rows: &[usize],
) -> MergedParts {
    let mut houses: Vec<usize> = records
        .iter()
        .flat_map(|(_, r)| r.houses.iter().copied())
        .collect();
    houses.sort_unstable();
    let mut info = shards[0].1.clone();
    info.shard = None;
    info.trials_sha256 = None;
    info.merged_from = records
        .iter()
        .zip(rows)
        .map(|(&(pos, r), &rows)| MergedShard {
            dir: shards[pos].0.to_path_buf(),
            index: r.index,
            houses: r.houses.len(),
            rows,
            trials_sha256: shards[pos].1.trials_sha256.clone().unwrap_or_default(),
        })
        .collect();
    let rec0 = records[0].1;
    MergedParts {
        info,
        houses,
        houses_run: records.iter().map(|(_, r)| r.houses_run).sum(),
        trials_run: records.iter().map(|(_, r)| r.trials_run).sum(),
        failures: records.iter().map(|(_, r)| r.failures).sum(),
        paired_against: rec0.paired_against.clone(),
        cells: rec0.cells,
        show_house: rec0.show_house,
    }
}

/// The shards merged into a directory by [`merge_dirs`]: what was written, and what the
/// pictures and the report need.
#[derive(Clone, Debug)]
pub struct MergedDir {
    /// run.json, summary.csv, paired.csv and summary.md as written, and the rows' costs.
    pub written: WrittenRun,
    /// Rows of the merged trials.csv.
    pub rows: usize,
    /// File indices of every shard's houses, in order.
    pub houses: Vec<usize>,
    /// Houses with a trial, over all shards.
    pub houses_run: usize,
    /// Failures, over all shards.
    pub failures: usize,
    /// The shards' `--show-house`.
    pub show_house: Option<usize>,
    /// The strategies with a row, in the order of the run's strategies: a strategy one machine
    /// dropped (its LLM failed under `--keep-going`) has no row in any shard.
    pub ran: Vec<String>,
    /// The houses, in order, where every strategy of [`ran`](Self::ran) finished a trial.
    pub complete: Vec<usize>,
}

/// Refuses a merge's `out` that is one of the shard folders `dirs`, inside one, or holds one:
/// writing there would replace what the merge reads (and a rerun could not be made).
pub fn check_out(dirs: &[PathBuf], out: &Path) -> crate::Result<()> {
    let o = crate::files::resolved(out);
    for d in dirs {
        let r = crate::files::resolved(d);
        if o.starts_with(&r) || r.starts_with(&o) {
            return Err(crate::LabError::invalid(format!(
                "--out {} {} the shard {}: write the merge to a folder of its own",
                out.display(),
                if o == r {
                    "is"
                } else {
                    "is inside or contains"
                },
                d.display()
            )));
        }
    }
    Ok(())
}

/// [`merge_runs`] of the shards in `dirs`, written into `out` (which must exist) as
/// [`MergedRun::write_all`] writes it, byte for byte, without holding the rows: every shard's
/// trials.csv is read row by row and the rows merged in house order into the merged trials.csv,
/// only their costs kept (24 bytes a row, for the summary and the paired comparisons) and, per
/// house, how many strategies finished there.
///
/// # Errors
/// A shard directory that [`EvalRun::read`] refuses; the refusals of [`merge_runs`]; a shard's
/// trials.csv not in house order; I/O errors writing `out` (which then keeps what it held).
pub fn merge_dirs(dirs: &[PathBuf], out: &Path) -> crate::Result<MergedDir> {
    check_out(dirs, out)?;
    let infos: Vec<RunInfo> = dirs
        .iter()
        .map(|d| crate::runs::read_checked_info(d))
        .collect::<crate::Result<_>>()?;
    let pairs: Vec<(&Path, &RunInfo)> = dirs.iter().map(PathBuf::as_path).zip(&infos).collect();
    let records = check_shards(&pairs)?;
    let mut readers = Vec::with_capacity(records.len());
    for &(pos, rec) in &records {
        readers.push(ShardRows::open(&dirs[pos], sorted(&rec.houses))?);
    }
    // The next row of every shard, smallest house first; equal houses (which the checks above
    // rule out across shards) in shard order, as the stable sort of merge_runs has them.
    let mut heads = std::collections::BinaryHeap::new();
    for (k, r) in readers.iter_mut().enumerate() {
        if let Some(row) = r.next_row()? {
            heads.push(std::cmp::Reverse((row.house_index, k, HeadRow(row))));
        }
    }
    let mut writer = crate::runs::RunWriter::create(out, false)?;
    let mut names: Vec<String> = Vec::new();
    let mut per_house: Vec<(usize, usize)> = Vec::new();
    let mut in_house: Vec<usize> = Vec::new();
    while let Some(std::cmp::Reverse((house, k, HeadRow(row)))) = heads.pop() {
        writer.push(&row)?;
        let s = match names.iter().position(|n| *n == row.strategy) {
            Some(s) => s,
            None => {
                names.push(row.strategy.clone());
                names.len() - 1
            }
        };
        if per_house.last().is_none_or(|(h, _)| *h != house) {
            per_house.push((house, 0));
            in_house.clear();
        }
        if !in_house.contains(&s) {
            in_house.push(s);
            if let Some(last) = per_house.last_mut() {
                last.1 += 1;
            }
        }
        if let Some(next) = readers[k].next_row()? {
            heads.push(std::cmp::Reverse((next.house_index, k, HeadRow(next))));
        }
    }
    let counts: Vec<usize> = readers.iter().map(|r| r.rows).collect();
    let m = merged_parts(&pairs, &records, &counts);
    let source = m.info.house_source().describe();
    let rows = writer.rows();
    let written = writer.finish(
        m.info,
        &ReportView {
            source: &source,
            houses: &m.houses,
            houses_run: m.houses_run,
            trials_run: m.trials_run,
            paired_against: &m.paired_against,
            cells: m.cells,
        },
    )?;
    let ran: Vec<String> = written
        .info
        .strategies
        .iter()
        .filter(|s| names.contains(s))
        .cloned()
        .collect();
    let complete = per_house
        .iter()
        .filter(|(_, n)| *n == names.len())
        .map(|(h, _)| *h)
        .collect();
    Ok(MergedDir {
        written,
        rows,
        houses: m.houses,
        houses_run: m.houses_run,
        failures: m.failures,
        show_house: m.show_house,
        ran,
        complete,
    })
}

/// A row waiting in the merge's heap: ordered by the house and shard beside it only.
struct HeadRow(TrialRow);

impl PartialEq for HeadRow {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}
impl Eq for HeadRow {}
impl PartialOrd for HeadRow {
    fn partial_cmp(&self, other: &Self) -> Option<std::cmp::Ordering> {
        Some(self.cmp(other))
    }
}
impl Ord for HeadRow {
    fn cmp(&self, _: &Self) -> std::cmp::Ordering {
        std::cmp::Ordering::Equal
    }
}

/// One shard's trials.csv read row by row, each row checked against the shard's houses and
/// for house order.
struct ShardRows {
    dir: PathBuf,
    path: PathBuf,
    reader: csv::DeserializeRecordsIntoIter<std::fs::File, TrialRow>,
    houses: Vec<usize>,
    rows: usize,
    last_house: usize,
}

impl ShardRows {
    fn open(dir: &Path, houses: Vec<usize>) -> crate::Result<Self> {
        let path = dir.join("trials.csv");
        let file = std::fs::File::open(&path)
            .map_err(|e| crate::LabError::io(format!("reading {}", path.display()), e))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            reader: csv::Reader::from_reader(file).into_deserialize(),
            path,
            houses,
            rows: 0,
            last_house: 0,
        })
    }

    fn next_row(&mut self) -> crate::Result<Option<TrialRow>> {
        let Some(row) = self.reader.next() else {
            return Ok(None);
        };
        let row = row.map_err(|source| crate::LabError::Csv {
            context: format!("{}: row {}", self.path.display(), self.rows + 2),
            source,
        })?;
        if self.houses.binary_search(&row.house_index).is_err() {
            return Err(not_loaded(&self.dir, &row).into());
        }
        if row.house_index < self.last_house {
            return Err(MergeError::Inconsistent {
                dir: self.dir.clone(),
                message: format!(
                    "trials.csv row {} (house {}) comes after house {}: not in house order",
                    self.rows + 2,
                    row.house_index,
                    self.last_house
                ),
            }
            .into());
        }
        self.last_house = row.house_index;
        self.rows += 1;
        Ok(Some(row))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_rule_is_pinned() {
        // Fixed house → fixed shard: a change here reassigns houses between existing shards.
        let of = |h| Shard::of_house(h, 3);
        assert_eq!(
            (0..10).map(of).collect::<Vec<_>>(),
            [0, 1, 2, 0, 1, 2, 0, 1, 2, 0]
        );
        assert_eq!(Shard::of_house(149, 3), 2);
        assert_eq!(Shard::of_house(9_999, 16), 15);
        assert_eq!(Shard::of_house(9_999, 128), 15);
        let s: Shard = "1/3".parse().unwrap();
        assert!(s.contains(4) && !s.contains(5));
        assert_eq!(s.to_string(), "1/3");
    }

    #[test]
    fn shards_partition_the_houses() {
        for n in 1..8 {
            for h in 0..100 {
                let owners = (0..n).filter(|&i| Shard { index: i, count: n }.contains(h));
                assert_eq!(owners.count(), 1);
            }
        }
    }

    #[test]
    fn bad_shards_are_refused() {
        assert!(matches!(
            "3/3".parse::<Shard>(),
            Err(ShardError::OutOfRange { .. })
        ));
        assert!(matches!(
            "0/0".parse::<Shard>(),
            Err(ShardError::OutOfRange { .. })
        ));
        assert!(matches!("x".parse::<Shard>(), Err(ShardError::Syntax(_))));
        assert_eq!("auto".parse::<ShardSpec>().unwrap(), ShardSpec::Auto);
    }

    fn env<'a>(vars: &'a [(&'a str, &'a str)]) -> impl Fn(&str) -> Option<String> + 'a {
        move |k| {
            vars.iter()
                .find(|(n, _)| *n == k)
                .map(|(_, v)| v.to_string())
        }
    }

    #[test]
    fn auto_reads_slurm_then_kubernetes() {
        let slurm = [
            ("SLURM_ARRAY_TASK_ID", "2"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("SLURM_ARRAY_TASK_MIN", "0"),
        ];
        assert_eq!(
            ShardSpec::Auto.resolve(env(&slurm)),
            Ok(Shard { index: 2, count: 3 })
        );
        let one_based = [
            ("SLURM_ARRAY_TASK_ID", "3"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("SLURM_ARRAY_TASK_MIN", "1"),
        ];
        assert_eq!(
            ShardSpec::Auto.resolve(env(&one_based)),
            Ok(Shard { index: 2, count: 3 })
        );
        let k8s = [("JOB_COMPLETION_INDEX", "4"), (SHARD_COUNT_VAR, "5")];
        assert_eq!(
            ShardSpec::Auto.resolve(env(&k8s)),
            Ok(Shard { index: 4, count: 5 })
        );
        let e = ShardSpec::Auto.resolve(env(&[])).unwrap_err().to_string();
        assert!(
            e.contains("SLURM_ARRAY_TASK_ID") && e.contains("JOB_COMPLETION_INDEX"),
            "{e}"
        );
        let e = ShardSpec::Auto
            .resolve(env(&[("JOB_COMPLETION_INDEX", "1")]))
            .unwrap_err()
            .to_string();
        assert!(e.contains(SHARD_COUNT_VAR), "{e}");
    }

    #[test]
    fn auto_refuses_two_batch_systems_and_numbers_that_are_not_plain_digits() {
        let both = [
            ("SLURM_ARRAY_TASK_ID", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "3"),
            ("JOB_COMPLETION_INDEX", "1"),
            (SHARD_COUNT_VAR, "3"),
        ];
        let e = ShardSpec::Auto.resolve(env(&both)).unwrap_err().to_string();
        assert!(e.contains("ambiguous"), "{e}");
        for bad in [" 1", "+1", "1 ", "", "-1", "1_0"] {
            let vars = [
                ("SLURM_ARRAY_TASK_ID", bad),
                ("SLURM_ARRAY_TASK_COUNT", "3"),
            ];
            let e = ShardSpec::Auto.resolve(env(&vars)).unwrap_err().to_string();
            assert!(e.contains("not a number"), "{bad:?}: {e}");
            let vars = [("JOB_COMPLETION_INDEX", "0"), (SHARD_COUNT_VAR, bad)];
            assert!(ShardSpec::Auto.resolve(env(&vars)).is_err(), "{bad:?}");
        }
        for bad in ["+1/3", "1/+3", "1 / 3", "0x1/3"] {
            assert!(
                matches!(bad.parse::<Shard>(), Err(ShardError::Syntax(_))),
                "{bad}"
            );
        }
        assert_eq!(" 1/3 ".parse::<Shard>(), Ok(Shard { index: 1, count: 3 }));
    }
}
