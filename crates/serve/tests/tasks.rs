//! Household tasks through the HTTP API: a trial of several targets with a destination costs
//! what the simulator says (the way there included), reports where each target was found and
//! the way to the destination, learns from replays of the same task; bad tasks and bad
//! observations get a 4xx naming the field.

mod support;

use std::path::Path;

use support::server::{Server, start};
use support::{SCENE, contents, strategies};

use ferret_plan::{
    Destination, Goal, ReplayMode, SearchProblem, Task, TrialSpec, replay_costs, run_trial,
};
use ferret_world::{GridParams, ObjectType, SceneFile, TravelCost};
use serde_json::{Value, json};

/// Runs a task to the end as a simulated robot that names the targets it sees; returns the
/// last state.
async fn run_task(s: &Server, deployment: i64, start: Value, scene: &Value) -> Value {
    let (status, mut reply) = s
        .post(&format!("/deployments/{deployment}/trials"), start)
        .await;
    assert_eq!(status, 201, "{reply}");
    let trial = reply["trial"].as_i64().unwrap();
    let targets: Vec<String> = reply["targets"]
        .as_array()
        .unwrap()
        .iter()
        .map(|t| t.as_str().unwrap().to_string())
        .collect();
    while reply["status"] == "searching" {
        let next = reply["next"]["container"].as_str().unwrap().to_string();
        let seen = contents(scene, &next);
        let found: Vec<&String> = targets.iter().filter(|t| seen.contains(t)).collect();
        let others: Vec<&String> = seen.iter().filter(|o| !targets.contains(o)).collect();
        let (status, r) = s
            .post(
                &format!("/trials/{trial}/observations"),
                json!({"container": next, "found": !found.is_empty(), "found_targets": found, "objects": others}),
            )
            .await;
        assert_eq!(status, 200, "{r}");
        reply = r;
    }
    reply
}

#[tokio::test(flavor = "multi_thread")]
async fn a_task_through_the_api_costs_what_the_simulator_says() {
    let s = start(None, None).await;
    let (_, scene) = s.get("/scenes/flat").await;
    let (status, dep) = s
        .post("/deployments", json!({"selector": "replay", "seed": 1}))
        .await;
    assert_eq!(status, 201, "{dep}");
    let id = dep["id"].as_i64().unwrap();
    let cases = [
        (json!(["Wallet", "Mug"]), "all", json!({"kind": "start"})),
        (
            json!(["Book", "Egg", "Pillow"]),
            "all",
            json!({"kind": "room", "name": "bedroom"}),
        ),
        (
            json!(["Wallet", "Apple"]),
            "any",
            json!({"kind": "container", "id": "sofa"}),
        ),
        (
            json!(["CellPhone", "Book"]),
            "all",
            json!({"kind": "point", "x": 6.0, "y": 2.5}),
        ),
    ];
    let file = SceneFile::parse(SCENE, Path::new("flat.json")).unwrap();
    let sim = file.to_scene(Path::new("flat.json"), None).unwrap();
    let (_, distances) = ferret_world::distance::build(&sim.house, &GridParams::default()).unwrap();
    let candidates = strategies();
    for (targets, goal, destination) in cases {
        let start =
            json!({"scene": "flat", "targets": targets, "goal": goal, "destination": destination});
        let end = run_task(&s, id, start, &scene).await;
        assert_eq!(end["status"], "done", "{end}");
        let found = end["found_in"].as_object().unwrap();
        let names: Vec<&str> = targets
            .as_array()
            .unwrap()
            .iter()
            .map(|t| t.as_str().unwrap())
            .collect();
        match goal {
            "all" => assert_eq!(found.len(), names.len(), "{end}"),
            _ => assert!(!found.is_empty(), "{end}"),
        }
        for (t, c) in found {
            assert!(
                contents(&scene, c.as_str().unwrap()).contains(t),
                "{t} not in {c}"
            );
        }
        // The way to the destination ends where the destination is; its length is in the cost.
        let dest = &end["destination"];
        assert_eq!(dest["kind"], destination["kind"], "{end}");
        let path = dest["path"].as_array().unwrap();
        let last = path.last().unwrap();
        assert!((last[0].as_f64().unwrap() - dest["at"][0].as_f64().unwrap()).abs() < 1e-9);
        let way = dest["distance_m"].as_f64().unwrap();
        // The same trial in the simulator, with the strategy the service chose.
        let strategy = end["strategy"].as_str().unwrap();
        let s_ = candidates.iter().find(|c| c.name() == strategy).unwrap();
        let dest_of = match destination["kind"].as_str().unwrap() {
            "start" => Destination::Start,
            "room" => Destination::Room { index: 2 },
            "container" => Destination::Container {
                index: sim.house.container_index("sofa").unwrap(),
            },
            _ => Destination::Point { x: 6.0, z: 2.5 },
        };
        let task = Task::new(
            names.iter().map(|t| ObjectType::new(*t)).collect(),
            if goal == "all" { Goal::All } else { Goal::Any },
            Some(dest_of),
        )
        .unwrap();
        let trial = TrialSpec::of(task);
        let problem = SearchProblem::new(&sim.house, &distances, &trial);
        let out = run_trial(s_.as_ref(), &problem, &sim.truth).unwrap();
        let cost = end["cost_m"].as_f64().unwrap();
        assert!(
            (cost - out.cost).abs() < 1e-9,
            "API {cost} vs simulator {}",
            out.cost
        );
        assert!(
            (way - out.delivery).abs() < 1e-9,
            "{way} vs {}",
            out.delivery
        );
        let searched: Vec<usize> = end["searched"]
            .as_array()
            .unwrap()
            .iter()
            .map(|c| sim.house.container_index(c.as_str().unwrap()).unwrap())
            .collect();
        assert_eq!(searched, out.searched);
        // Every candidate replayed on the same task.
        let replays = replay_costs(
            (ReplayMode::Pessimistic, TravelCost::Plain),
            &candidates,
            &problem,
            &sim.truth,
            &out.found_each,
            (
                candidates
                    .iter()
                    .position(|c| c.name() == strategy)
                    .unwrap(),
                out.cost,
            ),
        )
        .unwrap();
        for (c, r) in candidates.iter().zip(replays) {
            let api = end["replays_m"][c.name()].as_f64().unwrap();
            assert!((api - r).abs() < 1e-9, "{}: {api} vs {r}", c.name());
        }
        // Read again, the trial says the same; its view draws the way to the destination.
        let trial = end["trial"].as_i64().unwrap();
        let (_, again) = s.get(&format!("/trials/{trial}")).await;
        assert_eq!(again, end);
        let (_, view) = s.get(&format!("/trials/{trial}/view")).await;
        let route = view["route"].as_array().unwrap();
        assert_eq!(route.last(), path.last());
        assert!(view["target_likelihoods"].as_object().unwrap().len() == names.len());
    }
    let (_, d) = s.get(&format!("/deployments/{id}")).await;
    let deployed: u64 = d["per_strategy"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["deployed"].as_u64().unwrap())
        .sum();
    assert_eq!(deployed, 4, "{d}");
}

/// `target` alone is the single-target trial it always was: no destination, its one target.
#[tokio::test(flavor = "multi_thread")]
async fn a_single_target_reads_as_a_task_of_one() {
    let s = start(None, None).await;
    let (_, dep) = s.post("/deployments", json!({})).await;
    let id = dep["id"].as_i64().unwrap();
    let (status, r) = s
        .post(
            &format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Wallet"}),
        )
        .await;
    assert_eq!(status, 201, "{r}");
    assert_eq!(
        (r["target"].as_str(), r["goal"].as_str()),
        (Some("Wallet"), Some("all"))
    );
    assert_eq!(r["targets"], json!(["Wallet"]));
    assert!(r["destination"].is_null());
    assert_eq!(r["found_in"], json!({}));
}

#[tokio::test(flavor = "multi_thread")]
async fn bad_tasks_and_observations_name_their_field() {
    let s = start(None, None).await;
    let (_, dep) = s.post("/deployments", json!({})).await;
    let id = dep["id"].as_i64().unwrap();
    let trials = format!("/deployments/{id}/trials");
    let cases = [
        (json!({"scene": "flat"}), 400, "target"),
        (
            json!({"scene": "flat", "target": "Mug", "targets": ["Egg"]}),
            400,
            "targets",
        ),
        (
            json!({"scene": "flat", "targets": ["Mug", "Mug"]}),
            422,
            "targets",
        ),
        (
            json!({"scene": "flat", "targets": ["Mug", "Egg", "Book", "Apple", "Pillow"]}),
            422,
            "targets",
        ),
        (json!({"scene": "flat", "targets": []}), 422, "targets"),
        (
            json!({"scene": "flat", "targets": ["Mug", "Walet"]}),
            422,
            "targets[1]",
        ),
        (
            json!({"scene": "flat", "targets": ["Mug", "cell phone!"]}),
            422,
            "targets[1]",
        ),
        (
            json!({"scene": "flat", "targets": ["Mug"], "goal": "some"}),
            400,
            "",
        ),
        (
            json!({"scene": "flat", "targets": ["Mug"], "destination": {"kind": "container", "id": "oven"}}),
            422,
            "destination.id",
        ),
        (
            json!({"scene": "flat", "targets": ["Mug"], "destination": {"kind": "room", "name": "attic"}}),
            422,
            "destination.name",
        ),
        (
            json!({"scene": "flat", "targets": ["Mug"], "destination": {"kind": "point", "x": 50.0, "y": 50.0}}),
            422,
            "destination",
        ),
        (
            json!({"scene": "flat", "targets": ["Mug"], "destination": {"kind": "moon"}}),
            400,
            "",
        ),
    ];
    for (body, status, field) in cases {
        let (st, reply) = s.post(&trials, body.clone()).await;
        assert_eq!(st, status, "{body}: {reply}");
        if !field.is_empty() {
            assert_eq!(reply["error"]["field"], field, "{body}: {reply}");
        }
    }
    // No trial was stored by any of them.
    let (_, d) = s.get(&format!("/deployments/{id}")).await;
    assert_eq!(d["trials"], json!([]), "{d}");

    let (_, t) = s
        .post(
            &trials,
            json!({"scene": "flat", "targets": ["Wallet", "Mug"]}),
        )
        .await;
    let tid = t["trial"].as_i64().unwrap();
    let obs = format!("/trials/{tid}/observations");
    for (body, field) in [
        (
            json!({"container": "fridge", "found": true, "objects": ["Egg"]}),
            "found",
        ),
        (
            json!({"container": "fridge", "found": false, "found_targets": ["Egg"]}),
            "found_targets[0]",
        ),
    ] {
        let (st, reply) = s.post(&obs, body.clone()).await;
        assert_eq!(st, 422, "{body}: {reply}");
        assert_eq!(reply["error"]["field"], field, "{body}: {reply}");
    }
    // A target named only among the objects counts as found.
    let (st, r) = s
        .post(
            &obs,
            json!({"container": "counter", "found": false, "objects": ["Mug", "CellPhone"]}),
        )
        .await;
    assert_eq!(st, 200, "{r}");
    assert_eq!(r["found_in"], json!({"Mug": "counter"}));
    assert_eq!(r["status"], "searching");
}
