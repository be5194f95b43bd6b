//! Houses read and run a batch at a time: the files do not depend on the batch size, and shards
//! merged row by row are one machine's run.

use std::path::{Path, PathBuf};

use ferret_lab::merge::merge_dirs;
use ferret_lab::runs::{ReportView, RunWriter};
use ferret_lab::shard::{SHARD_RULE, ShardRecord};
use ferret_lab::{
    EvalContext, EvalRun, HouseInput, HouseSource, LlmSettings, PlanningSettings, RunInfo, Shard,
    Silent, Strategies, TrialDraw, merge_runs,
};
use ferret_plan::{Protocol, TrialsPerHouse};
use ferret_world::{ContainerSet, GridParams};

const COUNT: usize = 10;
const FILES: [&str; 5] = [
    "trials.csv",
    "summary.csv",
    "paired.csv",
    "summary.md",
    "run.json",
];

fn source() -> HouseSource {
    HouseSource {
        generate: COUNT,
        house_seed: 3,
        ..HouseSource::default()
    }
}

fn specs() -> Vec<String> {
    ["optimistic+greedy", "model/uniform", "oracle"]
        .map(String::from)
        .to_vec()
}

/// Two targets per house, seed 1, ferret's protocol.
fn draw() -> TrialDraw<'static> {
    TrialDraw {
        seed: 1,
        reveal_fraction: 0.0,
        per_house: TrialsPerHouse::Count(2),
        protocol: &Protocol::FERRET,
        holdout: None,
        tasks: None,
        team: None,
    }
}

fn info(shard: Option<ShardRecord>) -> RunInfo {
    let grid = GridParams::default();
    RunInfo {
        houses: None,
        range: None,
        asset_db: None,
        generate: COUNT,
        house_seed: 3,
        grid: [grid.resolution, grid.robot_radius, grid.wall_thickness],
        planning: PlanningSettings::default(),
        seed: 1,
        reveal_fraction: 0.0,
        trials_per_house: TrialsPerHouse::Count(2),
        protocol: Protocol::FERRET,
        tasks: None,
        team: None,
        strategies: specs(),
        trials_sha256: None,
        shard,
        merged_from: Vec::new(),
    }
}

/// `ferret eval` of the generated houses (of `shard`) into `out`, `batch` houses at a time; the
/// house indices handed over, in order.
fn eval(out: &Path, shard: Option<Shard>, batch: usize) -> Vec<usize> {
    std::fs::create_dir_all(out).unwrap();
    let llm = LlmSettings {
        llm_cache: out.join("cache.sqlite"),
        ..LlmSettings::default()
    };
    let setup = Strategies::builder(&PlanningSettings::default(), &llm)
        .for_specs(&specs())
        .build()
        .unwrap();
    let draw = draw();
    let src = source();
    let open = src.open(ContainerSet::Receptacles, shard).unwrap();
    let mut writer = RunWriter::create(out, false).unwrap();
    let mut seen = Vec::new();
    let totals = EvalContext::new(
        &setup,
        &specs(),
        &draw,
        &GridParams::default(),
        &llm,
        &Silent,
    )
    .with_batch(batch)
    .run(HouseInput::Source(&open), &mut |h| {
        seen.push(h.scene.house.index);
        for r in &h.rows {
            writer.push(r)?;
        }
        Ok(())
    })
    .unwrap();
    assert_eq!(totals.houses, seen);
    let record = shard.map(|sh| ShardRecord {
        index: sh.index,
        count: sh.count,
        rule: SHARD_RULE.into(),
        houses: totals.houses.clone(),
        houses_run: totals.houses_run,
        trials_run: totals.trials_run,
        failures: totals.errors.len(),
        paired_against: Vec::new(),
        cells: false,
        show_house: None,
    });
    writer
        .finish(
            info(record),
            &ReportView {
                source: &src.describe(),
                houses: &totals.houses,
                houses_run: totals.houses_run,
                trials_run: totals.trials_run,
                paired_against: &[],
                cells: false,
            },
        )
        .unwrap();
    seen
}

fn read(dir: &Path, f: &str) -> Vec<u8> {
    std::fs::read(dir.join(f)).unwrap_or_default()
}

#[test]
fn the_batch_size_changes_no_file() {
    let dir = tempfile::tempdir().unwrap();
    let all: Vec<usize> = (0..COUNT).collect();
    let mut runs = Vec::new();
    // 3 leaves a last batch of one house; usize::MAX reads every house in one batch.
    for batch in [1, 3, usize::MAX] {
        let out = dir.path().join(format!("b{batch}"));
        assert_eq!(eval(&out, None, batch), all, "batch {batch}");
        runs.push(out);
    }
    // The same houses loaded whole, as earlier versions did, and run on them.
    let loaded = source().load_for(ContainerSet::Receptacles).unwrap();
    assert_eq!(
        loaded
            .scenes
            .iter()
            .map(|s| s.house.index)
            .collect::<Vec<_>>(),
        all
    );
    let trials = read(&runs[0], "trials.csv");
    assert!(trials.len() > 200, "rows were written");
    for out in &runs[1..] {
        for f in FILES {
            assert!(
                read(&runs[0], f) == read(out, f),
                "{f} differs between batches of 1 and {out:?}"
            );
        }
    }
}

#[test]
fn shards_merged_row_by_row_are_one_machine() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one");
    eval(&one, None, 4);
    let shards: Vec<PathBuf> = (0..3)
        .map(|i| {
            let d = dir.path().join(format!("s{i}"));
            eval(&d, Some(Shard::new(i, 3).unwrap()), 2);
            d
        })
        .collect();
    // Given out of order: the merge orders the shards itself.
    let given = vec![shards[2].clone(), shards[0].clone(), shards[1].clone()];
    let merged = dir.path().join("merged");
    std::fs::create_dir_all(&merged).unwrap();
    let m = merge_dirs(&given, &merged).unwrap();
    assert_eq!(m.houses, (0..COUNT).collect::<Vec<_>>());
    for f in ["trials.csv", "summary.csv", "paired.csv", "summary.md"] {
        assert!(
            read(&one, f) == read(&merged, f),
            "{f} differs between one machine and the merged shards"
        );
    }
    // The in-memory merge writes the same run, run.json included.
    let runs: Vec<(PathBuf, EvalRun)> = given
        .iter()
        .map(|d| (d.clone(), EvalRun::read(d).unwrap()))
        .collect();
    let memory = dir.path().join("memory");
    std::fs::create_dir_all(&memory).unwrap();
    merge_runs(&runs).unwrap().write_all(&memory).unwrap();
    for f in FILES {
        assert!(
            read(&memory, f) == read(&merged, f),
            "{f} differs between the two merges"
        );
    }
    assert_eq!(
        m.rows,
        runs.iter().map(|(_, r)| r.rows.len()).sum::<usize>()
    );
}

/// Notes of a run, kept.
#[derive(Default)]
struct Notes(std::sync::Mutex<Vec<String>>);

impl ferret_lab::Feedback for Notes {
    fn note(&self, message: &str) {
        self.0.lock().unwrap().push(message.to_string());
    }
}

/// An LLM that answers every question "Yes", counting the requests.
struct Yes(std::sync::Arc<std::sync::atomic::AtomicUsize>);

impl wiremock::Respond for Yes {
    fn respond(&self, _req: &wiremock::Request) -> wiremock::ResponseTemplate {
        self.0.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        wiremock::ResponseTemplate::new(200).set_body_json(serde_json::json!({
            "id": "x", "object": "chat.completion", "created": 1, "model": "mock-model",
            "choices": [{"index": 0, "message": {"role": "assistant", "content": "Yes"},
                         "finish_reason": "stop"}],
            "usage": {"prompt_tokens": 10, "completion_tokens": 1, "total_tokens": 11}
        }))
    }
}

/// P-YESNO asks one question per target, container type and room type, so houses share
/// questions: asked a house at a time or all at once, a run sends and reports the same
/// questions, each once.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn questions_shared_by_batches_are_asked_and_counted_once() {
    use wiremock::matchers::{method, path};
    let server = wiremock::MockServer::start().await;
    let requests = std::sync::Arc::new(std::sync::atomic::AtomicUsize::new(0));
    wiremock::Mock::given(method("POST"))
        .and(path("/v1/chat/completions"))
        .respond_with(Yes(requests.clone()))
        .mount(&server)
        .await;
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("ferret.toml");
    std::fs::write(
        &config,
        format!(
            "[llm.mock]\nbase_url = \"{}/v1\"\nmodel = \"mock-model\"\nretry_base_ms = 10\n",
            server.uri()
        ),
    )
    .unwrap();
    let specs = vec!["llm+model/p-yesno/mock".to_string()];
    let mut runs = Vec::new();
    for batch in [1, usize::MAX] {
        let llm = LlmSettings {
            config: Some(config.clone()),
            llm_cache: dir.path().join(format!("cache-{batch}.sqlite")),
            ..LlmSettings::default()
        };
        let draw = draw();
        let notes = Notes::default();
        let before = requests.load(std::sync::atomic::Ordering::SeqCst);
        let totals = tokio::task::block_in_place(|| {
            let setup = Strategies::builder(&PlanningSettings::default(), &llm)
                .for_specs(&specs)
                .build()
                .unwrap();
            let src = source();
            let open = src.open(ContainerSet::Receptacles, None).unwrap();
            EvalContext::new(&setup, &specs, &draw, &GridParams::default(), &llm, &notes)
                .with_batch(batch)
                .run(HouseInput::Source(&open), &mut |_| Ok(()))
                .unwrap()
        });
        assert!(totals.trials_run > 0);
        let sent = requests.load(std::sync::atomic::Ordering::SeqCst) - before;
        let note = notes
            .0
            .lock()
            .unwrap()
            .iter()
            .find(|n| n.starts_with("LLM questions:"))
            .cloned()
            .unwrap();
        runs.push((note, sent));
    }
    assert_eq!(runs[0], runs[1]);
    let (note, sent) = &runs[0];
    assert_eq!(
        note,
        &format!(
            "LLM questions: {sent} distinct (0 cached, {sent} asked now, 0 skipped after a failure)"
        )
    );
}
