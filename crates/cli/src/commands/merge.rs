//! `ferret merge`: the run directories of an evaluation's shards (`ferret eval --shard`) into
//! the run one machine writes, and their LLM caches into one cache.

use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{Context, Result};

use ferret_lab::HouseSource;
use ferret_lab::TrialRow;
use ferret_lab::merge::MergedDir;
use ferret_lab::runs::RunInfo;
use ferret_llm::ResponseCache;
use ferret_world::procthor::HouseRange;

use super::eval::{Pictures, SHARD_CACHE, draw_pictures, no_trajectories};
use ferret_lab::ShownHouse;

/// Merge the shards of an evaluation (`ferret eval --shard i/n --out DIR_i`) into one run:
/// trials.csv in the order one machine writes it (byte for byte the same file), summary.csv,
/// paired.csv and summary.md made from it as `ferret eval` makes them, costs.png and
/// trajectories.png drawn as it draws them (shards draw none; the shown house is read again from
/// the house file), and run.json listing the shards. Refuses shards run with different settings, a shard given twice, houses in two shards
/// and missing shards, naming the directories. Each shard's LLM cache (DIR_i/llm-cache.sqlite,
/// and every --cache) is merged into one (insert-or-ignore by key); a key that two caches
/// answer differently is listed and makes the exit status 1. `select` and `calibrate` then read
/// the merged run as any other.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The shards' run directories (any order). With none, only the caches are merged.
    #[arg(value_name = "RUN_DIR")]
    pub runs: Vec<PathBuf>,
    /// More LLM caches to merge, besides each run directory's llm-cache.sqlite.
    #[arg(long = "cache", value_name = "FILE")]
    pub caches: Vec<PathBuf>,
    /// Where the merged cache is written (created, or added to when it exists); default
    /// <out>/llm-cache.sqlite.
    #[arg(long, value_name = "FILE")]
    pub cache_out: Option<PathBuf>,
    /// Output directory of the merged run.
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
}

/// Runs `ferret merge`.
pub fn run(args: Args) -> Result<ExitCode> {
    if args.runs.is_empty() && args.caches.is_empty() {
        anyhow::bail!("nothing to merge: give the shards' run directories, or --cache files");
    }
    let mut caches: Vec<PathBuf> = args
        .runs
        .iter()
        .map(|d| d.join(SHARD_CACHE))
        .filter(|p| p.is_file())
        .collect();
    caches.extend(args.caches.iter().cloned());
    let cache_out = args
        .cache_out
        .clone()
        .unwrap_or_else(|| args.out.join(SHARD_CACHE));
    if let Some(c) = caches.iter().find(|c| same_file(c, &cache_out)) {
        anyhow::bail!(
            "--cache-out {} is one of the caches being merged ({}); write the merge elsewhere",
            cache_out.display(),
            c.display()
        );
    }
    let mut status = ExitCode::SUCCESS;
    if !args.runs.is_empty() {
        // Before the lock, which would leave its file in a shard given as --out.
        ferret_lab::merge::check_out(&args.runs, &args.out)?;
        let mut lock = ferret_lab::files::DirLock::acquire(&args.out)?;
        let merged = ferret_lab::merge::merge_dirs(&args.runs, &args.out)?;
        lock.used();
        let pictures = draw_merged_pictures(&merged, &args.out)?;
        println!("{}", merged.written.report.markdown);
        println!(
            "merged {} shards: {} trials on {} houses; wrote {}/{{trials.csv,summary.csv,summary.md,paired.csv,run.json{}}}",
            args.runs.len(),
            merged.rows,
            merged.houses_run,
            args.out.display(),
            pictures.iter().map(|p| format!(",{p}")).collect::<String>()
        );
        if merged.failures > 0 {
            eprintln!(
                "{} house(s) or trial(s) failed in the shards (see their logs); every finished trial was merged",
                merged.failures
            );
            status = ExitCode::FAILURE;
        }
    }
    if !caches.is_empty() {
        let out = ResponseCache::open(&cache_out)?;
        let mut conflicts = 0;
        for c in &caches {
            let other = ResponseCache::open(c)
                .with_context(|| format!("opening the cache {}", c.display()))?;
            let m = out.merge_from(&other)?;
            for conflict in &m.conflicts {
                eprintln!("cache conflict: {conflict}");
            }
            conflicts += m.conflicts.len();
            println!(
                "{}: {} answers added, {} already there",
                c.display(),
                m.added,
                m.present
            );
        }
        println!("{}: {} answers", cache_out.display(), out.len()?);
        if conflicts > 0 {
            eprintln!(
                "{conflicts} key(s) were answered differently by two caches: the first answer was \
                 kept, but the shards' trials used different answers for the same question, \
                 which one machine never does (an endpoint that does not answer \
                 deterministically); rerun those shards from the merged cache with --offline to \
                 make them agree"
            );
            status = ExitCode::FAILURE;
        }
    }
    Ok(status)
}

/// Draws the merged run's costs.png and trajectories.png, those one machine draws: shards draw
/// none, so that the pictures are drawn once. The shown house is read again from the run's house
/// source and mapped alone; when that source cannot be read here (shards run on other machines
/// with other paths), trajectories.png is left out, saying why.
fn draw_merged_pictures(merged: &MergedDir, out: &Path) -> Result<Vec<&'static str>> {
    let info = &merged.written.info;
    let pick = merged
        .complete
        .iter()
        .copied()
        .find(|h| merged.show_house.is_none_or(|i| i == *h));
    let shown = match pick {
        Some(h) => match house_rows(&out.join("trials.csv"), h)
            .and_then(|rows| shown_house(info, h, &rows))
        {
            Ok(shown) => Some(shown),
            Err(e) => {
                eprintln!("house {h} could not be read again: {e:#}; trajectories.png not drawn");
                None
            }
        },
        None => {
            no_trajectories(merged.show_house);
            None
        }
    };
    draw_pictures(
        &Pictures {
            out,
            strategies: &info.strategies,
            ran: &merged.ran,
            houses: merged.houses.len(),
            seed: info.seed,
            team: info.team,
        },
        &merged.written.costs,
        shown.as_ref(),
    )
}

/// The rows of house `index` in a trials.csv, read row by row.
fn house_rows(path: &Path, index: usize) -> Result<Vec<TrialRow>> {
    let mut rows = Vec::new();
    let mut reader =
        csv::Reader::from_path(path).with_context(|| format!("reading {}", path.display()))?;
    for (i, row) in reader.deserialize::<TrialRow>().enumerate() {
        let row = row.with_context(|| format!("{}: row {}", path.display(), i + 2))?;
        if row.house_index == index {
            rows.push(row);
        }
    }
    Ok(rows)
}

/// House `index` of the run's source, mapped as the run mapped it, with its rows.
fn shown_house(info: &RunInfo, index: usize, rows: &[TrialRow]) -> Result<ShownHouse> {
    let source = HouseSource {
        range: Some(HouseRange::single(index)),
        ..info.house_source()
    };
    let loaded = source.load_for(info.protocol.containers)?;
    let scene = loaded
        .scenes
        .into_iter()
        .find(|s| s.house.index == index)
        .with_context(|| format!("not in {}", source.describe()))?;
    let (_, distances) =
        ferret_world::distance::build(&scene.house, &info.grid_params(info.protocol.access))?;
    Ok(ShownHouse {
        scene,
        distances,
        rows: rows
            .iter()
            .filter(|r| r.house_index == index)
            .cloned()
            .collect(),
    })
}

/// Whether two paths name the same existing file.
fn same_file(a: &Path, b: &Path) -> bool {
    match (a.canonicalize(), b.canonicalize()) {
        (Ok(a), Ok(b)) => a == b,
        _ => false,
    }
}
