//! Sharded evaluation end to end: `eval --shard` on every shard, `ferret merge`, and the merged
//! files against one machine's, byte for byte; the merge's refusals; the caches' merge.

mod common;

use std::path::Path;
use std::process::Command;

use common::{data_dir, ferret, s, text};

/// Runs `eval` with `args` into `out` (and `shard` when given); panics with its output on failure.
fn eval(args: &[&str], out: &Path, shard: Option<&str>) {
    let cache = out.with_extension("sqlite");
    let mut all: Vec<&str> = vec!["eval"];
    all.extend_from_slice(args);
    if let Some(sh) = shard {
        all.extend_from_slice(&["--shard", sh]);
    }
    all.extend_from_slice(&["--out", s(out), "--llm-cache", s(&cache)]);
    let o = ferret(&all);
    assert!(o.status.success(), "ferret {all:?}: {}", text(&o));
}

/// One machine, then `n` shards merged: the merged trials.csv, summary.csv, paired.csv and
/// summary.md must be the one-machine files.
fn shards_equal_one_machine(args: &[&str], n: usize) {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one");
    eval(args, &one, None);
    let shards: Vec<_> = (0..n)
        .map(|i| dir.path().join(format!("shard{i}")))
        .collect();
    // Given to the merge in reverse: the order of the arguments does not matter.
    for (i, d) in shards.iter().enumerate().rev() {
        eval(args, d, Some(&format!("{i}/{n}")));
    }
    let merged = dir.path().join("merged");
    let mut m = vec!["merge", "--out", s(&merged)];
    m.extend(shards.iter().rev().map(|d| s(d)));
    let o = ferret(&m);
    assert!(o.status.success(), "{}", text(&o));
    // The pictures too: shards draw none, the merge draws the one machine's.
    for f in [
        "trials.csv",
        "summary.csv",
        "paired.csv",
        "summary.md",
        "costs.png",
        "trajectories.png",
    ] {
        let a = std::fs::read(one.join(f)).unwrap();
        let b = std::fs::read(merged.join(f)).unwrap();
        assert!(
            a == b,
            "{f} differs between one machine and {n} shards merged ({args:?})"
        );
    }
    for d in &shards {
        for f in ["paired.csv", "costs.png", "trajectories.png"] {
            assert!(!d.join(f).exists(), "a shard wrote {f}");
        }
    }
    let info = common::read_json(&merged.join("run.json"));
    assert_eq!(info["merged_from"].as_array().map(Vec::len), Some(n));
    assert!(info.get("shard").is_none());
}

#[test]
fn three_shards_merged_are_one_machine_byte_for_byte() {
    shards_equal_one_machine(&["--generate", "10", "--trials-per-house", "all"], 3);
    // The paper's protocol draws with CPython's generator (--rng python): still per house.
    shards_equal_one_machine(
        &[
            "--generate",
            "8",
            "--protocol",
            "paper",
            "--paired-against",
            "model/uniform",
        ],
        3,
    );
    shards_equal_one_machine(
        &[
            "--generate",
            "7",
            "--trials-per-house",
            "2",
            "--cells",
            "--show-house",
            "5",
        ],
        4,
    );
}

#[test]
fn merge_refuses_mismatched_settings_overlaps_and_gaps() {
    let dir = tempfile::tempdir().unwrap();
    let p = |n: &str| dir.path().join(n);
    let base = [
        "--generate",
        "6",
        "--strategies",
        "optimistic+greedy,oracle",
    ];
    eval(&base, &p("a0"), Some("0/3"));
    eval(&base, &p("a1"), Some("1/3"));
    eval(&base, &p("a2"), Some("2/3"));
    let mut seeded = base.to_vec();
    seeded.extend_from_slice(&["--seed", "7"]);
    eval(&seeded, &p("b1"), Some("1/3"));
    eval(&base, &p("whole"), None);
    let out = p("merged");
    let refuse = |dirs: &[&str], expect: &[&str]| {
        let mut args = vec!["merge", "--out", s(&out)];
        let full: Vec<_> = dirs.iter().map(|d| p(d)).collect();
        args.extend(full.iter().map(|d| s(d)));
        let o = ferret(&args);
        let t = text(&o);
        assert!(!o.status.success(), "merge of {dirs:?} should fail: {t}");
        for e in expect {
            assert!(t.contains(e), "merge of {dirs:?}: expected {e:?} in: {t}");
        }
    };
    refuse(
        &["a0", "b1", "a2"],
        &["a0", "b1", "different settings", "seed: 0 vs 7"],
    );
    refuse(
        &["a0", "a1", "a1", "a2"],
        &["a1", "overlap", "both are shard 1/3"],
    );
    refuse(&["a0", "a2"], &["shards missing: 1 of 3", "a0", "a2"]);
    refuse(&["a0", "whole"], &["whole", "not a shard"]);
    assert!(
        !out.join("trials.csv").exists(),
        "a refused merge writes nothing"
    );
}

#[test]
fn shard_auto_reads_slurm_and_kubernetes_and_says_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let run = |env: &[(&str, &str)], out: &str| {
        let mut c = Command::new(env!("CARGO_BIN_EXE_ferret"));
        c.args([
            "eval",
            "--generate",
            "4",
            "--strategies",
            "optimistic+greedy",
            "--shard",
            "auto",
        ])
        .args(["--out", s(&dir.path().join(out))]);
        for v in [
            "SLURM_ARRAY_TASK_ID",
            "SLURM_ARRAY_TASK_COUNT",
            "SLURM_ARRAY_TASK_MIN",
        ] {
            c.env_remove(v);
        }
        c.env_remove("JOB_COMPLETION_INDEX")
            .env_remove("FERRET_SHARD_COUNT");
        c.envs(env.iter().copied());
        c.output().unwrap()
    };
    let o = run(&[], "none");
    assert!(!o.status.success());
    let t = text(&o);
    assert!(
        t.contains("SLURM_ARRAY_TASK_ID") && t.contains("JOB_COMPLETION_INDEX"),
        "{t}"
    );
    let o = run(
        &[
            ("SLURM_ARRAY_TASK_ID", "1"),
            ("SLURM_ARRAY_TASK_COUNT", "2"),
        ],
        "slurm",
    );
    assert!(o.status.success(), "{}", text(&o));
    let info = common::read_json(&dir.path().join("slurm/run.json"));
    assert_eq!(info["shard"]["index"], 1);
    assert_eq!(info["shard"]["houses"], serde_json::json!([1, 3]));
    let o = run(
        &[("JOB_COMPLETION_INDEX", "0"), ("FERRET_SHARD_COUNT", "2")],
        "k8s",
    );
    assert!(o.status.success(), "{}", text(&o));
    let info = common::read_json(&dir.path().join("k8s/run.json"));
    assert_eq!(info["shard"]["houses"], serde_json::json!([0, 2]));
}

fn reply(key: &str, answer: &str) -> ferret_llm::CachedReply {
    ferret_llm::CachedReply {
        key: key.into(),
        endpoint: "e".into(),
        model: "m".into(),
        server: "http://127.0.0.1:9".into(),
        messages: vec![ferret_llm::ChatMessage::user("Where is the remote?")],
        reply: answer.into(),
        usage: Default::default(),
        latency: std::time::Duration::ZERO,
        created_unix: 0,
        logprobs: None,
    }
}

#[test]
fn merging_caches_reports_conflicting_answers() {
    let dir = tempfile::tempdir().unwrap();
    let a = dir.path().join("a.sqlite");
    let b = dir.path().join("b.sqlite");
    {
        let ca = ferret_llm::ResponseCache::open(&a).unwrap();
        ca.put(&reply("k1", "70%")).unwrap();
        ca.put(&reply("k2", "10%")).unwrap();
        let cb = ferret_llm::ResponseCache::open(&b).unwrap();
        cb.put(&reply("k2", "10%")).unwrap();
        cb.put(&reply("k1", "40%")).unwrap();
        cb.put(&reply("k3", "5%")).unwrap();
    }
    let merged = dir.path().join("merged.sqlite");
    let o = ferret(&[
        "merge",
        "--cache",
        s(&a),
        "--cache",
        s(&b),
        "--cache-out",
        s(&merged),
        "--out",
        s(&dir.path().join("o")),
    ]);
    let t = text(&o);
    assert!(
        !o.status.success(),
        "a conflict must not pass silently: {t}"
    );
    assert!(
        t.contains("cache conflict: key k1") && t.contains("\"70%\"") && t.contains("\"40%\""),
        "{t}"
    );
    assert!(t.contains("b.sqlite"), "{t}");
    let m = ferret_llm::ResponseCache::open(&merged).unwrap();
    assert_eq!(m.len().unwrap(), 3);
    assert_eq!(m.get("k1").unwrap().unwrap().reply, "70%");
    // Without a conflict the merge succeeds.
    let o = ferret(&[
        "merge",
        "--cache",
        s(&a),
        "--cache-out",
        s(&dir.path().join("m2.sqlite")),
        "--out",
        s(&dir.path().join("o")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn merged_run_feeds_select() {
    let dir = tempfile::tempdir().unwrap();
    let args = [
        "--generate",
        "12",
        "--strategies",
        "optimistic+greedy,model/uniform,model/prior,oracle",
    ];
    for i in 0..2 {
        eval(
            &args,
            &dir.path().join(format!("s{i}")),
            Some(&format!("{i}/2")),
        );
    }
    let merged = dir.path().join("merged");
    let o = ferret(&[
        "merge",
        s(&dir.path().join("s0")),
        s(&dir.path().join("s1")),
        "--out",
        s(&merged),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let o = ferret(&[
        "select",
        "--trials",
        s(&merged),
        "--deployments",
        "5",
        "--trials-per-deployment",
        "10",
        "--out",
        s(&dir.path().join("select")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn val150_three_shards_merged_are_one_machine() {
    let Some(data) = data_dir() else { return };
    let houses = data.join("multiroom-val150.jsonl.gz");
    let db = data.join("databases/asset-database.json");
    shards_equal_one_machine(&["--houses", s(&houses), "--asset-db", s(&db)], 3);
}

/// `merge --out` into one of its own shards (or inside one, or a folder holding one) would
/// replace what it reads: refused before anything is written, the shards as they were.
#[test]
fn merge_refuses_an_out_that_is_or_holds_a_shard() {
    let dir = tempfile::tempdir().unwrap();
    let runs = dir.path().join("runs");
    let shards: Vec<_> = (0..2).map(|i| runs.join(format!("sh{i}"))).collect();
    for (i, d) in shards.iter().enumerate() {
        eval(&["--generate", "4"], d, Some(&format!("{i}/2")));
    }
    // Every file of every shard, with its bytes.
    let contents = || -> Vec<Vec<(std::ffi::OsString, Vec<u8>)>> {
        shards
            .iter()
            .map(|d| {
                let mut files: Vec<_> = std::fs::read_dir(d)
                    .unwrap()
                    .map(|e| {
                        let e = e.unwrap();
                        let bytes = std::fs::read(e.path()).unwrap_or_default();
                        (e.file_name(), bytes)
                    })
                    .collect();
                files.sort();
                files
            })
            .collect()
    };
    let before = contents();
    let through_dots = shards[1].join("..").join("sh0");
    for (out, says) in [
        (shards[0].clone(), "is the shard"),
        (through_dots, "is the shard"),
        (shards[1].join("merged"), "is inside or contains"),
        (runs.clone(), "is inside or contains"),
    ] {
        let o = ferret(&["merge", "--out", s(&out), s(&shards[0]), s(&shards[1])]);
        let t = text(&o);
        assert!(
            !o.status.success() && t.contains(says),
            "--out {out:?}: {t}"
        );
        assert!(!shards[1].join("merged").exists());
    }
    assert!(contents() == before, "a refused merge changed a shard");
    // A folder of its own beside them is fine.
    let o = ferret(&[
        "merge",
        "--out",
        s(&dir.path().join("merged")),
        s(&shards[0]),
        s(&shards[1]),
    ]);
    assert!(o.status.success(), "{}", text(&o));
}
