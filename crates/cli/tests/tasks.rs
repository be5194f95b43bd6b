//! Household tasks end to end: `ferret eval --task` and `--tasks`, their rows and pictures,
//! `select` over a run of tasks, `deploy --find` with tasks, and bad tasks refused as usage
//! errors before anything is written.

mod common;

use common::{data_dir, ferret, read_csv, read_json, s, text};

/// Every strategy's row of every task: the goal holds, the targets were found where the truth
/// of the run says they were searched, the last leg goes to the start, no strategy beats the
/// oracle and the task columns are there.
#[test]
fn eval_of_drawn_tasks_writes_their_columns_and_pictures() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = ferret(&[
        "eval",
        "--generate",
        "12",
        "--task",
        "all:3",
        "--deliver",
        "start",
        "--strategies",
        "optimistic+greedy,sequential/model/prior,model/prior,oracle",
        "--paired-against",
        "sequential/model/prior",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&out.join("trials.csv"));
    assert_eq!(rows.len(), 12 * 4, "{}", text(&o));
    for r in &rows {
        assert_eq!(r["goal"], "all");
        assert_eq!(r["destination"], "start");
        assert_eq!(r["found"], "true", "{r:?}");
        let targets: Vec<&str> = r["target"].split('+').collect();
        assert_eq!(targets.len(), 3, "{r:?}");
        let found: Vec<&str> = r["found_each"].split(' ').collect();
        assert_eq!(found.len(), 3);
        let searched: Vec<&str> = r["searched"].split(' ').collect();
        assert!(found.iter().all(|f| searched.contains(f)), "{r:?}");
        // The goal came to hold at the last container searched.
        assert_eq!(searched.last(), Some(&r["found_container"].as_str()));
        let delivery: f64 = r["delivery_m"].parse().unwrap();
        let cost: f64 = r["cost_m"].parse().unwrap();
        assert!(delivery >= 0.0 && delivery < cost, "{r:?}");
    }
    for house in rows.iter().map(|r| &r["house_index"]) {
        let of = |s: &str| -> f64 {
            rows.iter()
                .find(|r| &r["house_index"] == house && r["strategy"] == s)
                .unwrap()["cost_m"]
                .parse()
                .unwrap()
        };
        for s in ["optimistic+greedy", "sequential/model/prior", "model/prior"] {
            assert!(of(s) + 1e-9 >= of("oracle"), "house {house}: {s}");
        }
    }
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains("12 household tasks (tasks all:3, brought to start)"),
        "{md}"
    );
    assert!(md.contains("Against sequential/model/prior"), "{md}");
    assert!(
        std::fs::metadata(out.join("trajectories.png"))
            .unwrap()
            .len()
            > 10_000
    );
    let run = read_json(&out.join("run.json"));
    assert_eq!(run["tasks"]["drawn"]["deliver"], "start");

    // Selection replays every candidate on the same tasks.
    let o = ferret(&[
        "select",
        "--trials",
        s(&out),
        "--deployments",
        "5",
        "--trials-per-deployment",
        "10",
        "--out",
        s(&dir.path().join("select")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let text_of = std::fs::read_to_string(out.join("replay.csv")).unwrap();
    // Three candidates (the oracle is none): each replayed where each other was deployed.
    assert_eq!(text_of.lines().count(), 2 + 12 * 3 * 2, "{text_of}");
    assert!(
        text_of.contains("+"),
        "replays are keyed by the task's targets"
    );
}

/// A tasks file's trials are exactly its lines, with their destinations; the same house twice.
#[test]
fn eval_of_listed_tasks_runs_each_line() {
    let dir = tempfile::tempdir().unwrap();
    let houses = dir.path().join("h.jsonl");
    let o = ferret(&[
        "generate",
        "--count",
        "2",
        "--seed",
        "5",
        "--out",
        s(&houses),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    // Two types each house holds, and a container and a room of house 0.
    let lines: Vec<serde_json::Value> = std::fs::read_to_string(&houses)
        .unwrap()
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect();
    let types = |h: &serde_json::Value| -> Vec<String> {
        let mut t: Vec<String> = h["objects"]
            .as_array()
            .unwrap()
            .iter()
            .flat_map(|o| o["children"].as_array().cloned().unwrap_or_default())
            .filter_map(|c| c["objectType"].as_str().map(String::from))
            .collect();
        t.sort();
        t.dedup();
        t
    };
    let (t0, t1) = (types(&lines[0]), types(&lines[1]));
    let container = lines[0]["objects"][0]["id"].as_str().unwrap().to_string();
    let room = lines[0]["rooms"][1]["id"].as_str().unwrap().to_string();
    let file = dir.path().join("tasks.csv");
    std::fs::write(
        &file,
        format!(
            "house,targets,goal,destination\n0,{} {},all,container:{container}\n0,{}+{},any,room:{room}\n1,{},,\n",
            t0[0], t0[1], t0[2], t0[3], t1[0]
        ),
    )
    .unwrap();
    let out = dir.path().join("run");
    let o = ferret(&[
        "eval",
        "--houses",
        s(&houses),
        "--tasks",
        s(&file),
        // sequential/ alone needs the prior its spec plans over.
        "--strategies",
        "sequential/model/prior,optimistic+greedy",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&out.join("trials.csv"));
    assert_eq!(rows.len(), 3 * 2);
    let r = |i: usize| &rows[2 * i];
    assert_eq!(r(0)["destination"], format!("container:{container}"));
    assert_eq!(r(0)["target"], format!("{}+{}", t0[0], t0[1]));
    assert_eq!(r(1)["goal"], "any");
    assert_eq!(r(1)["target"], format!("{}|{}", t0[2], t0[3]));
    assert_eq!(r(1)["destination"], format!("room:{room}"));
    // Any: one target found, the other may not be.
    assert!(r(1)["found_each"].split(' ').any(|f| f != "-"));
    assert_eq!(
        (r(2)["destination"].as_str(), r(2)["delivery_m"].as_str()),
        ("", "0.0")
    );
}

/// Bad tasks are usage errors (exit 2) that name the field, and nothing is written.
#[test]
fn bad_tasks_are_refused_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let cases: [(&[&str], &str); 5] = [
        (&["--task", "all:5"], "1 to 4"),
        (&["--task", "some:2"], "goal"),
        (&["--deliver", "start"], "--task"),
        (&["--task", "all:2", "--deliver", "moon"], "destination"),
        (&["--task", "all:0"], "1 to 4"),
    ];
    for (args, says) in cases {
        let mut all = vec!["eval", "--generate", "3", "--out", s(&out)];
        all.extend_from_slice(args);
        let o = ferret(&all);
        assert_eq!(o.status.code(), Some(2), "{args:?}: {}", text(&o));
        assert!(text(&o).contains(says), "{args:?}: {}", text(&o));
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    let file = dir.path().join("tasks.csv");
    let lines: [(&str, &str); 6] = [
        ("0,Apple Apple,all,", "twice"),
        ("0,A B C D E,all,", "at most 4"),
        ("0,Apple,maybe,", "goal"),
        ("0,Apple,all,room:nowhere", "no room `nowhere`"),
        ("0,Apple,all,1000,1000", "columns"),
        ("999,Apple,all,", "no house 999"),
    ];
    for (line, says) in lines {
        std::fs::write(&file, format!("house,targets,goal,destination\n{line}\n")).unwrap();
        let o = ferret(&[
            "eval",
            "--generate",
            "3",
            "--tasks",
            s(&file),
            "--out",
            s(&out),
        ]);
        assert_eq!(o.status.code(), Some(2), "{line}: {}", text(&o));
        assert!(text(&o).contains(says), "{line}: {}", text(&o));
        assert!(!out.exists(), "{line} wrote {}", out.display());
    }
    // A point off the floor, named by its task and field.
    std::fs::write(
        &file,
        "house,targets,goal,destination\n0,Apple,any,\"1000,1000\"\n",
    )
    .unwrap();
    let o = ferret(&[
        "eval",
        "--generate",
        "3",
        "--tasks",
        s(&file),
        "--out",
        s(&out),
    ]);
    assert_eq!(o.status.code(), Some(2), "{}", text(&o));
    assert!(
        text(&o).contains("destination") && text(&o).contains("not on floor the robot can reach"),
        "{}",
        text(&o)
    );
    assert!(!out.exists());
}

/// `deploy --find` takes tasks: both targets found and brought back, each trial replayed for
/// every candidate.
#[test]
fn deploy_finds_tasks_in_one_home() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("deploy");
    let o = ferret(&[
        "deploy",
        "--generate",
        "1",
        "--task",
        "all:2",
        "--deliver",
        "start",
        "--trials",
        "1",
        "--strategies",
        "sequential/model/prior,model/prior",
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let rows = read_csv(&out.join("deploy.csv"));
    assert_eq!(rows.len(), 1);
    assert!(rows[0]["target"].contains('+'), "{:?}", rows[0]);
    assert_eq!(rows[0]["replays"].split(' ').count(), 2);
}

/// On real ProcTHOR houses: every strategy does `any` of 2 brought to a room type, skipping
/// (with a message) the houses without that room.
#[test]
fn tasks_on_procthor_houses_go_to_a_room_type() {
    let Some(d) = data_dir() else { return };
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let o = ferret(&[
        "eval",
        "--houses",
        s(&d.join("multiroom-val150.jsonl.gz")),
        "--asset-db",
        s(&d.join("databases/asset-database.json")),
        "--range",
        "0..12",
        "--task",
        "any:2",
        "--deliver",
        "room:Bathroom",
        "--strategies",
        "sequential/model/prior,model/prior,oracle",
        "--out",
        s(&out),
    ]);
    let rows = read_csv(&out.join("trials.csv"));
    assert!(!rows.is_empty(), "{}", text(&o));
    assert!(rows.iter().all(|r| r["destination"].starts_with("room:")));
    assert!(rows.iter().all(|r| r["found"] == "true"));
    // A house without a bathroom is a failure of that house, said so; the others ran.
    if !o.status.success() {
        assert!(
            text(&o).contains("no room of type Bathroom"),
            "{}",
            text(&o)
        );
    }
}
