//! The HTTP API on a real socket (127.0.0.1, an ephemeral port): a deployment driven through it
//! costs what the same trials cost in the simulator; bad input gets a 4xx naming the field;
//! retries are idempotent; a restarted service resumes from its database.

mod support;

use support::server::{Server, start, start_with};
use support::{SCENE, TARGETS, contents, strategies};

use std::path::Path;
use std::sync::Arc;

use ferret_plan::{ReplayMode, SearchProblem, TrialSpec, replay_costs, run_trial};
use ferret_select::{LiveDeployment, Method};
use ferret_serve::{ServeOptions, ServiceOptions};
use ferret_world::{GridParams, ObjectType, SceneFile, TravelCost};
use serde_json::{Value, json};

/// Runs one trial to the end through the API; returns (strategy, cost, searched).
async fn run_api_trial(
    s: &Server,
    deployment: i64,
    target: &str,
    scene: &Value,
) -> (String, f64, Vec<String>) {
    let (status, mut reply) = s
        .post(
            &format!("/deployments/{deployment}/trials"),
            json!({"scene": "flat", "target": target}),
        )
        .await;
    assert_eq!(status, 201, "{reply}");
    let trial = reply["trial"].as_i64().unwrap();
    let strategy = reply["strategy"].as_str().unwrap().to_string();
    while reply["status"] == "searching" {
        let next = reply["next"]["container"].as_str().unwrap().to_string();
        let seen = contents(scene, &next);
        let found = seen.iter().any(|o| o == target);
        let (status, r) = s
            .post(
                &format!("/trials/{trial}/observations"),
                json!({"container": next, "found": found, "objects": seen, "travelled_m": reply["next"]["distance_m"]}),
            )
            .await;
        assert_eq!(status, 200, "{r}");
        reply = r;
    }
    assert_eq!(reply["status"], "done", "{reply}");
    let searched = reply["searched"]
        .as_array()
        .unwrap()
        .iter()
        .map(|v| v.as_str().unwrap().to_string())
        .collect();
    (strategy, reply["cost_m"].as_f64().unwrap(), searched)
}

#[tokio::test(flavor = "multi_thread")]
async fn a_deployment_through_the_api_costs_what_the_simulator_says() {
    let s = start(None, None).await;
    let (status, scene) = s.get("/scenes/flat").await;
    assert_eq!(status, 200);
    let (status, dep) = s
        .post(
            "/deployments",
            json!({"selector": "replay", "c": 5.0, "seed": 3}),
        )
        .await;
    assert_eq!(status, 201, "{dep}");
    let id = dep["id"].as_i64().unwrap();
    let mut api = Vec::new();
    for t in TARGETS {
        api.push(run_api_trial(&s, id, t, &scene).await);
    }
    // The same trials by the library pieces `ferret deploy` uses.
    let file = SceneFile::parse(SCENE, Path::new("flat.json")).unwrap();
    let sim = file.to_scene(Path::new("flat.json"), None).unwrap();
    let (_, distances) = ferret_world::distance::build(&sim.house, &GridParams::default()).unwrap();
    let candidates = strategies();
    let mut live = LiveDeployment::new(Method::ReplaySelection, candidates.len(), 5.0, 3).unwrap();
    for (k, t) in TARGETS.iter().enumerate() {
        let trial = TrialSpec::single(ObjectType::new(*t));
        let i = live.choose();
        let problem = SearchProblem::new(&sim.house, &distances, &trial);
        let outcome = run_trial(candidates[i].as_ref(), &problem, &sim.truth).unwrap();
        let found = outcome.found.unwrap();
        let replays = replay_costs(
            (ReplayMode::Pessimistic, TravelCost::Plain),
            &candidates,
            &problem,
            &sim.truth,
            &[Some(found)],
            (i, outcome.cost),
        )
        .unwrap();
        live.finish(outcome.cost, &replays).unwrap();
        assert_eq!(api[k].0, candidates[i].name(), "trial {k}");
        assert!(
            (api[k].1 - outcome.cost).abs() < 1e-9,
            "trial {k}: {} vs {}",
            api[k].1,
            outcome.cost
        );
        let searched: Vec<String> = outcome
            .searched
            .iter()
            .map(|&c| sim.house.containers[c].id.clone())
            .collect();
        assert_eq!(api[k].2, searched, "trial {k}");
    }
    let (_, state) = s.get(&format!("/deployments/{id}")).await;
    let stats = live.stats();
    for (row, st) in state["per_strategy"].as_array().unwrap().iter().zip(&stats) {
        assert_eq!(row["deployed"].as_u64().unwrap() as usize, st.deployed);
        let rm = row["replay_mean_m"].as_f64().unwrap();
        assert!((rm - st.replay_mean.unwrap()).abs() < 1e-9);
    }
    assert_eq!(state["next"]["strategy"], candidates[live.peek()].name());
    assert!(state["next"]["why"].as_str().unwrap().contains("replay"));
}

#[tokio::test(flavor = "multi_thread")]
async fn bad_input_is_a_4xx_naming_the_field() {
    let s = start(None, None).await;
    // Sequential, as in the paper: a second open trial is a conflict.
    let (_, dep) = s.post("/deployments", json!({"sequential": true})).await;
    assert_eq!(dep["sequential"], true, "{dep}");
    let id = dep["id"].as_i64().unwrap();
    let (_, trial) = s
        .post(
            &format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Wallet"}),
        )
        .await;
    let tid = trial["trial"].as_i64().unwrap();
    let first = trial["next"]["container"].as_str().unwrap().to_string();
    let (st, _) = s
        .post(
            &format!("/trials/{tid}/observations"),
            json!({"container": first, "found": false}),
        )
        .await;
    assert_eq!(st, 200);
    let cases: Vec<(String, Value, u16, &str)> = vec![
        (
            "/deployments".into(),
            json!({"strategies": ["model/nothing"]}),
            422,
            "strategies[0]",
        ),
        ("/deployments".into(), json!({"c": -1.0}), 422, "c"),
        (
            "/deployments".into(),
            json!({"selector": "best"}),
            400,
            "selector",
        ),
        (
            "/deployments/99/trials".into(),
            json!({"scene": "flat", "target": "Wallet"}),
            404,
            "deployment",
        ),
        (
            format!("/deployments/{id}/trials"),
            json!({"scene": "attic", "target": "Wallet"}),
            422,
            "scene",
        ),
        // Not an object type the scene lists: a search for it could only end "not found".
        (
            format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "wallet"}),
            422,
            "target",
        ),
        (
            format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Wallet"}),
            409,
            "deployment",
        ),
        (
            format!("/deployments/{id}/trials"),
            json!({"scene": "flat"}),
            400,
            "",
        ),
        (
            format!("/trials/{tid}/observations"),
            json!({"container": first, "found": false}),
            409,
            "container",
        ),
        (
            format!("/trials/{tid}/observations"),
            json!({"container": "piano", "found": false}),
            422,
            "container",
        ),
        (
            format!("/trials/{tid}/observations"),
            json!({"container": "bed", "found": "yes"}),
            400,
            "found",
        ),
        (
            format!("/trials/{tid}/observations"),
            json!({"container": "bed", "found": false, "objects": ["a pen"]}),
            422,
            "objects[0]",
        ),
        (
            format!("/trials/{tid}/observations"),
            json!({"container": "bed", "found": false, "travelled_m": -2}),
            422,
            "travelled_m",
        ),
        (
            "/trials/77/observations".into(),
            json!({"container": "bed", "found": false}),
            404,
            "trial",
        ),
        (
            "/trials/x/observations".into(),
            json!({"container": "bed", "found": false}),
            404,
            "trial",
        ),
        (
            "/scenes".into(),
            json!({"scene": {"ferret_scene": 1}}),
            422,
            "scene",
        ),
        (
            "/scenes".into(),
            json!({"scene": {"ferret_scene": 1, "name": "x", "rooms": [], "containers": [], "start": [0, 0, 0]}}),
            422,
            "scene.rooms",
        ),
    ];
    for (path, body, status, field) in cases {
        let (st, reply) = s.post(&path, body.clone()).await;
        assert_eq!(st, status, "{path} {body}: {reply}");
        if !field.is_empty() {
            assert_eq!(reply["error"]["field"], field, "{path} {body}: {reply}");
        }
        assert!(!reply["error"]["message"].as_str().unwrap().is_empty());
    }
    // The refusal of a name the scene does not list says which one was meant.
    let (_, reply) = s
        .post(
            &format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Walet"}),
        )
        .await;
    assert_eq!(
        reply["error"]["message"], "unknown target \"Walet\": did you mean \"Wallet\"?",
        "{reply}"
    );
    let (st, reply) = s
        .post_raw(
            &format!("/trials/{tid}/observations"),
            "{\"container\": \"bed\",",
        )
        .await;
    assert_eq!(st, 400, "{reply}");
    // Poses: off the map, and inside a wall far from any floor.
    let (_, d2) = s.post("/deployments", json!({})).await;
    let d2 = d2["id"].as_i64().unwrap();
    for pose in [json!([50.0, 2.0, 0.0]), json!([-3.0, -3.0, 0.0])] {
        let (st, reply) = s
            .post(
                &format!("/deployments/{d2}/trials"),
                json!({"scene": "flat", "target": "Wallet", "pose": pose}),
            )
            .await;
        assert_eq!(st, 422, "{reply}");
        assert_eq!(reply["error"]["field"], "pose");
    }
    // A scene with a container nobody can reach: the bedroom door removed.
    let mut closed: Value = serde_json::from_str(SCENE).unwrap();
    closed["name"] = json!("closed");
    closed["doors"] = json!([{"from": [4, 1], "to": [4, 2]}]);
    let (st, reply) = s.post("/scenes", json!({"scene": closed})).await;
    assert_eq!(st, 422, "{reply}");
    assert!(
        reply["error"]["message"]
            .as_str()
            .unwrap()
            .contains("unreachable"),
        "{reply}"
    );
    let (st, _) = s.get("/nowhere").await;
    assert_eq!(st, 404);
    // Uploading: a new scene is offered at once; the same one again is fine; another scene
    // under a taken name is refused.
    let mut copy: Value = serde_json::from_str(SCENE).unwrap();
    copy["name"] = json!("copy");
    let (st, reply) = s.post("/scenes", json!({"scene": copy})).await;
    assert_eq!(st, 201, "{reply}");
    assert_eq!(reply["containers"].as_array().unwrap().len(), 7);
    let (st, _) = s.post("/scenes", json!({"scene": copy})).await;
    assert_eq!(st, 200);
    copy["start"] = json!([6.0, 2.0, 0]);
    let (st, reply) = s.post("/scenes", json!({"scene": copy})).await;
    assert_eq!(st, 409, "{reply}");
    assert_eq!(reply["error"]["field"], "scene.name");
    let (st, reply) = s.get("/scenes").await;
    assert_eq!(st, 200);
    assert_eq!(reply.as_array().unwrap().len(), 2, "{reply}");
}

#[tokio::test(flavor = "multi_thread")]
async fn a_retried_request_changes_nothing_and_a_reused_id_is_refused() {
    let s = start(None, None).await;
    let body = json!({"request_id": "dep-1", "seed": 9});
    let (a, first) = s.post("/deployments", body.clone()).await;
    let (b, again) = s.post("/deployments", body).await;
    assert_eq!((a, b), (201, 201));
    assert_eq!(first, again);
    let (st, reply) = s
        .post("/deployments", json!({"request_id": "dep-1", "seed": 10}))
        .await;
    assert_eq!(st, 422, "the same id with another body: {reply}");
    assert_eq!(reply["error"]["field"], "request_id");
    // Any text is an id, NUL included (which PostgreSQL text cannot hold), and names with NUL
    // name nothing.
    let nul = json!({"request_id": "dep\u{0}2", "seed": 4});
    let (a, first_nul) = s.post("/deployments", nul.clone()).await;
    let (b, again_nul) = s.post("/deployments", nul).await;
    assert_eq!((a, b), (201, 201), "{first_nul}");
    assert_eq!(first_nul, again_nul);
    let (st, reply) = s
        .post(
            &format!("/deployments/{}/trials", first_nul["id"]),
            json!({"scene": "fl\u{0}at", "target": "Wallet"}),
        )
        .await;
    assert_eq!(st, 422, "{reply}");
    let id = first["id"].as_i64().unwrap();
    let start = json!({"request_id": "t-1", "scene": "flat", "target": "Wallet"});
    let (_, t1) = s
        .post(&format!("/deployments/{id}/trials"), start.clone())
        .await;
    let (st, t1b) = s.post(&format!("/deployments/{id}/trials"), start).await;
    assert_eq!(st, 201);
    assert_eq!(
        t1, t1b,
        "the retry gets the stored reply, not a 409 for a second trial"
    );
    let tid = t1["trial"].as_i64().unwrap();
    let next = t1["next"]["container"].as_str().unwrap();
    let obs = json!({"request_id": "o-1", "container": next, "found": false});
    let (_, o1) = s
        .post(&format!("/trials/{tid}/observations"), obs.clone())
        .await;
    let (st, o1b) = s.post(&format!("/trials/{tid}/observations"), obs).await;
    assert_eq!(st, 200, "{o1b}");
    assert_eq!(o1, o1b);
    let (_, trial) = s.get(&format!("/trials/{tid}")).await;
    assert_eq!(trial["searched"].as_array().unwrap().len(), 1, "{trial}");
    let (_, dep) = s.get(&format!("/deployments/{id}")).await;
    assert_eq!(dep["trials"].as_array().unwrap().len(), 1);
}

#[tokio::test(flavor = "multi_thread")]
async fn a_token_guards_everything_but_health() {
    let s = start(None, Some("s3cret-token")).await;
    let (st, _) = s.get("/health").await;
    assert_eq!(st, 200);
    let (st, reply) = s.get("/scenes").await;
    assert_eq!(st, 401);
    assert_eq!(reply["error"]["field"], "authorization");
    let r = s
        .client
        .get(format!("{}/scenes", s.url))
        .bearer_auth("s3cret-token")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 200);
    let r = s
        .client
        .get(format!("{}/scenes", s.url))
        .bearer_auth("s3cret-tokeN")
        .send()
        .await
        .unwrap();
    assert_eq!(r.status().as_u16(), 401);
    // No CORS headers unless origins are configured.
    let r = s
        .client
        .get(format!("{}/health", s.url))
        .header("origin", "http://example.org")
        .send()
        .await
        .unwrap();
    assert!(r.headers().get("access-control-allow-origin").is_none());
}

#[tokio::test(flavor = "multi_thread")]
async fn the_openapi_document_lists_every_route() {
    let s = start(None, None).await;
    let (st, doc) = s.get("/openapi.json").await;
    assert_eq!(st, 200);
    assert!(doc["openapi"].as_str().unwrap().starts_with("3."));
    for (path, method) in [
        ("/health", "get"),
        ("/scenes", "get"),
        ("/scenes", "post"),
        ("/scenes/{name}", "get"),
        ("/scenes/{name}/map", "get"),
        ("/deployments", "post"),
        ("/deployments/{id}", "get"),
        ("/deployments/{id}/trials", "post"),
        ("/trials/{id}", "get"),
        ("/trials/{id}/observations", "post"),
    ] {
        assert!(
            doc["paths"][path][method].is_object(),
            "{method} {path} missing"
        );
    }
    assert!(doc["components"]["schemas"]["Observe"]["properties"]["container"].is_object());
}

#[tokio::test(flavor = "multi_thread")]
async fn a_restarted_service_resumes_every_open_trial() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("serve.sqlite");
    // Uninterrupted reference run.
    let reference = {
        let s = start(Some(&dir.path().join("ref.sqlite")), None).await;
        let (_, scene) = s.get("/scenes/flat").await;
        let (_, dep) = s.post("/deployments", json!({"seed": 5})).await;
        let id = dep["id"].as_i64().unwrap();
        let mut out = Vec::new();
        for t in TARGETS {
            out.push(run_api_trial(&s, id, t, &scene).await);
        }
        out
    };
    // Interrupted after every request: a new service on the same file each time.
    let mut results = Vec::new();
    let scene = start(Some(&db), None).await.get("/scenes/flat").await.1;
    let id = start(Some(&db), None)
        .await
        .post("/deployments", json!({"seed": 5}))
        .await
        .1["id"]
        .as_i64()
        .unwrap();
    for t in TARGETS {
        let (_, mut reply) = start(Some(&db), None)
            .await
            .post(
                &format!("/deployments/{id}/trials"),
                json!({"scene": "flat", "target": t}),
            )
            .await;
        let trial = reply["trial"].as_i64().unwrap();
        while reply["status"] == "searching" {
            // A fresh server reads the trial back: the next container survives the restart.
            let s = start(Some(&db), None).await;
            let (_, again) = s.get(&format!("/trials/{trial}")).await;
            assert_eq!(again["next"], reply["next"]);
            let next = reply["next"]["container"].as_str().unwrap().to_string();
            let seen = contents(&scene, &next);
            let found = seen.iter().any(|o| o == t);
            reply = s
                .post(
                    &format!("/trials/{trial}/observations"),
                    json!({"container": next, "found": found, "objects": seen}),
                )
                .await
                .1;
        }
        let searched: Vec<String> = reply["searched"]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_str().unwrap().to_string())
            .collect();
        results.push((
            reply["strategy"].as_str().unwrap().to_string(),
            reply["cost_m"].as_f64().unwrap(),
            searched,
        ));
    }
    assert_eq!(results, reference);
}

/// A search kept between requests answers exactly as one rebuilt from the store on every
/// request, replays kept from earlier trial ends as replaying again, and plans kept from other
/// searches as solving again: the same deployment driven twice, once keeping all three and once
/// keeping none, from several poses, gets the same replies byte for byte, and the first run did
/// answer replays and planner decisions from what it kept.
#[tokio::test(flavor = "multi_thread")]
async fn kept_searches_replays_and_plans_answer_as_rebuilt_ones() {
    let mut runs = Vec::new();
    let mut reused = Vec::new();
    let mut planned = Vec::new();
    let poses = [None, Some([2.0, 2.0, 90.0]), Some([7.5, 2.5, -45.0])];
    for keep in [64, 0] {
        let options = ServiceOptions {
            live_searches: keep,
            kept_replays: keep * 64,
            kept_plans: keep * 32,
            ..ServiceOptions::default()
        };
        let s = start_with(None, None, options, ServeOptions::default()).await;
        let (_, scene) = s.get("/scenes/flat").await;
        let contents = |id: &str| -> Vec<Value> {
            scene["containers"]
                .as_array()
                .unwrap()
                .iter()
                .find(|c| c["id"] == id)
                .map(|c| c["contents"].as_array().unwrap().clone())
                .unwrap_or_default()
        };
        let (_, dep) = s.post("/deployments", json!({"seed": 2})).await;
        let mut replies = Vec::new();
        for (target, pose) in TARGETS
            .iter()
            .chain(TARGETS.iter())
            .flat_map(|t| poses.iter().map(move |p| (t, p)))
        {
            let mut body = json!({"scene": "flat", "target": target});
            if let Some(pose) = pose {
                body["pose"] = json!(pose);
            }
            let (st, mut t) = s
                .post(&format!("/deployments/{}/trials", dep["id"]), body)
                .await;
            assert_eq!(st, 201, "{t}");
            replies.push(t.clone());
            while t["status"] == "searching" {
                let next = t["next"]["container"].as_str().unwrap().to_string();
                let seen = contents(&next);
                let found = seen.iter().any(|o| o == target);
                let (st, reply) = s
                    .post(
                        &format!("/trials/{}/observations", t["trial"]),
                        json!({"container": next, "found": found, "objects": seen}),
                    )
                    .await;
                assert_eq!(st, 200, "{reply}");
                replies.push(reply.clone());
                t = reply;
            }
        }
        runs.push(replies);
        reused.push(s.service.replays_reused());
        planned.push(s.service.plans_reused());
    }
    assert!(runs[0].len() > 60, "{}", runs[0].len());
    assert_eq!(runs[0], runs[1]);
    // Every target comes twice from each pose, so each second ending reuses the other
    // candidates' replays.
    assert!(reused[0] >= TARGETS.len() as u64, "{reused:?}");
    assert_eq!(reused[1], 0);
    assert!(planned[0] > 0, "no decision came from a kept plan");
    assert_eq!(planned[1], 0);
}

/// A robot that gives a search up ends its trial: the trial reads `abandoned` with the map
/// distance of the legs it reported, selection learns nothing from it (the next choice is the
/// selector's after an abandoned trial), and a sequential deployment takes its next trial.
#[tokio::test(flavor = "multi_thread")]
async fn an_abandoned_trial_ends_and_teaches_nothing() {
    let s = start(None, None).await;
    let (_, dep) = s
        .post("/deployments", json!({"sequential": true, "seed": 3}))
        .await;
    let id = dep["id"].as_i64().unwrap();
    let start_body = json!({"scene": "flat", "target": "Wallet"});
    let (st, trial) = s
        .post(&format!("/deployments/{id}/trials"), start_body.clone())
        .await;
    assert_eq!(st, 201, "{trial}");
    let tid = trial["trial"].as_i64().unwrap();
    let first = trial["next"]["container"].as_str().unwrap().to_string();
    let (_, stepped) = s
        .post(
            &format!("/trials/{tid}/observations"),
            json!({"container": first, "found": false}),
        )
        .await;
    let walked = stepped["cost_m"].as_f64().unwrap();
    assert!(walked > 0.0, "{stepped}");

    let abandon = json!({"request_id": "give-up-1"});
    let (st, ended) = s
        .post(&format!("/trials/{tid}/abandon"), abandon.clone())
        .await;
    assert_eq!(st, 200, "{ended}");
    assert_eq!(ended["status"], "abandoned", "{ended}");
    assert_eq!(ended["next"], Value::Null, "{ended}");
    assert_eq!(ended["cost_m"].as_f64().unwrap(), walked, "{ended}");
    assert_eq!(ended["searched"], json!([first]), "{ended}");
    // The same request again is the same reply; another is a conflict, as is a step.
    let (st, again) = s.post(&format!("/trials/{tid}/abandon"), abandon).await;
    assert_eq!((st, &again), (200, &ended));
    let (st, e) = s.post(&format!("/trials/{tid}/abandon"), json!({})).await;
    assert_eq!(
        (st, e["error"]["field"].as_str()),
        (409, Some("trial")),
        "{e}"
    );
    assert!(
        e["error"]["message"]
            .as_str()
            .unwrap()
            .contains("abandoned"),
        "{e}"
    );
    let (st, e) = s
        .post(
            &format!("/trials/{tid}/observations"),
            json!({"container": "bed", "found": false}),
        )
        .await;
    assert_eq!(st, 409, "{e}");
    let (st, e) = s.post("/trials/999/abandon", json!({})).await;
    assert_eq!(st, 404, "{e}");
    let (_, read) = s.get(&format!("/trials/{tid}")).await;
    assert_eq!(read, ended);

    // Nothing learned: the selector after one abandoned trial chooses the next.
    let mut live =
        LiveDeployment::new(Method::ReplaySelection, strategies().len(), 5.0, 3).unwrap();
    let names: Vec<String> = strategies().iter().map(|s| s.name().to_string()).collect();
    let first_choice = live.choose();
    assert_eq!(trial["strategy"], names[first_choice]);
    live.abandon().unwrap();
    let (_, state) = s.get(&format!("/deployments/{id}")).await;
    assert_eq!(state["open_trial"], Value::Null, "{state}");
    assert_eq!(state["trials"][0]["status"], "abandoned", "{state}");
    for row in state["per_strategy"].as_array().unwrap() {
        assert_eq!(row["deployed"], 0, "{state}");
    }
    assert_eq!(state["next"]["strategy"], names[live.peek()], "{state}");
    let (st, second) = s
        .post(&format!("/deployments/{id}/trials"), start_body)
        .await;
    assert_eq!(st, 201, "{second}");
    assert_eq!(second["strategy"], names[live.choose()], "{second}");
    assert_eq!(second["k"], 2, "{second}");
}

/// A trial's start is stored before its first container is planned; a retry that finds only
/// the trial's name stored (the server stopped in between) plans it again, to the very reply
/// the first run gave.
#[tokio::test(flavor = "multi_thread")]
async fn a_start_stored_before_its_plan_is_answered_again_alike() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("serve.sqlite");
    let s = start(Some(&db), None).await;
    let (_, dep) = s.post("/deployments", json!({"seed": 2})).await;
    let id = dep["id"].as_i64().unwrap();
    let path = format!("{}/deployments/{id}/trials", s.url);
    let body = r#"{"request_id": "start-1", "scene": "flat", "target": "Wallet"}"#;
    let send = || async {
        let r = s
            .client
            .post(&path)
            .header("content-type", "application/json")
            .body(body)
            .send()
            .await
            .unwrap();
        (r.status().as_u16(), r.text().await.unwrap())
    };
    let (st, first) = send().await;
    assert_eq!(st, 201, "{first}");
    let trial: Value = serde_json::from_str(&first).unwrap();
    assert!(trial["next"]["container"].is_string(), "{first}");
    let stored_body = |db: &Path| -> String {
        rusqlite::Connection::open(db)
            .unwrap()
            .query_row("SELECT body FROM requests WHERE id = 'start-1'", [], |r| {
                r.get(0)
            })
            .unwrap()
    };
    assert_eq!(
        stored_body(&db),
        first,
        "the planned reply is what is stored"
    );
    // As a server stopped between storing the trial and planning it leaves the request.
    rusqlite::Connection::open(&db)
        .unwrap()
        .execute(
            "UPDATE requests SET body = ?1 WHERE id = 'start-1'",
            [format!(r#"{{"unplanned_trial":{}}}"#, trial["trial"])],
        )
        .unwrap();
    let (st, again) = send().await;
    assert_eq!((st, &again), (201, &first));
    let (_, state) = s.get(&format!("/deployments/{id}")).await;
    assert_eq!(state["trials"].as_array().unwrap().len(), 1, "{state}");
}

/// Robots of a fleet starting trials in one deployment at once: the starts waiting for the
/// deployment's lock are stored together, and each gets the choice it would have got alone in
/// the order the trials are numbered (no trial ended: the selector's overlapping choices, one
/// after another). A retried request gets its reply byte for byte.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn starts_made_at_once_are_stored_together_with_the_choices_made_one_by_one() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("serve.sqlite");
    let s = Arc::new(start((!support::on_postgres()).then_some(db.as_path()), None).await);
    let (_, dep) = s.post("/deployments", json!({"seed": 3})).await;
    let id = dep["id"].as_i64().unwrap();
    let robots = 32;
    let body = |r: usize| json!({"request_id": format!("start-{r}"), "scene": "flat", "target": TARGETS[r % TARGETS.len()]});
    let starts: Vec<_> = (0..robots)
        .map(|r| {
            let s = s.clone();
            let body = body(r);
            tokio::spawn(async move {
                let r = s
                    .client
                    .post(format!("{}/deployments/{id}/trials", s.url))
                    .json(&body)
                    .send()
                    .await
                    .unwrap();
                (r.status().as_u16(), r.text().await.unwrap())
            })
        })
        .collect();
    let mut replies = Vec::new();
    for start in starts {
        let (status, text) = start.await.unwrap();
        assert_eq!(status, 201, "{text}");
        replies.push(text);
    }
    assert!(
        s.service.starts_made_together() > 0,
        "{robots} starts at once were each stored alone"
    );
    let mut trials: Vec<Value> = replies
        .iter()
        .map(|t| serde_json::from_str(t).unwrap())
        .collect();
    trials.sort_by_key(|t| t["k"].as_i64().unwrap());
    let ks: Vec<i64> = trials.iter().map(|t| t["k"].as_i64().unwrap()).collect();
    assert_eq!(ks, (1..=robots as i64).collect::<Vec<_>>());
    let names: Vec<String> = strategies().iter().map(|s| s.name().to_string()).collect();
    let mut live =
        LiveDeployment::new(Method::ReplaySelection, strategies().len(), 5.0, 3).unwrap();
    for t in &trials {
        assert_eq!(
            t["strategy"],
            names[live.choose_overlapping()],
            "trial {}",
            t["k"]
        );
        assert!(t["next"]["container"].is_string(), "{t}");
    }
    // The history replays (the GET rebuilds the selector and checks every stored choice).
    let (st, state) = s.get(&format!("/deployments/{id}")).await;
    assert_eq!(st, 200, "{state}");
    assert_eq!(state["open_trials"].as_array().unwrap().len(), robots);
    for r in [0, robots / 2, robots - 1] {
        let again = s
            .client
            .post(format!("{}/deployments/{id}/trials", s.url))
            .json(&body(r))
            .send()
            .await
            .unwrap();
        assert_eq!(again.status().as_u16(), 201);
        assert_eq!(again.text().await.unwrap(), replies[r], "robot {r}'s retry");
    }
}

/// A scene's kept plans are shared by its every start, and counted once in the grid cache's
/// memory: the scene at its own start and at two more poses hold less than twice the scene at
/// its start alone (each would hold the plans' room again if counted per start).
#[tokio::test(flavor = "multi_thread")]
async fn kept_plans_are_counted_once_per_scene() {
    let options = ServiceOptions {
        kept_plans: 100_000,
        grid_cache_bytes: 1 << 30,
        ..ServiceOptions::default()
    };
    let s = start_with(None, None, options, ServeOptions::default()).await;
    let (_, dep) = s.post("/deployments", json!({})).await;
    let path = format!("/deployments/{}/trials", dep["id"]);
    let (st, t) = s
        .post(&path, json!({"scene": "flat", "target": "Wallet"}))
        .await;
    assert_eq!(st, 201, "{t}");
    let alone = s.service.grid_cache_bytes();
    assert!(alone > 100_000 * 512, "{alone}");
    for pose in [[2.0, 2.0, 90.0], [7.5, 2.5, -45.0]] {
        let (st, t) = s
            .post(
                &path,
                json!({"scene": "flat", "target": "Wallet", "pose": pose}),
            )
            .await;
        assert_eq!(st, 201, "{t}");
    }
    let three = s.service.grid_cache_bytes();
    assert!(three > alone, "{three} {alone}");
    assert!(three < 2 * alone, "{three} against {alone} for one start");
}

/// A robot that names itself at a trial's start is shown as that trial's robot in the
/// deployment's list, with the time since it last reported, which each report resets; a
/// malformed id, or one beside a team, is refused naming `robot`.
#[tokio::test(flavor = "multi_thread")]
async fn a_robot_that_names_itself_is_listed_with_the_time_since_it_was_heard() {
    let s = start(None, None).await;
    let (_, dep) = s.post("/deployments", json!({"seed": 2})).await;
    let id = dep["id"].as_i64().unwrap();
    let (st, mine) = s
        .post(
            &format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Wallet", "robot": "/kitchen/r1"}),
        )
        .await;
    assert_eq!(st, 201, "{mine}");
    assert_eq!(mine["robot"], "/kitchen/r1", "{mine}");
    let (st, anonymous) = s
        .post(
            &format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Mug"}),
        )
        .await;
    assert_eq!(st, 201, "{anonymous}");
    assert_eq!(anonymous["robot"], Value::Null, "{anonymous}");

    let heard = |state: &Value, k: usize| state["trials"][k]["heard_s_ago"].as_f64().unwrap();
    tokio::time::sleep(std::time::Duration::from_millis(1300)).await;
    let (_, before) = s.get(&format!("/deployments/{id}")).await;
    assert_eq!(before["trials"][0]["robot"], "/kitchen/r1", "{before}");
    assert_eq!(before["trials"][1]["robot"], Value::Null, "{before}");
    assert!(heard(&before, 0) >= 1.3, "{before}");
    assert!(heard(&before, 1) >= 1.3, "{before}");
    let tid = mine["trial"].as_i64().unwrap();
    let first = mine["next"]["container"].as_str().unwrap();
    let (st, stepped) = s
        .post(
            &format!("/trials/{tid}/observations"),
            json!({"container": first, "found": false}),
        )
        .await;
    assert_eq!(st, 200, "{stepped}");
    assert_eq!(stepped["robot"], "/kitchen/r1", "{stepped}");
    let (_, after) = s.get(&format!("/deployments/{id}")).await;
    assert!(heard(&after, 0) < 1.0, "{after}");
    assert!(heard(&after, 1) >= 1.3, "{after}");

    for (body, says) in [
        (
            json!({"scene": "flat", "target": "Mug", "robot": "r 1"}),
            "not a robot id",
        ),
        (
            json!({"scene": "flat", "target": "Mug", "robot": "x".repeat(65)}),
            "not a robot id",
        ),
        (
            json!({"scene": "flat", "target": "Mug", "robot": "a", "robots": [{"id": "a"}]}),
            "named in `robots`",
        ),
    ] {
        let (st, e) = s.post(&format!("/deployments/{id}/trials"), body).await;
        assert_eq!(
            (st, e["error"]["field"].as_str()),
            (422, Some("robot")),
            "{e}"
        );
        assert!(
            e["error"]["message"].as_str().unwrap().contains(says),
            "{e}"
        );
    }
}

/// A scene's map is the grid the planner measures on, cell for cell: its runs decode to the
/// kinds of the grid the library builds from the same file, walls and free floor among them.
#[tokio::test(flavor = "multi_thread")]
async fn a_scene_map_is_the_planners_grid_cell_for_cell() {
    let s = start(None, None).await;
    let (st, map) = s.get("/scenes/flat/map").await;
    assert_eq!(st, 200, "{map}");
    let file = SceneFile::parse(SCENE, Path::new("flat.json")).unwrap();
    let sim = file.to_scene(Path::new("flat.json"), None).unwrap();
    let grid = ferret_world::OccupancyGrid::build(&sim.house, &GridParams::default()).unwrap();
    assert_eq!(map["width"].as_u64().unwrap(), u64::from(grid.width()));
    assert_eq!(map["height"].as_u64().unwrap(), u64::from(grid.height()));
    assert_eq!(map["resolution_m"].as_f64().unwrap(), grid.resolution());
    assert_eq!(map["origin"][0].as_f64().unwrap(), grid.origin().x);
    assert_eq!(map["origin"][1].as_f64().unwrap(), grid.origin().z);
    let mut kinds = Vec::new();
    let runs = map["runs"].as_array().unwrap();
    for run in runs {
        let (k, n) = (run[0].as_u64().unwrap(), run[1].as_u64().unwrap());
        assert!(n > 0, "an empty run: {run}");
        kinds.extend(std::iter::repeat_n(k as u8, n as usize));
    }
    let expected: Vec<u8> = grid.cells().map(|(_, k)| k as u8).collect();
    assert_eq!(kinds.len(), expected.len());
    assert!(kinds == expected, "the map's cells differ from the grid's");
    for kind in [1, 4] {
        assert!(kinds.contains(&kind), "no cell of kind {kind}");
    }
    assert!(runs.len() < expected.len() / 4, "{} runs", runs.len());
    let (st, e) = s.get("/scenes/nowhere/map").await;
    assert_eq!(st, 404, "{e}");
}
