//! Teams of robots end to end: `ferret eval --robots` and its rows, summary and picture, one
//! robot as the run without a team, spread starts, and bad teams refused before anything is
//! written.

mod common;

use common::{ferret, read_csv, read_json, s, text};

const SPECS: &str = "model/prior,independent/model/prior,split/model/prior,oracle";

fn eval(out: &std::path::Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["eval", "--generate", "10", "--out", s(out)];
    args.extend_from_slice(extra);
    ferret(&args)
}

fn cost(row: &std::collections::HashMap<String, String>) -> f64 {
    row["cost_m"].parse().unwrap()
}

/// Two robots on one task: every row has the team's columns, each container searched by one
/// of the two, the team drove at least the makespan, nobody beats the team oracle, and the
/// summary and picture say it is a team.
#[test]
fn eval_of_a_team_writes_its_columns_summary_and_picture() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = eval(
        &out,
        &["--robots", "2", "--task", "all:2", "--strategies", SPECS],
    );
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&out.join("trials.csv"));
    assert_eq!(rows.len(), 10 * 4, "{}", text(&o));
    for r in &rows {
        assert_eq!(r["robots"], "2", "{r:?}");
        assert_eq!(r["found"], "true", "{r:?}");
        let by: Vec<&str> = r["searched_by"].split_whitespace().collect();
        assert_eq!(by.len(), r["searches"].parse::<usize>().unwrap(), "{r:?}");
        assert!(by.iter().all(|b| *b == "0" || *b == "1"), "{r:?}");
        let total: f64 = r["total_travel_m"].parse().unwrap();
        assert!(total + 1e-9 >= cost(r), "{r:?}");
        assert!(total <= 2.0 * cost(r) + 1e-9, "{r:?}");
        let oracle = rows
            .iter()
            .find(|x| x["house_index"] == r["house_index"] && x["strategy"] == "oracle")
            .unwrap();
        assert!(cost(r) + 1e-9 >= cost(oracle), "{r:?} beat {oracle:?}");
    }
    // Coordinated robots never open a container twice; at least one trial used both robots.
    let coordinated: Vec<_> = rows
        .iter()
        .filter(|r| r["strategy"] == "model/prior")
        .collect();
    assert!(coordinated.iter().any(|r| r["searched_by"].contains('1')));
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains("## Teams") && md.contains("mean total travel (m)"),
        "{md}"
    );
    let summary = read_csv(&out.join("summary.csv"));
    assert!(summary.iter().all(|r| !r["mean_total_travel_m"].is_empty()));
    let info = read_json(&out.join("run.json"));
    assert_eq!(info["team"]["robots"], 2);
    assert_eq!(info["team"]["starts"], "together");
    assert!(out.join("trajectories.png").metadata().unwrap().len() > 10_000);
}

/// Selection over a run of teams replays each strategy with the same team from the same
/// starts: where a strategy's own trial found the target in the container the deployed one
/// did, its replay is exactly its own makespan (its searches before meet nothing in either
/// world), which one robot's replay would not be.
#[test]
fn select_over_a_team_run_replays_each_strategy_with_the_team() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let specs = "model/prior,independent/model/prior,split/model/prior";
    let o = eval(
        &out,
        &["--robots", "2", "--starts", "spread", "--strategies", specs],
    );
    assert!(o.status.success(), "{}", text(&o));
    let o = ferret(&[
        "select",
        "--trials",
        s(&out),
        "--trials-per-deployment",
        "8",
        "--out",
        s(&dir.path().join("select")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&out.join("trials.csv"));
    let row = |house: &str, strategy: &str| {
        rows.iter()
            .find(|r| r["house_index"] == house && r["strategy"] == strategy)
            .unwrap()
    };
    let replays = std::fs::read_to_string(out.join("replay.csv")).unwrap();
    let mut reader = csv::ReaderBuilder::new()
        .comment(Some(b'#'))
        .from_reader(replays.as_bytes());
    let (mut same, mut all) = (0, 0);
    for r in reader.deserialize::<std::collections::HashMap<String, String>>() {
        let r = r.unwrap();
        let (deployed, replayed) = (
            row(&r["house_index"], &r["deployed"]),
            row(&r["house_index"], &r["strategy"]),
        );
        all += 1;
        if deployed["found_container"] == replayed["found_container"] {
            let replay: f64 = r["replay_cost_m"].parse().unwrap();
            assert!(
                (replay - cost(replayed)).abs() < 1e-9,
                "{r:?}: replay {replay} vs the team's own {}",
                cost(replayed)
            );
            same += 1;
        }
    }
    assert_eq!(
        all,
        10 * 3 * 2,
        "every strategy replayed on every other's trial"
    );
    assert!(
        same >= 10,
        "{same} of {all} replays on a trial found where the strategy found it"
    );
}

/// A team of one is the run without a team, row for row; independent robots all at the start
/// cost what one robot costs.
#[test]
fn one_robot_is_the_run_without_a_team() {
    let dir = tempfile::tempdir().unwrap();
    let (alone, one, two) = (
        dir.path().join("alone"),
        dir.path().join("one"),
        dir.path().join("two"),
    );
    let specs = ["--strategies", "model/prior,optimistic+greedy,oracle"];
    for (out, team) in [(&alone, &[][..]), (&one, &["--robots", "1"][..])] {
        let mut extra = specs.to_vec();
        extra.extend_from_slice(team);
        let o = eval(out, &extra);
        assert!(o.status.success(), "{}", text(&o));
    }
    let o = eval(
        &two,
        &["--robots", "2", "--strategies", "independent/model/prior"],
    );
    assert!(o.status.success(), "{}", text(&o));
    let (alone, one, two) = (
        read_csv(&alone.join("trials.csv")),
        read_csv(&one.join("trials.csv")),
        read_csv(&two.join("trials.csv")),
    );
    assert_eq!(alone.len(), one.len());
    for (a, b) in alone.iter().zip(&one) {
        for k in [
            "strategy",
            "target",
            "cost_m",
            "searched",
            "found_container",
        ] {
            assert_eq!(a[k], b[k], "{k}: {a:?} vs {b:?}");
        }
        assert!(!a.contains_key("robots"));
        assert_eq!(b["robots"], "1");
    }
    for r in &two {
        let a = alone
            .iter()
            .find(|a| a["house_index"] == r["house_index"] && a["strategy"] == "model/prior")
            .unwrap();
        assert!((cost(r) - cost(a)).abs() < 1e-9, "{r:?} vs {a:?}");
    }
}

/// Spread starts move the robots: some trial costs otherwise than with every robot at the
/// start, and still none beats the team's own oracle.
#[test]
fn spread_starts_are_drawn_and_the_team_oracle_bounds_them() {
    let dir = tempfile::tempdir().unwrap();
    let (together, spread) = (dir.path().join("together"), dir.path().join("spread"));
    for (out, starts) in [(&together, "together"), (&spread, "spread")] {
        let o = eval(
            out,
            &["--robots", "3", "--starts", starts, "--strategies", SPECS],
        );
        assert!(o.status.success(), "{}", text(&o));
    }
    let (t, sp) = (
        read_csv(&together.join("trials.csv")),
        read_csv(&spread.join("trials.csv")),
    );
    assert!(t.iter().zip(&sp).any(|(a, b)| a["cost_m"] != b["cost_m"]));
    for r in &sp {
        let oracle = sp
            .iter()
            .find(|x| x["house_index"] == r["house_index"] && x["strategy"] == "oracle")
            .unwrap();
        assert!(cost(r) + 1e-9 >= cost(oracle), "{r:?}");
    }
    assert_eq!(
        read_json(&spread.join("run.json"))["team"]["starts"],
        "spread"
    );
}

/// Bad teams are refused with what is wrong, and nothing is written: bad options as usage
/// errors (exit 2), settings that do not go together and strategies the registry refuses as
/// any such (exit 1).
#[test]
fn bad_teams_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    for (extra, says, code) in [
        (&["--robots", "5"][..], "5 is not in 1..=4", 2),
        (&["--robots", "0"][..], "0 is not in 1..=4", 2),
        (&["--starts", "spread"][..], "--robots", 2),
        (
            &["--robots", "2", "--starts", "scattered"][..],
            "`scattered`: expected `together` or `spread`",
            2,
        ),
        (
            &["--robots", "2", "--protocol", "paper"][..],
            "a team's makespan is measured in plain metres",
            1,
        ),
        (
            &[
                "--robots",
                "2",
                "--strategies",
                "independent/split/model/prior",
            ][..],
            "one of independent/ and split/",
            1,
        ),
    ] {
        let o = eval(&out, extra);
        assert_eq!(o.status.code(), Some(code), "{extra:?}: {}", text(&o));
        assert!(text(&o).contains(says), "{extra:?}: {}", text(&o));
        assert!(
            !out.join("trials.csv").exists(),
            "{extra:?} wrote trials.csv"
        );
    }
}
