//! Teams through the HTTP API: several robots search one trial, each asking for its own next
//! container; no two are sent to the same one, each plans with what all of them saw (the
//! plan `ferret_plan::Search` makes with its teammates' claims left to them), a silent
//! robot's claim lapses, a team of one searches as one robot does, and every bad robot id is
//! refused naming the field. On PostgreSQL, robots on two replicas share one trial.

mod support;

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use support::server::{Server, start, start_with};
use support::{SCENE, contents};

use ferret_plan::{PlannerConfig, Search, SearchProblem, StrategyRegistry, TrialSpec};
use ferret_serve::{ServeOptions, ServiceOptions};
use ferret_world::{GridParams, ObjectType, SceneFile};
use serde_json::{Value, json};

async fn deployment(s: &Server, body: Value) -> i64 {
    let (status, dep) = s.post("/deployments", body).await;
    assert_eq!(status, 201, "{dep}");
    dep["id"].as_i64().unwrap()
}

/// Robot `robot`'s claim in trial `trial`: the trial's state, its container in `next`.
async fn claim(s: &Server, trial: i64, robot: &str) -> Value {
    let (status, reply) = s
        .post(&format!("/trials/{trial}/claims"), json!({"robot": robot}))
        .await;
    assert_eq!(status, 200, "{reply}");
    reply
}

/// A trial for the Wallet in deployment `id` searched by `robots`; its id.
async fn start_team(s: &Server, id: i64, robots: &[&str]) -> i64 {
    let team: Vec<Value> = robots.iter().map(|r| json!({"id": r})).collect();
    let (status, started) = s
        .post(
            &format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Wallet", "robots": team}),
        )
        .await;
    assert_eq!(status, 201, "{started}");
    started["trial"].as_i64().unwrap()
}

/// What robot `robot` reports after searching `container` of the scene, for target `target`.
fn observation(scene: &Value, robot: &str, container: &str, target: &str) -> Value {
    let seen = contents(scene, container);
    json!({"robot": robot, "container": container,
           "found": seen.iter().any(|s| s == target), "objects": seen})
}

/// The live claims of a state's robots, by robot.
fn claims(state: &Value) -> BTreeMap<String, String> {
    state["robots"]
        .as_array()
        .unwrap()
        .iter()
        .filter_map(|r| {
            Some((
                r["id"].as_str()?.to_string(),
                r["claim"].as_str()?.to_string(),
            ))
        })
        .collect()
}

fn strings(v: &Value) -> Vec<String> {
    v.as_array()
        .unwrap()
        .iter()
        .map(|s| s.as_str().unwrap().to_string())
        .collect()
}

/// The container robot `me` should be sent to next, planned here with the trial's strategy
/// from `state` (what each robot searched, every teammate's claim) and, when `me` reports
/// `searched` in the same request, that search too: its own searches move it, its teammates'
/// are known, their claims left to them.
fn expected_next(state: &Value, me: &str, searched: Option<&str>) -> Option<String> {
    let file = SceneFile::parse(SCENE, Path::new("flat.json")).unwrap();
    let scene = file.to_scene(Path::new("flat.json"), None).unwrap();
    let house = &scene.house;
    let (_, distances) = ferret_world::distance::build(house, &GridParams::default()).unwrap();
    let registry = StrategyRegistry::builtin(None, PlannerConfig::default(), 10);
    let strategy = registry.build(state["strategy"].as_str().unwrap()).unwrap();
    let trial = TrialSpec::single(ObjectType::new(state["target"].as_str().unwrap()));
    let problem = SearchProblem::new(house, &distances, &trial);
    let mut search = Search::start(strategy.as_ref(), &problem, None).unwrap();
    let by: BTreeMap<String, String> = state["robots"]
        .as_array()
        .unwrap()
        .iter()
        .flat_map(|r| {
            let id = r["id"].as_str().unwrap().to_string();
            strings(&r["searched"])
                .into_iter()
                .map(move |c| (c, id.clone()))
        })
        .collect();
    let file_json: Value = serde_json::from_str(SCENE).unwrap();
    let mut order = strings(&state["searched"]);
    order.extend(searched.map(str::to_string));
    for c in &order {
        let i = house.container_index(c).unwrap();
        let seen: Vec<ObjectType> = contents(&file_json, c)
            .iter()
            .map(ObjectType::new)
            .collect();
        if Some(c.as_str()) == searched || by.get(c).map(String::as_str) == Some(me) {
            search.record(i, seen).unwrap();
        } else {
            search.observe(i, seen).unwrap();
        }
    }
    if search.goal_holds() {
        return None;
    }
    let others: Vec<usize> = claims(state)
        .iter()
        .filter(|(r, c)| r.as_str() != me && Some(c.as_str()) != searched)
        .map(|(_, c)| house.container_index(c).unwrap())
        .collect();
    search
        .next_container_leaving(&others)
        .unwrap()
        .map(|c| house.containers[c].id.clone())
}

/// Three robots drive one trial to the end, one request at a time: at every reply the live
/// claims are distinct and none is searched; each robot's next container is the one its own
/// search chooses knowing what every teammate saw and leaving their claims to them; the trial
/// ends done with the makespan as its cost and every candidate replayed with the same team.
#[tokio::test(flavor = "multi_thread")]
async fn three_robots_never_share_a_container_and_plan_with_what_all_saw() {
    let s = start(None, None).await;
    let (_, scene) = s.get("/scenes/flat").await;
    let id = deployment(&s, json!({"seed": 2})).await;
    let (status, started) = s
        .post(
            &format!("/deployments/{id}/trials"),
            json!({"scene": "flat", "target": "Wallet",
                   "robots": [{"id": "a"}, {"id": "b"}, {"id": "c"}]}),
        )
        .await;
    assert_eq!(status, 201, "{started}");
    assert!(
        started["next"].is_null(),
        "a team's robots ask for their own"
    );
    let trial = started["trial"].as_i64().unwrap();
    let mut next: BTreeMap<String, String> = BTreeMap::new();
    let mut last = started;
    for r in ["a", "b", "c"] {
        let (status, reply) = s
            .post(&format!("/trials/{trial}/claims"), json!({"robot": r}))
            .await;
        assert_eq!(status, 200, "{reply}");
        next.insert(
            r.into(),
            reply["next"]["container"].as_str().unwrap().into(),
        );
        last = reply;
    }
    let firsts: BTreeSet<&String> = next.values().collect();
    assert_eq!(firsts.len(), 3, "three robots, three containers: {next:?}");
    // Asking again gives the same claim.
    let again = claim(&s, trial, "b").await;
    assert_eq!(
        again["next"]["container"].as_str(),
        Some(next["b"].as_str())
    );
    let mut steps = 0;
    while last["status"] == "searching" {
        // Each robot in turn reports its container.
        let Some((robot, container)) = (0..3)
            .map(|k| ["a", "b", "c"][(steps + k) % 3])
            .find_map(|r| next.get(r).map(|c| (r.to_string(), c.clone())))
        else {
            panic!("robots have nothing to do while the trial searches: {last}");
        };
        let expected = expected_next(&last, &robot, Some(&container));
        let (status, reply) = s
            .post(
                &format!("/trials/{trial}/observations"),
                observation(&scene, &robot, &container, "Wallet"),
            )
            .await;
        assert_eq!(status, 200, "{reply}");
        next.remove(&robot);
        if reply["status"] == "searching" {
            assert_eq!(
                reply["next"]["container"].as_str().map(str::to_string),
                expected,
                "robot {robot} after {container}: {reply}"
            );
            if let Some(n) = reply["next"]["container"].as_str() {
                next.insert(robot.clone(), n.to_string());
            }
        }
        let held = claims(&reply);
        let distinct: BTreeSet<&String> = held.values().collect();
        assert_eq!(
            distinct.len(),
            held.len(),
            "two robots hold one container: {reply}"
        );
        let searched = strings(&reply["searched"]);
        assert!(held.values().all(|c| !searched.contains(c)), "{reply}");
        last = reply;
        steps += 1;
        assert!(steps <= 7, "more searches than containers");
    }
    assert_eq!(last["status"], "done", "{last}");
    assert!(
        claims(&last).is_empty(),
        "an ended trial holds claims: {last}"
    );
    let (_, read) = s.get(&format!("/trials/{trial}")).await;
    assert!(claims(&read).is_empty(), "{read}");
    let searched = strings(&last["searched"]);
    let unique: BTreeSet<&String> = searched.iter().collect();
    assert_eq!(unique.len(), searched.len(), "a container searched twice");
    assert_eq!(last["found_in"]["Wallet"], "dresser");
    let robots = last["robots"].as_array().unwrap();
    let longest = robots
        .iter()
        .map(|r| r["cost_m"].as_f64().unwrap())
        .fold(0.0, f64::max);
    assert!(
        (last["cost_m"].as_f64().unwrap() - longest).abs() < 1e-9,
        "{last}"
    );
    let by_robot: usize = robots
        .iter()
        .map(|r| r["searched"].as_array().unwrap().len())
        .sum();
    assert_eq!(by_robot, searched.len());
    assert!(
        robots
            .iter()
            .filter(|r| !r["searched"].as_array().unwrap().is_empty())
            .count()
            >= 2
    );
    let replays = last["replays_m"].as_object().unwrap();
    assert_eq!(replays.len(), 3, "{last}");
    assert_eq!(replays[last["strategy"].as_str().unwrap()], last["cost_m"]);
    // The selector learnt from it as from any trial.
    let (_, dep) = s.get(&format!("/deployments/{id}")).await;
    let deployed: u64 = dep["per_strategy"]
        .as_array()
        .unwrap()
        .iter()
        .map(|r| r["deployed"].as_u64().unwrap())
        .sum();
    assert_eq!(deployed, 1, "{dep}");
    // A claim on an ended trial says so.
    let (status, over) = s
        .post(&format!("/trials/{trial}/claims"), json!({"robot": "a"}))
        .await;
    assert_eq!(status, 200, "{over}");
    assert_eq!(over["status"], "done");
    assert!(over["next"].is_null());
}

/// A team of one searches as one robot does: the same containers in the same order, the same
/// cost, under the same single strategy.
#[tokio::test(flavor = "multi_thread")]
async fn a_team_of_one_is_one_robot() {
    let s = start(None, None).await;
    let (_, scene) = s.get("/scenes/flat").await;
    for target in ["Wallet", "CellPhone", "Book"] {
        let alone = deployment(&s, json!({"strategies": ["model/uniform"]})).await;
        let team = deployment(&s, json!({"strategies": ["model/uniform"]})).await;
        let (_, mut one) = s
            .post(
                &format!("/deployments/{alone}/trials"),
                json!({"scene": "flat", "target": target}),
            )
            .await;
        while one["status"] == "searching" {
            let c = one["next"]["container"].as_str().unwrap().to_string();
            let mut body = observation(&scene, "x", &c, target);
            body.as_object_mut().unwrap().remove("robot");
            one = s
                .post(&format!("/trials/{}/observations", one["trial"]), body)
                .await
                .1;
        }
        let (_, started) = s
            .post(
                &format!("/deployments/{team}/trials"),
                json!({"scene": "flat", "target": target, "robots": [{"id": "solo"}]}),
            )
            .await;
        let trial = started["trial"].as_i64().unwrap();
        let (_, mut t) = s
            .post(&format!("/trials/{trial}/claims"), json!({"robot": "solo"}))
            .await;
        while t["status"] == "searching" {
            let c = t["next"]["container"].as_str().unwrap().to_string();
            t = s
                .post(
                    &format!("/trials/{trial}/observations"),
                    observation(&scene, "solo", &c, target),
                )
                .await
                .1;
        }
        assert_eq!(t["searched"], one["searched"], "{target}");
        assert!(
            (t["cost_m"].as_f64().unwrap() - one["cost_m"].as_f64().unwrap()).abs() < 1e-9,
            "{target}: {t} vs {one}"
        );
    }
}

/// A robot that claims and goes silent loses its claim after the claim time: a teammate is
/// sent there. Its late word is still taken (the container had not been searched), and the
/// teammate that then reports the same container is told who searched it.
#[tokio::test(flavor = "multi_thread")]
async fn a_silent_robots_claim_lapses() {
    let options = ServiceOptions {
        claim_ttl: Duration::from_millis(400),
        ..ServiceOptions::default()
    };
    let s = start_with(None, None, options, ServeOptions::default()).await;
    let (_, scene) = s.get("/scenes/flat").await;
    let id = deployment(&s, json!({"strategies": ["model/uniform"]})).await;
    let trial = start_team(&s, id, &["a", "b"]).await;
    let a = claim(&s, trial, "a").await;
    let first = a["next"]["container"].as_str().unwrap().to_string();
    let b = claim(&s, trial, "b").await;
    let held = b["next"]["container"].as_str().unwrap().to_string();
    assert_ne!(held, first, "a's claim is a's while it lasts");
    // b gives its claim up by searching it; a stays silent past its claim time.
    let (status, _) = s
        .post(
            &format!("/trials/{trial}/observations"),
            observation(&scene, "b", &held, "Wallet"),
        )
        .await;
    assert_eq!(status, 200);
    tokio::time::sleep(Duration::from_millis(600)).await;
    let (_, now) = s.get(&format!("/trials/{trial}")).await;
    let a_now = &now["robots"][0];
    assert_eq!(a_now["id"], "a");
    assert!(a_now["claim"].is_null(), "a's claim lapsed: {now}");
    assert!(a_now["heard_s_ago"].as_f64().unwrap() >= 0.5, "{now}");
    // b plans as if a held nothing; with a's claim still there it would be kept off it.
    let b = claim(&s, trial, "b").await;
    let b_next = b["next"]["container"].as_str().unwrap().to_string();
    assert_eq!(Some(b_next.clone()), expected_next(&now, "b", None), "{b}");
    let mut with_a = now.clone();
    with_a["robots"][0]["claim"] = json!(first);
    let kept_off = expected_next(&with_a, "b", None);
    assert_ne!(kept_off.as_deref(), Some(first.as_str()));
    // A trial whose claims lapse and come back to the first choice: a's container goes to b.
    let trial = start_team(&s, id, &["a", "b"]).await;
    let a = claim(&s, trial, "a").await;
    let first = a["next"]["container"].as_str().unwrap().to_string();
    tokio::time::sleep(Duration::from_millis(600)).await;
    // Same start, same knowledge: b's best is a's, now free.
    let b = claim(&s, trial, "b").await;
    assert_eq!(b["next"]["container"].as_str(), Some(first.as_str()), "{b}");
    // a comes back and reports it first: taken, and b's claim there let go.
    let (status, late) = s
        .post(
            &format!("/trials/{trial}/observations"),
            observation(&scene, "a", &first, "Wallet"),
        )
        .await;
    assert_eq!(status, 200, "{late}");
    assert!(claims(&late).values().all(|c| *c != first), "{late}");
    let (status, again) = s
        .post(
            &format!("/trials/{trial}/observations"),
            observation(&scene, "b", &first, "Wallet"),
        )
        .await;
    assert_eq!(status, 409, "{again}");
    assert!(
        again["error"]["message"]
            .as_str()
            .unwrap()
            .contains("by robot a"),
        "{again}"
    );
}

/// Every bad robot id gets a 4xx naming the field and saying what is wrong; nothing is stored
/// for a refused request.
#[tokio::test(flavor = "multi_thread")]
async fn bad_robots_are_refused_naming_the_field() {
    let s = start(None, None).await;
    let (_, scene) = s.get("/scenes/flat").await;
    let id = deployment(&s, json!({})).await;
    let start = |robots: Value| json!({"scene": "flat", "target": "Wallet", "robots": robots});
    let path = format!("/deployments/{id}/trials");
    let cases = [
        (
            json!([{"id": "a"}, {"id": "a"}]),
            "robots[1].id",
            "given twice",
        ),
        (json!([]), "robots", "1 to 4"),
        (
            json!([{"id": "a"}, {"id": "b"}, {"id": "c"}, {"id": "d"}, {"id": "e"}]),
            "robots",
            "1 to 4",
        ),
        (json!([{"id": "a b"}]), "robots[0].id", "not a robot id"),
        (
            json!([{"id": "a", "pose": [500.0, 0.0, 0.0]}]),
            "robots[0].pose",
            "",
        ),
    ];
    for (robots, field, says) in cases {
        let (status, reply) = s.post(&path, start(robots.clone())).await;
        assert_eq!(status, 422, "{robots}: {reply}");
        assert_eq!(reply["error"]["field"], field, "{reply}");
        assert!(
            reply["error"]["message"].as_str().unwrap().contains(says),
            "{reply}"
        );
    }
    let (_, dep) = s.get(&format!("/deployments/{id}")).await;
    assert_eq!(dep["trials"], json!([]), "a refused start stored a trial");

    let (_, home) = s
        .post(
            &path,
            start(json!([{"id": "kitchen-bot"}, {"id": "hall-bot"}])),
        )
        .await;
    let (_, other) = s.post(&path, start(json!([{"id": "upstairs-bot"}]))).await;
    let (home, other) = (
        home["trial"].as_i64().unwrap(),
        other["trial"].as_i64().unwrap(),
    );
    let (_, single) = s
        .post(&path, json!({"scene": "flat", "target": "Wallet"}))
        .await;
    let single = single["trial"].as_i64().unwrap();
    // A robot of another trial.
    let (status, reply) = s
        .post(
            &format!("/trials/{home}/claims"),
            json!({"robot": "upstairs-bot"}),
        )
        .await;
    assert_eq!(status, 422, "{reply}");
    assert_eq!(reply["error"]["field"], "robot");
    let message = reply["error"]["message"].as_str().unwrap();
    assert!(message.contains("kitchen-bot, hall-bot"), "{reply}");
    let (status, reply) = s
        .post(
            &format!("/trials/{other}/observations"),
            observation(&scene, "kitchen-bot", "sofa", "Wallet"),
        )
        .await;
    assert_eq!(
        (status, reply["error"]["field"].as_str()),
        (422, Some("robot")),
        "{reply}"
    );
    // A team's observation without a robot.
    let mut anonymous = observation(&scene, "x", "sofa", "Wallet");
    anonymous.as_object_mut().unwrap().remove("robot");
    let (status, reply) = s
        .post(&format!("/trials/{home}/observations"), anonymous)
        .await;
    assert_eq!(
        (status, reply["error"]["field"].as_str()),
        (422, Some("robot")),
        "{reply}"
    );
    // A robot in a trial without a team, and a claim there.
    let (status, reply) = s
        .post(
            &format!("/trials/{single}/observations"),
            observation(&scene, "kitchen-bot", "sofa", "Wallet"),
        )
        .await;
    assert_eq!(
        (status, reply["error"]["field"].as_str()),
        (422, Some("robot")),
        "{reply}"
    );
    let (status, reply) = s
        .post(
            &format!("/trials/{single}/claims"),
            json!({"robot": "kitchen-bot"}),
        )
        .await;
    assert_eq!(
        (status, reply["error"]["field"].as_str()),
        (422, Some("robot")),
        "{reply}"
    );
    // None of it was stored.
    for t in [home, other, single] {
        let (_, state) = s.get(&format!("/trials/{t}")).await;
        assert_eq!(state["searched"], json!([]), "{state}");
    }
    // Abandoned, a team's trial costs its makespan, not the sum of its robots' ways.
    let abandoned = start_team(&s, id, &["a", "b"]).await;
    let first = claim(&s, abandoned, "a").await;
    let second = claim(&s, abandoned, "b").await;
    let mut ways = Vec::new();
    for (robot, c) in [("a", &first), ("b", &second)] {
        let c = c["next"]["container"].as_str().unwrap();
        let (status, r) = s
            .post(
                &format!("/trials/{abandoned}/observations"),
                json!({"robot": robot, "container": c, "found": false, "objects": []}),
            )
            .await;
        assert_eq!(status, 200, "{r}");
        ways = r["robots"]
            .as_array()
            .unwrap()
            .iter()
            .map(|x| x["cost_m"].as_f64().unwrap())
            .collect();
    }
    let (status, ended) = s
        .post(&format!("/trials/{abandoned}/abandon"), json!({}))
        .await;
    assert_eq!(status, 200, "{ended}");
    assert_eq!(ended["status"], "abandoned");
    let longest = ways.iter().copied().fold(0.0, f64::max);
    assert!(ways.iter().all(|w| *w > 0.0), "{ways:?}");
    assert!(
        (ended["cost_m"].as_f64().unwrap() - longest).abs() < 1e-9,
        "{ended}"
    );
    // A container a teammate searched: 409 naming who.
    let (_, _) = s
        .post(
            &format!("/trials/{home}/observations"),
            observation(&scene, "kitchen-bot", "sofa", "Wallet"),
        )
        .await;
    let (status, reply) = s
        .post(
            &format!("/trials/{home}/observations"),
            observation(&scene, "hall-bot", "sofa", "Wallet"),
        )
        .await;
    assert_eq!(status, 409, "{reply}");
    assert!(
        reply["error"]["message"]
            .as_str()
            .unwrap()
            .contains("by robot kitchen-bot"),
        "{reply}"
    );
}

/// Robots racing for their next containers at once get distinct ones.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn robots_racing_for_claims_get_distinct_containers() {
    let s = Arc::new(start(None, None).await);
    for round in 0..5 {
        let id = deployment(&s, json!({"seed": round})).await;
        let (_, started) = s
            .post(
                &format!("/deployments/{id}/trials"),
                json!({"scene": "flat", "target": "Wallet",
                       "robots": [{"id": "a"}, {"id": "b"}, {"id": "c"}, {"id": "d"}]}),
            )
            .await;
        let trial = started["trial"].as_i64().unwrap();
        let asks: Vec<_> = ["a", "b", "c", "d"]
            .into_iter()
            .map(|r| {
                let s = s.clone();
                tokio::spawn(async move {
                    s.post(&format!("/trials/{trial}/claims"), json!({"robot": r}))
                        .await
                })
            })
            .collect();
        let mut got = BTreeSet::new();
        for a in asks {
            let (status, reply) = a.await.unwrap();
            assert_eq!(status, 200, "{reply}");
            assert!(got.insert(reply["next"]["container"].as_str().unwrap().to_string()));
        }
        assert_eq!(got.len(), 4);
    }
}

/// Three robots of each of four trials, each robot on its own replica of two, all at once:
/// no container is searched twice or claimed by two robots, every acknowledged observation is
/// stored, every trial ends done.
#[tokio::test(flavor = "multi_thread", worker_threads = 4)]
async fn robots_on_two_replicas_share_one_trial() {
    let Some(url) = support::postgres_or_skip("robots_on_two_replicas_share_one_trial") else {
        return;
    };
    let (a, ha) = support::server::replica(&url).await;
    let (b, hb) = support::server::replica(&url).await;
    let client = reqwest::Client::new();
    let scene: Value = client
        .get(format!("{a}/scenes/flat"))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let dep: Value = client
        .post(format!("{a}/deployments"))
        .json(&json!({"seed": 4}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    let id = dep["id"].as_i64().unwrap();
    let mut runs = Vec::new();
    let mut trials = Vec::new();
    for t in 0..4 {
        let started: Value = client
            .post(format!("{b}/deployments/{id}/trials"))
            .json(&json!({"scene": "flat", "target": "Wallet",
                          "robots": [{"id": "r0"}, {"id": "r1"}, {"id": "r2"}]}))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        let trial = started["trial"].as_i64().unwrap();
        trials.push(trial);
        for r in 0..3 {
            let base = if (r + t) % 2 == 0 {
                a.clone()
            } else {
                b.clone()
            };
            let (client, scene) = (client.clone(), scene.clone());
            runs.push(tokio::spawn(async move {
                team_robot(&client, &base, trial, &format!("r{r}"), &scene).await
            }));
        }
    }
    let mut acked: BTreeMap<i64, Vec<(String, String)>> = BTreeMap::new();
    for run in runs {
        let (trial, mine) = run.await.unwrap();
        acked.entry(trial).or_default().extend(mine);
    }
    for trial in trials {
        let state: Value = client
            .get(format!("{a}/trials/{trial}"))
            .send()
            .await
            .unwrap()
            .json()
            .await
            .unwrap();
        assert_eq!(state["status"], "done", "{state}");
        let searched = strings(&state["searched"]);
        let unique: BTreeSet<&String> = searched.iter().collect();
        assert_eq!(unique.len(), searched.len(), "searched twice: {state}");
        let mut stored: Vec<(String, String)> = Vec::new();
        for r in state["robots"].as_array().unwrap() {
            for c in strings(&r["searched"]) {
                stored.push((r["id"].as_str().unwrap().to_string(), c));
            }
        }
        stored.sort();
        let mut mine = acked.remove(&trial).unwrap_or_default();
        mine.sort();
        assert_eq!(
            stored, mine,
            "trial {trial}: acknowledged observations lost or added"
        );
    }
    ha.abort();
    hb.abort();
}

/// One robot of a team: claims, searches, reports, until its trial ends. Returns the trial and
/// the observations acknowledged to it (robot, container).
async fn team_robot(
    client: &reqwest::Client,
    base: &str,
    trial: i64,
    robot: &str,
    scene: &Value,
) -> (i64, Vec<(String, String)>) {
    let mut acked = Vec::new();
    let mut reply: Value = client
        .post(format!("{base}/trials/{trial}/claims"))
        .json(&json!({"robot": robot}))
        .send()
        .await
        .unwrap()
        .json()
        .await
        .unwrap();
    for _ in 0..100 {
        if reply["status"] != "searching" {
            break;
        }
        let body = match reply["next"]["container"].as_str() {
            Some(c) => {
                let held = claims(&reply);
                let distinct: BTreeSet<&String> = held.values().collect();
                assert_eq!(distinct.len(), held.len(), "claimed twice: {reply}");
                Some(observation(scene, robot, c, "Wallet"))
            }
            None => None,
        };
        let r = match &body {
            Some(b) => client
                .post(format!("{base}/trials/{trial}/observations"))
                .json(b),
            None => {
                tokio::time::sleep(Duration::from_millis(20)).await;
                client
                    .post(format!("{base}/trials/{trial}/claims"))
                    .json(&json!({"robot": robot}))
            }
        };
        let response = r.send().await.unwrap();
        let status = response.status().as_u16();
        let v: Value = response.json().await.unwrap();
        match (status, &body) {
            (200, Some(b)) => {
                acked.push((
                    robot.to_string(),
                    b["container"].as_str().unwrap().to_string(),
                ));
                reply = v;
            }
            (200, None) => reply = v,
            // The trial ended while this robot was on its way.
            (409, _) if v["error"]["field"] == "trial" => break,
            _ => panic!("robot {robot}: {status} {v}"),
        }
    }
    (trial, acked)
}
