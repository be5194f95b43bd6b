//! End-to-end, against loopback servers: what `ferret eval` and `ferret calibrate` say about LLM
//! answers (classes, warnings, the fallback gate), and how a run ends when an endpoint is dead.

mod common;

use common::{ferret, s, text};

use std::path::Path;
use std::process::Command;
use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use serde_json::{Value, json};
use wiremock::matchers::method;
use wiremock::{Mock, MockServer, Request, Respond, ResponseTemplate};

/// A weak model: "10%" to almost everything, nothing readable about beds.
struct Collapsed {
    requests: Arc<AtomicUsize>,
}

fn prompt_of(req: &Request) -> String {
    let body: Value = serde_json::from_slice(&req.body).unwrap_or_default();
    body["messages"]
        .as_array()
        .map(|m| {
            m.iter()
                .filter_map(|x| x["content"].as_str())
                .collect::<Vec<_>>()
                .join("\n")
        })
        .unwrap_or_default()
}

fn reply(text: &str) -> ResponseTemplate {
    ResponseTemplate::new(200).set_body_json(json!({
        "id": "x", "object": "chat.completion", "created": 1, "model": "m",
        "choices": [{"index": 0, "message": {"role": "assistant", "content": text}, "finish_reason": "stop"}],
        "usage": {"prompt_tokens": 40, "completion_tokens": 2, "total_tokens": 42}
    }))
}

impl Respond for Collapsed {
    fn respond(&self, req: &Request) -> ResponseTemplate {
        self.requests.fetch_add(1, Ordering::SeqCst);
        let prompt = prompt_of(req);
        let question = prompt.rsplit("likelihood").next().unwrap_or_default();
        if question.contains(" bed ") {
            reply("It depends on the household.")
        } else {
            reply("10%")
        }
    }
}

/// An informed model: high for containers that usually hold small things.
struct Informed {
    requests: Arc<AtomicUsize>,
}

impl Respond for Informed {
    fn respond(&self, req: &Request) -> ResponseTemplate {
        self.requests.fetch_add(1, Ordering::SeqCst);
        let prompt = prompt_of(req);
        let q = prompt.rsplit("likelihood").next().unwrap_or_default();
        let p = if q.contains("counter") || q.contains("table") || q.contains("shelf") {
            60
        } else if q.contains("fridge") {
            5
        } else {
            20
        };
        reply(&format!("{p}%"))
    }
}

async fn server(r: impl Respond + 'static) -> MockServer {
    let s = MockServer::start().await;
    Mock::given(method("POST")).respond_with(r).mount(&s).await;
    s
}

fn config(dir: &Path, server: &MockServer, extra: &str) -> std::path::PathBuf {
    let path = dir.join("ferret.toml");
    std::fs::write(
        &path,
        format!(
            "[llm.mock]\nbase_url = \"{}/v1\"\nmodel = \"m\"\nretry_base_ms = 10\nmax_attempts = 2\n{extra}",
            server.uri()
        ),
    )
    .unwrap();
    path
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn weak_answers_are_classed_marked_and_gated() {
    let requests = Arc::new(AtomicUsize::new(0));
    let srv = server(Collapsed {
        requests: requests.clone(),
    })
    .await;
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), &srv, "");
    let out = dir.path().join("out");
    let cache = dir.path().join("c.sqlite");
    let run = |extra: &[&str]| {
        let mut args = vec![
            "eval",
            "--generate",
            "8",
            "--house-seed",
            "5",
            "--strategies",
            "optimistic+greedy,llm+model/p-minimal/mock",
            "--config",
            s(&cfg),
            "--llm-cache",
            s(&cache),
            "--out",
            s(&out),
        ];
        args.extend_from_slice(extra);
        ferret(&args)
    };
    let o = tokio::task::block_in_place(|| run(&[]));
    assert!(o.status.success(), "{}", text(&o));
    let all = text(&o);
    assert!(
        all.contains("WARNING: llm+model/p-minimal/mock"),
        "a loud warning: {all}"
    );
    let md = std::fs::read_to_string(out.join("summary.md")).unwrap();
    assert!(
        md.contains("| llm+model/p-minimal/mock ⚠ |"),
        "the row is marked: {md}"
    );
    let answers = md.split("## LLM answers").nth(1).expect("answers table");
    let row = answers
        .lines()
        .find(|l| l.starts_with("| llm+model/p-minimal/mock |"))
        .expect("a row for the strategy");
    let header: Vec<&str> = answers
        .lines()
        .find(|l| l.starts_with("| strategy |"))
        .expect("a header")
        .split('|')
        .map(str::trim)
        .collect();
    let cells: Vec<&str> = row.split('|').map(str::trim).collect();
    let cell = |name: &str| {
        let i = header.iter().position(|h| *h == name).expect(name);
        cells[i]
    };
    let answers_n: u64 = cell("answers").parse().unwrap();
    let number_only: u64 = cell("number-only").parse().unwrap();
    let none: u64 = cell("no-number").parse().unwrap();
    let reasked: u64 = cell("re-asked").parse().unwrap();
    let fell_back: u64 = cell("fell back")
        .split_whitespace()
        .next()
        .unwrap()
        .parse()
        .unwrap();
    assert!(none > 0 && number_only > 0, "{row}");
    assert_eq!(answers_n, number_only + none, "{row}");
    // Each unreadable bed answer was asked once more, and stayed unreadable.
    assert_eq!((reasked, fell_back), (none, none), "{row}");
    assert!(cell("most common p").starts_with("10.0 %"), "{row}");
    let tokens = std::fs::read_to_string(out.join("tokens.csv")).unwrap();
    assert!(tokens.lines().next().unwrap().contains("class_no_number"));
    assert!(tokens.contains("barely depend on the question"), "{tokens}");

    // The gate: the same run with --max-fallback-share 0 fails after writing its results.
    let sent = requests.load(Ordering::SeqCst);
    std::fs::remove_dir_all(&out).unwrap();
    let o = tokio::task::block_in_place(|| run(&["--max-fallback-share", "0"]));
    assert!(!o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("--max-fallback-share"), "{}", text(&o));
    assert!(out.join("trials.csv").exists());
    assert_eq!(
        requests.load(Ordering::SeqCst),
        sent,
        "all answers came from the cache"
    );
    // A generous gate passes.
    let o = tokio::task::block_in_place(|| run(&["--max-fallback-share", "1"]));
    assert!(o.status.success(), "{}", text(&o));
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_dead_endpoint_stops_the_run_quickly_or_is_left_out_with_keep_going() {
    let requests = Arc::new(AtomicUsize::new(0));
    struct Down(Arc<AtomicUsize>);
    impl Respond for Down {
        fn respond(&self, _: &Request) -> ResponseTemplate {
            self.0.fetch_add(1, Ordering::SeqCst);
            ResponseTemplate::new(502).set_body_string("<html>bad gateway</html>")
        }
    }
    let srv = server(Down(requests.clone())).await;
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), &srv, "concurrency = 1\n");
    let cache = dir.path().join("c.sqlite");
    let run = |out: &str, extra: &[&str]| {
        let out = dir.path().join(out);
        let mut args = vec![
            "eval",
            "--generate",
            "10",
            "--strategies",
            "optimistic+greedy,llm+model/p-context-a/mock",
            "--config",
            s(&cfg),
            "--llm-cache",
            s(&cache),
            "--out",
        ];
        let out = out.to_string_lossy().into_owned();
        args.push(&out);
        args.extend_from_slice(extra);
        ferret(&args)
    };
    let o = tokio::task::block_in_place(|| run("a", &[]));
    assert!(!o.status.success());
    let t = text(&o);
    assert!(t.contains("`mock`") && t.contains("502"), "{t}");
    assert!(t.contains("--keep-going"), "{t}");
    // One question's two attempts, not two per question of ten houses.
    assert_eq!(requests.load(Ordering::SeqCst), 2);

    let o = tokio::task::block_in_place(|| run("b", &["--keep-going"]));
    assert!(o.status.success(), "{}", text(&o));
    let trials = std::fs::read_to_string(dir.path().join("b/trials.csv")).unwrap();
    assert_eq!(trials.lines().count(), 1 + 10, "greedy only: {trials}");
    assert!(!trials.contains("llm+model"));
    assert_eq!(requests.load(Ordering::SeqCst), 4);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn calibrate_scores_sources_and_asks_each_question_once() {
    let requests = Arc::new(AtomicUsize::new(0));
    let srv = server(Informed {
        requests: requests.clone(),
    })
    .await;
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), &srv, "");
    let out = dir.path().join("cal");
    let run = || {
        ferret(&[
            "calibrate",
            "--generate",
            "6",
            "--house-seed",
            "3",
            "--sources",
            "model/uniform,model/prior,llm+model/p-minimal/mock",
            "--config",
            s(&cfg),
            "--llm-cache",
            s(&dir.path().join("c.sqlite")),
            "--out",
            s(&out),
        ])
    };
    let o = tokio::task::block_in_place(run);
    assert!(o.status.success(), "{}", text(&o));
    let sent = requests.load(Ordering::SeqCst);
    assert!(sent > 0);
    let csv = std::fs::read_to_string(out.join("calibration.csv")).unwrap();
    let rows: Vec<Vec<String>> = csv
        .lines()
        .skip(1)
        .map(|l| l.split(',').map(String::from).collect())
        .collect();
    assert_eq!(
        csv.lines().next().unwrap(),
        "source,pairs,positives,brier,log_loss,auroc,mean_p_pos,mean_p_neg"
    );
    assert_eq!(rows.len(), 3);
    // The same pairs for every source.
    assert!(
        rows.iter()
            .all(|r| r[1] == rows[0][1] && r[2] == rows[0][2])
    );
    let auroc = |i: usize| rows[i][5].parse::<f64>().unwrap();
    assert_eq!(auroc(0), 0.5, "a constant source ranks nothing");
    assert!(
        auroc(1) > 0.6,
        "the trained prior ranks holders higher: {csv}"
    );
    for ext in ["png", "svg"] {
        assert!(
            std::fs::metadata(out.join(format!("reliability.{ext}")))
                .unwrap()
                .len()
                > 1000
        );
    }
    assert!(
        std::fs::read_to_string(out.join("calibration.md"))
            .unwrap()
            .contains("| model/uniform |")
    );
    // A second run answers from the cache.
    let o = tokio::task::block_in_place(run);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(requests.load(Ordering::SeqCst), sent);
}

/// A model that knows where small things are kept: Yes for counters, tables, shelves, desks and
/// dressers, No elsewhere; for a listing, the first such place's letter.
struct Knowing {
    requests: Arc<AtomicUsize>,
}

const KEPT: [&str; 5] = ["counter", "table", "shelv", "desk", "dresser"];

impl Respond for Knowing {
    fn respond(&self, req: &Request) -> ResponseTemplate {
        self.requests.fetch_add(1, Ordering::SeqCst);
        let prompt = prompt_of(req);
        if prompt.contains("Answer Yes or No") {
            let q = prompt.rsplit("found in or on").next().unwrap_or_default();
            return reply(if KEPT.iter().any(|k| q.contains(k)) {
                "Yes"
            } else {
                "No"
            });
        }
        let letter = prompt
            .lines()
            .filter(|l| l.as_bytes().get(1) == Some(&b'.'))
            .find(|l| KEPT.iter().any(|k| l.contains(k)))
            .map_or("A", |l| &l[..1])
            .to_string();
        reply(&letter)
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn fusion_is_fitted_by_calibrate_and_planned_over_by_eval() {
    let requests = Arc::new(AtomicUsize::new(0));
    let srv = server(Knowing {
        requests: requests.clone(),
    })
    .await;
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), &srv, "");
    let cache = dir.path().join("c.sqlite");
    let fusion = dir.path().join("fusion.json");
    let common = |cmd: &'static str| -> Vec<String> {
        [cmd, "--config", s(&cfg), "--llm-cache", s(&cache)]
            .iter()
            .map(|a| a.to_string())
            .collect()
    };
    let run = |args: Vec<String>| {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        tokio::task::block_in_place(|| ferret(&args))
    };
    // Fitted on training houses (generated with one seed) ...
    let mut fit = common("calibrate");
    fit.extend(
        [
            "--generate",
            "16",
            "--house-seed",
            "11",
            "--sources",
            "llm+model/p-yesno/mock,llm+model/p-choice/mock",
            "--fit-fusion",
            s(&fusion),
            "--out",
            s(&dir.path().join("fit")),
        ]
        .map(String::from),
    );
    let o = run(fit);
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("Fusion with the prior or the learned likelihood"),
        "{}",
        text(&o)
    );
    let file: Value = serde_json::from_str(&std::fs::read_to_string(&fusion).unwrap()).unwrap();
    let fits = file["fits"].as_array().unwrap();
    let sources: Vec<&str> = fits.iter().map(|f| f["source"].as_str().unwrap()).collect();
    assert_eq!(sources, ["p-yesno/mock", "p-choice/mock"]);
    for f in fits {
        assert!(f["pairs"].as_u64().unwrap() > 50, "{f}");
        assert!(f["weights"]["b"].as_f64().unwrap().is_finite(), "{f}");
        assert!(
            f["trained_on"].as_str().unwrap().contains("16 houses"),
            "{f}"
        );
    }
    // ... used on other houses: eval plans over the fused source, calibrate scores it.
    let out = dir.path().join("eval");
    let mut eval = common("eval");
    eval.extend(
        [
            "--generate",
            "6",
            "--house-seed",
            "12",
            "--strategies",
            "model/prior,fused/p-yesno/mock,fused/p-choice/mock/exact",
            "--fusion",
            s(&fusion),
            "--out",
            s(&out),
        ]
        .map(String::from),
    );
    let o = run(eval.clone());
    assert!(o.status.success(), "{}", text(&o));
    let trials = std::fs::read_to_string(out.join("trials.csv")).unwrap();
    assert_eq!(
        trials
            .lines()
            .filter(|l| l.contains(",fused/p-yesno/mock,"))
            .count(),
        6,
        "{trials}"
    );
    let tokens = std::fs::read_to_string(out.join("tokens.csv")).unwrap();
    assert!(tokens.contains("fused/p-choice/mock/exact"), "{tokens}");
    // select replays the fused strategies from the same cache, asking nothing new.
    let asked = requests.load(Ordering::SeqCst);
    let mut select = common("select");
    select.extend(
        [
            "--trials",
            s(&out),
            "--deployments",
            "20",
            "--trials-per-deployment",
            "4",
            "--fusion",
            s(&fusion),
            "--out",
            s(&dir.path().join("select")),
        ]
        .map(String::from),
    );
    let o = run(select);
    assert!(o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("fused/p-yesno/mock"), "{}", text(&o));
    assert_eq!(requests.load(Ordering::SeqCst), asked);
    let mut cal = common("calibrate");
    cal.extend(
        [
            "--generate",
            "6",
            "--house-seed",
            "12",
            "--sources",
            "model/prior,fused/p-yesno/mock",
            "--fusion",
            s(&fusion),
            "--out",
            s(&dir.path().join("cal")),
        ]
        .map(String::from),
    );
    let o = run(cal);
    assert!(o.status.success(), "{}", text(&o));
    // Without the fusion file the fused strategy is refused with what to do.
    let without: Vec<String> = eval
        .iter()
        .filter(|a| *a != "--fusion" && **a != s(&fusion))
        .cloned()
        .collect();
    let o = run(without);
    assert!(!o.status.success());
    assert!(text(&o).contains("--fit-fusion"), "{}", text(&o));
    // --fit-fusion without an LLM source to fit.
    let mut nothing = common("calibrate");
    nothing.extend(
        [
            "--generate",
            "2",
            "--sources",
            "model/prior",
            "--fit-fusion",
            s(&dir.path().join("f2.json")),
            "--out",
            s(&dir.path().join("c2")),
        ]
        .map(String::from),
    );
    let o = run(nothing);
    assert!(!o.status.success());
    assert!(text(&o).contains("names no llm+model"), "{}", text(&o));
    assert!(!dir.path().join("f2.json").exists());
}

/// With a prior that has a learned part, `calibrate --fit-fusion` also fuses each LLM source (and
/// the control) with `model/learned`, and `fused-learned/...` plans over those fits in eval and
/// select from the same cached answers; with a prior of counts only it is refused, saying why.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_llm_is_fused_with_the_learned_likelihood_as_with_the_prior() {
    let requests = Arc::new(AtomicUsize::new(0));
    let srv = server(Knowing {
        requests: requests.clone(),
    })
    .await;
    let dir = tempfile::tempdir().unwrap();
    let cfg = config(dir.path(), &srv, "");
    let cache = dir.path().join("c.sqlite");
    let table = common::word_table(dir.path());
    let (learned, counts) = (
        dir.path().join("learned.json"),
        dir.path().join("counts.json"),
    );
    let fusion = dir.path().join("fusion.json");
    let run = |args: &[&str]| tokio::task::block_in_place(|| ferret(args));
    let ok = |args: &[&str]| {
        let o = run(args);
        assert!(o.status.success(), "ferret {args:?}: {}", text(&o));
        text(&o)
    };
    let train = ["prior", "train", "--generate", "30", "--house-seed", "9"];
    ok(&[
        &train[..],
        &["--embeddings", s(&table), "--learned-folds", "3"],
        &["--learned-epochs", "10", "--out", s(&learned)],
    ]
    .concat());
    ok(&[&train[..], &["--out", s(&counts)]].concat());
    let llm = ["--config", s(&cfg), "--llm-cache", s(&cache)];
    // Fitted on other houses, the prior's unseen view with 5 folds; the learned one with its 3.
    let said = ok(&[
        &["calibrate", "--generate", "16", "--house-seed", "11"][..],
        &llm,
        &["--prior", s(&learned), "--fit-fusion", s(&fusion)],
        &["--sources", "llm+model/p-yesno/mock,model/noise"],
        &["--out", s(&dir.path().join("fit"))],
    ]
    .concat());
    assert!(said.contains("| fused-learned/p-yesno/mock |"), "{said}");
    let file: Value = serde_json::from_str(&std::fs::read_to_string(&fusion).unwrap()).unwrap();
    let fits = file["fits"].as_array().unwrap();
    let named: Vec<(&str, &str)> = fits
        .iter()
        .map(|f| {
            (
                f["base"].as_str().unwrap_or("prior"),
                f["source"].as_str().unwrap(),
            )
        })
        .collect();
    assert_eq!(
        named,
        [
            ("prior", "p-yesno/mock"),
            ("prior", "noise"),
            ("learned", "p-yesno/mock"),
            ("learned", "noise")
        ]
    );
    assert!(
        fits[0]["trained_on"]
            .as_str()
            .unwrap()
            .ends_with("fold of 5")
    );
    assert!(
        fits[2]["trained_on"]
            .as_str()
            .unwrap()
            .ends_with("fold of 3")
    );
    // Fused with another base, the same answers get other weights.
    assert_ne!(fits[0]["weights"], fits[2]["weights"], "{file}");
    // Where the prior has no evidence, the model that knows gets more weight than noise.
    let d = |i: usize| fits[i]["weights"]["d"].as_f64().unwrap();
    assert!(d(2) > d(3), "{file}");

    let eval = |strategies: &str, prior: &Path, out: &str| {
        run(&[
            &["eval", "--generate", "6", "--house-seed", "12"][..],
            &llm,
            &["--prior", s(prior), "--fusion", s(&fusion)],
            &[
                "--strategies",
                strategies,
                "--out",
                s(&dir.path().join(out)),
            ],
        ]
        .concat())
    };
    let o = eval(
        "fused/p-yesno/mock,fused-learned/p-yesno/mock,fused-learned/noise/exact",
        &learned,
        "eval",
    );
    assert!(o.status.success(), "{}", text(&o));
    let trials = std::fs::read_to_string(dir.path().join("eval/trials.csv")).unwrap();
    for strategy in ["fused-learned/p-yesno/mock", "fused-learned/noise/exact"] {
        assert_eq!(
            trials
                .lines()
                .filter(|l| l.contains(&format!(",{strategy},")))
                .count(),
            6,
            "{trials}"
        );
    }
    // fused-learned asks the LLM what fused asks: alone, it finds every answer in the cache.
    let asked = requests.load(Ordering::SeqCst);
    let o = eval("fused-learned/p-yesno/mock", &learned, "again");
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(requests.load(Ordering::SeqCst), asked);
    let o = run(&[
        &["select", "--trials", s(&dir.path().join("eval"))][..],
        &llm,
        &["--fusion", s(&fusion), "--deployments", "10"],
        &[
            "--trials-per-deployment",
            "4",
            "--out",
            s(&dir.path().join("sel")),
        ],
    ]
    .concat());
    assert!(o.status.success(), "{}", text(&o));
    assert!(
        text(&o).contains("fused-learned/p-yesno/mock"),
        "{}",
        text(&o)
    );
    assert_eq!(requests.load(Ordering::SeqCst), asked);

    // A prior of counts only: its fit (another prior's) is refused, and a file fitted with it
    // holds no learned fits, which eval names.
    let o = eval("fused-learned/p-yesno/mock", &counts, "counts");
    assert!(!o.status.success());
    assert!(text(&o).contains("made with another prior"), "{}", text(&o));
    let counts_fusion = dir.path().join("counts-fusion.json");
    ok(&[
        &["calibrate", "--generate", "16", "--house-seed", "11"][..],
        &llm,
        &["--prior", s(&counts), "--fit-fusion", s(&counts_fusion)],
        &[
            "--sources",
            "llm+model/p-yesno/mock",
            "--out",
            s(&dir.path().join("fit2")),
        ],
    ]
    .concat());
    let o = run(&[
        &["eval", "--generate", "2", "--house-seed", "12"][..],
        &llm,
        &["--prior", s(&counts), "--fusion", s(&counts_fusion)],
        &["--strategies", "fused-learned/p-yesno/mock"],
        &["--out", s(&dir.path().join("counts2"))],
    ]
    .concat());
    assert!(!o.status.success());
    let said = text(&o);
    assert!(
        said.contains("no fit for fused-learned/p-yesno/mock")
            && said.contains("fused/p-yesno/mock")
            && said.contains("prior train --embeddings"),
        "{said}"
    );
}

/// The real-model lane's configuration (written by `scripts/real-llm.sh config`) is one ferret
/// reads: four endpoints over one server, sharing one cache id, in the four answer modes.
#[test]
fn the_real_model_lane_writes_a_config_ferret_reads() {
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../scripts/real-llm.sh");
    // The config the lane writes into a fresh directory with these environment settings.
    let lane_config = |env: &[(&str, &str)]| {
        let dir = tempfile::tempdir().unwrap();
        let o = Command::new("bash")
            .arg(&script)
            .arg("config")
            .env("FERRET_LANE_OUT", dir.path())
            .envs(env.iter().copied())
            .output()
            .expect("bash runs");
        assert!(o.status.success(), "{}", text(&o));
        let toml = std::fs::read_to_string(dir.path().join("ferret.toml")).unwrap();
        (dir, toml)
    };
    let (dir, toml) = lane_config(&[("FERRET_LANE_PORT", "18999")]);
    assert_eq!(
        toml.matches("cache_id = \"qwen2.5-coder-1.5b-instruct-q4_k_m\"")
            .count(),
        4
    );
    assert!(
        toml.contains("base_url = \"http://127.0.0.1:18999/v1\""),
        "{toml}"
    );
    // llama.cpp's server (the default) takes OpenAI's json_schema form; llama-cpp-python's
    // server only reads a schema under json_object.
    assert_eq!(
        toml.matches("answer_format = \"json_schema\"").count(),
        2,
        "{toml}"
    );
    assert_eq!(
        toml.matches("answer_format = \"json_object\"").count(),
        0,
        "{toml}"
    );
    let (_, python) = lane_config(&[("FERRET_LANE_SERVER", "llama-cpp-python")]);
    assert_eq!(
        python.matches("answer_format = \"json_object\"").count(),
        2,
        "{python}"
    );
    assert_eq!(
        python.matches("answer_format = \"json_schema\"").count(),
        0,
        "{python}"
    );
    let o = ferret(&[
        "llm",
        "list",
        "--config",
        s(&dir.path().join("ferret.toml")),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let listed = text(&o);
    for name in ["qwen ", "qwen-logprobs", "qwen-json ", "qwen-json-logprobs"] {
        assert!(listed.contains(name), "{name} missing: {listed}");
    }
    // The lane refuses what it does not know, without starting anything.
    let o = Command::new("bash")
        .arg(&script)
        .arg("nonsense")
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(2));
}
