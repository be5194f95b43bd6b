//! The event stream's contract: every event a stream sends, and the data of each, is what the
//! OpenAPI document says `GET /events` sends (its OpenAPI 3.2 `itemSchema`, and each event's
//! `contentSchema`), checked with a JSON Schema validator on the events of real trials.

mod support;

use std::time::Duration;

use ferret_serve::events::{DeploymentEvent, EVENT_SCHEMAS, HelloEvent, ResyncEvent};
use serde_json::{Value, json};
use support::contents;
use support::events::Stream;
use support::server::{Server, start};

/// Checks one event (its name and its data's text) against the document: the item schema of
/// `GET /events`, then the data against the schema its `contentSchema` names.
fn check(doc: &Value, name: &str, data: &str) {
    let item = &doc["paths"]["/events"]["get"]["responses"]["200"]["content"]["text/event-stream"]
        ["itemSchema"];
    let with_components = |schema: &Value| json!({"$schema": "https://json-schema.org/draft/2020-12/schema", "allOf": [schema], "components": doc["components"]});
    let event = json!({"event": name, "data": data});
    let v = jsonschema::validator_for(&with_components(item)).expect("the item schema compiles");
    let errors: Vec<String> = v.iter_errors(&event).map(|e| e.to_string()).collect();
    assert!(errors.is_empty(), "event {event}: {errors:?}");
    let kind = item["oneOf"]
        .as_array()
        .unwrap()
        .iter()
        .find(|k| k["properties"]["event"]["const"] == name)
        .unwrap_or_else(|| panic!("no kind `{name}` in the document"));
    let content = &kind["properties"]["data"]["contentSchema"];
    let v = jsonschema::validator_for(&with_components(content)).expect("the data schema compiles");
    let parsed: Value = serde_json::from_str(data).unwrap();
    let errors: Vec<String> = v.iter_errors(&parsed).map(|e| e.to_string()).collect();
    assert!(errors.is_empty(), "`{name}` data {data}: {errors:?}");
}

/// Reads events until `until` says stop, checking each; returns their names.
async fn read_checked(
    doc: &Value,
    stream: &mut Stream,
    until: impl Fn(&str, &Value) -> bool,
) -> Vec<String> {
    let mut names = Vec::new();
    loop {
        let (name, data) = stream.next(Duration::from_secs(10)).await;
        check(doc, &name, &data.to_string());
        names.push(name.clone());
        if until(&name, &data) {
            return names;
        }
    }
}

async fn run_to_end(s: &Server, scene: &Value, deployment: i64, start: Value) -> i64 {
    let (status, mut t) = s
        .post(&format!("/deployments/{deployment}/trials"), start)
        .await;
    assert_eq!(status, 201, "{t}");
    let id = t["trial"].as_i64().unwrap();
    let targets: Vec<String> = serde_json::from_value(t["targets"].clone()).unwrap();
    while t["status"] == "searching" {
        let next = t["next"]["container"].as_str().unwrap().to_string();
        let seen = contents(scene, &next);
        let found: Vec<&String> = targets.iter().filter(|x| seen.contains(x)).collect();
        let (status, r) = s
            .post(
                &format!("/trials/{id}/observations"),
                json!({"container": next, "found": !found.is_empty(), "found_targets": found, "objects": seen}),
            )
            .await;
        assert_eq!(status, 200, "{r}");
        t = r;
    }
    id
}

#[tokio::test(flavor = "multi_thread")]
async fn every_event_is_what_the_document_says() {
    let s = start(None, None).await;
    let (status, doc) = s.get("/openapi.json").await;
    assert_eq!(status, 200);
    assert_eq!(doc["openapi"], "3.2.0");
    let (_, scene) = s.get("/scenes/flat").await;
    let (status, stream) = Stream::open(&s, None).await;
    assert_eq!(status, 200);
    let mut stream = stream.unwrap();
    let (_, dep) = s.post("/deployments", json!({})).await;
    let id = dep["id"].as_i64().unwrap();
    let one = run_to_end(&s, &scene, id, json!({"scene": "flat", "target": "Wallet"})).await;
    let task = run_to_end(
        &s,
        &scene,
        id,
        json!({"scene": "flat", "targets": ["Book", "Pillow"], "destination": {"kind": "start"}}),
    )
    .await;
    let names = read_checked(&doc, &mut stream, |name, data| {
        name == "trial" && data["trial"] == task && data["status"] == "done"
    })
    .await;
    assert_eq!(names[0], "hello");
    assert!(names.contains(&"deployment".to_string()));
    assert!(
        names.iter().filter(|n| *n == "trial").count() > 4,
        "{names:?}"
    );
    assert!(one < task);
    // The events no trial makes here, from the types the server sends them from.
    for data in [
        serde_json::to_string(&ResyncEvent { missed: Some(12) }).unwrap(),
        serde_json::to_string(&ResyncEvent { missed: None }).unwrap(),
    ] {
        check(&doc, "resync", &data);
    }
    check(
        &doc,
        "deployment",
        &serde_json::to_string(&DeploymentEvent { deployment: 3 }).unwrap(),
    );
    check(
        &doc,
        "hello",
        &serde_json::to_string(&HelloEvent { shared: true }).unwrap(),
    );
    // Every kind the server sends is in the document, and nothing else is.
    let kinds: Vec<&str> = doc["paths"]["/events"]["get"]["responses"]["200"]["content"]
        ["text/event-stream"]["itemSchema"]["oneOf"]
        .as_array()
        .unwrap()
        .iter()
        .map(|k| k["properties"]["event"]["const"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, EVENT_SCHEMAS.map(|(n, _)| n));
}

/// A field the document does not list, or one it requires missing, is caught: the check above
/// can fail.
#[tokio::test(flavor = "multi_thread")]
async fn an_event_unlike_the_document_is_refused() {
    let s = start(None, None).await;
    let (_, doc) = s.get("/openapi.json").await;
    for (name, data) in [
        ("hello", r#"{"shared": true, "extra": 1}"#),
        ("hello", r#"{}"#),
        ("deployment", r#"{"deployment": "seven"}"#),
        ("trial", r#"{"trial": 1}"#),
        ("bye", r#"{}"#),
    ] {
        let caught = std::panic::catch_unwind(|| check(&doc, name, data));
        assert!(caught.is_err(), "{name} {data} passed the check");
    }
}
