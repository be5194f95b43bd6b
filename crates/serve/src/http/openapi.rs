//! The OpenAPI document: derived from the types and handlers, then completed with what the
//! service enforces and the derive cannot say.

use serde_json::{Value, json};
use utoipa::OpenApi;

use crate::api::{ErrorBody, ErrorDetail};
use crate::model::SceneLimits;

use super::HttpOptions;

/// The OpenAPI document as derived from the types; [`document`] adds what the derive cannot say.
#[derive(OpenApi)]
#[openapi(
    info(
        title = "ferret serve",
        description = "LLM-informed object search for a real robot: scenes, deployments with strategy selection, trials step by step. See docs/serve.md."
    ),
    components(schemas(
        ErrorBody,
        ErrorDetail,
        crate::events::HelloEvent,
        crate::events::TrialEvent,
        crate::events::DeploymentEvent,
        crate::events::ResyncEvent
    ))
)]
pub struct ApiDoc;

/// Statuses every route may answer besides its own, and why.
const COMMON_STATUSES: [(u16, &str); 3] = [
    (
        403,
        "The Host header names another server, or a browser Origin is not allowed",
    ),
    (500, "The server's own failure (its database)"),
    (
        503,
        "The database is out of reach or busy for now: retry, here or on another replica",
    ),
];

/// Statuses of every route that takes a body.
const BODY_STATUSES: [(u16, &str); 6] = [
    (
        400,
        "Malformed JSON, not an object, a missing or mistyped field",
    ),
    (
        409,
        "The same request id is still in flight (retry later), or a conflicting state",
    ),
    (
        408,
        "The body did not arrive within the server's body timeout",
    ),
    (413, "The body is larger than the server's limit"),
    (415, "The body is not application/json"),
    (
        422,
        "A value the server cannot use (named in `field`), or a request id used before with another body",
    ),
];

/// The OpenAPI document this server serves: the derived one, plus what the service enforces
/// and the derive cannot say (the scene schema with this server's limits, the strategies it
/// offers, unique items, patterns of array items, every status a route can answer, the token).
pub fn document(options: &HttpOptions, strategies: &[String], limits: &SceneLimits) -> Value {
    let mut doc = serde_json::to_value(super::routes().1).unwrap_or_default();
    let error_ref =
        json!({"application/json": {"schema": {"$ref": "#/components/schemas/ErrorBody"}}});
    if let Some(schemas) = doc
        .pointer_mut("/components/schemas")
        .and_then(Value::as_object_mut)
    {
        schemas.insert("Scene".into(), crate::api::scene_schema(limits));
    }
    if let Some(scene) = doc.pointer_mut("/components/schemas/UploadScene/properties/scene") {
        *scene = json!({
            "$ref": "#/components/schemas/Scene",
            "description": "The scene, as in a scene file (version 1, without `map`)."
        });
    }
    if let Some(s) = doc.pointer_mut("/components/schemas/CreateDeployment/properties/strategies") {
        s["uniqueItems"] = json!(true);
        s["items"] = json!({"type": "string", "enum": strategies});
    }
    if let Some(items) = doc.pointer_mut("/components/schemas/Observe/properties/objects/items") {
        *items = json!({"type": "string", "pattern": crate::api::TYPE_NAME_PATTERN});
    }
    if let Some(start) = doc.pointer_mut("/components/schemas/StartTrial") {
        // One target or a task's targets, never both (a null one counts as absent).
        start["oneOf"] = json!([
            {"required": ["target"], "properties": {"target": {"type": "string"}}},
            {"required": ["targets"], "properties": {"targets": {"type": "array"}}}
        ]);
    }
    // Each kind of destination takes its own fields only (serde refuses others).
    if let Some(kinds) = doc
        .pointer_mut("/components/schemas/DestinationBody/oneOf")
        .and_then(Value::as_array_mut)
    {
        for kind in kinds {
            kind["additionalProperties"] = json!(false);
        }
    }
    for at in [
        "/components/schemas/StartTrial/properties/targets",
        "/components/schemas/Observe/properties/found_targets",
    ] {
        if let Some(targets) = doc.pointer_mut(at) {
            targets["uniqueItems"] = json!(true);
            targets["items"] = json!({"type": "string", "pattern": crate::api::TYPE_NAME_PATTERN});
        }
    }
    if let Some(pose) = doc.pointer_mut("/components/schemas/StartTrial/properties/pose") {
        *pose = json!({
            "type": ["array", "null"],
            "items": {"type": "number"},
            "minItems": 3,
            "maxItems": 3,
            "description": "The robot's pose `[x, y, yaw°]` in the map frame, yaw within ±360°; default: the scene's start."
        });
    }
    describe_event_stream(&mut doc);
    let paths: Vec<(String, String)> = doc
        .pointer("/paths")
        .and_then(Value::as_object)
        .map(|paths| {
            paths
                .iter()
                .flat_map(|(path, ops)| {
                    ops.as_object()
                        .into_iter()
                        .flat_map(|o| o.keys())
                        .map(move |method| (path.clone(), method.clone()))
                })
                .collect()
        })
        .unwrap_or_default();
    for (path, method) in paths {
        let Some(op) = doc
            .pointer_mut(&format!("/paths/{}/{method}", path.replace('/', "~1")))
            .and_then(Value::as_object_mut)
        else {
            continue;
        };
        let mut all: Vec<(u16, &str)> = Vec::new();
        if op.contains_key("requestBody") {
            all.extend(BODY_STATUSES);
        }
        all.extend(COMMON_STATUSES);
        if options.token.is_some() && path != "/health" {
            all.push((401, "The bearer token is missing or wrong"));
            op.insert("security".into(), json!([{"bearer": []}]));
        }
        let responses = op
            .entry("responses")
            .or_insert_with(|| json!({}))
            .as_object_mut();
        if let Some(responses) = responses {
            // A route's own description of a status (in its attribute) comes first.
            for (status, description) in all {
                responses
                    .entry(status.to_string())
                    .or_insert_with(|| json!({"description": description, "content": error_ref}));
            }
        }
    }
    for (path, method, status, links) in links() {
        if let Some(response) = doc.pointer_mut(&format!(
            "/paths/{}/{method}/responses/{status}",
            path.replace('/', "~1")
        )) {
            response["links"] = links;
        }
    }
    if options.token.is_some() {
        doc["components"]["securitySchemes"] =
            json!({"bearer": {"type": "http", "scheme": "bearer"}});
    }
    doc
}

/// How the objects one route creates are reached by the others (OpenAPI links), so that a client
/// generator or a contract tester can follow a deployment to its trials and their observations.
fn links() -> Vec<(&'static str, &'static str, u16, Value)> {
    let to = |operation: &str, parameter: &str, from: &str| json!({"operationId": operation, "parameters": {parameter: format!("$response.body#/{from}")}});
    let trial = || {
        json!({
            "GetTrial": to("get_trial", "id", "trial"),
            "Observe": to("observe", "id", "trial"),
            "Claim": to("claim", "id", "trial"),
            "Abandon": to("abandon", "id", "trial"),
        })
    };
    vec![
        (
            "/scenes",
            "post",
            201,
            json!({"GetScene": to("get_scene", "name", "name")}),
        ),
        (
            "/deployments",
            "post",
            201,
            json!({
                "GetDeployment": to("get_deployment", "id", "id"),
                "StartTrial": to("start_trial", "id", "id"),
            }),
        ),
        ("/deployments/{id}/trials", "post", 201, trial()),
        ("/trials/{id}/observations", "post", 200, trial()),
        ("/trials/{id}/claims", "post", 200, trial()),
    ]
}

/// `GET /events` as OpenAPI 3.2 describes an event stream: `itemSchema` is one event, an
/// object of its `event` name and its `data`, one line of JSON whose schema is the type the
/// server serializes it from ([`EVENT_SCHEMAS`](crate::events::EVENT_SCHEMAS)).
fn describe_event_stream(doc: &mut Value) {
    doc["openapi"] = json!("3.2.0");
    let kinds: Vec<Value> = crate::events::EVENT_SCHEMAS
        .iter()
        .map(|(name, schema)| {
            json!({
                "type": "object",
                "title": name,
                "required": ["event", "data"],
                "additionalProperties": false,
                "properties": {
                    "event": {"const": name},
                    "data": {
                        "type": "string",
                        "contentMediaType": "application/json",
                        "contentSchema": {"$ref": format!("#/components/schemas/{schema}")}
                    },
                    "id": {"type": "string"},
                    "retry": {"type": "integer", "minimum": 0}
                }
            })
        })
        .collect();
    if let Some(ok) = doc.pointer_mut("/paths/~1events/get/responses/200/content") {
        *ok = json!({"text/event-stream": {"itemSchema": {"oneOf": kinds}}});
    }
}
