//! Helpers shared by the integration tests: OpenAI-compatible replies and endpoints pointed at a
//! loopback wiremock server.
#![allow(dead_code)]

use std::collections::BTreeMap;
use std::sync::Arc;

use ferret_llm::{Endpoint, EndpointConfig, LlmConfig, LlmOptions, LlmService};
use serde_json::{Value, json};
use wiremock::matchers::method;
use wiremock::{Mock, MockServer, Request, ResponseTemplate};

/// The key the tests configure; it must never show up anywhere but the Authorization header.
pub const KEY: &str = "sk-test-0123456789-secret";

/// A plain OpenAI chat completion.
pub fn completion(text: &str, prompt_tokens: u32, completion_tokens: u32) -> Value {
    json!({
        "id": "chatcmpl-1",
        "object": "chat.completion",
        "created": 1_700_000_000u32,
        "model": "test-model",
        "choices": [{
            "index": 0,
            "message": {"role": "assistant", "content": text},
            "finish_reason": "stop"
        }],
        "usage": {
            "prompt_tokens": prompt_tokens,
            "completion_tokens": completion_tokens,
            "total_tokens": prompt_tokens + completion_tokens
        }
    })
}

/// Settings for an endpoint at `server`, with fast retries.
pub fn config(server: &MockServer) -> EndpointConfig {
    let mut c = EndpointConfig::new(format!("{}/v1", server.uri()), "test-model");
    c.api_key_env = Some("FERRET_TEST_KEY".into());
    c.retry_base_ms = 10;
    c.retry_max_secs = 5.0;
    c.timeout_secs = 5.0;
    c
}

/// An endpoint at `server` holding [`KEY`].
pub fn endpoint(server: &MockServer) -> Endpoint {
    Endpoint::with_key("mock", config(server), Some(KEY.into()))
}

/// A request body's `messages[i].content`.
pub fn message_content(body: &Value, i: usize) -> String {
    body["messages"][i]["content"]
        .as_str()
        .unwrap_or_default()
        .to_string()
}

use ferret_world::{
    Container, Distances, Footprint, GroundTruth, House, ObjectType, Point, Polygon, Pose, Room,
    RoomType, SmallObject,
};

/// A three-room house along the x axis: kitchen (fridge at x=1, counter tops at 2 and 3),
/// bedroom (bed at 6), bedroom (bed at 10, dresser at 11); the start at x=0.5 in the kitchen.
/// A remote control lies in the dresser, an apple in the fridge.
pub fn small_scene(name: &str) -> (House, GroundTruth) {
    let square = |x0: f64| {
        Polygon::new(vec![
            Point::new(x0, 0.0),
            Point::new(x0 + 4.0, 0.0),
            Point::new(x0 + 4.0, 4.0),
            Point::new(x0, 4.0),
        ])
    };
    let room = |i: usize, t: &str| Room {
        id: format!("room|{i}"),
        room_type: RoomType::new(t),
        floor: square(4.0 * i as f64),
    };
    let container = |id: &str, t: &str, room: usize, x: f64| Container {
        id: id.into(),
        object_type: ObjectType::new(t),
        room: Some(room),
        position: Point::new(x, 2.0),
        footprint: Footprint {
            center: Point::new(x, 2.0),
            size_x: 0.5,
            size_z: 0.5,
            yaw_deg: 0.0,
        },
        access: None,
    };
    let house = House {
        name: name.into(),
        index: 0,
        rooms: vec![room(0, "Kitchen"), room(1, "Bedroom"), room(2, "Bedroom")],
        walls: vec![],
        doors: vec![],
        containers: vec![
            container("0|1", "Fridge", 0, 1.0),
            container("0|2", "CounterTop", 0, 2.0),
            container("0|3", "CounterTop", 0, 3.0),
            container("1|1", "Bed", 1, 6.0),
            container("2|1", "Bed", 2, 10.0),
            container("2|2", "Dresser", 2, 11.0),
        ],
        obstacles: vec![],
        start: Pose {
            position: Point::new(0.5, 2.0),
            yaw_deg: 0.0,
        },
        map: None,
    };
    let o = |t: &str| SmallObject {
        id: format!("{t}|1"),
        object_type: ObjectType::new(t),
    };
    let truth = GroundTruth::new(vec![
        vec![o("Apple")],
        vec![],
        vec![],
        vec![],
        vec![],
        vec![o("RemoteControl")],
    ]);
    (house, truth)
}

/// Straight-line distances between the start and the containers.
pub fn straight_distances(house: &House) -> Distances {
    let places: Vec<Point> = std::iter::once(house.start.position)
        .chain(house.containers.iter().map(|c| c.position))
        .collect();
    let n = places.len();
    let m = (0..n * n)
        .map(|k| places[k / n].distance(places[k % n]))
        .collect();
    Distances::from_matrix(house.containers.len(), m).expect("a valid matrix")
}

/// The last message of a request body (where the question is).
pub fn last_message(body: &Value) -> String {
    body["messages"]
        .as_array()
        .and_then(|m| m.last())
        .and_then(|m| m["content"].as_str())
        .unwrap_or_default()
        .to_string()
}

/// A loopback OpenAI-compatible server whose reply is computed from each request body, with its own
/// runtime so synchronous tests can drive it.
pub struct JsonServer {
    pub rt: tokio::runtime::Runtime,
    pub server: MockServer,
}

impl JsonServer {
    /// Starts the server; `respond` answers every POST.
    pub fn start(respond: impl Fn(&Value) -> ResponseTemplate + Send + Sync + 'static) -> Self {
        let rt = tokio::runtime::Runtime::new().unwrap();
        let server = rt.block_on(MockServer::start());
        rt.block_on(
            Mock::given(method("POST"))
                .respond_with(move |req: &Request| respond(&req.body_json().unwrap_or_default()))
                .mount(&server),
        );
        Self { rt, server }
    }

    /// Every request body received, in order.
    pub fn bodies(&self) -> Vec<Value> {
        self.rt
            .block_on(self.server.received_requests())
            .unwrap_or_default()
            .iter()
            .map(|r| r.body_json().unwrap_or_default())
            .collect()
    }

    /// A service with one endpoint `mock` at this server, as `edit` configures it.
    pub fn service(&self, edit: impl FnOnce(&mut EndpointConfig)) -> Arc<LlmService> {
        self.service_with(edit, LlmOptions::default())
    }

    /// The same with a response cache or offline mode.
    pub fn service_with(
        &self,
        edit: impl FnOnce(&mut EndpointConfig),
        options: LlmOptions,
    ) -> Arc<LlmService> {
        let mut c = EndpointConfig::new(format!("{}/v1", self.server.uri()), "test-model");
        c.retry_base_ms = 10;
        c.timeout_secs = 5.0;
        edit(&mut c);
        let config = LlmConfig {
            file: "test.toml".into(),
            endpoints: BTreeMap::from([("mock".to_string(), c)]),
            prompts: BTreeMap::new(),
        };
        Arc::new(LlmService::new(config, options).unwrap())
    }
}

/// One token of `logprobs.content` with its alternatives.
pub fn logprob(token: &str, p: f64, alts: &[(&str, f64)]) -> Value {
    json!({
        "token": token, "logprob": p.ln(), "bytes": null,
        "top_logprobs": alts.iter().map(|(t, p)| json!({"token": t, "logprob": p.ln(), "bytes": null})).collect::<Vec<_>>()
    })
}
