//! An evaluation streamed to disk (rows written as houses finish, only costs kept) writes the
//! files of the in-memory writer, byte for byte: on generated houses run through both paths, and
//! on arbitrary rows.

use std::path::Path;
use std::sync::Arc;

use ferret_lab::runs::{ReportView, RunWriter};
use ferret_lab::shard::{SHARD_RULE, ShardRecord};
use ferret_lab::{
    EvalContext, EvalRun, HouseInput, HouseSource, LlmSettings, PlanningSettings, RunInfo, Silent,
    Strategies, TrialDraw, TrialRow, build_maps, evaluate,
};
use ferret_plan::{Protocol, Strategy, TrialsPerHouse};
use ferret_world::GridParams;
use proptest::prelude::*;

const FILES: [&str; 5] = [
    "trials.csv",
    "summary.csv",
    "paired.csv",
    "summary.md",
    "run.json",
];

fn info(strategies: &[String], count: usize) -> RunInfo {
    let grid = GridParams::default();
    RunInfo {
        houses: None,
        range: None,
        asset_db: None,
        generate: count,
        house_seed: 5,
        grid: [grid.resolution, grid.robot_radius, grid.wall_thickness],
        planning: PlanningSettings::default(),
        seed: 0,
        reveal_fraction: 0.0,
        trials_per_house: TrialsPerHouse::Count(2),
        protocol: Protocol::FERRET,
        tasks: None,
        team: None,
        strategies: strategies.to_vec(),
        trials_sha256: None,
        shard: None,
        merged_from: Vec::new(),
    }
}

fn view<'a>(houses: &'a [usize], houses_run: usize, trials_run: usize) -> ReportView<'a> {
    ReportView {
        source: "test houses",
        houses,
        houses_run,
        trials_run,
        paired_against: &[],
        cells: false,
    }
}

/// Every file of `a` is the same file in `b`; a file missing from both is fine.
fn assert_same_files(a: &Path, b: &Path) {
    for f in FILES {
        let (x, y) = (std::fs::read(a.join(f)).ok(), std::fs::read(b.join(f)).ok());
        assert!(x == y, "{f} differs between {a:?} and {b:?}");
    }
}

/// Generated houses evaluated twice: every map built first and every row kept (the way of
/// earlier versions), then streamed a batch at a time into the run writer. With one thread the
/// batches are 8 houses, so 40 houses cross four batch boundaries.
#[test]
fn a_streamed_evaluation_writes_the_in_memory_run_byte_for_byte() {
    let dir = tempfile::tempdir().unwrap();
    let count = 40;
    let loaded = HouseSource {
        generate: count,
        house_seed: 5,
        ..HouseSource::default()
    }
    .load_for(ferret_world::ContainerSet::Receptacles)
    .unwrap();
    let specs: Vec<String> = [
        "optimistic+greedy",
        "model/uniform",
        "model/prior",
        "oracle",
    ]
    .iter()
    .map(|s| s.to_string())
    .collect();
    let llm = LlmSettings {
        llm_cache: dir.path().join("cache.sqlite"),
        ..LlmSettings::default()
    };
    let setup = Strategies::builder(&PlanningSettings::default(), &llm)
        .for_specs(&specs)
        .build()
        .unwrap();
    let draw = TrialDraw {
        seed: 0,
        reveal_fraction: 0.0,
        per_house: TrialsPerHouse::Count(2),
        protocol: &Protocol::FERRET,
        holdout: None,
        tasks: None,
        team: None,
    };
    let grid = GridParams::default();
    let houses: Vec<usize> = loaded.scenes.iter().map(|s| s.house.index).collect();

    let maps = build_maps(&loaded.scenes, &grid, &Silent);
    let strategies: Vec<Arc<dyn Strategy>> = specs
        .iter()
        .map(|s| setup.registry.build(s).unwrap())
        .collect();
    let whole = evaluate(&loaded.scenes, &maps, &strategies, &draw, &Silent);
    assert!(whole.errors.is_empty(), "{:?}", whole.errors);
    drop(maps);

    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    for (cells, shard) in [(false, false), (true, false), (false, true)] {
        let memory = dir.path().join(format!("memory-{cells}-{shard}"));
        let streamed = dir.path().join(format!("streamed-{cells}-{shard}"));
        std::fs::create_dir_all(&memory).unwrap();
        std::fs::create_dir_all(&streamed).unwrap();
        let mut info = info(&specs, count);
        if shard {
            // A whole run's paired.csv left in the directory is not this shard's.
            std::fs::write(streamed.join("paired.csv"), "stale").unwrap();
            info.shard = Some(ShardRecord {
                index: 0,
                count: 1,
                rule: SHARD_RULE.into(),
                houses: houses.clone(),
                houses_run: whole.houses_run,
                trials_run: whole.trials_run,
                failures: 0,
                paired_against: Vec::new(),
                cells,
                show_house: None,
            });
        }
        let view = ReportView {
            cells,
            ..view(&houses, whole.houses_run, whole.trials_run)
        };

        let mut rows = whole.rows.clone();
        if cells {
            for r in &mut rows {
                r.cost_cells = Some(r.cost_m / ferret_lab::CELL_M);
            }
        }
        let run = EvalRun::new(info.clone(), rows).unwrap();
        run.write_all(&memory, &run.report(&view)).unwrap();

        let mut writer = RunWriter::create(&streamed, cells).unwrap();
        let mut batches_seen = Vec::new();
        let totals = pool.install(|| {
            EvalContext::new(&setup, &specs, &draw, &grid, &llm, &Silent)
                .run(HouseInput::Scenes(&loaded.scenes), &mut |h| {
                    batches_seen.push(h.scene.house.index);
                    for r in &h.rows {
                        writer.push(r)?;
                    }
                    Ok(())
                })
                .unwrap()
        });
        assert_eq!(batches_seen, houses, "houses are handed over in order");
        assert_eq!(
            (totals.houses_run, totals.trials_run),
            (whole.houses_run, whole.trials_run)
        );
        assert_eq!(writer.rows(), whole.rows.len());
        let written = writer.finish(info, &view).unwrap();
        assert_eq!(written.info.trials_sha256, run.info.trials_sha256);
        assert_same_files(&memory, &streamed);
        assert_eq!(streamed.join("paired.csv").exists(), !shard);
        // What was written reads back as a run.
        let back = EvalRun::read(&streamed).unwrap();
        assert_eq!(back.rows.len(), whole.rows.len());
    }
}

/// A run writer dropped before it finishes leaves the directory as it was.
#[test]
fn an_unfinished_streamed_run_leaves_the_previous_files() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("trials.csv"), "previous").unwrap();
    let mut w = RunWriter::create(dir.path(), false).unwrap();
    w.push(&row("a", 0, "Apple", 1.0, "x")).unwrap();
    drop(w);
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("trials.csv")]);
    assert_eq!(
        std::fs::read_to_string(dir.path().join("trials.csv")).unwrap(),
        "previous"
    );
}

fn row(strategy: &str, house_index: usize, target: &str, cost_m: f64, searched: &str) -> TrialRow {
    TrialRow {
        house: format!("house, \"{house_index}\""),
        house_index,
        target: target.into(),
        strategy: strategy.into(),
        cost_m,
        searches: searched.split_whitespace().count(),
        found: cost_m > 1.0,
        found_container: searched.split_whitespace().last().unwrap_or("").into(),
        searched: searched.into(),
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

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Arbitrary rows (quotes, commas and newlines in the text, any finite cost, strategies that
    /// miss trials) written through the streaming writer and through the in-memory one.
    #[test]
    fn the_streaming_writer_writes_the_in_memory_files(
        trials in prop::collection::vec(
            (0usize..6, prop::sample::select(vec!["Apple", "Book", "Cup,\"x\""]),
             prop::collection::vec(prop::option::of(0.0f64..1e4), 3),
             "[a-z ,\"\n]{0,12}"),
            1..30),
        cells in any::<bool>(),
    ) {
        let strategies: Vec<String> =
            ["optimistic+greedy", "model/x", "oracle"].iter().map(|s| s.to_string()).collect();
        let mut rows = Vec::new();
        for (house, target, costs, searched) in &trials {
            for (s, cost) in strategies.iter().zip(costs) {
                if let Some(c) = cost {
                    rows.push(row(s, *house, target, *c, searched));
                }
            }
        }
        prop_assume!(!rows.is_empty());
        let dir = tempfile::tempdir().unwrap();
        let (memory, streamed) = (dir.path().join("m"), dir.path().join("s"));
        std::fs::create_dir_all(&memory).unwrap();
        std::fs::create_dir_all(&streamed).unwrap();
        let mut houses: Vec<usize> = rows.iter().map(|r| r.house_index).collect();
        houses.sort_unstable();
        houses.dedup();
        let view = ReportView { cells, ..view(&houses, houses.len(), trials.len()) };
        let info = info(&strategies, 6);

        let mut in_memory = rows.clone();
        if cells {
            for r in &mut in_memory {
                r.cost_cells = Some(r.cost_m / ferret_lab::CELL_M);
            }
        }
        let run = EvalRun::new(info.clone(), in_memory).unwrap();
        run.write_all(&memory, &run.report(&view)).unwrap();

        let mut w = RunWriter::create(&streamed, cells).unwrap();
        for r in &rows {
            w.push(r).unwrap();
        }
        w.finish(info, &view).unwrap();
        for f in FILES {
            let (x, y) = (std::fs::read(memory.join(f)).unwrap(), std::fs::read(streamed.join(f)).unwrap());
            prop_assert!(x == y, "{} differs", f);
        }
    }
}
