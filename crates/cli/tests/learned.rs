//! The learned likelihood end to end through the `ferret` binary: training it into a prior file,
//! planning with it in every command (eval, calibrate, select, deploy, shards, hold-outs), the
//! embeddings opened only for names the file lacks, clear errors; and on real ProcTHOR houses
//! with real GloVe vectors, language that reaches the planner where counts have nothing.

mod common;

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use common::{Server, data_dir, post, read_csv, s, text, word_table as table};

/// Runs ferret with `args`, without `FERRET_EMBEDDINGS` unless `embeddings` gives it.
fn run(args: &[&str], embeddings: Option<&Path>) -> Output {
    let mut c = Command::new(env!("CARGO_BIN_EXE_ferret"));
    c.args(args).env_remove("FERRET_EMBEDDINGS");
    if let Some(e) = embeddings {
        c.env("FERRET_EMBEDDINGS", e);
    }
    c.output().expect("the ferret binary runs")
}

/// Runs ferret with `args` (without embeddings), expecting it to fail saying `needle`.
fn fails_with(args: &[&str], needle: &str) {
    let o = run(args, None);
    let said = text(&o);
    assert!(
        !o.status.success() && said.contains(needle),
        "ferret {args:?} should fail saying {needle:?}: {said}"
    );
}

fn ok(args: &[&str], embeddings: Option<&Path>) -> String {
    let o = run(args, embeddings);
    assert!(o.status.success(), "ferret {args:?}: {}", text(&o));
    text(&o)
}

fn costs(run: &Path, strategy: &str) -> Vec<f64> {
    read_csv(&run.join("trials.csv"))
        .iter()
        .filter(|r| r["strategy"] == strategy)
        .map(|r| r["cost_m"].parse().unwrap())
        .collect()
}

fn mean(v: &[f64]) -> f64 {
    v.iter().sum::<f64>() / v.len() as f64
}

#[test]
fn a_learned_prior_is_trained_the_same_twice_and_plans_in_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let table = table(dir.path());
    let (a, b) = (dir.path().join("a.json"), dir.path().join("b.json"));
    let train = |out: &Path| {
        ok(
            &[
                "prior",
                "train",
                "--generate",
                "30",
                "--house-seed",
                "9",
                "--embeddings",
                s(&table),
                "--learned-folds",
                "3",
                "--learned-epochs",
                "10",
                "--out",
                s(out),
            ],
            None,
        )
    };
    let said = train(&a);
    assert!(said.contains("learned likelihood over tiny"), "{said}");
    train(&b);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());

    let specs = "model/prior,model/learned,model/learned-head,model/learned-random,model/learned-head-random,model/learned/exact";
    let eval = dir.path().join("eval");
    ok(
        &[
            "eval",
            "--generate",
            "12",
            "--prior",
            s(&a),
            "--strategies",
            specs,
            "--out",
            s(&eval),
        ],
        None,
    );
    let rows = read_csv(&eval.join("trials.csv"));
    assert_eq!(rows.len(), 6 * 12);
    // The heads over the names' vectors and over random ones plan differently somewhere (where
    // the prior has seen everything, as here, model/learned is the prior's and so is its
    // control).
    let searched = |st: &str| -> Vec<String> {
        rows.iter()
            .filter(|r| r["strategy"] == st)
            .map(|r| r["searched"].clone())
            .collect()
    };
    assert_ne!(
        searched("model/learned-head"),
        searched("model/learned-head-random")
    );

    // Shards merged are one machine, with learned strategies too.
    let one = dir.path().join("one");
    let base = [
        "eval",
        "--generate",
        "8",
        "--prior",
        s(&a),
        "--strategies",
        "model/learned,model/learned-random",
    ];
    let with = |extra: &[&str], out: &Path| {
        let mut args = base.to_vec();
        args.extend_from_slice(extra);
        args.extend(["--out", s(out)]);
        ok(&args, None);
    };
    with(&[], &one);
    let shards: Vec<PathBuf> = (0..2).map(|i| dir.path().join(format!("sh{i}"))).collect();
    for (i, d) in shards.iter().enumerate() {
        with(&["--shard", &format!("{i}/2")], d);
    }
    let merged = dir.path().join("merged");
    ok(
        &["merge", "--out", s(&merged), s(&shards[0]), s(&shards[1])],
        None,
    );
    assert_eq!(
        std::fs::read(one.join("trials.csv")).unwrap(),
        std::fs::read(merged.join("trials.csv")).unwrap()
    );

    // Held-out types answered by the heads of the same folds; other fold counts refused.
    let held = dir.path().join("held");
    ok(
        &[
            "eval",
            "--generate",
            "12",
            "--prior",
            s(&a),
            "--holdout-types",
            "3",
            "--strategies",
            "model/prior,model/learned",
            "--out",
            s(&held),
        ],
        None,
    );
    assert_eq!(costs(&held, "model/learned").len(), 12);
    fails_with(
        &[
            "eval",
            "--generate",
            "4",
            "--prior",
            s(&a),
            "--holdout-types",
            "5",
            "--strategies",
            "model/learned",
            "--out",
            s(&dir.path().join("h5")),
        ],
        "3 folds",
    );

    // calibrate, select and deploy take the learned sources as they take the prior.
    let cal = dir.path().join("cal");
    let said = ok(
        &[
            "calibrate",
            "--generate",
            "10",
            "--prior",
            s(&a),
            "--sources",
            "model/prior,model/learned,model/learned-random",
            "--out",
            s(&cal),
        ],
        None,
    );
    assert!(said.contains("model/learned-random"), "{said}");
    let sel = dir.path().join("sel");
    ok(
        &[
            "select",
            "--trials",
            s(&eval),
            "--deployments",
            "5",
            "--trials-per-deployment",
            "6",
            "--out",
            s(&sel),
        ],
        None,
    );
    let said = ok(
        &[
            "deploy",
            "--generate",
            "6",
            "--prior",
            s(&a),
            "--strategies",
            "model/prior,model/learned",
            "--trials",
            "6",
            "--out",
            s(&dir.path().join("dep")),
        ],
        None,
    );
    assert!(said.contains("model/learned"), "{said}");
}

#[test]
fn training_and_planning_say_what_is_missing() {
    let dir = tempfile::tempdir().unwrap();
    let nowhere = dir.path().join("nowhere");
    let o = run(
        &[
            "prior",
            "train",
            "--generate",
            "10",
            "--embeddings",
            s(&nowhere),
            "--out",
            s(&dir.path().join("p.json")),
        ],
        None,
    );
    assert!(!o.status.success());
    let said = text(&o);
    assert!(
        said.contains("nowhere") && said.contains("scripts/embeddings.sh install"),
        "{said}"
    );
    assert!(!dir.path().join("p.json").exists());

    // A prior of counts only cannot plan model/learned, and says how to get one that can.
    let plain = dir.path().join("plain.json");
    ok(
        &["prior", "train", "--generate", "10", "--out", s(&plain)],
        None,
    );
    fails_with(
        &[
            "eval",
            "--generate",
            "3",
            "--prior",
            s(&plain),
            "--strategies",
            "model/learned",
            "--out",
            s(&dir.path().join("e")),
        ],
        "--embeddings",
    );
}

/// The embeddings `FERRET_GLOVE` names (real GloVe from `scripts/embeddings.sh install`; the
/// tests' own variable, so that the other tests' `prior train` stay counts only), or `None` with
/// a message saying how to run the test.
fn glove() -> Option<PathBuf> {
    match std::env::var_os("FERRET_GLOVE") {
        Some(d) if !d.is_empty() => Some(PathBuf::from(d)),
        _ => {
            eprintln!(
                "skipped: set FERRET_GLOVE=$(scripts/embeddings.sh install) to run the real-embedding tests"
            );
            None
        }
    }
}

#[test]
fn on_real_houses_language_plans_unseen_targets_cheaper_than_counts_and_random_vectors_do_not() {
    let (Some(data), Some(glove)) = (data_dir(), glove()) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let prior = dir.path().join("prior.json");
    let asset = data.join("databases/asset-database.json");
    ok(
        &[
            "prior",
            "train",
            "--houses",
            s(&data.join("smallhouse-train1000.jsonl.gz")),
            "--asset-db",
            s(&asset),
            "--also",
            s(&data.join("oneroom-train500.jsonl.gz")),
            "--embeddings",
            s(&glove),
            "--out",
            s(&prior),
        ],
        None,
    );
    // Every name of val150 is in the file: an embeddings folder that does not exist is never
    // opened.
    let unseen = dir.path().join("unseen");
    ok(
        &[
            "eval",
            "--houses",
            s(&data.join("multiroom-val150.jsonl.gz")),
            "--asset-db",
            s(&asset),
            "--prior",
            s(&prior),
            "--holdout-types",
            "5",
            "--embeddings",
            s(&dir.path().join("absent")),
            "--strategies",
            "model/prior,model/learned,model/learned-random",
            "--out",
            s(&unseen),
        ],
        None,
    );
    let (counts, language, control) = (
        mean(&costs(&unseen, "model/prior")),
        mean(&costs(&unseen, "model/learned")),
        mean(&costs(&unseen, "model/learned-random")),
    );
    assert!(
        language < 0.9 * counts,
        "model/learned {language:.2} m against the prior's {counts:.2} m on unseen target types"
    );
    assert!(
        language < control,
        "model/learned {language:.2} m against its random-vector control's {control:.2} m"
    );

    // Furniture and rooms no training house had: without the embeddings, a clear error for the
    // learned rows (the others are written); with them, every row.
    let workshop = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/workshop/scene.yaml");
    let args = |out: &Path| -> Vec<String> {
        [
            "eval",
            "--houses",
            s(&workshop),
            "--prior",
            s(&prior),
            "--trials-per-house",
            "all",
            "--strategies",
            "model/prior,model/learned",
            "--out",
            s(out),
        ]
        .iter()
        .map(|a| a.to_string())
        .collect()
    };
    let without = dir.path().join("ws-without");
    let a = args(&without);
    let o = run(&a.iter().map(String::as_str).collect::<Vec<_>>(), None);
    let said = text(&o);
    assert!(
        !o.status.success() && said.contains("FERRET_EMBEDDINGS"),
        "{said}"
    );
    assert!(!costs(&without, "model/prior").is_empty());
    let with = dir.path().join("ws-with");
    let a = args(&with);
    ok(
        &a.iter().map(String::as_str).collect::<Vec<_>>(),
        Some(&glove),
    );
    assert_eq!(
        costs(&with, "model/learned").len(),
        costs(&with, "model/prior").len()
    );
}

const TARGETS: &str = "Blanket,CellPhone,RemoteControl,Pillow,Wallet";

/// The tests' word table and a prior trained over it on 30 generated houses (3 folds, short
/// training): the table's folder and the prior's file.
fn tiny_learned_prior(dir: &Path) -> (PathBuf, PathBuf) {
    let table = table(dir);
    let prior = dir.join("prior.json");
    ok(
        &[
            "prior",
            "train",
            "--generate",
            "30",
            "--house-seed",
            "9",
            "--embeddings",
            s(&table),
            "--learned-folds",
            "3",
            "--learned-epochs",
            "10",
            "--out",
            s(&prior),
        ],
        None,
    );
    (table, prior)
}

/// `ferret deploy` on the apartment and the same deployment driven through `ferret serve` by the
/// Python robot client choose the same strategies at the same costs, `model/learned` among them
/// (the apartment's names the prior file lacks come from `FERRET_EMBEDDINGS` in both).
#[test]
fn serve_plans_model_learned_as_deploy_does() {
    let dir = tempfile::tempdir().unwrap();
    let (table, prior) = tiny_learned_prior(dir.path());
    let scene = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/apartment/scene.yaml");
    let strategies = "model/prior,model/learned,model/learned-head";
    let out = dir.path().join("deploy");
    ok(
        &[
            "deploy",
            "--houses",
            s(&scene),
            "--find",
            TARGETS,
            "--strategies",
            strategies,
            "--prior",
            s(&prior),
            "--seed",
            "4",
            "--out",
            s(&out),
        ],
        Some(&table),
    );
    let deployed: Vec<(String, f64)> = read_csv(&out.join("deploy.csv"))
        .iter()
        .map(|r| (r["chosen"].clone(), r["cost_m"].parse().unwrap()))
        .collect();
    assert_eq!(deployed.len(), 5);
    assert!(deployed.iter().any(|(s, _)| s.starts_with("model/learned")));

    let db = dir.path().join("serve.sqlite");
    let server = Server::spawn(
        &[
            "--scene",
            s(&scene),
            "--strategies",
            strategies,
            "--prior",
            s(&prior),
            "--listen",
            "127.0.0.1:0",
            "--db",
            s(&db),
        ],
        &[("FERRET_EMBEDDINGS", &table)],
    );
    let url = server.url.clone();
    let o = Command::new("python3")
        .arg(Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/robot_client.py"))
        .args(["--url", &url, "--scene", "apartment", "--targets", TARGETS])
        .args(["--strategies", strategies, "--seed", "4", "--json"])
        .env_remove("FERRET_SERVE_TOKEN")
        .output()
        .expect("python3 runs");
    server.kill();
    assert!(o.status.success(), "{}", text(&o));
    let report: serde_json::Value = serde_json::from_slice(&o.stdout).unwrap();
    let served: Vec<(String, f64)> = report["trials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| {
            (
                t["strategy"].as_str().unwrap().to_string(),
                t["cost_m"].as_f64().unwrap(),
            )
        })
        .collect();
    assert_eq!(served.len(), deployed.len());
    for (k, ((a, x), (b, y))) in served.iter().zip(&deployed).enumerate() {
        assert_eq!(a, b, "trial {k}");
        assert!(
            (x - y).abs() < 0.005,
            "trial {k}: served {x} m, deployed {y} m"
        );
    }
}

/// A scene of two rooms whose dresser is of type `dresser` (a name to misspell), holding a wallet.
fn scene_with(dir: &Path, name: &str, dresser: &str) -> PathBuf {
    let scene = serde_json::json!({
        "ferret_scene": 1, "name": name,
        "rooms": [
            {"name": "bedroom", "type": "Bedroom", "polygon": [[0, 0], [5, 0], [5, 4], [0, 4]]},
            {"name": "kitchen", "type": "Kitchen", "polygon": [[5, 0], [9, 0], [9, 4], [5, 4]]}
        ],
        "doors": [{"from": [5, 1.5], "to": [5, 2.5]}],
        "containers": [
            {"id": "d", "type": dresser, "pose": [2, 3.6, -90], "size": [0.5, 1.2], "contents": ["Wallet"]},
            {"id": "b", "type": "Bed", "pose": [1.2, 1.2, 0], "size": [1.4, 2.0]},
            {"id": "f", "type": "Fridge", "pose": [8.5, 3.5, -90], "size": [0.7, 0.8], "contents": ["Egg"]}
        ],
        "start": [4, 2, 0]
    });
    let path = dir.join(format!("{name}.yaml"));
    std::fs::write(&path, scene.to_string()).unwrap();
    path
}

/// A misspelt name never plans in silence: a word left out of a name's vector is said once on
/// stderr; a name with no known word fails the learned rows (the others are written), stops
/// `ferret serve` from starting, and is answered 422 when uploaded; a served trial's state
/// carries the note on its scene's names.
#[test]
fn a_misspelt_name_is_refused_or_said_and_never_planned_in_silence() {
    let dir = tempfile::tempdir().unwrap();
    let (table, prior) = tiny_learned_prior(dir.path());
    let typo = scene_with(dir.path(), "typo", "Xyzzyblorp");
    let noted = scene_with(dir.path(), "noted", "XyzzyDresser");
    let eval = |scene: &Path, out: &Path| -> Output {
        run(
            &[
                "eval",
                "--houses",
                s(scene),
                "--prior",
                s(&prior),
                "--trials-per-house",
                "all",
                "--strategies",
                "model/prior,model/learned",
                "--out",
                s(out),
            ],
            Some(&table),
        )
    };
    let out = dir.path().join("typo-eval");
    let o = eval(&typo, &out);
    let said = text(&o);
    assert!(
        !o.status.success() && said.contains("`Xyzzyblorp`"),
        "{said}"
    );
    assert!(
        said.contains("xyzzyblorp") && said.contains("spelling"),
        "{said}"
    );
    assert_eq!(costs(&out, "model/prior").len(), 2);
    assert!(costs(&out, "model/learned").is_empty());

    let out = dir.path().join("noted-eval");
    let o = eval(&noted, &out);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert_eq!(
        said.matches("`XyzzyDresser`: `xyzzy`").count(),
        1,
        "said once, whatever the trials: {said}"
    );
    assert_eq!(costs(&out, "model/learned").len(), 2);

    // `ferret serve` checks its scenes before it listens.
    let serve = |scene: &Path, embeddings: Option<&Path>| {
        run(
            &[
                "serve",
                "--scene",
                s(scene),
                "--strategies",
                "model/prior,model/learned",
                "--prior",
                s(&prior),
                "--listen",
                "127.0.0.1:0",
                "--db",
                s(&dir.path().join("refused.sqlite")),
            ],
            embeddings,
        )
    };
    let o = serve(&typo, Some(&table));
    let said = text(&o);
    assert!(
        !o.status.success() && said.contains("`Xyzzyblorp`"),
        "{said}"
    );
    let apartment =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("../../examples/apartment/scene.yaml");
    let o = serve(&apartment, None);
    let said = text(&o);
    assert!(
        !o.status.success() && said.contains("`DiningRoom`") && said.contains("--embeddings"),
        "{said}"
    );

    let server = Server::spawn(
        &[
            "--scene",
            s(&noted),
            "--strategies",
            "model/learned",
            "--prior",
            s(&prior),
            "--listen",
            "127.0.0.1:0",
            "--db",
            s(&dir.path().join("served.sqlite")),
        ],
        &[("FERRET_EMBEDDINGS", &table)],
    );
    let url = server.url.clone();
    let upload: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&typo).unwrap()).unwrap();
    let (status, reply) = post(
        &format!("{url}/scenes"),
        serde_json::json!({"scene": upload}),
    );
    assert_eq!(status, 422, "{reply}");
    assert!(reply.to_string().contains("`Xyzzyblorp`"), "{reply}");
    let (status, deployment) = post(
        &format!("{url}/deployments"),
        serde_json::json!({"seed": 1}),
    );
    assert_eq!(status, 201, "{deployment}");
    let id = deployment["id"].as_i64().unwrap();
    let (status, trial) = post(
        &format!("{url}/deployments/{id}/trials"),
        serde_json::json!({"scene": "noted", "target": "Wallet"}),
    );
    server.kill();
    assert_eq!(status, 201, "{trial}");
    let language = trial["language"].as_array().cloned().unwrap_or_default();
    assert!(
        language.len() == 1 && language[0].as_str().unwrap().contains("`xyzzy`"),
        "{trial}"
    );
}

/// `--knowledge wordnet` puts WordNet's knowledge of each name beside its vector (and says when
/// WordNet cannot be read); its shuffled control reads other nouns' and makes another file.
#[test]
fn wordnet_knowledge_stands_beside_the_vectors_with_its_shuffled_control() {
    let dir = tempfile::tempdir().unwrap();
    let table = table(dir.path());
    let train = |knowledge: &str, out: &Path, wordnet: Option<&Path>| -> Output {
        let mut c = Command::new(env!("CARGO_BIN_EXE_ferret"));
        c.args([
            "prior",
            "train",
            "--generate",
            "30",
            "--house-seed",
            "9",
            "--embeddings",
            s(&table),
            "--learned-folds",
            "3",
            "--learned-epochs",
            "10",
            "--knowledge",
            knowledge,
            "--out",
            s(out),
        ])
        .env_remove("FERRET_EMBEDDINGS");
        if let Some(w) = wordnet {
            c.env("FERRET_WORDNET", w);
        }
        c.output().expect("the ferret binary runs")
    };
    let nowhere = dir.path().join("nowhere");
    let o = train("wordnet", &dir.path().join("x.json"), Some(&nowhere));
    assert!(
        !o.status.success() && text(&o).contains("nowhere"),
        "{}",
        text(&o)
    );
    let real = std::env::var_os("FERRET_WORDNET")
        .map(PathBuf::from)
        .or_else(|| Some(PathBuf::from("/usr/share/wordnet")))
        .filter(|d| d.join("index.noun").is_file());
    let Some(wordnet) = real else {
        eprintln!(
            "skipped: scripts/embeddings.sh install wordnet (or FERRET_WORDNET) to run the rest"
        );
        return;
    };
    let mut files = Vec::new();
    for k in ["wordnet", "wordnet-shuffled"] {
        let out = dir.path().join(format!("{k}.json"));
        let o = train(k, &out, Some(&wordnet));
        assert!(o.status.success(), "{}", text(&o));
        assert!(text(&o).contains(&format!("over tiny+{k}")), "{}", text(&o));
        let learned = &common::read_json(&out)["learned"];
        assert_eq!(learned["embedding"], format!("tiny+{k}"));
        assert_eq!(learned["dim"], 10);
        files.push(std::fs::read(&out).unwrap());
        ok(
            &[
                "eval",
                "--generate",
                "3",
                "--prior",
                s(&out),
                "--strategies",
                "model/prior,model/learned",
                "--out",
                s(&dir.path().join(format!("e-{k}"))),
            ],
            None,
        );
    }
    assert_ne!(files[0], files[1]);
}
