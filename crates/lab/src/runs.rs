//! The files of an evaluation run: `trials.csv` (one [`TrialRow`] per trial and strategy) and
//! `run.json` ([`RunInfo`], what rebuilds its houses and strategies), read back with their
//! identity checked.

use std::path::{Path, PathBuf};

use ferret_plan::{Protocol, TrialsPerHouse};
use ferret_world::{AccessRule, GridParams};
use serde::{Deserialize, Serialize};

use crate::error::{Context, LabError, Result};
use crate::houses::HouseSource;
use crate::report::{RunFigures, run_markdown};
use crate::rows::{CELL_M, TrialRow};
use crate::shard::{MergedShard, ShardRecord};
use crate::strategies::PlanningSettings;
use crate::summary::{
    CostTable, PairedRow, SummaryRow, paired_comparisons_of, reference_means_of, summarize_costs,
};

/// What rebuilds the houses and strategies of an evaluation run.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunInfo {
    /// The house file.
    pub houses: Option<PathBuf>,
    /// The range of houses in it.
    pub range: Option<String>,
    /// The asset database.
    pub asset_db: Option<PathBuf>,
    /// Houses generated when there is no file.
    pub generate: usize,
    /// Seed of the generated houses.
    pub house_seed: u64,
    /// Grid resolution, robot radius, wall thickness.
    pub grid: [f64; 3],
    /// Planner settings.
    pub planning: PlanningSettings,
    /// Trial seed.
    pub seed: u64,
    /// Reveal fraction.
    pub reveal_fraction: f64,
    /// Trials per house; left out when 1, so that single-trial runs keep the shorter file.
    #[serde(default, skip_serializing_if = "is_one_per_house")]
    pub trials_per_house: TrialsPerHouse,
    /// The protocol; left out when it is ferret's, for the same reason.
    #[serde(default, skip_serializing_if = "is_ferret_protocol")]
    pub protocol: Protocol,
    /// Household tasks instead of one target per trial; absent for single targets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub tasks: Option<crate::tasks::Tasks>,
    /// The team on every trial, in a run of teams.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub team: Option<ferret_plan::TeamSettings>,
    /// Strategies in order.
    pub strategies: Vec<String>,
    /// SHA-256 of the trials.csv written with this file, so that a trials.csv of another run
    /// beside it (an eval stopped between the two) is recognised.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub trials_sha256: Option<String>,
    /// The shard this run is (`ferret eval --shard`); absent in a whole run.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub shard: Option<ShardRecord>,
    /// The shards a merged run was made of (`ferret merge`); absent otherwise.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub merged_from: Vec<MergedShard>,
}

fn is_ferret_protocol(p: &Protocol) -> bool {
    *p == Protocol::FERRET
}

fn is_one_per_house(t: &TrialsPerHouse) -> bool {
    *t == TrialsPerHouse::One
}

impl RunInfo {
    /// Where the run's houses come from (invalid houses skipped, as the run skipped them).
    pub fn house_source(&self) -> HouseSource {
        HouseSource {
            houses: self.houses.clone(),
            range: self.range.as_ref().and_then(|r| r.parse().ok()),
            asset_db: self.asset_db.clone(),
            skip_invalid: true,
            generate: self.generate,
            house_seed: self.house_seed,
        }
    }

    /// The grid the run's maps were built on, with access points chosen by `access`.
    pub fn grid_params(&self, access: AccessRule) -> GridParams {
        GridParams {
            resolution: self.grid[0],
            robot_radius: self.grid[1],
            wall_thickness: self.grid[2],
            access,
        }
    }
}

/// Lower-case hex SHA-256 of `bytes`.
pub fn sha256_hex(bytes: &[u8]) -> String {
    use sha2::{Digest, Sha256};
    format!("{:x}", Sha256::digest(bytes))
}

/// Largest run file read (trials.csv of a very large run is tens of megabytes).
const MAX_RUN_FILE_BYTES: u64 = 1 << 30;

/// A run file, through the bounded reader every input goes through.
pub fn read_run_file(path: &Path) -> std::io::Result<Vec<u8>> {
    ferret_world::input::read_file(path, MAX_RUN_FILE_BYTES)
}

/// Parses serde rows from the CSV text of `path`; errors name the file and line.
pub fn parse_csv<T: for<'de> Deserialize<'de>>(bytes: &[u8], path: &Path) -> Result<Vec<T>> {
    let mut r = csv::Reader::from_reader(bytes);
    r.deserialize()
        .enumerate()
        .map(|(i, row)| {
            row.map_err(|source| LabError::Csv {
                context: format!("{}: row {}", path.display(), i + 2),
                source,
            })
        })
        .collect()
}

/// An evaluation run read back from its directory.
#[derive(Clone, Debug)]
pub struct EvalRun {
    /// `run.json`.
    pub info: RunInfo,
    /// `trials.csv`.
    pub rows: Vec<TrialRow>,
    /// The bytes of `run.json`, part of the run's identity.
    pub run_json: Vec<u8>,
    /// The bytes of `trials.csv`, part of the run's identity.
    pub trials_csv: Vec<u8>,
}

/// run.json's text.
fn run_json_bytes(info: &RunInfo) -> Result<Vec<u8>> {
    serde_json::to_string_pretty(info)
        .map(String::into_bytes)
        .map_err(|source| LabError::Json {
            context: "writing run.json".into(),
            source,
        })
}

impl EvalRun {
    /// The run of `rows` that `info` describes, as `ferret eval` writes it: `info`'s
    /// `trials_sha256` is set to the hash of the rows' CSV text.
    pub fn new(mut info: RunInfo, rows: Vec<TrialRow>) -> Result<Self> {
        let trials_csv = crate::files::csv_bytes(&rows)?;
        info.trials_sha256 = Some(sha256_hex(&trials_csv));
        let run_json = run_json_bytes(&info)?;
        Ok(Self {
            info,
            rows,
            run_json,
            trials_csv,
        })
    }

    /// Writes `dir/trials.csv`, then `dir/run.json` (each atomically; [`EvalRun::read`] tells
    /// a pair of different runs apart by the hash).
    pub fn write(&self, dir: &Path) -> Result<()> {
        crate::files::write_bytes(&dir.join("trials.csv"), &self.trials_csv)?;
        crate::files::write_bytes(&dir.join("run.json"), &self.run_json)
    }

    /// The summary (the paper's table I), the paired comparisons and `summary.md` of this run,
    /// as `ferret eval` writes them; `view` says what the run's files cannot.
    pub fn report(&self, view: &ReportView<'_>) -> RunReport {
        run_report(&self.info, &CostTable::from_rows(&self.rows), view)
    }

    /// Writes every file of an evaluation into `dir`: `summary.csv`, `paired.csv`, `summary.md`
    /// of `report`, then the run itself ([`EvalRun::write`]). `ferret eval`'s streaming writer
    /// ([`RunWriter`]) and the Python package's `Evaluation.save` write the same files.
    pub fn write_all(&self, dir: &Path, report: &RunReport) -> Result<()> {
        write_report(dir, &self.info, report)?;
        self.write(dir)
    }

    /// Reads `dir/run.json` and `dir/trials.csv` and checks that they belong together.
    pub fn read(dir: &Path) -> Result<Self> {
        let (info, run_json) = read_info(dir)?;
        let trials_path = dir.join("trials.csv");
        let trials_csv = read_run_file(&trials_path)
            .map_err(|e| LabError::io(format!("reading {}", trials_path.display()), e))?;
        check_hash(dir, &info, &sha256_hex(&trials_csv))?;
        let rows = parse_csv(&trials_csv, &trials_path)?;
        Ok(Self {
            info,
            rows,
            run_json,
            trials_csv,
        })
    }
}

/// `dir/run.json`, parsed and as read.
fn read_info(dir: &Path) -> Result<(RunInfo, Vec<u8>)> {
    let run_json = read_run_file(&dir.join("run.json"))
        .map_err(LabError::from_io_plain)
        .context_with(|| format!("{}: not a `ferret eval` output directory", dir.display()))?;
    let info: RunInfo = serde_json::from_slice(&run_json).map_err(|source| LabError::Json {
        context: "reading run.json".into(),
        source,
    })?;
    Ok((info, run_json))
}

/// Refuses a trials.csv whose hash is not the one run.json records.
fn check_hash(dir: &Path, info: &RunInfo, actual: &str) -> Result<()> {
    if let Some(expected) = &info.trials_sha256
        && expected != actual
    {
        return Err(LabError::invalid(format!(
            "{}: trials.csv and run.json are from different runs (an eval was stopped between \
             writing them, or one file was copied from another run); run `ferret eval` into this \
             directory again",
            dir.display()
        )));
    }
    Ok(())
}

/// `dir/run.json`, checked as [`EvalRun::read`] checks it against `dir/trials.csv`, whose hash
/// is computed reading the file through rather than holding it.
pub fn read_checked_info(dir: &Path) -> Result<RunInfo> {
    use sha2::Digest;
    let (info, _) = read_info(dir)?;
    let trials_path = dir.join("trials.csv");
    let io = |e| LabError::io(format!("reading {}", trials_path.display()), e);
    let mut file = std::fs::File::open(&trials_path).map_err(io)?;
    let mut hasher = sha2::Sha256::new();
    std::io::copy(&mut file, &mut hasher).map_err(io)?;
    check_hash(dir, &info, &format!("{:x}", hasher.finalize()))?;
    Ok(info)
}

/// The report of a run described by `info` whose rows' costs are `costs`: the summary (the
/// paper's table I), the paired comparisons and `summary.md`.
///
/// A shard's report has no paired comparisons: its bootstrap over a part of the trials is
/// thrown away when `ferret merge` compares all of them, and it is most of the report's cost, so
/// every shard would repeat a third of the one machine's work for nothing. Its summary.md says
/// so.
pub fn run_report(info: &RunInfo, costs: &CostTable, view: &ReportView<'_>) -> RunReport {
    let mut summary = summarize_costs(costs, &info.strategies);
    if view.cells {
        summary = summary.into_iter().map(SummaryRow::with_cells).collect();
    }
    let paired = if info.shard.is_some() {
        Vec::new()
    } else {
        paired_comparisons_of(costs, &info.strategies, view.paired_against, info.seed)
    };
    let reference_means = (info.protocol.rng == ferret_plan::TrialRng::Python
        && info.trials_per_house == TrialsPerHouse::One)
        .then(|| reference_means_of(costs, &info.strategies, view.houses));
    let tasks = info.tasks.as_ref().map(crate::tasks::Tasks::describe);
    let markdown = run_markdown(&RunFigures {
        summary: &summary,
        source: view.source,
        houses_run: view.houses_run,
        trials_per_house: info.trials_per_house,
        trials_run: view.trials_run,
        tasks: tasks.as_deref(),
        cells: view.cells,
        reference_means: reference_means.as_deref(),
        shard: info.shard.as_ref().map(|sh| (sh.index, sh.count)),
        paired: &paired,
    });
    RunReport {
        summary,
        paired,
        markdown,
    }
}

/// Files a shard does not write (see [`run_report`]); one left in its directory by an earlier
/// run there would be taken for this run's.
const NOT_IN_A_SHARD: [&str; 3] = ["paired.csv", "costs.png", "trajectories.png"];

/// Writes `summary.csv`, `paired.csv` (not for a shard) and `summary.md` of `report` into `dir`.
fn write_report(dir: &Path, info: &RunInfo, report: &RunReport) -> Result<()> {
    crate::files::write_csv(&dir.join("summary.csv"), &report.summary)?;
    if info.shard.is_some() {
        for f in NOT_IN_A_SHARD {
            match std::fs::remove_file(dir.join(f)) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(LabError::io(
                        format!("removing the stale {f} in {}", dir.display()),
                        e,
                    ));
                }
                _ => {}
            }
        }
    } else {
        crate::files::write_csv(&dir.join("paired.csv"), &report.paired)?;
    }
    crate::files::write_bytes(&dir.join("summary.md"), &report.markdown)
}

/// Writes an evaluation run as its trials finish: each row goes to `trials.csv` (a temporary
/// file until [`finish`](Self::finish)) and only its cost stays in memory ([`CostTable`]), so
/// that an evaluation's memory does not grow with its houses. The files are those of
/// [`EvalRun::new`] and [`EvalRun::write_all`], byte for byte.
pub struct RunWriter {
    dir: PathBuf,
    file: crate::files::AtomicFile,
    csv: csv::Writer<HashingWriter<std::io::BufWriter<std::fs::File>>>,
    costs: CostTable,
    cells: bool,
}

impl std::fmt::Debug for RunWriter {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RunWriter")
            .field("dir", &self.dir)
            .field("rows", &self.costs.len())
            .field("cells", &self.cells)
            .finish_non_exhaustive()
    }
}

impl RunWriter {
    /// Starts a run in `dir` (which must exist); with `cells`, rows get their cost in 0.05 m
    /// cells (`cost_cells`). Nothing in `dir` changes until [`finish`](Self::finish).
    ///
    /// # Errors
    /// I/O errors creating the temporary trials file.
    pub fn create(dir: &Path, cells: bool) -> Result<Self> {
        let path = dir.join("trials.csv");
        let io = |e| LabError::io(format!("writing {}", path.display()), e);
        let file = crate::files::AtomicFile::create(&path).map_err(io)?;
        let handle = file.handle().map_err(io)?;
        Ok(Self {
            dir: dir.to_path_buf(),
            file,
            csv: csv::Writer::from_writer(HashingWriter::new(std::io::BufWriter::new(handle))),
            costs: CostTable::default(),
            cells,
        })
    }

    /// Appends a finished trial.
    ///
    /// # Errors
    /// I/O errors writing it.
    pub fn push(&mut self, row: &TrialRow) -> Result<()> {
        self.costs.push(row);
        let result = if self.cells {
            self.csv.serialize(TrialRow {
                cost_cells: Some(row.cost_m / CELL_M),
                ..row.clone()
            })
        } else {
            self.csv.serialize(row)
        };
        result.map_err(|source| LabError::Csv {
            context: format!("writing {}", self.dir.join("trials.csv").display()),
            source,
        })
    }

    /// Rows written so far.
    pub fn rows(&self) -> usize {
        self.costs.len()
    }

    /// The costs of the rows written so far.
    pub fn costs(&self) -> &CostTable {
        &self.costs
    }

    /// Writes the report of the run `info` describes (its `trials_sha256` set to the written
    /// trials'), then puts `trials.csv` in place and writes `run.json`, in the order of
    /// [`EvalRun::write_all`]. Returns the report, the costs and run.json as written.
    ///
    /// # Errors
    /// I/O errors; then `trials.csv` and `run.json` keep what they held.
    pub fn finish(self, mut info: RunInfo, view: &ReportView<'_>) -> Result<WrittenRun> {
        let trials_path = self.dir.join("trials.csv");
        let io = |e| LabError::io(format!("writing {}", trials_path.display()), e);
        let hashing = self
            .csv
            .into_inner()
            .map_err(|e| io(std::io::Error::other(e.error().to_string())))?;
        let (buffered, sha) = hashing.finish();
        buffered.into_inner().map_err(|e| io(e.into_error()))?;
        info.trials_sha256 = Some(sha);
        let run_json = run_json_bytes(&info)?;
        let report = run_report(&info, &self.costs, view);
        write_report(&self.dir, &info, &report)?;
        self.file.commit().map_err(io)?;
        crate::files::write_bytes(&self.dir.join("run.json"), &run_json)?;
        Ok(WrittenRun {
            info,
            report,
            costs: self.costs,
        })
    }
}

/// What [`RunWriter::finish`] wrote.
#[derive(Clone, Debug)]
pub struct WrittenRun {
    /// run.json.
    pub info: RunInfo,
    /// summary.csv, paired.csv and summary.md.
    pub report: RunReport,
    /// The costs of trials.csv's rows.
    pub costs: CostTable,
}

/// A writer that hashes (SHA-256) what passes through it: trials.csv's hash for run.json
/// without reading the file back.
struct HashingWriter<W> {
    inner: W,
    hasher: sha2::Sha256,
}

impl<W: std::io::Write> HashingWriter<W> {
    fn new(inner: W) -> Self {
        use sha2::Digest;
        Self {
            inner,
            hasher: sha2::Sha256::new(),
        }
    }

    /// The writer and the lower-case hex hash of everything written.
    fn finish(self) -> (W, String) {
        use sha2::Digest;
        (self.inner, format!("{:x}", self.hasher.finalize()))
    }
}

impl<W: std::io::Write> std::io::Write for HashingWriter<W> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        use sha2::Digest;
        let n = self.inner.write(buf)?;
        self.hasher.update(&buf[..n]);
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

impl LabError {
    /// An I/O error whose message is the cause alone (the caller's context says which file).
    pub(crate) fn from_io_plain(e: std::io::Error) -> Self {
        LabError::Io {
            context: e.to_string(),
            source: e,
        }
    }
}

/// What a run's report needs that its files do not say.
#[derive(Clone, Copy, Debug)]
pub struct ReportView<'a> {
    /// Where the houses came from, as the report names it ([`HouseSource::describe`]).
    pub source: &'a str,
    /// Indices of the houses evaluated (the reference code's means average over them).
    pub houses: &'a [usize],
    /// Houses with at least one finished trial.
    pub houses_run: usize,
    /// Trials (house and target) drawn on those houses.
    pub trials_run: usize,
    /// Strategies to compare every other one against, besides the best.
    pub paired_against: &'a [String],
    /// Costs in grid cells too (the paper's unit).
    pub cells: bool,
}

/// A run's summary, paired comparisons and `summary.md`.
#[derive(Clone, Debug)]
pub struct RunReport {
    /// The paper's table I, one row per strategy.
    pub summary: Vec<SummaryRow>,
    /// Paired comparisons.
    pub paired: Vec<PairedRow>,
    /// `summary.md`.
    pub markdown: String,
}
