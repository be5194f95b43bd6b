//! `ferret serve` as a robot meets it: the real binary on 127.0.0.1, driven by the Python robot
//! client of examples/ and by raw HTTP, killed with SIGKILL and restarted.

mod common;

use std::path::{Path, PathBuf};
use std::process::Command;

use common::{Server, ferret, post, s, text};
use serde_json::{Value, json};

const TARGETS: &str = "Blanket,CellPhone,RemoteControl,Pillow,Wallet";
const STRATEGIES: &str = "optimistic+greedy,model/uniform,model/uniform/k2";

fn repo() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

fn apartment() -> PathBuf {
    repo().join("examples/apartment/scene.yaml")
}

/// A running `ferret serve`; killed (SIGKILL) when dropped.
impl Server {
    fn start(db: &Path) -> Server {
        Self::start_with(db, STRATEGIES, &[])
    }

    /// `ferret serve` on the apartment with these strategies and further arguments.
    fn start_with(db: &Path, strategies: &str, extra: &[&str]) -> Server {
        let scene = apartment();
        let mut args = vec![
            "--scene",
            s(&scene),
            "--strategies",
            strategies,
            "--listen",
            "127.0.0.1:0",
            "--db",
            s(db),
        ];
        args.extend_from_slice(extra);
        Server::spawn(&args, &[])
    }
}

fn get(url: &str) -> Value {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async { reqwest::get(url).await.unwrap().json().await.unwrap() })
}

/// (strategy, cost) per trial of `ferret deploy` on the apartment.
fn deploy_costs(dir: &Path, seed: &str) -> Vec<(String, f64)> {
    let out = dir.join("deploy");
    let o = ferret(&[
        "deploy",
        "--houses",
        s(&apartment()),
        "--find",
        TARGETS,
        "--strategies",
        STRATEGIES,
        "--seed",
        seed,
        "--out",
        s(&out),
    ]);
    assert!(o.status.success(), "{}", text(&o));
    let mut reader = csv::Reader::from_path(out.join("deploy.csv")).unwrap();
    let headers = reader.headers().unwrap().clone();
    let col = |name: &str| headers.iter().position(|h| h == name).unwrap();
    let (chosen, cost) = (col("chosen"), col("cost_m"));
    reader
        .records()
        .map(|r| {
            let r = r.unwrap();
            (r[chosen].to_string(), r[cost].parse().unwrap())
        })
        .collect()
}

/// A type to `--find` that no house holds is refused before any trial, naming the type meant.
#[test]
fn deploy_refuses_a_target_no_house_holds_with_the_name_meant() {
    let dir = tempfile::tempdir().unwrap();
    let o = ferret(&[
        "deploy",
        "--houses",
        s(&apartment()),
        "--find",
        "Blanket,wallet",
        "--strategies",
        STRATEGIES,
        "--out",
        s(&dir.path().join("deploy")),
    ]);
    assert!(!o.status.success(), "{}", text(&o));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains(r#"--find: unknown target "wallet": did you mean "Wallet"?"#),
        "{err}"
    );
    assert!(!dir.path().join("deploy/deploy.csv").exists());
}

#[test]
fn the_paper_targets_through_the_python_client_cost_what_deploy_says() {
    let dir = tempfile::tempdir().unwrap();
    let expected = deploy_costs(dir.path(), "4");
    assert_eq!(expected.len(), 5);
    let server = Server::start(&dir.path().join("serve.sqlite"));
    let o = Command::new("python3")
        .arg(repo().join("examples/robot_client.py"))
        .args([
            "--url",
            &server.url,
            "--scene",
            "apartment",
            "--targets",
            TARGETS,
        ])
        .args(["--strategies", STRATEGIES, "--seed", "4", "--json"])
        .env_remove("FERRET_SERVE_TOKEN")
        .output()
        .expect("python3 runs");
    assert!(o.status.success(), "{}", text(&o));
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    let trials = report["trials"].as_array().unwrap();
    assert_eq!(trials.len(), 5);
    for (k, (t, (strategy, cost))) in trials.iter().zip(&expected).enumerate() {
        assert_eq!(t["strategy"].as_str().unwrap(), strategy, "trial {k}");
        let api = t["cost_m"].as_f64().unwrap();
        assert!(
            (api - cost).abs() < 0.005,
            "trial {k}: API {api} vs deploy {cost}"
        );
    }
    server.kill();
}

/// Three `examples/robot_client.py` processes, one per robot of a team (`--robot`, `--team`),
/// search the five targets together in one deployment against a real `ferret serve`: each
/// trial holds the three robots, no container is searched twice, every robot's searches are
/// its own in the trial, and more than one robot searched in some trial.
#[test]
fn three_python_clients_search_as_one_team() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("serve.sqlite"));
    let (st, dep) = post(&format!("{}/deployments", server.url), json!({"seed": 4}));
    assert_eq!(st, 201, "{dep}");
    let id = dep["id"].as_i64().unwrap().to_string();
    let team = ["kitchen-bot", "hall-bot", "upstairs-bot"];
    let robots: Vec<_> = team
        .iter()
        .map(|me| {
            Command::new("python3")
                .arg(repo().join("examples/robot_client.py"))
                .args(["--url", &server.url, "--scene", "apartment"])
                .args(["--deployment", &id, "--targets", TARGETS, "--json"])
                .args(["--robot", me, "--team", &team.join(",")])
                // As robots take time to drive: the team's searches interleave.
                .args(["--pace", "0.2"])
                .env_remove("FERRET_SERVE_TOKEN")
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped())
                .spawn()
                .expect("python3 runs")
        })
        .collect();
    let mut mine: Vec<(String, i64, Vec<String>)> = Vec::new();
    for (me, child) in team.iter().zip(robots) {
        let o = child.wait_with_output().unwrap();
        assert!(o.status.success(), "{me}: {}", text(&o));
        let report: Value = serde_json::from_slice(&o.stdout).unwrap();
        let trials = report["trials"].as_array().unwrap();
        assert_eq!(trials.len(), 5, "{me}: {report}");
        for t in trials {
            let searched = t["searched"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_str().unwrap().to_string())
                .collect();
            mine.push((me.to_string(), t["trial"].as_i64().unwrap(), searched));
        }
    }
    let state = get(&format!("{}/deployments/{id}", server.url));
    let trials = state["trials"].as_array().unwrap();
    assert_eq!(trials.len(), 5, "one trial per target: {state}");
    let mut several = 0;
    for t in trials {
        assert_eq!(t["status"], "done", "{state}");
        let trial = get(&format!("{}/trials/{}", server.url, t["trial"]));
        let searched: Vec<&str> = trial["searched"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| c.as_str().unwrap())
            .collect();
        let unique: std::collections::BTreeSet<&&str> = searched.iter().collect();
        assert_eq!(unique.len(), searched.len(), "searched twice: {trial}");
        let robots = trial["robots"].as_array().unwrap();
        let ids: Vec<&str> = robots.iter().map(|r| r["id"].as_str().unwrap()).collect();
        assert_eq!(ids, team, "{trial}");
        let active = robots
            .iter()
            .filter(|r| !r["searched"].as_array().unwrap().is_empty())
            .count();
        several += usize::from(active > 1);
        for r in robots {
            let theirs: Vec<String> = r["searched"]
                .as_array()
                .unwrap()
                .iter()
                .map(|c| c.as_str().unwrap().to_string())
                .collect();
            let client = mine
                .iter()
                .find(|(me, trial, _)| {
                    me == r["id"].as_str().unwrap() && Some(*trial) == t["trial"].as_i64()
                })
                .map(|(_, _, s)| s.clone())
                .unwrap();
            assert_eq!(theirs, client, "{trial}");
        }
    }
    assert!(
        several > 0,
        "no trial was searched by more than one robot: {state}"
    );
    server.kill();
}

/// A trial left open on the server (a robot stopped mid-search) is given up by the Python
/// client's `--abandon-open`: it reads `abandoned`, and the client's own trials follow it.
#[test]
fn the_python_client_abandons_an_open_trial() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("serve.sqlite"));
    let (st, dep) = post(&format!("{}/deployments", server.url), json!({"seed": 4}));
    assert_eq!(st, 201, "{dep}");
    let id = dep["id"].as_i64().unwrap();
    let (st, open) = post(
        &format!("{}/deployments/{id}/trials", server.url),
        json!({"scene": "apartment", "target": "Wallet"}),
    );
    assert_eq!(st, 201, "{open}");
    let o = Command::new("python3")
        .arg(repo().join("examples/robot_client.py"))
        .args(["--url", &server.url, "--scene", "apartment"])
        .args(["--deployment", &id.to_string(), "--abandon-open"])
        .args(["--targets", "Blanket", "--json"])
        .env_remove("FERRET_SERVE_TOKEN")
        .output()
        .expect("python3 runs");
    assert!(o.status.success(), "{}", text(&o));
    let report: Value = serde_json::from_slice(&o.stdout).unwrap();
    let trials = report["trials"].as_array().unwrap();
    assert_eq!(trials.len(), 2, "{report}");
    assert_eq!(trials[0]["trial"], open["trial"], "{report}");
    assert_eq!(trials[0]["status"], "abandoned", "{report}");
    assert_eq!(trials[1]["status"], "done", "{report}");
    let state = get(&format!("{}/deployments/{id}", server.url));
    let statuses: Vec<&str> = state["trials"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t["status"].as_str().unwrap())
        .collect();
    assert_eq!(statuses, ["abandoned", "done"], "{state}");
    server.kill();
}

/// Runs the five targets through HTTP; `kill_at` = (trial index, observations) after which the
/// server is killed with SIGKILL and restarted on the same database.
fn run_through_http(db: &Path, kill_at: Option<(usize, usize)>) -> Vec<(String, f64, Vec<String>)> {
    let mut server = Server::start(db);
    let scene = get(&format!("{}/scenes/apartment", server.url));
    let contents = |id: &str| -> Vec<String> {
        scene["containers"]
            .as_array()
            .unwrap()
            .iter()
            .find(|c| c["id"] == id)
            .unwrap()["contents"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap().to_string())
            .collect()
    };
    let (st, dep) = post(&format!("{}/deployments", server.url), json!({"seed": 4}));
    assert_eq!(st, 201, "{dep}");
    let id = dep["id"].as_i64().unwrap();
    let mut out = Vec::new();
    for (k, target) in TARGETS.split(',').enumerate() {
        let (st, mut reply) = post(
            &format!("{}/deployments/{id}/trials", server.url),
            json!({"scene": "apartment", "target": target}),
        );
        assert_eq!(st, 201, "{reply}");
        let trial = reply["trial"].as_i64().unwrap();
        let mut observed = 0;
        while reply["status"] == "searching" {
            if kill_at == Some((k, observed)) {
                let db = db.to_path_buf();
                server.kill();
                server = Server::start(&db);
                let again = get(&format!("{}/trials/{trial}", server.url));
                assert_eq!(
                    again["next"], reply["next"],
                    "the next container survives SIGKILL"
                );
                reply = again;
            }
            let next = reply["next"]["container"].as_str().unwrap().to_string();
            let seen = contents(&next);
            let found = seen.iter().any(|o| o == target);
            let (st, r) = post(
                &format!("{}/trials/{trial}/observations", server.url),
                json!({"request_id": format!("{trial}-{observed}"), "container": next, "found": found, "objects": seen}),
            );
            assert_eq!(st, 200, "{r}");
            reply = r;
            observed += 1;
        }
        let searched = reply["searched"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap().to_string())
            .collect();
        out.push((
            reply["strategy"].as_str().unwrap().to_string(),
            reply["cost_m"].as_f64().unwrap(),
            searched,
        ));
    }
    server.kill();
    out
}

#[test]
fn a_server_killed_mid_trial_resumes_with_identical_results() {
    let dir = tempfile::tempdir().unwrap();
    let reference = run_through_http(&dir.path().join("reference.sqlite"), None);
    let killed = run_through_http(&dir.path().join("killed.sqlite"), Some((2, 1)));
    assert_eq!(killed, reference);
    // Killed before any observation of a trial, too.
    let killed = run_through_http(&dir.path().join("killed0.sqlite"), Some((3, 0)));
    assert_eq!(killed, reference);
}

#[test]
fn scene_check_reports_the_apartment_and_refuses_a_closed_door() {
    let o = ferret(&["scene", "check", s(&apartment())]);
    assert!(o.status.success(), "{}", text(&o));
    let out = text(&o);
    assert!(
        out.contains("9 containers") && out.contains("4 rooms"),
        "{out}"
    );
    // The same scene without a map and without doors: walls enclose every room.
    let dir = tempfile::tempdir().unwrap();
    let yaml = std::fs::read_to_string(apartment()).unwrap();
    let closed: String = yaml
        .lines()
        .filter(|l| !l.trim_start().starts_with("map:"))
        .collect::<Vec<_>>()
        .join("\n");
    let closed = match closed.find("\ndoors:") {
        Some(i) => {
            let rest = &closed[i + 1..];
            let end = rest
                .find("\ncontainers:")
                .map(|j| i + 1 + j)
                .unwrap_or(closed.len());
            format!("{}{}", &closed[..i], &closed[end..])
        }
        None => closed,
    };
    let file = dir.path().join("closed.yaml");
    std::fs::write(&file, closed).unwrap();
    let o = ferret(&["scene", "check", s(&file)]);
    assert!(!o.status.success(), "{}", text(&o));
    assert!(text(&o).contains("cannot be reached"), "{}", text(&o));
}

/// An LLM on 127.0.0.1 that says Yes for sofas, tables and beds and No elsewhere (P-YESNO).
fn yes_no_llm(rt: &tokio::runtime::Runtime) -> wiremock::MockServer {
    use wiremock::matchers::method;
    use wiremock::{Mock, MockServer, Request, ResponseTemplate};
    rt.block_on(async {
        let server = MockServer::start().await;
        Mock::given(method("POST"))
            .respond_with(|req: &Request| {
                let body: Value = serde_json::from_slice(&req.body).unwrap_or_default();
                let q = body["messages"][0]["content"].as_str().unwrap_or_default().to_string();
                let q = q.rsplit("in or on").next().unwrap_or_default();
                let yes = ["sofa", "table", "bed "].iter().any(|k| q.contains(k));
                ResponseTemplate::new(200).set_body_json(json!({
                    "id": "x", "object": "chat.completion", "created": 1, "model": "m",
                    "choices": [{"index": 0, "finish_reason": "stop",
                        "message": {"role": "assistant", "content": if yes { "Yes" } else { "No" }}}],
                    "usage": {"prompt_tokens": 30, "completion_tokens": 1, "total_tokens": 31}
                }))
            })
            .mount(&server)
            .await;
        server
    })
}

#[test]
fn a_fused_strategy_is_served_with_its_fusion_file() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let llm = yes_no_llm(&rt);
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("ferret.toml");
    std::fs::write(
        &config,
        format!(
            "[llm.mock]\nbase_url = \"{}/v1\"\nmodel = \"m\"\nretry_base_ms = 10\n",
            llm.uri()
        ),
    )
    .unwrap();
    let cache = dir.path().join("c.sqlite");
    let fusion = dir.path().join("fusion.json");
    let llm_args = ["--config", s(&config), "--llm-cache", s(&cache)];
    let fit_out = dir.path().join("fit");
    let mut fit = vec![
        "calibrate",
        "--generate",
        "10",
        "--sources",
        "llm+model/p-yesno/mock",
        "--fit-fusion",
        s(&fusion),
        "--out",
        s(&fit_out),
    ];
    fit.extend(llm_args);
    let o = ferret(&fit);
    assert!(o.status.success(), "{}", text(&o));
    let mut extra = vec!["--fusion", s(&fusion)];
    extra.extend(llm_args);
    let server = Server::start_with(
        &dir.path().join("serve.sqlite"),
        "fused/p-yesno/mock",
        &extra,
    );
    let (st, dep) = post(&format!("{}/deployments", server.url), json!({"seed": 1}));
    assert_eq!(st, 201, "{dep}");
    let id = dep["id"].as_i64().unwrap();
    let (st, reply) = post(
        &format!("{}/deployments/{id}/trials", server.url),
        json!({"scene": "apartment", "target": "RemoteControl"}),
    );
    assert_eq!(st, 201, "{reply}");
    assert_eq!(reply["strategy"], "fused/p-yesno/mock", "{reply}");
    assert!(reply["next"]["container"].is_string(), "{reply}");
    server.kill();
    // Without the fusion file the server refuses the strategy at start, saying what to do.
    let o = ferret(&[
        "serve",
        "--scene",
        s(&apartment()),
        "--strategies",
        "fused/p-yesno/mock",
        "--listen",
        "127.0.0.1:0",
        "--db",
        s(&dir.path().join("other.sqlite")),
        "--config",
        s(&config),
    ]);
    assert!(!o.status.success());
    assert!(text(&o).contains("--fit-fusion"), "{}", text(&o));
}

/// An LLM on 127.0.0.1 that answers P-YESNO while `up`, else 500; counts what it is asked.
fn flaky_llm(
    rt: &tokio::runtime::Runtime,
    up: std::sync::Arc<std::sync::atomic::AtomicBool>,
) -> wiremock::MockServer {
    use std::sync::atomic::Ordering;
    use wiremock::matchers::method;
    use wiremock::{Mock, MockServer, Request, ResponseTemplate};
    rt.block_on(async {
        let server = MockServer::start().await;
        Mock::given(method("POST"))
            .respond_with(move |_: &Request| {
                if !up.load(Ordering::SeqCst) {
                    return ResponseTemplate::new(500).set_body_string("model unloaded");
                }
                ResponseTemplate::new(200).set_body_json(json!({
                    "id": "x", "object": "chat.completion", "created": 1, "model": "m",
                    "choices": [{"index": 0, "finish_reason": "stop",
                        "message": {"role": "assistant", "content": "No"}}],
                    "usage": {"prompt_tokens": 30, "completion_tokens": 1, "total_tokens": 31}
                }))
            })
            .mount(&server)
            .await;
        server
    })
}

/// One failure of an LLM endpoint made every later trial of its strategies a 503 until the
/// server was restarted. Now the endpoint is not asked for `--llm-retry-after` seconds (503 at
/// once, nothing sent), and the first trial after the pause finds it back.
#[test]
fn serve_asks_a_failed_llm_endpoint_again_after_the_pause() {
    use std::sync::atomic::{AtomicBool, Ordering};
    use std::time::{Duration, Instant};
    let rt = tokio::runtime::Runtime::new().unwrap();
    let up = std::sync::Arc::new(AtomicBool::new(false));
    let llm = flaky_llm(&rt, up.clone());
    let asked = || {
        rt.block_on(llm.received_requests())
            .unwrap_or_default()
            .len()
    };
    let dir = tempfile::tempdir().unwrap();
    let config = dir.path().join("ferret.toml");
    std::fs::write(
        &config,
        format!(
            "[llm.mock]\nbase_url = \"{}/v1\"\nmodel = \"m\"\nmax_attempts = 1\nretry_base_ms = 10\n",
            llm.uri()
        ),
    )
    .unwrap();
    let cache = dir.path().join("c.sqlite");
    let server = Server::start_with(
        &dir.path().join("serve.sqlite"),
        "llm+model/p-yesno/mock",
        &[
            "--config",
            s(&config),
            "--llm-cache",
            s(&cache),
            "--llm-retry-after",
            "2",
        ],
    );
    let (st, dep) = post(&format!("{}/deployments", server.url), json!({}));
    assert_eq!(st, 201, "{dep}");
    let trials = format!("{}/deployments/{}/trials", server.url, dep["id"]);
    let start = json!({"scene": "apartment", "target": "RemoteControl"});
    let (st, reply) = post(&trials, start.clone());
    assert_eq!(st, 503, "{reply}");
    let failed_at = Instant::now();
    let before = asked();
    assert!(before > 0);
    // Open: refused at once without asking.
    let (st, reply) = post(&trials, start.clone());
    assert_eq!(st, 503, "{reply}");
    assert_eq!(asked(), before, "a paused endpoint was asked");
    up.store(true, Ordering::SeqCst);
    let (st, _) = post(&trials, start.clone());
    if failed_at.elapsed() < Duration::from_millis(1800) {
        assert_eq!(st, 503, "still paused");
    }
    std::thread::sleep(Duration::from_millis(2200).saturating_sub(failed_at.elapsed()));
    let (st, reply) = post(&trials, start);
    assert_eq!(st, 201, "the endpoint is back: {reply}");
    assert!(asked() > before);
    assert_eq!(reply["strategy"], "llm+model/p-yesno/mock");
}

/// A fleet of two `ferret serve` replicas on one PostgreSQL database: one is killed with SIGKILL
/// in the middle of a burst of robots, which carry on against the other, retrying with their
/// request ids. Every acknowledged observation is stored exactly once, every deployment holds
/// exactly the trials its robot started, and no robot gets an error. Needs a PostgreSQL server
/// (`FERRET_TEST_POSTGRES`; `scripts/postgres.sh start` starts a throwaway one).
#[test]
fn a_replica_killed_mid_burst_loses_and_doubles_no_acknowledged_observation() {
    let Ok(pg) = std::env::var("FERRET_TEST_POSTGRES") else {
        eprintln!(
            "skipped: set FERRET_TEST_POSTGRES to a PostgreSQL URL (eval \"$(scripts/postgres.sh start)\" starts a throwaway server and sets it)"
        );
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let houses = dir.path().join("houses.jsonl");
    let out = ferret(&[
        "generate",
        "--count",
        "12",
        "--seed",
        "4",
        "--out",
        s(&houses),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let out = ferret(&[
        "bench",
        "serve",
        "--houses",
        s(&houses),
        "--strategies",
        STRATEGIES,
        "--deployments",
        "24",
        "--trials",
        "12",
        "--replicas",
        "2",
        "--db",
        &pg,
        "--kill-replica-after",
        "0.4",
        "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let line: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert!(line["killed_after_s"].as_f64().is_some(), "{line}");
    // The kill interrupted robots: some requests had to go to the other replica.
    assert!(line["retries"].as_u64().unwrap() > 0, "{line}");
    assert!(
        line["verified_observations"].as_u64().unwrap() > 100,
        "{line}"
    );
    assert_zero(
        &line,
        &[
            "errors",
            "lost_observations",
            "duplicated_observations",
            "mismatched_deployments",
        ],
    );
}

/// Robots sharing one deployment (`bench serve --shared-deployment`): every start answered
/// (none refused while other robots' starts and ends change the deployment), every robot's
/// trials stored in the one deployment in its order, every acknowledged observation once.
#[test]
fn bench_serve_runs_robots_sharing_one_deployment_without_refusals() {
    let out = ferret(&[
        "bench",
        "serve",
        "--generate",
        "6",
        "--strategies",
        STRATEGIES,
        "--deployments",
        "12",
        "--trials",
        "4",
        "--shared-deployment",
        "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let line: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(line["shared_deployment"], true, "{line}");
    let starts = line["by_reply"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k["reply"] == "start")
        .map(|k| k["count"].as_u64().unwrap());
    assert_eq!(starts, Some(48), "{line}");
    assert_zero(
        &line,
        &[
            "refused_starts",
            "errors",
            "lost_observations",
            "duplicated_observations",
            "mismatched_deployments",
        ],
    );
    assert!(
        line["verified_observations"].as_u64().unwrap() >= 48,
        "{line}"
    );
}

/// `bench serve --fresh-trials`: every trial starts from a pose of its own, with targets drawn
/// per trial, so no two trials the server sees are alike (read back from its database).
#[test]
fn bench_serve_fresh_trials_never_repeats_a_trial() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("bench.sqlite");
    let out = ferret(&[
        "bench",
        "serve",
        "--generate",
        "6",
        "--strategies",
        STRATEGIES,
        "--deployments",
        "6",
        "--trials",
        "4",
        "--fresh-trials",
        "--db",
        s(&db),
        "--json",
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let line: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(line["fresh_trials"], true, "{line}");
    assert_zero(
        &line,
        &["errors", "lost_observations", "duplicated_observations"],
    );
    let store = ferret_serve::Store::open(&db).unwrap();
    let trials: Vec<_> = store
        .read(|r| {
            let mut all = Vec::new();
            for d in r.deployment_ids()? {
                all.extend(r.trials_of(d)?);
            }
            Ok(all)
        })
        .unwrap();
    assert_eq!(trials.len(), 24);
    let mut seen = std::collections::HashSet::new();
    for t in &trials {
        let pose = t
            .pose
            .unwrap_or_else(|| panic!("trial {} has no pose", t.id));
        assert!(
            seen.insert((t.scene.clone(), pose.map(f64::to_bits), t.target.clone())),
            "trial {} repeats another",
            t.id
        );
    }
    let pairs: std::collections::HashSet<_> = trials
        .iter()
        .map(|t| (t.scene.clone(), t.target.clone()))
        .collect();
    assert!(pairs.len() > 6, "one target per scene: {pairs:?}");
}

/// A page that goes away while the server writes its events (a tab closed mid-stream) makes a
/// later write to its socket raise SIGPIPE, which ends a process that does not ignore it (as a
/// `ferret` command piped into `head` should end): the server ignores it and goes on serving.
#[test]
fn sigpipe_from_a_page_gone_mid_stream_leaves_the_server_serving() {
    let dir = tempfile::tempdir().unwrap();
    let mut server = Server::start(&dir.path().join("serve.sqlite"));
    let pid = i32::try_from(server.child.id()).unwrap();
    // SAFETY: a signal to the child this test started and still holds.
    assert_eq!(unsafe { libc::kill(pid, libc::SIGPIPE) }, 0);
    std::thread::sleep(std::time::Duration::from_millis(200));
    assert!(
        server.child.try_wait().unwrap().is_none(),
        "SIGPIPE ended the server: {:?}",
        server.child.try_wait()
    );
    assert_eq!(
        post(&format!("{}/deployments", server.url), json!({})).0,
        201
    );
    assert_eq!(get(&format!("{}/health", server.url))["status"], "ok");
}

/// `bench serve --team 3`: homes whose trials three robots search together, each robot asking
/// for its own containers: no container held by two robots in any reply, every robot's
/// acknowledged observations stored as its own, every trial started once per home. On
/// SQLite in-process, and (with `FERRET_TEST_POSTGRES`) with the team's robots spread over two
/// `ferret serve` replicas of one PostgreSQL database.
#[test]
fn bench_serve_teams_claim_no_container_twice() {
    let dir = tempfile::tempdir().unwrap();
    let houses = dir.path().join("houses.jsonl");
    let out = ferret(&[
        "generate",
        "--count",
        "6",
        "--seed",
        "5",
        "--out",
        s(&houses),
    ]);
    assert!(out.status.success(), "{}", text(&out));
    let pg = std::env::var("FERRET_TEST_POSTGRES").ok();
    if pg.is_none() {
        eprintln!(
            "the PostgreSQL half skipped: set FERRET_TEST_POSTGRES to a PostgreSQL URL (eval \"$(scripts/postgres.sh start)\" starts a throwaway server and sets it)"
        );
    }
    let mut runs = vec![vec![]];
    if let Some(pg) = &pg {
        runs.push(vec![
            "--replicas".to_string(),
            "2".into(),
            "--db".into(),
            pg.clone(),
        ]);
    }
    for extra in runs {
        let mut args = vec![
            "bench",
            "serve",
            "--houses",
            s(&houses),
            "--strategies",
            STRATEGIES,
            "--deployments",
            "4",
            "--team",
            "3",
            "--trials",
            "5",
            "--json",
        ];
        args.extend(extra.iter().map(String::as_str));
        let out = ferret(&args);
        assert!(out.status.success(), "{extra:?}: {}", text(&out));
        let line: Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(line["team"], 3, "{line}");
        assert_eq!(line["double_claims"], 0, "{line}");
        let count = |kind: &str| {
            line["by_reply"]
                .as_array()
                .unwrap()
                .iter()
                .find(|k| k["reply"] == kind)
                .map(|k| k["count"].as_u64().unwrap())
                .unwrap()
        };
        assert_eq!(
            count("start"),
            4 * 5,
            "one start per home and trial: {line}"
        );
        assert!(count("claim") >= 4 * 5 * 3, "each robot claims: {line}");
        assert_zero(
            &line,
            &[
                "errors",
                "lost_observations",
                "duplicated_observations",
                "mismatched_deployments",
            ],
        );
        assert!(
            line["verified_observations"].as_u64().unwrap() >= 20,
            "{line}"
        );
    }
}

/// Asserts that every one of `fields` of a `bench serve --json` line is 0.
fn assert_zero(line: &Value, fields: &[&str]) {
    for field in fields {
        assert_eq!(line[*field], 0, "{field}: {line}");
    }
}

/// A fresh database on the PostgreSQL server at `admin` (a URL ending in `/database`).
fn fresh_database(admin: &str, name: &str) -> String {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    rt.block_on(async {
        let (client, connection) = tokio_postgres::connect(admin, tokio_postgres::NoTls)
            .await
            .unwrap();
        tokio::spawn(connection);
        for sql in [
            format!("DROP DATABASE IF EXISTS {name}"),
            format!("CREATE DATABASE {name}"),
        ] {
            client.batch_execute(&sql).await.unwrap();
        }
    });
    format!("{}/{name}", admin.rsplit_once('/').unwrap().0)
}

/// The reply to a POST when it was a success; `None` for an error or no reply.
async fn acknowledged(client: &reqwest::Client, url: String, body: Value) -> Option<Value> {
    let r = client.post(url).json(&body).send().await.ok()?;
    r.status().is_success().then_some(())?;
    r.json::<Value>().await.ok()
}

/// A replica killed (SIGKILL) between a write's commit and its notification took that event
/// with it: a page on the other replica never heard of it, and was not told to read again. Now
/// every acknowledged event reaches the page, or the page is told to read everything again.
/// Needs a PostgreSQL server (`FERRET_TEST_POSTGRES`).
#[test]
fn a_page_gets_every_acknowledged_event_or_a_resync_when_the_other_replica_is_killed() {
    let Ok(admin) = std::env::var("FERRET_TEST_POSTGRES") else {
        eprintln!(
            "skipped: set FERRET_TEST_POSTGRES to a PostgreSQL URL (eval \"$(scripts/postgres.sh start)\" starts a throwaway server and sets it)"
        );
        return;
    };
    let db = fresh_database(&admin, &format!("ferret_cli_kill_{}", std::process::id()));
    let replica = || {
        let scene = apartment();
        Server::spawn(
            &[
                "--scene",
                s(&scene),
                "--strategies",
                STRATEGIES,
                "--listen",
                "127.0.0.1:0",
                "--db",
                &db,
            ],
            &[],
        )
    };
    let (a, b) = (replica(), replica());
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let client = reqwest::Client::new();
    let deployment = rt
        .block_on(acknowledged(
            &client,
            format!("{}/deployments", b.url),
            json!({}),
        ))
        .unwrap()["id"]
        .as_i64()
        .unwrap();
    // The page on B, reading its stream into `heard`.
    type Heard = std::sync::Arc<std::sync::Mutex<Vec<(String, Value)>>>;
    let heard: Heard = Heard::default();
    let page = {
        let (heard, url) = (
            heard.clone(),
            format!("{}/events?deployment={deployment}", b.url),
        );
        let client = client.clone();
        rt.spawn(async move {
            let mut r = client.get(url).send().await.unwrap();
            let mut buffer = String::new();
            while let Ok(Some(chunk)) = r.chunk().await {
                buffer.push_str(std::str::from_utf8(&chunk).unwrap());
                while let Some(end) = buffer.find("\n\n") {
                    let block: String = buffer.drain(..end + 2).collect();
                    let name = block.lines().find_map(|l| l.strip_prefix("event: "));
                    let data = block.lines().find_map(|l| l.strip_prefix("data: "));
                    if let (Some(name), Some(data)) = (name, data) {
                        let data = serde_json::from_str(data).unwrap();
                        heard.lock().unwrap().push((name.to_string(), data));
                    }
                }
            }
        })
    };
    // Until the other replica has heard that B's page watches (it publishes only then).
    std::thread::sleep(std::time::Duration::from_millis(500));
    // A robot on A, as fast as A answers, until A is gone: every reply is an acknowledged
    // event (trial, containers searched, status).
    let robot = {
        let (url, client) = (a.url.clone(), client.clone());
        let post = move |url: String, body: Value| {
            let client = client.clone();
            async move { acknowledged(&client, url, body).await }
        };
        rt.spawn(async move {
            let mut acked = Vec::new();
            'trials: loop {
                let Some(mut t) = post(
                    format!("{url}/deployments/{deployment}/trials"),
                    json!({"scene": "apartment", "target": "Wallet"}),
                )
                .await
                else {
                    break;
                };
                let id = t["trial"].as_i64().unwrap();
                loop {
                    acked.push((
                        id,
                        t["searched"].as_array().unwrap().len(),
                        t["status"].as_str().unwrap().to_string(),
                    ));
                    if t["status"] != "searching" {
                        break;
                    }
                    let c = t["next"]["container"].clone();
                    match post(
                        format!("{url}/trials/{id}/observations"),
                        json!({"container": c, "found": false, "objects": []}),
                    )
                    .await
                    {
                        Some(next) => t = next,
                        None => break 'trials,
                    }
                }
            }
            acked
        })
    };
    std::thread::sleep(std::time::Duration::from_millis(1500));
    a.kill();
    let acked = rt.block_on(robot).unwrap();
    // Long enough for B to notice that A left.
    std::thread::sleep(std::time::Duration::from_secs(3));
    page.abort();
    let heard = heard.lock().unwrap().clone();
    assert!(
        acked.len() > 20,
        "the kill came mid-run: {} acknowledged",
        acked.len()
    );
    let resynced = heard.iter().any(|(name, _)| name == "resync");
    let got: std::collections::BTreeSet<(i64, usize, String)> = heard
        .iter()
        .filter(|(name, _)| name == "trial")
        .map(|(_, e)| {
            (
                e["trial"].as_i64().unwrap(),
                usize::try_from(e["searched"].as_u64().unwrap()).unwrap(),
                e["status"].as_str().unwrap().to_string(),
            )
        })
        .collect();
    let missed: Vec<_> = acked.iter().filter(|e| !got.contains(e)).collect();
    assert!(
        missed.is_empty() || resynced,
        "{} of {} acknowledged events never reached the page, and no resync: {missed:?}",
        missed.len(),
        acked.len()
    );
    drop(b);
}

/// Robots sharing a deployment, each left an open trial (stopped mid-search), restart at once:
/// each client named by `--robot` finishes its own open trial and no other, a client without
/// one takes up only the trial no robot named, and every trial they start names its robot.
#[test]
fn python_clients_started_at_once_each_resume_only_their_own_open_trial() {
    let dir = tempfile::tempdir().unwrap();
    let server = Server::start(&dir.path().join("serve.sqlite"));
    let (st, dep) = post(&format!("{}/deployments", server.url), json!({"seed": 4}));
    assert_eq!(st, 201, "{dep}");
    let id = dep["id"].as_i64().unwrap();
    let robots = [Some("kitchen-bot"), Some("hall-bot"), None];
    let mut left_open = Vec::new();
    for (robot, target) in robots.iter().zip(["Wallet", "Pillow", "Blanket"]) {
        let mut body = json!({"scene": "apartment", "target": target});
        if let Some(r) = robot {
            body["robot"] = json!(r);
        }
        let (st, t) = post(&format!("{}/deployments/{id}/trials", server.url), body);
        assert_eq!(st, 201, "{t}");
        left_open.push(t["trial"].as_i64().unwrap());
    }
    let clients: Vec<_> = robots
        .iter()
        .map(|robot| {
            let mut c = Command::new("python3");
            c.arg(repo().join("examples/robot_client.py"))
                .args(["--url", &server.url, "--scene", "apartment"])
                .args(["--deployment", &id.to_string(), "--json"])
                .args(["--targets", "CellPhone,RemoteControl"])
                .args(["--pace", "0.1"])
                .env_remove("FERRET_SERVE_TOKEN")
                .stdout(std::process::Stdio::piped())
                .stderr(std::process::Stdio::piped());
            if let Some(r) = robot {
                c.args(["--robot", r]);
            }
            c.spawn().expect("python3 runs")
        })
        .collect();
    let mut mine = Vec::new();
    for ((robot, child), open) in robots.iter().zip(clients).zip(&left_open) {
        let o = child.wait_with_output().unwrap();
        assert!(o.status.success(), "{robot:?}: {}", text(&o));
        let report: Value = serde_json::from_slice(&o.stdout).unwrap();
        let trials: Vec<i64> = report["trials"]
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t["trial"].as_i64().unwrap())
            .collect();
        assert_eq!(trials.len(), 3, "{robot:?}: {report}");
        assert_eq!(
            trials[0], *open,
            "{robot:?} resumed another's trial: {report}"
        );
        mine.extend(trials.iter().map(|t| (*t, *robot)));
    }
    let state = get(&format!("{}/deployments/{id}", server.url));
    let listed = state["trials"].as_array().unwrap();
    assert_eq!(listed.len(), 9, "{state}");
    for t in listed {
        assert_eq!(t["status"], "done", "{state}");
        let (_, robot) = mine
            .iter()
            .find(|(trial, _)| Some(*trial) == t["trial"].as_i64())
            .unwrap_or_else(|| panic!("no client reported trial {}: {state}", t["trial"]));
        assert_eq!(t["robot"].as_str(), *robot, "{state}");
    }
    server.kill();
}
