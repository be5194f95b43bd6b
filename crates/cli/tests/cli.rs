//! End-to-end tests of the `ferret` binary on generated houses and hand-made bad input.

mod common;

use common::{data_dir, ferret, read_csv, s, text};

use std::path::Path;
use std::process::Command;

#[test]
fn generated_houses_check_clean_and_bad_houses_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let houses = dir.path().join("h.jsonl");
    let o = ferret(&[
        "generate",
        "--count",
        "5",
        "--seed",
        "3",
        "--out",
        s(&houses),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let o = ferret(&["houses", "check", "--houses", s(&houses), "--json"]);
    assert!(o.status.success(), "{}", text(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["houses"], 5);
    assert_eq!(report["valid"], 5);
    assert_eq!(report["invalid"], 0);
    assert_eq!(report["unreachable_containers"], 0);
    assert!(report["containers"].as_u64().unwrap() >= 5);
    assert!(report["seconds"].as_f64().unwrap() > 0.0);

    // Append a garbled line and a house whose door names a missing wall.
    let mut lines: Vec<String> = std::fs::read_to_string(&houses)
        .unwrap()
        .lines()
        .map(String::from)
        .collect();
    let mut broken: serde_json::Value = serde_json::from_str(&lines[0]).unwrap();
    broken["doors"][0]["wall0"] = "wall|nowhere|0|0|1|1".into();
    lines.push("{\"rooms\": [".into());
    lines.push(broken.to_string());
    let bad = dir.path().join("bad.jsonl");
    std::fs::write(&bad, lines.join("\n")).unwrap();
    let o = ferret(&["houses", "check", "--houses", s(&bad), "--json"]);
    assert!(
        !o.status.success(),
        "a file with invalid houses must fail the check"
    );
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(report["valid"], 5);
    assert_eq!(report["invalid"], 2);
    let messages = report["invalid_houses"].to_string();
    assert!(messages.contains("bad.jsonl, house 5"), "{messages}");
    assert!(
        messages.contains("bad.jsonl, house 6") && messages.contains("wall0"),
        "{messages}"
    );

    // Without --skip-invalid, eval stops with the same clear message and a failure code.
    let o = ferret(&[
        "eval",
        "--houses",
        s(&bad),
        "--out",
        s(&dir.path().join("e")),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("house 5"), "{}", text(&o));
}

#[test]
fn eval_then_select_on_generated_houses() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("eval");
    let o = ferret(&[
        "eval",
        "--generate",
        "12",
        "--house-seed",
        "5",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&out.join("trials.csv"));
    assert_eq!(rows.len(), 12 * 5, "one row per house × strategy");
    for col in ["house", "target", "strategy", "cost_m", "searches", "found"] {
        assert!(rows[0].contains_key(col), "trials.csv lacks {col}");
    }
    // No strategy beats the oracle on any house, and every strategy found the target.
    for r in &rows {
        assert_eq!(r["found"], "true");
        let oracle = rows
            .iter()
            .find(|o| o["house"] == r["house"] && o["strategy"] == "oracle")
            .unwrap();
        let (c, oc): (f64, f64) = (
            r["cost_m"].parse().unwrap(),
            oracle["cost_m"].parse().unwrap(),
        );
        assert!(
            c + 1e-9 >= oc,
            "{} beat the oracle on {}",
            r["strategy"],
            r["house"]
        );
    }
    let summary = std::fs::read_to_string(out.join("summary.md")).unwrap();
    for strategy in [
        "optimistic+greedy",
        "model/uniform",
        "model/prior",
        "model/prior/exact",
        "oracle",
    ] {
        assert!(summary.contains(&format!("| {strategy} |")), "{summary}");
    }
    for pic in ["costs.png", "trajectories.png"] {
        let bytes = std::fs::read(out.join(pic)).unwrap();
        assert_eq!(&bytes[1..4], b"PNG", "{pic} is a PNG");
    }
    // The same command again gives the same trials (deterministic per seed).
    let again = dir.path().join("again");
    let o = ferret(&[
        "eval",
        "--generate",
        "12",
        "--house-seed",
        "5",
        "--out",
        s(&again),
    ]);
    assert!(o.status.success());
    assert_eq!(
        std::fs::read_to_string(out.join("trials.csv")).unwrap(),
        std::fs::read_to_string(again.join("trials.csv")).unwrap()
    );

    let sel = dir.path().join("sel");
    let o = ferret(&[
        "select",
        "--trials",
        s(&out),
        "--deployments",
        "40",
        "--trials-per-deployment",
        "10",
        "--out",
        s(&sel),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        out.join("replay.csv").exists(),
        "replay costs are cached beside the trials"
    );
    let rows = read_csv(&sel.join("selection.csv"));
    assert_eq!(rows.len(), 2 * 10, "two methods × k = 1..10");
    for col in ["method", "k", "avg_cost", "cum_regret"] {
        assert!(rows[0].contains_key(col), "selection.csv lacks {col}");
    }
    // Regret can only grow with k when the best single strategy is also the best per house on
    // average; what must hold is that k runs 1..=10 for both methods.
    for m in ["ucb", "replay"] {
        let ks: Vec<usize> = rows
            .iter()
            .filter(|r| r["method"] == m)
            .map(|r| r["k"].parse().unwrap())
            .collect();
        assert_eq!(ks, (1..=10).collect::<Vec<_>>());
    }
    assert!(sel.join("selection.png").exists() && sel.join("selection.md").exists());
}

#[test]
fn show_draws_png_and_svg_with_a_path() {
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("plan.png");
    let o = ferret(&[
        "houses",
        "show",
        "--generate",
        "3",
        "--index",
        "2",
        "--out",
        s(&png),
        "--path",
        "start",
        "Fridge",
    ]);
    // A generated house may lack a fridge; then the error names the places there are.
    if !o.status.success() {
        assert!(text(&o).contains("no place named `Fridge`"), "{}", text(&o));
        let o = ferret(&[
            "houses",
            "show",
            "--generate",
            "3",
            "--index",
            "2",
            "--out",
            s(&png),
        ]);
        assert!(o.status.success(), "{}", text(&o));
    }
    assert_eq!(&std::fs::read(&png).unwrap()[1..4], b"PNG");
    let svg = dir.path().join("plan.svg");
    let o = ferret(&[
        "houses",
        "show",
        "--generate",
        "3",
        "--index",
        "0",
        "--out",
        s(&svg),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert!(std::fs::read_to_string(&svg).unwrap().contains("<svg"));
}

#[test]
fn prior_train_feeds_eval_and_bench_prints_json() {
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("prior.json");
    let o = ferret(&[
        "prior",
        "train",
        "--generate",
        "30",
        "--house-seed",
        "9",
        "--out",
        s(&prior),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&prior).unwrap()).unwrap();
    assert_eq!(json["houses"], 30);
    let out = dir.path().join("e");
    let o = ferret(&[
        "eval",
        "--generate",
        "4",
        "--prior",
        s(&prior),
        "--strategies",
        "model/prior,oracle",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(read_csv(&out.join("trials.csv")).len(), 8);
    let o = ferret(&[
        "eval",
        "--generate",
        "2",
        "--strategies",
        "teleport",
        "--out",
        s(&out),
    ]);
    assert!(!o.status.success());
    assert!(
        text(&o).contains("unknown strategy `teleport`"),
        "{}",
        text(&o)
    );

    let o = ferret(&[
        "bench",
        "planner",
        "--sizes",
        "4,8",
        "--instances",
        "5",
        "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let lines: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(lines[1]["containers"], 8);
    assert!(lines[1]["median_us"].as_f64().unwrap() > 0.0);

    // The task table of 3 targets: 2^8 searched sets × 2^3 found sets × 8 positions.
    let o = ferret(&[
        "bench",
        "planner",
        "--targets",
        "3",
        "--sizes",
        "8",
        "--instances",
        "3",
        "--json",
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let lines: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    assert_eq!(
        (
            lines[0]["targets"].as_u64(),
            lines[0]["containers"].as_u64()
        ),
        (Some(3), Some(8))
    );
    assert_eq!(
        lines[0]["table_mib"].as_f64(),
        Some((256 * 8 * 8 * 8) as f64 / 1048576.0)
    );
    let o = ferret(&["bench", "planner", "--targets", "3", "--sizes", "16"]);
    assert!(
        !o.status.success() && text(&o).contains("limit of 15"),
        "{}",
        text(&o)
    );
}

#[test]
fn real_houses_check_and_show() {
    let Some(data) = data_dir() else { return };
    let file = data.join("multiroom-val150.jsonl.gz");
    let db = data.join("databases/asset-database.json");
    let o = ferret(&[
        "houses",
        "check",
        "--houses",
        s(&file),
        "--asset-db",
        s(&db),
        "--json",
    ]);
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap_or_default();
    assert_eq!(report["houses"], 150, "{}", text(&o));
    assert_eq!(report["valid"], 150, "{}", text(&o));
    assert_eq!(report["unreachable_containers"], 0, "{}", text(&o));
    assert!(o.status.success());
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("p.png");
    let o = ferret(&[
        "houses",
        "show",
        "--houses",
        s(&file),
        "--index",
        "7",
        "--out",
        s(&png),
        "--path",
        "start",
        "Fridge",
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

#[test]
fn real_eval_and_selection_reach_the_papers_goals() {
    let Some(data) = data_dir() else { return };
    let db = data.join("databases/asset-database.json");
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("prior.json");
    let o = ferret(&[
        "prior",
        "train",
        "--houses",
        s(&data.join("smallhouse-train1000.jsonl.gz")),
        "--also",
        s(&data.join("oneroom-train500.jsonl.gz")),
        "--asset-db",
        s(&db),
        "--out",
        s(&prior),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let out = dir.path().join("eval");
    let o = ferret(&[
        "eval",
        "--houses",
        s(&data.join("multiroom-val150.jsonl.gz")),
        "--asset-db",
        s(&db),
        "--prior",
        s(&prior),
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let summary = read_csv(&out.join("summary.csv"));
    let mean = |name: &str| -> f64 {
        summary
            .iter()
            .find(|r| r["strategy"] == name)
            .map(|r| r["mean_m"].parse().unwrap())
            .unwrap()
    };
    let trials: usize = summary[0]["trials"].parse().unwrap();
    assert_eq!(trials, 150);
    let (greedy, prior_k8, exact, oracle) = (
        mean("optimistic+greedy"),
        mean("model/prior"),
        mean("model/prior/exact"),
        mean("oracle"),
    );
    eprintln!(
        "greedy {greedy:.2} m, model/prior {prior_k8:.2} m, exact {exact:.2} m, oracle {oracle:.2} m"
    );
    assert!(
        prior_k8 <= 0.7 * greedy,
        "model/prior must be at least 30 % cheaper than optimistic+greedy"
    );
    assert!(
        exact <= prior_k8,
        "exact planning should not lose to the K = 8 limit on average"
    );
    assert!(oracle < exact);

    let sel = dir.path().join("select");
    let o = ferret(&["select", "--trials", s(&out), "--out", s(&sel)]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&sel.join("selection.csv"));
    let at = |m: &str, col: &str| -> f64 {
        rows.iter()
            .find(|r| r["method"] == m && r["k"] == "100")
            .map(|r| r[col].parse().unwrap())
            .unwrap()
    };
    eprintln!(
        "k = 100: UCB {:.2} m / regret {:.1}; replay {:.2} m / regret {:.1}",
        at("ucb", "avg_cost"),
        at("ucb", "cum_regret"),
        at("replay", "avg_cost"),
        at("replay", "cum_regret")
    );
    assert!(at("replay", "cum_regret") <= 0.7 * at("ucb", "cum_regret"));
    assert!(at("replay", "avg_cost") < at("ucb", "avg_cost"));
}

#[cfg(unix)]
#[test]
fn closing_the_output_pipe_early_does_not_panic() {
    use std::io::{BufRead, BufReader};
    use std::process::Stdio;
    let mut child = Command::new(env!("CARGO_BIN_EXE_ferret"))
        // More than a pipe buffer (64 KiB) of output, so the writer must hit the closed pipe.
        .args(["houses", "check", "--generate", "250", "--json"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut first = String::new();
    BufReader::new(child.stdout.take().unwrap())
        .read_line(&mut first)
        .unwrap();
    // The reader is dropped here, as `| head -1` would.
    assert!(first.starts_with('{'), "{first}");
    let out = child.wait_with_output().unwrap();
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(!stderr.contains("panicked"), "{stderr}");
}

#[test]
fn deploy_runs_chooses_and_replays_every_candidate() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("deploy");
    let o = ferret(&[
        "deploy",
        "--generate",
        "10",
        "--trials",
        "8",
        "--strategies",
        "optimistic+greedy,model/uniform,model/prior,oracle",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&out.join("deploy.csv"));
    assert_eq!(rows.len(), 8);
    let mut houses: Vec<&str> = rows.iter().map(|r| r["house"].as_str()).collect();
    houses.sort_unstable();
    houses.dedup();
    assert_eq!(houses.len(), 8, "every trial is in a distinct house");
    let mut total = 0.0;
    for (k, r) in rows.iter().enumerate() {
        assert_ne!(r["chosen"], "oracle", "the oracle is never a candidate");
        let cost: f64 = r["cost_m"].parse().unwrap();
        total += cost;
        let avg: f64 = r["average_cost_m"].parse().unwrap();
        assert!((avg - total / (k + 1) as f64).abs() < 1e-9);
        // The replay of the deployed strategy is its own cost; every candidate is replayed.
        let replays: std::collections::HashMap<&str, f64> = r["replays"]
            .split(' ')
            .map(|kv| kv.split_once('=').unwrap())
            .map(|(k, v)| (k, v.parse().unwrap()))
            .collect();
        assert_eq!(replays.len(), 3);
        assert!(
            (replays[r["chosen"].as_str()] - cost).abs() < 0.006,
            "{r:?}"
        );
    }
}

#[test]
fn several_targets_per_house_are_trials_of_their_own_for_eval_and_select() {
    let dir = tempfile::tempdir().unwrap();
    let one = dir.path().join("one");
    let base = [
        "eval",
        "--generate",
        "8",
        "--house-seed",
        "2",
        "--strategies",
    ];
    let strategies = "optimistic+greedy,model/uniform,model/prior";
    let o = ferret(&[&base[..], &[strategies, "--out", s(&one)]].concat());
    assert!(o.status.success(), "{}", text(&o));
    let run: serde_json::Value =
        serde_json::from_slice(&std::fs::read(one.join("run.json")).unwrap()).unwrap();
    assert!(
        run.get("trials_per_house").is_none(),
        "the default leaves trials_per_house out of run.json"
    );
    let three = dir.path().join("three");
    let o = ferret(
        &[
            &base[..],
            &[strategies, "--trials-per-house", "3", "--out", s(&three)],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&three.join("trials.csv"));
    let mut trials: std::collections::BTreeMap<(String, String), Vec<String>> =
        std::collections::BTreeMap::new();
    for r in &rows {
        trials
            .entry((r["house"].clone(), r["target"].clone()))
            .or_default()
            .push(r["strategy"].clone());
    }
    // Every trial is run by all three strategies, and houses have up to three distinct targets.
    assert!(trials.values().all(|v| v.len() == 3), "{trials:?}");
    let mut per_house: std::collections::BTreeMap<&str, usize> = Default::default();
    for (h, _) in trials.keys() {
        *per_house.entry(h.as_str()).or_default() += 1;
    }
    assert_eq!(per_house.len(), 8);
    assert!(per_house.values().all(|&n| (1..=3).contains(&n)));
    assert!(trials.len() > 8, "several targets on some house");
    let summary = std::fs::read_to_string(three.join("summary.md")).unwrap();
    assert!(
        summary.contains(&format!(
            "{} trials, up to 3 distinct targets per house",
            trials.len()
        )),
        "{summary}"
    );
    assert!(
        summary.contains(&format!("| model/prior | {} |", trials.len())),
        "{summary}"
    );
    // Selection draws one trial per house in a deployment: 8 houses allow 8 trials, not 9.
    let sel = dir.path().join("sel");
    let o = ferret(&[
        "select",
        "--trials",
        s(&three),
        "--deployments",
        "20",
        "--trials-per-deployment",
        "8",
        "--out",
        s(&sel),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let replays = std::fs::read_to_string(three.join("replay.csv")).unwrap();
    // Header line plus 2 × 1 replays per deployed strategy, 3 deployed, per trial.
    assert_eq!(replays.lines().count(), 2 + 6 * trials.len(), "{replays}");
    let o = ferret(&[
        "select",
        "--trials",
        s(&three),
        "--deployments",
        "20",
        "--trials-per-deployment",
        "9",
        "--out",
        s(&sel),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("only 8 houses"), "{}", text(&o));
}

/// Replay costs of replay.csv by (house, target, deployed, strategy).
fn replay_costs(dir: &Path) -> std::collections::BTreeMap<(String, String, String, String), f64> {
    let text = std::fs::read_to_string(dir.join("replay.csv")).unwrap();
    let body: String = text.lines().skip(1).map(|l| format!("{l}\n")).collect();
    let mut r = csv::Reader::from_reader(body.as_bytes());
    r.records()
        .map(|rec| {
            let rec = rec.unwrap();
            (
                (
                    rec[0].to_string(),
                    rec[1].to_string(),
                    rec[2].to_string(),
                    rec[3].to_string(),
                ),
                rec[4].parse().unwrap(),
            )
        })
        .collect()
}

#[test]
fn protocol_switches_change_what_they_should_and_select_refuses_to_mix() {
    let dir = tempfile::tempdir().unwrap();
    let strategies = "optimistic+greedy,model/uniform,model/prior,oracle";
    let eval = |out: &Path, extra: &[&str]| {
        let base = [
            "eval",
            "--generate",
            "10",
            "--house-seed",
            "4",
            "--strategies",
            strategies,
            "--out",
            s(out),
        ];
        ferret(&[&base[..], extra].concat())
    };
    let plain = dir.path().join("plain");
    assert!(eval(&plain, &[]).status.success());
    // The paper's initial belief: the same targets, the oracle's cost unchanged (it goes
    // straight to a goal, which is never marked searched), run.json records every setting.
    let belief = dir.path().join("belief");
    let o = eval(&belief, &["--initial-belief", "paper"]);
    assert!(o.status.success(), "{}", text(&o));
    let (a, b) = (
        read_csv(&plain.join("trials.csv")),
        read_csv(&belief.join("trials.csv")),
    );
    assert_eq!(a.len(), b.len());
    for (x, y) in a.iter().zip(&b) {
        assert_eq!((&x["house"], &x["target"]), (&y["house"], &y["target"]));
        if x["strategy"] == "oracle" {
            assert_eq!(x["cost_m"], y["cost_m"]);
        }
    }
    let run: serde_json::Value =
        serde_json::from_slice(&std::fs::read(belief.join("run.json")).unwrap()).unwrap();
    assert_eq!(
        run["protocol"],
        serde_json::json!({"initial_belief": "paper", "containers": "receptacles",
            "targets": "pickupable", "replay": "pessimistic", "draw": "distinct",
            "travel_cost": "plain", "access": "footprint", "rng": "ferret", "untried": "first"})
    );
    // Selecting over the plain run with the paper's belief would mix protocols: refused.
    let sel = dir.path().join("sel");
    let select = |trials: &Path, extra: &[&str]| {
        let base = [
            "select",
            "--trials",
            s(trials),
            "--deployments",
            "10",
            "--trials-per-deployment",
            "6",
            "--out",
            s(&sel),
        ];
        ferret(&[&base[..], extra].concat())
    };
    let o = select(&plain, &["--initial-belief", "paper"]);
    assert!(!o.status.success());
    assert!(text(&o).contains("mix"), "{}", text(&o));
    // Counterfactual replays never exceed pessimistic ones, trial by trial.
    assert!(select(&plain, &[]).status.success());
    let pessimistic = replay_costs(&plain);
    let o = select(&plain, &["--replay", "counterfactual"]);
    assert!(o.status.success(), "{}", text(&o));
    let counterfactual = replay_costs(&plain);
    assert_eq!(pessimistic.len(), counterfactual.len());
    assert!(!pessimistic.is_empty());
    for (k, p) in &pessimistic {
        assert!(
            counterfactual[k] <= p + 1e-9,
            "{k:?}: {} > {p}",
            counterfactual[k]
        );
    }
    // With replacement a deployment may be longer than the number of houses.
    let o = ferret(&[
        "select",
        "--trials",
        s(&plain),
        "--deployments",
        "10",
        "--trials-per-deployment",
        "15",
        "--draw",
        "replacement",
        "--out",
        s(&sel),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    // --protocol paper sets every part; a single switch overrides one.
    let paper = dir.path().join("paper");
    let o = eval(&paper, &["--protocol", "paper", "--access", "footprint"]);
    assert!(o.status.success(), "{}", text(&o));
    let run: serde_json::Value =
        serde_json::from_slice(&std::fs::read(paper.join("run.json")).unwrap()).unwrap();
    assert_eq!(
        run["protocol"],
        serde_json::json!({"initial_belief": "paper", "containers": "furniture",
            "targets": "paper", "replay": "counterfactual", "draw": "replacement",
            "travel_cost": "soft", "access": "footprint", "rng": "python", "untried": "zero"})
    );
    // deploy draws with replacement: 14 trials from 10 houses repeat a house.
    let o = ferret(&[
        "deploy",
        "--generate",
        "10",
        "--trials",
        "14",
        "--strategies",
        strategies,
        "--draw",
        "replacement",
        "--out",
        s(&dir.path().join("deploy")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&dir.path().join("deploy").join("deploy.csv"));
    assert_eq!(rows.len(), 14);
    let houses: std::collections::BTreeSet<&str> =
        rows.iter().map(|r| r["house"].as_str()).collect();
    assert!(houses.len() < 14);
}

/// Under the paper's protocol a live deployment runs the very trials eval runs (same draws,
/// same access points) and learns from the same reported costs: every chosen cost and every
/// counterfactual replay equals eval's soft cost of that strategy on that house.
#[test]
fn deploy_under_the_paper_protocol_reports_evals_soft_costs() {
    let dir = tempfile::tempdir().unwrap();
    let strategies = "optimistic+greedy,model/uniform,model/prior";
    let common = [
        "--generate",
        "6",
        "--house-seed",
        "9",
        "--protocol",
        "paper",
        "--strategies",
        strategies,
    ];
    // One command over the shared options; every run must succeed.
    let run = |command: &str, extra: &[&str]| {
        let o = ferret(&[&[command][..], &common, extra].concat());
        assert!(o.status.success(), "{}", text(&o));
    };
    let eval_out = dir.path().join("eval");
    run("eval", &["--out", s(&eval_out)]);
    let plain_out = dir.path().join("plain");
    run("eval", &["--travel-cost", "plain", "--out", s(&plain_out)]);
    let cost = |rows: &[std::collections::HashMap<String, String>]| {
        rows.iter()
            .map(|r| {
                (
                    (r["house"].clone(), r["strategy"].clone()),
                    r["cost_m"].parse::<f64>().unwrap(),
                )
            })
            .collect::<std::collections::HashMap<_, _>>()
    };
    let soft = cost(&read_csv(&eval_out.join("trials.csv")));
    let plain = cost(&read_csv(&plain_out.join("trials.csv")));
    // The comparison below can only tell soft from plain where they differ.
    assert!(soft.iter().any(|(k, v)| (v - plain[k]).abs() > 0.01));
    let deploy_out = dir.path().join("deploy");
    run("deploy", &["--trials", "12", "--out", s(&deploy_out)]);
    let rows = read_csv(&deploy_out.join("deploy.csv"));
    assert_eq!(rows.len(), 12);
    for r in &rows {
        let chosen: f64 = r["cost_m"].parse().unwrap();
        let want = soft[&(r["house"].clone(), r["chosen"].clone())];
        assert!((chosen - want).abs() < 1e-6, "{r:?}: eval says {want}");
        for entry in r["replays"].split(' ') {
            let (name, m) = entry.split_once('=').unwrap();
            let m: f64 = m.parse().unwrap();
            let want = soft[&(r["house"].clone(), name.to_owned())];
            assert!((m - want).abs() < 0.006, "{r:?}: {name} eval says {want}");
        }
    }
}

#[test]
fn cells_report_costs_in_the_papers_unit_too() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("cells");
    let o = ferret(&[
        "eval",
        "--generate",
        "4",
        "--strategies",
        "optimistic+greedy,oracle",
        "--cells",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    for r in read_csv(&out.join("trials.csv")) {
        let (m, c): (f64, f64) = (
            r["cost_m"].parse().unwrap(),
            r["cost_cells"].parse().unwrap(),
        );
        assert!((c - m / 0.05).abs() < 1e-6, "{m} m is not {c} cells");
    }
    let summary = read_csv(&out.join("summary.csv"));
    let (m, c): (f64, f64) = (
        summary[0]["mean_m"].parse().unwrap(),
        summary[0]["mean_cells"].parse().unwrap(),
    );
    assert!((c - 20.0 * m).abs() < 1e-6);
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains("| strategy | trials | mean cost (cells) |"),
        "{md}"
    );
    assert!(md.contains(&format!("| {:.1} |", 20.0 * m)), "{md}");
    // select still reads the trials with the extra column.
    let o = ferret(&["eval", "--generate", "4", "--out", s(&out), "--cells"]);
    assert!(o.status.success(), "{}", text(&o));
    let o = ferret(&[
        "select",
        "--trials",
        s(&out),
        "--deployments",
        "3",
        "--trials-per-deployment",
        "3",
        "--out",
        s(&dir.path().join("sel")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
}

/// A generated house rewritten the ProcTHOR-10k way (types only in id prefixes, no
/// `objectType` fields, line index 1000) runs end to end under the paper's protocol, and the
/// soft reported cost is never below the plain one on the same trials.
#[test]
fn a_procthor_10k_style_house_runs_under_the_paper_protocol() {
    let dir = tempfile::tempdir().unwrap();
    let generated = dir.path().join("g.jsonl");
    let o = ferret(&[
        "generate",
        "--count",
        "1",
        "--seed",
        "3",
        "--out",
        s(&generated),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let mut house: serde_json::Value = serde_json::from_str(
        std::fs::read_to_string(&generated)
            .unwrap()
            .lines()
            .next()
            .unwrap(),
    )
    .unwrap();
    let mut k = 0;
    for o in house["objects"].as_array_mut().unwrap() {
        let room = o["id"]
            .as_str()
            .unwrap()
            .split('|')
            .next()
            .unwrap()
            .to_owned();
        let ty = o["objectType"].as_str().unwrap().to_owned();
        o["id"] = format!("{ty}|{room}|{k}").into();
        o.as_object_mut().unwrap().remove("objectType");
        k += 1;
        if let Some(children) = o.get_mut("children").and_then(|c| c.as_array_mut()) {
            for c in children {
                let ty = c["objectType"].as_str().unwrap().to_owned();
                c["id"] = format!("{ty}|surface|{room}|{k}").into();
                c.as_object_mut().unwrap().remove("objectType");
                k += 1;
            }
        }
    }
    // House 1000 of the file, as the reference's seeds are line indices.
    let file = dir.path().join("procthor-10k-train.jsonl");
    std::fs::write(&file, "\n".repeat(1000) + &house.to_string() + "\n").unwrap();
    let run = |travel: &str, out: &Path| {
        let o = ferret(&[
            "eval",
            "--houses",
            s(&file),
            "--range",
            "1000",
            "--protocol",
            "paper",
            "--travel-cost",
            travel,
            "--cells",
            "--strategies",
            "optimistic+greedy,oracle",
            "--out",
            s(out),
        ]);
        assert!(o.status.success(), "{}", text(&o));
        read_csv(&out.join("trials.csv"))
    };
    let (soft_out, plain_out) = (dir.path().join("soft"), dir.path().join("plain"));
    let soft = run("soft", &soft_out);
    let plain = run("plain", &plain_out);
    assert_eq!(soft.len(), 2);
    for (a, b) in soft.iter().zip(&plain) {
        assert_eq!(
            (&a["target"], &a["searched"]),
            (&b["target"], &b["searched"])
        );
        let (s, p): (f64, f64) = (a["cost_m"].parse().unwrap(), b["cost_m"].parse().unwrap());
        assert!(s >= p - 1e-9, "soft {s} < plain {p}");
        assert!(a["house_index"] == "1000");
    }
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(soft_out.join("run.json")).unwrap()).unwrap();
    assert_eq!(info["protocol"]["containers"], "furniture");
    assert_eq!(info["protocol"]["travel_cost"], "soft");
    assert_eq!(info["protocol"]["rng"], "python");
    let md = std::fs::read_to_string(soft_out.join("summary.md")).unwrap();
    assert!(md.contains("As the reference code averages"), "{md}");
}

/// Sizes no machine holds are refused with the bounds before anything is allocated (they
/// panicked with "capacity overflow" or aborted after gigabytes).
#[test]
fn bench_serve_and_hold_outs_refuse_sizes_past_their_bounds() {
    for args in [
        &["--deployments", "18446744073709551615"][..],
        &["--trials", "18446744073709551615"],
        &["--deployments", "100000000"],
        &["--deployments", "5000", "--trials", "5000"],
        &["--replicas", "100000"],
    ] {
        let mut all = vec!["bench", "serve"];
        all.extend_from_slice(args);
        let o = ferret(&all);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {t}");
        assert!(t.contains("at most"), "{args:?}: {t}");
    }
    let dir = tempfile::tempdir().unwrap();
    for h in ["18446744073709551615", "1/100000", "1001"] {
        let o = ferret(&[
            "eval",
            "--generate",
            "2",
            "--strategies",
            "model/prior",
            "--holdout-types",
            h,
            "--out",
            s(&dir.path().join("e")),
        ]);
        let t = text(&o);
        assert_eq!(o.status.code(), Some(2), "{h}: {t}");
        assert!(t.contains("--holdout-types"), "{h}: {t}");
    }
}
