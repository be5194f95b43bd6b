//! The merge of shards' runs (`ferret eval --shard`, see [`shard`](crate::shard)) into the run
//! one machine would have written: [`merge_runs`] over runs in memory, [`merge_dirs`] over run
//! directories row by row.

use std::path::{Path, PathBuf};

use crate::error::{LabError, Result};
use crate::rows::TrialRow;
use crate::runs::{EvalRun, ReportView, RunInfo, RunReport, WrittenRun};
use crate::shard::{MergeError, MergedShard, SHARD_RULE, Shard, ShardRecord};

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
    pub fn write_all(&self, dir: &Path) -> Result<RunReport> {
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
pub fn check_out(dirs: &[PathBuf], out: &Path) -> Result<()> {
    let o = crate::files::resolved(out);
    for d in dirs {
        let r = crate::files::resolved(d);
        if o.starts_with(&r) || r.starts_with(&o) {
            return Err(LabError::invalid(format!(
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
pub fn merge_dirs(dirs: &[PathBuf], out: &Path) -> Result<MergedDir> {
    check_out(dirs, out)?;
    let infos: Vec<RunInfo> = dirs
        .iter()
        .map(|d| crate::runs::read_checked_info(d))
        .collect::<Result<_>>()?;
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
    fn open(dir: &Path, houses: Vec<usize>) -> Result<Self> {
        let path = dir.join("trials.csv");
        let file = std::fs::File::open(&path)
            .map_err(|e| LabError::io(format!("reading {}", path.display()), e))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            reader: csv::Reader::from_reader(file).into_deserialize(),
            path,
            houses,
            rows: 0,
            last_house: 0,
        })
    }

    fn next_row(&mut self) -> Result<Option<TrialRow>> {
        let Some(row) = self.reader.next() else {
            return Ok(None);
        };
        let row = row.map_err(|source| LabError::Csv {
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
