//! End-to-end reliability tests: nothing lost, nothing stale, no panics, fast failure.

mod common;

use common::{ferret, s, stderr, text};

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::process::Output;

use rand::{Rng, SeedableRng};

/// Quick strategies: no prior to train.
const STRATEGIES: &str = "optimistic+greedy,model/uniform,oracle";

fn eval(out: &Path, seed: &str, houses: &str) -> Output {
    ferret(&[
        "eval",
        "--generate",
        houses,
        "--strategies",
        STRATEGIES,
        "--seed",
        seed,
        "--out",
        s(out),
    ])
}

fn select(trials: &Path, out: &Path) -> Output {
    ferret(&[
        "select",
        "--trials",
        s(trials),
        "--deployments",
        "20",
        "--trials-per-deployment",
        "5",
        "--out",
        s(out),
    ])
}

/// Every file of a directory tree with its bytes.
fn snapshot(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut files = BTreeMap::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap() {
            let p = e.unwrap().path();
            if p.is_dir() {
                todo.push(p);
            } else {
                files.insert(p.clone(), std::fs::read(&p).unwrap());
            }
        }
    }
    files
}

/// The rows of replay.csv (after its key line), as a set.
fn replay_rows(dir: &Path) -> BTreeSet<String> {
    let text = std::fs::read_to_string(dir.join("replay.csv")).unwrap();
    assert!(
        text.starts_with("# ferret replay cache for trials sha256:"),
        "{text}"
    );
    text.lines().skip(2).map(String::from).collect()
}

#[test]
fn rerunning_eval_replaces_output_files_instead_of_rewriting_them() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e");
    assert!(eval(&out, "0", "6").status.success());
    // A hard link shares the file's inode: writing in place (truncate + write) changes what it
    // shows, replacing the file by a rename does not. A kill during an in-place write leaves a
    // 0-byte file; after a rename there is only ever the old file or the new one.
    let keep = dir.path().join("keep");
    std::fs::create_dir(&keep).unwrap();
    let names = [
        "trials.csv",
        "summary.csv",
        "summary.md",
        "paired.csv",
        "run.json",
        "costs.png",
        "trajectories.png",
    ];
    for n in names {
        std::fs::hard_link(out.join(n), keep.join(n)).unwrap();
    }
    let before = snapshot(&keep);
    let o = eval(&out, "1", "6");
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(
        snapshot(&keep),
        before,
        "a previous output was rewritten in place"
    );
    let changed = names
        .iter()
        .filter(|n| std::fs::read(out.join(n)).unwrap() != std::fs::read(keep.join(n)).unwrap())
        .count();
    assert!(changed >= 4, "the new run wrote new outputs");
    // No temporary file is left behind.
    let mut listed: Vec<String> = std::fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    listed.sort();
    let mut expected: Vec<String> = names.iter().map(|n| n.to_string()).collect();
    // The run's claim on the directory: an empty file, kept (removing a locked file would let
    // two later runs hold two different files).
    expected.push(".ferret-lock".into());
    expected.sort();
    assert_eq!(listed, expected);
}

#[test]
fn bad_options_are_refused_before_outputs_are_touched() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e");
    assert!(eval(&out, "0", "6").status.success());
    let sel = dir.path().join("sel");
    assert!(select(&out, &sel).status.success());
    let before = snapshot(dir.path());

    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let mut bad = |lo: f64, hi: f64| -> String {
        match rng.random_range(0..4) {
            0 => "NaN".into(),
            1 => "inf".into(),
            2 => "-inf".into(),
            _ => format!("{}", rng.random_range(lo..hi)),
        }
    };
    // (option, value) pairs for eval, each refused with the option named.
    let mut cases: Vec<(&str, String)> = vec![
        ("--resolution", "0".into()),
        ("--resolution", "0.001".into()),
        ("--robot-radius", "-0.1".into()),
        ("--wall-thickness", "NaN".into()),
        ("--search-cost", "NaN".into()),
        ("--search-cost", "-1".into()),
        ("--reveal-fraction", "1.5".into()),
        ("--reveal-fraction", "-0.1".into()),
        ("--exact-max", "40".into()),
        ("--max-containers", "0".into()),
        ("--show-house", "50".into()),
        ("--strategies", "oracle,model/uniform,oracle".into()),
        ("--paired-against", "model/prior/k4".into()),
    ];
    for _ in 0..4 {
        cases.push(("--resolution", bad(-10.0, 0.005)));
        cases.push(("--robot-radius", bad(-10.0, -1e-9)));
        cases.push(("--wall-thickness", bad(-10.0, -1e-9)));
        cases.push(("--search-cost", bad(-1e6, -1e-9)));
        cases.push(("--reveal-fraction", bad(1.0 + 1e-9, 1e6)));
    }
    for (option, value) in &cases {
        let arg = format!("{option}={value}");
        let o = ferret(&["eval", "--generate", "4", &arg, "--out", s(&out)]);
        assert!(!o.status.success(), "{arg} was accepted");
        assert!(stderr(&o).contains(option), "{arg}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{arg}: {}", stderr(&o));
    }
    // select: too many deployment trials (used to be killed for memory), zeros, a bad c.
    for args in [
        ["--deployments", "100000000"],
        ["--deployments", "0"],
        ["--trials-per-deployment", "0"],
        ["--trials-per-deployment", "99"],
        ["--c", "NaN"],
    ] {
        let o = ferret(&[
            "select",
            "--trials",
            s(&out),
            args[0],
            args[1],
            "--out",
            s(&sel),
        ]);
        assert!(!o.status.success(), "{args:?} was accepted");
        assert!(stderr(&o).contains(args[0]), "{args:?}: {}", stderr(&o));
    }
    let o = ferret(&["select", "--trials", s(&out), "--deployments", "100000000"]);
    assert!(stderr(&o).contains("5000000"), "{}", stderr(&o));
    assert_eq!(
        snapshot(dir.path()),
        before,
        "a refused run touched the outputs"
    );
}

#[test]
fn select_replays_again_after_a_new_eval_into_the_same_directory() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e");
    assert!(eval(&out, "0", "8").status.success());
    assert!(select(&out, &dir.path().join("s0")).status.success());
    let seed0 = replay_rows(&out);
    assert!(eval(&out, "1", "8").status.success());
    let o = select(&out, &dir.path().join("s1"));
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        stderr(&o).contains("computed for other trials"),
        "{}",
        stderr(&o)
    );
    // The same replays as a select on a fresh eval of seed 1.
    let fresh = dir.path().join("fresh");
    assert!(eval(&fresh, "1", "8").status.success());
    assert!(select(&fresh, &dir.path().join("s2")).status.success());
    assert_eq!(replay_rows(&out), replay_rows(&fresh));
    assert_ne!(replay_rows(&out), seed0, "seed 1 draws other trials");
    assert_eq!(
        std::fs::read(dir.path().join("s1/selection.csv")).unwrap(),
        std::fs::read(dir.path().join("s2/selection.csv")).unwrap()
    );
}

#[test]
fn an_interrupted_select_resumes_and_corrupt_rows_are_replayed() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e");
    assert!(eval(&out, "0", "8").status.success());
    assert!(select(&out, &dir.path().join("s0")).status.success());
    let full = std::fs::read_to_string(out.join("replay.csv")).unwrap();
    let all = replay_rows(&out);
    // 8 houses × 2 deployed × 1 replayed.
    assert_eq!(all.len(), 16);

    // As a kill would leave it: the first six rows, the seventh cut short. Then a corrupted row.
    let lines: Vec<&str> = full.lines().collect();
    let mut cut = lines[..8].join("\n");
    cut.push('\n');
    let (h, rest) = lines[2].split_once(',').unwrap();
    let negative = format!("{h},{}", rest.rsplit_once(',').unwrap().0);
    cut = cut.replacen(lines[2], &format!("{negative},-4.0"), 1);
    cut.push_str(&lines[8][..lines[8].len() - 3]);
    std::fs::write(out.join("replay.csv"), &cut).unwrap();

    let o = select(&out, &dir.path().join("s1"));
    assert!(o.status.success(), "{}", text(&o));
    let err = stderr(&o);
    assert!(err.contains("replay.csv: line 3: replay cost -4"), "{err}");
    assert!(err.contains("replay.csv: line 9: cut short"), "{err}");
    // Rows are sorted by house, two per house: houses 1 and 2 survived whole; house 0 (row 1
    // corrupt), house 3 (row 7 cut) and houses 4..7 (never written) are replayed.
    let houses: usize = err
        .split("replaying 2 strategies on ")
        .nth(1)
        .and_then(|r| r.split(' ').next())
        .and_then(|n| n.parse().ok())
        .unwrap();
    assert_eq!(houses, 6, "{err}");
    assert_eq!(replay_rows(&out), all);
    assert_eq!(
        std::fs::read(dir.path().join("s0/selection.csv")).unwrap(),
        std::fs::read(dir.path().join("s1/selection.csv")).unwrap()
    );
    // A clean cache is used as is.
    let o = select(&out, &dir.path().join("s2"));
    assert!(!stderr(&o).contains("replaying"), "{}", stderr(&o));
}

#[test]
fn a_file_without_houses_fails_the_check() {
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in [("blank.jsonl", &b"\n \n\t\n"[..]), ("empty.jsonl", b"")] {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let o = ferret(&["houses", "check", "--houses", s(&path)]);
        assert!(!o.status.success(), "{name} passed the check");
        assert!(
            stderr(&o).contains(&format!("{name}: the file holds no houses")),
            "{}",
            stderr(&o)
        );
    }
    let o = ferret(&["houses", "check", "--generate", "0"]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("no houses to check"), "{}", stderr(&o));
}

#[cfg(unix)]
#[test]
fn endless_input_fails_fast_with_the_limit_named() {
    let o = ferret(&["houses", "check", "--houses", "/dev/zero"]);
    assert!(!o.status.success());
    assert!(
        stderr(&o).contains("/dev/zero: not a regular file (a device)"),
        "{}",
        stderr(&o)
    );
    // The limits are documented where the option is.
    let help = String::from_utf8_lossy(&ferret(&["eval", "--help"]).stdout).into_owned();
    for limit in ["64 MiB", "2000 containers", "16.7 M"] {
        assert!(help.contains(limit), "eval --help lacks {limit}");
    }
    let help = String::from_utf8_lossy(&ferret(&["select", "--help"]).stdout).into_owned();
    assert!(help.contains("5 000 000"), "{help}");
}

#[test]
fn a_house_without_target_is_reported_once_and_the_others_drawn() {
    let dir = tempfile::tempdir().unwrap();
    let houses = dir.path().join("h.jsonl");
    assert!(
        ferret(&[
            "generate",
            "--count",
            "3",
            "--seed",
            "3",
            "--out",
            s(&houses)
        ])
        .status
        .success()
    );
    // House 0 loses every small object, so no target can be drawn there.
    let mut lines: Vec<serde_json::Value> = std::fs::read_to_string(&houses)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    for o in lines[0]["objects"].as_array_mut().unwrap() {
        o["children"] = serde_json::json!([]);
    }
    let text_lines: Vec<String> = lines.iter().map(|v| v.to_string()).collect();
    std::fs::write(&houses, text_lines.join("\n")).unwrap();
    let out = dir.path().join("e");
    let o = ferret(&[
        "-vv",
        "eval",
        "--houses",
        s(&houses),
        "--strategies",
        STRATEGIES,
        "--out",
        s(&out),
    ]);
    let err = stderr(&o);
    assert_eq!(err.matches("no target can be drawn").count(), 1, "{err}");
    assert!(
        !err.contains('\u{1b}'),
        "colour codes in a non-terminal stderr: {err:?}"
    );
    assert!(err.contains("DEBUG"), "-vv logs: {err}");
    assert!(!o.status.success(), "a failed house fails the run");
    let png = std::fs::read(out.join("trajectories.png")).unwrap();
    assert_eq!(&png[1..4], b"PNG");
    assert_eq!(
        std::fs::read_to_string(out.join("trials.csv"))
            .unwrap()
            .lines()
            .count(),
        1 + 2 * 3
    );
}

#[test]
fn a_corrupt_llm_cache_is_named_as_such() {
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("ferret.toml");
    std::fs::write(
        &config,
        "[llm.local]\nbase_url = \"http://127.0.0.1:9/v1\"\nmodel = \"m\"\n",
    )
    .unwrap();
    let cache = dir.path().join("cache.sqlite");
    std::fs::write(&cache, vec![b'x'; 4096]).unwrap();
    for spec in ["llm+model/p-minimal/local", "llm-direct/p-direct/local"] {
        let o = ferret(&[
            "eval",
            "--generate",
            "2",
            "--config",
            s(&config),
            "--llm-cache",
            s(&cache),
            "--offline",
            "--strategies",
            &format!("optimistic+greedy,{spec}"),
            "--out",
            s(&dir.path().join("e")),
        ]);
        let err = stderr(&o);
        assert!(!o.status.success());
        assert!(!err.contains("unknown strategy"), "{err}");
        assert!(err.contains("response cache"), "{err}");
        assert!(err.contains(spec), "{err}");
    }
}

/// `--generate 18446744073709551615` panicked (capacity overflow), 4294967296 aborted in the
/// allocator and 100000000 grew to 700 MB: every count of generated houses has one limit, named
/// with the option before anything is generated.
#[test]
fn counts_of_generated_houses_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e");
    let houses = dir.path().join("h.jsonl");
    for (args, option) in [
        (
            vec!["eval", "--generate", "18446744073709551615"],
            "--generate",
        ),
        (vec!["eval", "--generate", "4294967296"], "--generate"),
        (vec!["eval", "--generate", "100000000"], "--generate"),
        (
            vec!["generate", "--count", "18446744073709551615"],
            "--count",
        ),
        (vec!["generate", "--count", "100000000"], "--count"),
        (
            vec![
                "prompts",
                "show",
                "p-minimal",
                "--target",
                "Book",
                "--index",
                "1000000000",
            ],
            "--index",
        ),
    ] {
        let mut args = args;
        if args[0] == "eval" {
            args.extend(["--strategies", "optimistic+greedy", "--out", s(&out)]);
        } else if args[0] == "generate" {
            args.extend(["--out", s(&houses)]);
        }
        let o = ferret(&args);
        assert!(!o.status.success(), "{args:?} was accepted");
        assert_ne!(o.status.code(), Some(101), "{args:?}: {}", stderr(&o));
        let err = stderr(&o);
        assert!(
            err.contains(option) && err.contains("10000"),
            "{args:?}: {err}"
        );
        assert!(!out.exists() && !houses.exists(), "{args:?}");
    }
}

/// `dir`'s lock file, held as a running ferret run holds it (until dropped).
fn hold_lock(dir: &Path) -> std::fs::File {
    std::fs::create_dir_all(dir).unwrap();
    let lock = std::fs::OpenOptions::new()
        .create(true)
        .truncate(false)
        .write(true)
        .open(dir.join(".ferret-lock"))
        .unwrap();
    {
        use std::os::fd::AsRawFd;
        // SAFETY: flock on a descriptor this test owns.
        assert_eq!(unsafe { libc::flock(lock.as_raw_fd(), libc::LOCK_EX) }, 0);
    }
    lock
}

/// `select`, `deploy` and `calibrate` took no lock: two into one directory both wrote. Each
/// now claims its output directory as `eval` does, and is refused while another holds it.
#[test]
fn select_deploy_and_calibrate_refuse_a_busy_output_directory() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    assert!(eval(&run, "0", "6").status.success());
    let busy = dir.path().join("busy");
    let lock = hold_lock(&busy);
    let commands: [(&[&str], &str); 3] = [
        (
            &[
                "select",
                "--trials",
                s(&run),
                "--deployments",
                "3",
                "--trials-per-deployment",
                "3",
            ],
            "selection.csv",
        ),
        (
            &[
                "deploy",
                "--generate",
                "4",
                "--trials",
                "4",
                "--strategies",
                STRATEGIES,
            ],
            "deploy.csv",
        ),
        (
            &["calibrate", "--generate", "3", "--sources", "model/uniform"],
            "calibration.csv",
        ),
    ];
    for (args, file) in commands {
        let mut all = args.to_vec();
        all.extend_from_slice(&["--out", s(&busy)]);
        let o = ferret(&all);
        assert!(!o.status.success(), "{args:?}: {}", text(&o));
        assert!(stderr(&o).contains("another ferret run"), "{}", stderr(&o));
        assert!(!busy.join(file).exists(), "{args:?} wrote {file}");
    }
    drop(lock);
    for (args, file) in commands {
        let mut all = args.to_vec();
        all.extend_from_slice(&["--out", s(&busy)]);
        let o = ferret(&all);
        assert!(o.status.success(), "{args:?}: {}", text(&o));
        assert!(busy.join(file).exists(), "{args:?}");
    }
}

/// Two evals into one directory both reported success while only the later one's files
/// remained: a run claims its output directory, and a second one is refused while it runs.
#[test]
fn a_second_run_into_a_busy_output_directory_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("e");
    // As a running eval holds it.
    let lock = hold_lock(&out);
    let o = eval(&out, "0", "2");
    assert!(!o.status.success());
    assert!(stderr(&o).contains("another ferret run"), "{}", stderr(&o));
    assert!(!out.join("trials.csv").exists());
    drop(lock);
    let o = eval(&out, "0", "2");
    assert!(o.status.success(), "{}", stderr(&o));
}

/// Every command that takes strategies names the learned ones and their fused forms in its help.
#[test]
fn every_strategy_list_in_help_names_the_learned_strategies() {
    for command in ["eval", "calibrate", "deploy", "serve"] {
        let o = ferret(&[command, "--help"]);
        assert!(o.status.success(), "{command} --help failed");
        let help = String::from_utf8_lossy(&o.stdout).into_owned();
        for name in [
            "model/learned",
            "model/learned-random",
            "fused-learned/<prompt>/<llm>",
            "fused-learned/noise",
        ] {
            assert!(help.contains(name), "{command} --help does not name {name}");
        }
    }
}
