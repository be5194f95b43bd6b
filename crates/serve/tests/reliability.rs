//! The service on a robot's network: the guards against cross-site requests and DNS rebinding,
//! limits on what clients upload and how long they may hold connections, bounded memory for
//! grids, exact replies to retries, and a health check that tells a broken database. Every
//! server listens on 127.0.0.1 on an ephemeral port; connection tests are bounded in count and
//! time.

mod support;

use std::io::{Read, Write};
use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use ferret_plan::{PlannerConfig, Strategy, StrategyRegistry};
use ferret_serve::{
    HttpOptions, SceneLimits, ServeOptions, Service, ServiceOptions, Store, document,
};
use ferret_world::{GridParams, SceneFile};
use serde_json::{Value, json};

/// Two rooms with a door, three containers.
fn scene(name: &str) -> Value {
    json!({
        "ferret_scene": 1, "name": name,
        "rooms": [
            {"name": "kitchen", "type": "Kitchen", "polygon": [[0,0],[4,0],[4,4],[0,4]]},
            {"name": "bedroom", "type": "Bedroom", "polygon": [[4,0],[8,0],[8,4],[4,4]]}
        ],
        "doors": [{"from": [4, 1], "to": [4, 2]}],
        "containers": [
            {"id": "fridge", "type": "Fridge", "pose": [0.5, 3.4, 0], "contents": ["Egg"]},
            {"id": "counter", "type": "CounterTop", "pose": [2.5, 3.6, 0], "size": [1.5, 0.6], "contents": ["CellPhone"]},
            {"id": "bed", "type": "Bed", "pose": [6.5, 2.0, 0], "size": [2.0, 1.6], "contents": ["Pillow"]}
        ],
        "start": [1.0, 1.0, 0]
    })
}

/// One square room `side` metres wide with two containers.
fn square(name: &str, side: f64) -> Value {
    json!({
        "ferret_scene": 1, "name": name,
        "rooms": [{"name": "hall", "type": "LivingRoom", "polygon": [[0,0],[side,0],[side,side],[0,side]]}],
        "containers": [
            {"id": "a", "type": "Dresser", "pose": [side / 2.0, side / 2.0, 0]},
            {"id": "b", "type": "Bed", "pose": [1.0, 1.0, 0]}
        ],
        "start": [side / 3.0, side / 3.0, 0]
    })
}

fn strategies() -> Vec<Arc<dyn Strategy>> {
    let registry = StrategyRegistry::builtin(None, PlannerConfig::default(), 10);
    ["optimistic+greedy", "model/uniform"]
        .iter()
        .map(|s| registry.build(s).unwrap())
        .collect()
}

struct Server {
    addr: std::net::SocketAddr,
    service: Arc<Service>,
    /// Runs the server; dropped with it.
    _rt: tokio::runtime::Runtime,
}

#[derive(Default)]
struct Setup {
    service: ServiceOptions,
    serve: ServeOptions,
    http: HttpOptions,
    db: Option<std::path::PathBuf>,
}

fn start(setup: Setup) -> Server {
    let rt = tokio::runtime::Builder::new_multi_thread()
        .worker_threads(2)
        .enable_all()
        .build()
        .unwrap();
    let store = match &setup.db {
        Some(p) => Store::open(p).unwrap(),
        None => support::store(),
    };
    let service = Arc::new(
        Service::with_options(store, GridParams::default(), strategies(), setup.service).unwrap(),
    );
    let text = scene("flat").to_string();
    let flat = SceneFile::parse(&text, Path::new("flat.json"))
        .unwrap()
        .to_scene(Path::new("flat.json"), None)
        .unwrap();
    service.add_scene("flat", flat).unwrap();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let addr = listener.local_addr().unwrap();
    let http = HttpOptions {
        listen: Some(addr),
        ..setup.http
    };
    let app = ferret_serve::router(service.clone(), &http).unwrap();
    rt.spawn(ferret_serve::serve(
        listener,
        app,
        setup.serve,
        std::future::pending(),
    ));
    Server {
        addr,
        service,
        _rt: rt,
    }
}

/// A raw HTTP/1.1 exchange on a fresh connection: status, body bytes.
fn raw(addr: std::net::SocketAddr, request: &str) -> (u16, Vec<u8>) {
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    s.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
    s.write_all(request.as_bytes()).unwrap();
    let mut out = Vec::new();
    let _ = s.read_to_end(&mut out);
    let text = String::from_utf8_lossy(&out);
    let status = text
        .split_whitespace()
        .nth(1)
        .and_then(|c| c.parse().ok())
        .unwrap_or(0);
    let body = out
        .windows(4)
        .position(|w| w == b"\r\n\r\n")
        .map(|i| out[i + 4..].to_vec())
        .unwrap_or_default();
    (status, body)
}

/// A `POST` with these headers (each `Name: value`) and body, the connection closed after it.
fn post(s: &Server, path: &str, headers: &[&str], body: &str) -> (u16, Value) {
    let mut req = format!(
        "POST {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nContent-Length: {}\r\n",
        s.addr,
        body.len()
    );
    for h in headers {
        req.push_str(h);
        req.push_str("\r\n");
    }
    req.push_str("\r\n");
    req.push_str(body);
    let (status, bytes) = raw(s.addr, &req);
    (
        status,
        serde_json::from_slice(&bytes).unwrap_or(Value::Null),
    )
}

fn post_json(s: &Server, path: &str, body: &Value) -> (u16, Value) {
    post(
        s,
        path,
        &["Content-Type: application/json"],
        &body.to_string(),
    )
}

fn get(s: &Server, path: &str, headers: &[&str]) -> (u16, Vec<u8>) {
    let mut req = format!(
        "GET {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n",
        s.addr
    );
    for h in headers {
        req.push_str(h);
        req.push_str("\r\n");
    }
    req.push_str("\r\n");
    raw(s.addr, &req)
}

/// A page on another site could post `text/plain` or form bodies (no CORS preflight) and
/// end a robot's trial with a false "found"; a DNS-rebinding page reaches the server under its
/// own name.
#[test]
fn cross_site_requests_and_foreign_hosts_are_refused() {
    let s = start(Setup::default());
    let (st, dep) = post_json(&s, "/deployments", &json!({}));
    assert_eq!(st, 201, "{dep}");
    let body = r#"{"scene":"flat","target":"Egg"}"#;
    for ct in [
        "text/plain",
        "application/x-www-form-urlencoded",
        "multipart/form-data; boundary=x",
    ] {
        let (st, reply) = post(
            &s,
            "/deployments/1/trials",
            &[&format!("Content-Type: {ct}")],
            body,
        );
        assert_eq!(st, 415, "{ct}: {reply}");
        assert_eq!(reply["error"]["field"], "content-type");
    }
    let (st, _) = post(&s, "/deployments/1/trials", &[], body);
    assert_eq!(st, 415, "no content type");
    let (st, reply) = post(
        &s,
        "/deployments/1/trials",
        &[
            "Content-Type: application/json",
            "Origin: http://evil.example",
        ],
        body,
    );
    assert_eq!(st, 403, "{reply}");
    assert_eq!(reply["error"]["field"], "origin");
    let (st, _) = get(&s, "/scenes", &["Origin: null"]);
    assert_eq!(st, 403);
    // DNS rebinding: the page's own name in Host.
    let req = format!(
        "GET /scenes HTTP/1.1\r\nHost: evil.example:{}\r\nConnection: close\r\n\r\n",
        s.addr.port()
    );
    assert_eq!(raw(s.addr, &req).0, 403);
    let req = "GET /scenes HTTP/1.1\r\nHost: 127.0.0.1:1\r\nConnection: close\r\n\r\n";
    assert_eq!(raw(s.addr, req).0, 403, "another port");
    for host in [format!("localhost:{}", s.addr.port()), s.addr.to_string()] {
        let req = format!("GET /scenes HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n");
        assert_eq!(raw(s.addr, &req).0, 200, "{host}");
    }
    // Nothing was created by the refused requests.
    let (_, state) = get(&s, "/deployments/1", &[]);
    let state: Value = serde_json::from_slice(&state).unwrap();
    assert_eq!(state["trials"], json!([]), "{state}");
}

/// A `POST` to a route that takes none was answered 415 (no JSON body) instead of 405.
#[test]
fn a_method_a_route_does_not_take_is_405_whatever_its_body() {
    let s = start(Setup::default());
    for path in ["/health", "/scenes/flat", "/deployments/1", "/trials/1"] {
        let (st, reply) = post(&s, path, &[], "");
        assert_eq!(st, 405, "{path}: {reply}");
        let (st, _) = post(&s, path, &["Content-Type: text/plain"], "x");
        assert_eq!(st, 405, "{path}");
    }
}

/// The document's links lead from a created object to the routes that use it.
#[test]
fn the_openapi_links_name_operations_that_exist() {
    let doc = document(
        &HttpOptions::default(),
        &["model/uniform".to_string()],
        &SceneLimits::default(),
    );
    let mut ids = Vec::new();
    for item in doc["paths"].as_object().unwrap().values() {
        for op in item.as_object().unwrap().values() {
            if let Some(id) = op["operationId"].as_str() {
                ids.push(id.to_string());
            }
        }
    }
    let mut followed = 0;
    for (path, method, status) in [
        ("/scenes", "post", "201"),
        ("/deployments", "post", "201"),
        ("/deployments/{id}/trials", "post", "201"),
        ("/trials/{id}/observations", "post", "200"),
        ("/trials/{id}/claims", "post", "200"),
    ] {
        let links = doc["paths"][path][method]["responses"][status]["links"]
            .as_object()
            .unwrap();
        for link in links.values() {
            let id = link["operationId"].as_str().unwrap();
            assert!(
                ids.iter().any(|i| i == id),
                "{path}: {id} is no operation of {ids:?}"
            );
            followed += 1;
        }
    }
    assert_eq!(followed, 15);
}

#[test]
fn allowed_origins_and_hosts_get_in() {
    let s = start(Setup {
        http: HttpOptions {
            cors_origins: vec!["http://robot-ui.local:3000".into()],
            allowed_hosts: vec!["robot.local".into()],
            ..HttpOptions::default()
        },
        ..Setup::default()
    });
    let (st, _) = get(&s, "/scenes", &["Origin: http://robot-ui.local:3000"]);
    assert_eq!(st, 200);
    let req = "GET /scenes HTTP/1.1\r\nHost: Robot.Local\r\nConnection: close\r\n\r\n";
    assert_eq!(raw(s.addr, req).0, 200);
}

/// The CORS layer ran before the guards: a preflight (`OPTIONS`) naming another server in its
/// Host was answered 200 without a token. It now passes the Host and Origin checks first.
#[test]
fn a_cors_preflight_is_refused_for_a_foreign_host_or_origin_and_answered_for_the_allowed_one() {
    let s = start(Setup {
        http: HttpOptions {
            token: Some("s3cret".into()),
            cors_origins: vec!["http://robot-ui.local:3000".into()],
            ..HttpOptions::default()
        },
        ..Setup::default()
    });
    let preflight = |host: &str, origin: &str| {
        let mut c = std::net::TcpStream::connect(s.addr).unwrap();
        c.set_read_timeout(Some(Duration::from_secs(20))).unwrap();
        write!(
            c,
            "OPTIONS /scenes HTTP/1.1\r\nHost: {host}\r\nOrigin: {origin}\r\nAccess-Control-Request-Method: GET\r\nAccess-Control-Request-Headers: authorization\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
        let mut reply = String::new();
        let _ = c.read_to_string(&mut reply);
        reply
    };
    let own = s.addr.to_string();
    let allowed = preflight(&own, "http://robot-ui.local:3000");
    assert!(allowed.starts_with("HTTP/1.1 200"), "{allowed}");
    assert!(
        allowed
            .to_ascii_lowercase()
            .contains("access-control-allow-origin: http://robot-ui.local:3000"),
        "{allowed}"
    );
    let foreign_host = preflight("evil.example", "http://robot-ui.local:3000");
    assert!(foreign_host.starts_with("HTTP/1.1 403"), "{foreign_host}");
    let foreign_origin = preflight(&own, "http://evil.example");
    assert!(
        foreign_origin.starts_with("HTTP/1.1 403"),
        "{foreign_origin}"
    );
    // Past the preflight, the request itself still needs the token.
    let (st, _) = get(&s, "/scenes", &["Origin: http://robot-ui.local:3000"]);
    assert_eq!(st, 401);
}

/// The scheme of `Authorization` is case-insensitive (RFC 9110); lowercase `bearer` was refused.
#[test]
fn the_bearer_scheme_is_case_insensitive_and_an_empty_token_is_refused() {
    let s = start(Setup {
        http: HttpOptions {
            token: Some("s3cret".into()),
            ..HttpOptions::default()
        },
        ..Setup::default()
    });
    for h in [
        "Authorization: bearer s3cret",
        "Authorization: BEARER s3cret",
        "Authorization: Bearer  s3cret",
    ] {
        assert_eq!(get(&s, "/scenes", &[h]).0, 200, "{h}");
    }
    for h in [
        "Authorization: bearer s3cre",
        "Authorization: Basic s3cret",
        "Authorization: s3cret",
    ] {
        assert_eq!(get(&s, "/scenes", &[h]).0, 401, "{h}");
    }
    let service = Arc::new(
        Service::new(
            Store::in_memory().unwrap(),
            GridParams::default(),
            strategies(),
        )
        .unwrap(),
    );
    for empty in ["", "  "] {
        let e = ferret_serve::router(
            service.clone(),
            &HttpOptions {
                token: Some(empty.into()),
                ..HttpOptions::default()
            },
        )
        .unwrap_err();
        assert!(e.message.contains("empty"), "{e}");
    }
}

/// `[]` made a deployment with every default; 1e308 was taken as the exploration constant.
#[test]
fn bodies_must_be_objects_and_numbers_within_their_bounds() {
    let s = start(Setup::default());
    for (path, body) in [
        ("/deployments", "[]"),
        ("/deployments", "[1, 2]"),
        ("/scenes", "\"x\""),
        ("/deployments/1/trials", "null"),
    ] {
        let (st, reply) = post(&s, path, &["Content-Type: application/json"], body);
        assert_eq!(st, 400, "{path} {body}: {reply}");
    }
    for (body, field) in [
        (json!({"c": 1e308}), "c"),
        (json!({"c": 1000.5}), "c"),
        (json!({"seed": 9_007_199_254_740_992_u64}), "seed"),
    ] {
        let (st, reply) = post_json(&s, "/deployments", &body);
        assert_eq!(st, 422, "{body}: {reply}");
        assert_eq!(reply["error"]["field"], field);
    }
    let (st, _) = post_json(&s, "/deployments", &json!({"c": 1000.0}));
    assert_eq!(st, 201);
    // JSON Schema's integers: 2232.0 is one, 1.5 is not.
    let (st, reply) = post(
        &s,
        "/deployments",
        &["Content-Type: application/json"],
        r#"{"seed": 2232.0}"#,
    );
    assert_eq!((st, reply["seed"].clone()), (201, json!(2232)), "{reply}");
    let (st, reply) = post(
        &s,
        "/deployments",
        &["Content-Type: application/json"],
        r#"{"seed": 1.5}"#,
    );
    assert_eq!(
        (st, reply["error"]["field"].clone()),
        (400, json!("seed")),
        "{reply}"
    );
    let (st, reply) = post(
        &s,
        "/deployments",
        &["Content-Type: application/json"],
        r#"{"seed": 1e300}"#,
    );
    assert_eq!(
        (st, reply["error"]["field"].clone()),
        (422, json!("seed")),
        "{reply}"
    );
    let (st, reply) = post_json(&s, "/deployments", &json!({"request_id": "é".repeat(200)}));
    assert_eq!(
        st, 201,
        "200 characters are fine whatever their bytes: {reply}"
    );
}

/// Three legs of 1.7e308 m summed to infinity, and the reply said `"travelled_m": null`.
#[test]
fn odometry_is_bounded_so_its_sum_stays_a_number() {
    let s = start(Setup::default());
    post_json(&s, "/deployments", &json!({}));
    let (_, t) = post_json(
        &s,
        "/deployments/1/trials",
        &json!({"scene": "flat", "target": "Pillow"}),
    );
    let trial = t["trial"].as_i64().unwrap();
    let next = t["next"]["container"].as_str().unwrap().to_string();
    let (st, reply) = post_json(
        &s,
        &format!("/trials/{trial}/observations"),
        &json!({"container": next, "found": false, "travelled_m": 1.7e308}),
    );
    assert_eq!(st, 422, "{reply}");
    assert_eq!(reply["error"]["field"], "travelled_m");
    let mut reply = t;
    let mut legs = 0;
    while reply["status"] == "searching" {
        let next = reply["next"]["container"].as_str().unwrap().to_string();
        let (st, r) = post_json(
            &s,
            &format!("/trials/{trial}/observations"),
            &json!({"container": next, "found": next == "bed", "travelled_m": 100_000.0}),
        );
        assert_eq!(st, 200, "{r}");
        reply = r;
        legs += 1;
    }
    assert_eq!(reply["travelled_m"], json!(100_000.0 * f64::from(legs)));
}

/// A retried request got a reply that differed in the last digit of a float (the stored JSON
/// was parsed and printed again); the promise is the first reply.
#[test]
fn a_retry_gets_the_bytes_of_the_first_reply() {
    let s = start(Setup::default());
    let (_, dep) = post_json(&s, "/deployments", &json!({"request_id": "d"}));
    let d = dep["id"].as_i64().unwrap();
    let mut checked = 0;
    for k in 0..12 {
        let f = f64::from(k);
        // Poses with many digits, so that distances and paths do too.
        let pose = [1.0 + f * 0.123_456_789_012_345_67, 1.0 + f * 0.1, 17.0 * f];
        let body = json!({"request_id": format!("t{k}"), "scene": "flat", "target": "Pillow", "pose": pose}).to_string();
        let path = format!("/deployments/{d}/trials");
        let (st, first) = post_raw_bytes(&s, &path, &body);
        assert_eq!(st, 201, "{}", String::from_utf8_lossy(&first));
        for _ in 0..3 {
            let (st, again) = post_raw_bytes(&s, &path, &body);
            assert_eq!(st, 201);
            assert_eq!(again, first, "retry {k}");
            checked += 1;
        }
        // End the trial so the next can start.
        let reply: Value = serde_json::from_slice(&first).unwrap();
        let trial = reply["trial"].as_i64().unwrap();
        let mut reply = reply;
        let mut n = 0;
        while reply["status"] == "searching" {
            let next = reply["next"]["container"].as_str().unwrap().to_string();
            let body = json!({"request_id": format!("o{k}-{n}"), "container": next, "found": next == "bed", "travelled_m": 1.0 / 3.0 + f}).to_string();
            let path = format!("/trials/{trial}/observations");
            let (_, bytes) = post_raw_bytes(&s, &path, &body);
            let (_, again) = post_raw_bytes(&s, &path, &body);
            assert_eq!(again, bytes, "observation retry");
            reply = serde_json::from_slice(&bytes).unwrap();
            n += 1;
        }
    }
    assert_eq!(checked, 36);
}

fn post_raw_bytes(s: &Server, path: &str, body: &str) -> (u16, Vec<u8>) {
    let req = format!(
        "POST {path} HTTP/1.1\r\nHost: {}\r\nConnection: close\r\nContent-Type: application/json\r\nContent-Length: {}\r\n\r\n{body}",
        s.addr,
        body.len()
    );
    raw(s.addr, &req)
}

/// Uploads were unbounded: a 290-byte room of 204 m × 204 m cost 32–48 MB for good, and
/// 600 of them exhausted the machine.
#[test]
fn uploaded_scenes_are_bounded_in_number_size_and_shape() {
    let s = start(Setup {
        service: ServiceOptions {
            limits: SceneLimits {
                max_scenes: 3,
                max_cells: 500_000,
                max_containers: 5,
                max_vertices: 12,
            },
            ..ServiceOptions::default()
        },
        http: HttpOptions {
            max_body_bytes: 4096,
            ..HttpOptions::default()
        },
        ..Setup::default()
    });
    let started = Instant::now();
    let (st, reply) = post_json(&s, "/scenes", &json!({"scene": square("huge", 204.0)}));
    assert_eq!(st, 422, "{reply}");
    assert_eq!(reply["error"]["field"], "scene.rooms");
    assert!(
        reply["error"]["message"]
            .as_str()
            .unwrap()
            .contains("cells"),
        "{reply}"
    );
    assert!(
        started.elapsed() < Duration::from_secs(1),
        "refused before building"
    );
    let mut many = scene("many");
    many["containers"] = json!((0..6).map(|i| json!({"id": format!("c{i}"), "type": "Box", "pose": [1.0 + 0.4 * f64::from(i), 1.0, 0]})).collect::<Vec<_>>());
    let (st, reply) = post_json(&s, "/scenes", &json!({"scene": many}));
    assert_eq!(
        (st, reply["error"]["field"].clone()),
        (422, json!("scene.containers")),
        "{reply}"
    );
    let mut jagged = scene("jagged");
    jagged["rooms"][0]["polygon"] = json!(
        (0..11)
            .map(|i| {
                let a = f64::from(i) * 0.57;
                [2.0 + 2.0 * a.cos(), 2.0 + 2.0 * a.sin()]
            })
            .collect::<Vec<_>>()
    );
    let (st, reply) = post_json(&s, "/scenes", &json!({"scene": jagged}));
    assert_eq!(
        (st, reply["error"]["field"].clone()),
        (422, json!("scene.rooms")),
        "{reply}"
    );
    let mut big = scene("big");
    big["padding"] = json!("x".repeat(5000));
    let (st, _) = post_json(&s, "/scenes", &json!({"scene": big}));
    assert_eq!(st, 413, "the body limit");
    for i in 0..3 {
        let (st, reply) = post_json(&s, "/scenes", &json!({"scene": scene(&format!("s{i}"))}));
        assert_eq!(st, 201, "{reply}");
    }
    let (st, reply) = post_json(&s, "/scenes", &json!({"scene": scene("s3")}));
    assert_eq!(st, 413, "{reply}");
    // The same scene again is not a new one.
    let (st, _) = post_json(&s, "/scenes", &json!({"scene": scene("s1")}));
    assert_eq!(st, 200);
}

/// Every grid stayed in memory for good; now they are built on demand into a cache of
/// bounded size, and a scene whose grid was dropped is built again when asked for.
#[test]
fn grids_live_in_a_bounded_cache() {
    let budget = 6 << 20;
    let s = start(Setup {
        service: ServiceOptions {
            grid_cache_bytes: budget,
            ..ServiceOptions::default()
        },
        ..Setup::default()
    });
    // 40 m × 40 m: about 0.7 M cells, 1.4 MB each.
    for i in 0..12 {
        let (st, reply) = post_json(
            &s,
            "/scenes",
            &json!({"scene": square(&format!("sq{i}"), 40.0)}),
        );
        assert_eq!(st, 201, "{reply}");
        assert!(
            s.service.grid_cache_bytes() <= budget,
            "{} after {i}",
            s.service.grid_cache_bytes()
        );
    }
    for i in 0..12 {
        let (st, body) = get(&s, &format!("/scenes/sq{i}"), &[]);
        assert_eq!(st, 200, "{}", String::from_utf8_lossy(&body));
    }
    assert!(s.service.grid_cache_bytes() <= budget);
    assert!(
        s.service.grid_cache_bytes() > budget / 4,
        "the cache is used"
    );
}

/// Start-up rebuilt every stored scene; now it only lists them.
#[test]
fn start_up_reads_no_stored_scene() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("s.sqlite");
    {
        let s = start(Setup {
            db: Some(db.clone()),
            ..Setup::default()
        });
        for i in 0..5 {
            assert_eq!(
                post_json(&s, "/scenes", &json!({"scene": scene(&format!("s{i}"))})).0,
                201
            );
        }
    }
    // A stored scene the server can no longer read does not stop it from starting; it fails
    // when used.
    let conn = rusqlite::Connection::open(&db).unwrap();
    conn.execute(
        "UPDATE scenes SET body = '{\"ferret_scene\": 1}' WHERE name = 's2'",
        [],
    )
    .unwrap();
    drop(conn);
    let started = Instant::now();
    let s = start(Setup {
        db: Some(db),
        ..Setup::default()
    });
    assert!(started.elapsed() < Duration::from_secs(2));
    assert_eq!(s.service.cached_grids(), ["flat"]);
    let (st, list) = get(&s, "/scenes", &[]);
    assert_eq!(st, 200);
    let list: Value = serde_json::from_slice(&list).unwrap();
    assert_eq!(list.as_array().unwrap().len(), 6, "{list}");
    assert_eq!(list[1]["containers"], 3);
    assert_eq!(get(&s, "/scenes/s1", &[]).0, 200);
    assert_eq!(get(&s, "/scenes/s2", &[]).0, 500);
}

/// Idle connections were never closed and there was no cap: 1 100 idle connections made a
/// normal request time out.
#[test]
fn idle_connections_are_closed_and_cannot_lock_a_client_out() {
    let s = start(Setup {
        serve: ServeOptions {
            header_timeout: Duration::from_millis(600),
            idle_timeout: Duration::from_millis(900),
            max_connections: 32,
            ..ServeOptions::default()
        },
        ..Setup::default()
    });
    // A connection that never sends a request is closed after the header timeout.
    let mut silent = std::net::TcpStream::connect(s.addr).unwrap();
    silent
        .set_read_timeout(Some(Duration::from_secs(5)))
        .unwrap();
    let started = Instant::now();
    let mut buf = [0u8; 64];
    assert!(matches!(silent.read(&mut buf), Ok(0) | Err(_)));
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );
    // A kept-alive connection after its reply is closed after the idle timeout.
    let mut kept = std::net::TcpStream::connect(s.addr).unwrap();
    kept.set_read_timeout(Some(Duration::from_secs(5))).unwrap();
    write!(kept, "GET /health HTTP/1.1\r\nHost: {}\r\n\r\n", s.addr).unwrap();
    let n = kept.read(&mut buf).unwrap();
    assert!(String::from_utf8_lossy(&buf[..n]).starts_with("HTTP/1.1 200"));
    let started = Instant::now();
    let mut rest = Vec::new();
    let _ = kept.read_to_end(&mut rest);
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );
    // Three times the cap of idle connections, then a normal client.
    let idle: Vec<_> = (0..96)
        .map(|_| std::net::TcpStream::connect(s.addr).unwrap())
        .collect();
    let mut times = Vec::new();
    for _ in 0..20 {
        let started = Instant::now();
        assert_eq!(get(&s, "/scenes", &[]).0, 200);
        times.push(started.elapsed());
    }
    times.sort();
    assert!(times[19] < Duration::from_millis(500), "{times:?}");
    drop(idle);
}

/// `/health` said ok while every data route failed on a damaged database.
#[test]
fn health_reports_a_database_that_cannot_be_read() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("s.sqlite");
    let s = start(Setup {
        db: Some(db.clone()),
        ..Setup::default()
    });
    assert_eq!(get(&s, "/health", &[]).0, 200);
    // Another program drops a table the server needs.
    let conn = rusqlite::Connection::open(&db).unwrap();
    conn.execute_batch("DROP TABLE observations").unwrap();
    drop(conn);
    let (st, body) = get(&s, "/health", &[]);
    assert_eq!(st, 503, "{}", String::from_utf8_lossy(&body));
    let body: Value = serde_json::from_slice(&body).unwrap();
    assert_eq!(body["error"]["status"], 503);
    // A 503 says when to try again, so a robot tells it from a refusal.
    let mut c = std::net::TcpStream::connect(s.addr).unwrap();
    write!(
        c,
        "GET /health HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
        s.addr
    )
    .unwrap();
    let mut reply = String::new();
    c.read_to_string(&mut reply).unwrap();
    assert!(
        reply
            .to_ascii_lowercase()
            .contains("\r\nretry-after: 1\r\n"),
        "{reply}"
    );
}

/// The document was looser than the server: `selector` a free string, `strategies: []` and
/// `scene: {}` valid, statuses the routes return missing.
#[test]
fn the_openapi_document_says_what_the_server_enforces() {
    let names = vec!["optimistic+greedy".to_string(), "model/uniform".to_string()];
    let doc = document(
        &HttpOptions {
            token: Some("t".into()),
            ..HttpOptions::default()
        },
        &names,
        &SceneLimits::default(),
    );
    let schemas = &doc["components"]["schemas"];
    let dep = &schemas["CreateDeployment"]["properties"];
    assert_eq!(dep["strategies"]["minItems"], 1);
    assert_eq!(dep["strategies"]["uniqueItems"], true);
    assert_eq!(dep["strategies"]["items"]["enum"], json!(names));
    let selector = serde_json::to_string(&dep["selector"]).unwrap();
    assert!(selector.contains("Selector"), "{selector}");
    let methods: Vec<&str> = ferret_select::Method::ALL
        .iter()
        .map(|m| m.name())
        .collect();
    assert_eq!(schemas["Selector"]["enum"], json!(methods));
    assert!(methods.contains(&"replay") && methods.contains(&"ucb"));
    assert_eq!(dep["c"]["maximum"], 1000.0);
    let scene = &schemas["Scene"];
    assert_eq!(
        scene["required"],
        json!(["ferret_scene", "name", "rooms", "containers", "start"])
    );
    assert_eq!(scene["properties"]["containers"]["maxItems"], 200);
    assert_eq!(
        schemas["StartTrial"]["properties"]["target"]["pattern"],
        "^[A-Za-z0-9]{1,100}$"
    );
    assert_eq!(
        schemas["Observe"]["properties"]["travelled_m"]["maximum"],
        100000.0
    );
    for (path, method, statuses) in [
        (
            "/scenes",
            "post",
            &[200, 201, 400, 401, 403, 409, 413, 415, 422, 500][..],
        ),
        (
            "/deployments",
            "post",
            &[201, 400, 401, 409, 413, 415, 422][..],
        ),
        (
            "/deployments/{id}/trials",
            "post",
            &[201, 400, 404, 409, 415, 422, 503][..],
        ),
        (
            "/trials/{id}/observations",
            "post",
            &[200, 400, 404, 409, 415, 422, 503][..],
        ),
        ("/trials/{id}", "get", &[200, 401, 404, 503][..]),
        ("/health", "get", &[200, 503][..]),
    ] {
        let responses = &doc["paths"][path][method]["responses"];
        for st in statuses {
            assert!(
                responses[st.to_string()].is_object(),
                "{method} {path} {st}: {responses}"
            );
        }
    }
    assert!(doc["paths"]["/health"]["get"]["security"].is_null());
    assert!(doc["paths"]["/scenes"]["get"]["security"].is_array());
}

/// Sockets that sent a request's headers and one byte of its body, then nothing, held their
/// connections (and, past the cap, every other client's) for as long as they stayed open.
#[test]
fn a_body_that_stops_arriving_is_timed_out() {
    let s = start(Setup {
        serve: ServeOptions {
            header_timeout: Duration::from_millis(600),
            body_timeout: Duration::from_millis(600),
            max_connections: 8,
            ..ServeOptions::default()
        },
        ..Setup::default()
    });
    // Twelve for a cap of eight: the last ones find every connection busy and are refused.
    let stalled: Vec<_> = (0..12)
        .map(|_| {
            let mut c = std::net::TcpStream::connect(s.addr).unwrap();
            c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
            let _ = write!(
                c,
                "POST /deployments HTTP/1.1\r\nHost: {}\r\nContent-Type: application/json\r\nContent-Length: 100\r\n\r\n{{",
                s.addr
            );
            c
        })
        .collect();
    // Every stalled request is answered 408 and closed (or was refused at the cap) instead of
    // holding its connection.
    let mut timed_out = 0;
    for mut c in stalled {
        let mut reply = Vec::new();
        let read = c.read_to_end(&mut reply);
        assert!(
            !matches!(&read, Err(e) if matches!(e.kind(), std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut)),
            "a stalled body kept its connection open: {read:?}"
        );
        let text = String::from_utf8_lossy(&reply);
        if text.starts_with("HTTP/1.1 408") {
            timed_out += 1;
        } else {
            assert!(text.is_empty(), "{text}");
        }
    }
    assert!(timed_out >= 8, "{timed_out}");
    assert_eq!(get(&s, "/health", &[]).0, 200);
}

/// `/health` read one row of each table, from pages the connection had cached: damage to the
/// rest of the file went unseen while the routes reading it failed.
#[test]
fn health_reads_the_pages_on_disk() {
    let dir = tempfile::tempdir().unwrap();
    let db = dir.path().join("s.sqlite");
    let s = start(Setup {
        db: Some(db.clone()),
        ..Setup::default()
    });
    for _ in 0..300 {
        assert_eq!(post_json(&s, "/deployments", &json!({})).0, 201);
    }
    // Every committed page in the main file, so that overwriting the file's tail damages rows.
    let conn = rusqlite::Connection::open(&db).unwrap();
    conn.execute_batch("PRAGMA wal_checkpoint(TRUNCATE)")
        .unwrap();
    let page: i64 = conn
        .query_row("PRAGMA page_size", [], |r| r.get(0))
        .unwrap();
    let page = page as u64;
    drop(conn);
    assert_eq!(get(&s, "/health", &[]).0, 200);
    let len = std::fs::metadata(&db).unwrap().len();
    assert!(len >= 6 * page, "{len}");
    let mut f = std::fs::OpenOptions::new().write(true).open(&db).unwrap();
    use std::io::{Seek, SeekFrom};
    f.seek(SeekFrom::Start(len - 3 * page)).unwrap();
    f.write_all(&vec![0xA5; 3 * page as usize]).unwrap();
    f.sync_all().unwrap();
    drop(f);
    let (st, body) = get(&s, "/health", &[]);
    assert_eq!(st, 503, "{}", String::from_utf8_lossy(&body));
}

/// A new pose rebuilt the scene's whole grid and distance matrix (24 s on a 99 m × 99 m room
/// with 200 containers) where one search from the pose gives the same distances.
#[test]
fn a_new_pose_is_one_search_on_the_scenes_grid() {
    let s = start(Setup::default());
    assert_eq!(s.service.grids_built(), 1);
    let pose = [6.0, 3.0, 90.0];
    let spec = json!({"strategies": ["optimistic+greedy"]});
    let trial = |scene: &str, pose: Value| {
        let (st, dep) = post_json(&s, "/deployments", &spec);
        assert_eq!(st, 201, "{dep}");
        let (st, trial) = post_json(
            &s,
            &format!("/deployments/{}/trials", dep["id"]),
            &json!({"scene": scene, "target": "Pillow", "pose": pose}),
        );
        assert_eq!(st, 201, "{trial}");
        trial["next"].clone()
    };
    let from_pose = trial("flat", json!(pose));
    assert_eq!(s.service.grids_built(), 1, "a new pose built a whole grid");
    // The same scene uploaded with the pose as its start: the same next step and distance.
    let mut moved = scene("moved");
    moved["start"] = json!(pose);
    assert_eq!(post_json(&s, "/scenes", &json!({"scene": moved})).0, 201);
    let from_start = trial("moved", Value::Null);
    assert_eq!(from_pose, from_start);
    assert!(
        from_pose["distance_m"].as_f64().unwrap() > 0.0,
        "{from_pose}"
    );
}

/// An abandoned trial's cost read `-0.0` in one route and `0.0` in another: every route says
/// `0.0`.
#[test]
fn a_trial_abandoned_before_moving_costs_zero_in_every_route() {
    let s = start(Setup::default());
    let (_, dep) = post_json(&s, "/deployments", &json!({}));
    let (st, trial) = post_json(
        &s,
        &format!("/deployments/{}/trials", dep["id"]),
        &json!({"scene": "flat", "target": "Egg"}),
    );
    assert_eq!(st, 201, "{trial}");
    let id = &trial["trial"];
    let (st, ended) = post_json(&s, &format!("/trials/{id}/abandon"), &json!({}));
    assert_eq!(st, 200, "{ended}");
    let mut texts = vec![ended.to_string()];
    for path in [
        format!("/trials/{id}"),
        format!("/trials/{id}/view"),
        format!("/deployments/{}", dep["id"]),
        "/deployments".to_string(),
    ] {
        let (st, body) = get(&s, &path, &[]);
        assert_eq!(st, 200, "{path}");
        texts.push(String::from_utf8_lossy(&body).into_owned());
    }
    for text in texts {
        assert!(!text.contains("-0.0"), "{text}");
    }
    assert_eq!(ended["cost_m"], 0.0);
}

/// A yaw of 1e308 was taken (it names no direction); `c: -0.0` was stored and echoed as `-0.0`;
/// `Host: localhost..` passed as `localhost`.
#[test]
fn a_yaw_is_within_a_turn_and_c_and_host_are_read_as_they_mean() {
    let s = start(Setup::default());
    let (st, dep) = post_json(&s, "/deployments", &json!({"c": -0.0}));
    assert_eq!(st, 201, "{dep}");
    let (_, text) = get(&s, &format!("/deployments/{}", dep["id"]), &[]);
    let text = String::from_utf8_lossy(&text);
    assert!(text.contains(r#""c":0.0"#), "{text}");
    for (yaw, status) in [(1e308, 422), (-360.5, 422), (359.0, 201), (-180.0, 201)] {
        let (st, reply) = post_json(
            &s,
            &format!("/deployments/{}/trials", dep["id"]),
            &json!({"scene": "flat", "target": "Egg", "pose": [1.0, 1.0, yaw]}),
        );
        assert_eq!(st, status, "{yaw}: {reply}");
        if st == 422 {
            assert_eq!(reply["error"]["field"], "pose", "{reply}");
        }
    }
    let port = s.addr.port();
    for (host, status) in [
        (format!("localhost.:{port}"), 200),
        (format!("localhost..:{port}"), 403),
        (format!("localhost:0{port}"), 200),
    ] {
        let req = format!("GET /scenes HTTP/1.1\r\nHost: {host}\r\nConnection: close\r\n\r\n");
        assert_eq!(raw(s.addr, &req).0, status, "{host}");
    }
}

/// RFC 9112 §3.2: no Host on HTTP/1.1, two Host headers, or a target in absolute form naming
/// another host are refused 400 (they were served); HTTP/1.0 may omit Host.
#[test]
fn requests_without_one_host_of_their_own_are_refused() {
    let s = start(Setup::default());
    let port = s.addr.port();
    let refused = [
        "GET /scenes HTTP/1.1\r\nConnection: close\r\n\r\n".to_string(),
        format!(
            "GET /scenes HTTP/1.1\r\nHost: {}\r\nHost: {}\r\nConnection: close\r\n\r\n",
            s.addr, s.addr
        ),
        format!(
            "GET http://evil.example:{port}/scenes HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            s.addr
        ),
    ];
    for req in &refused {
        let (status, body) = raw(s.addr, req);
        assert_eq!(status, 400, "{req:?}: {}", String::from_utf8_lossy(&body));
        let v: Value = serde_json::from_slice(&body).unwrap();
        assert_eq!(v["error"]["field"], "host", "{v}");
    }
    let served = [
        format!(
            "GET /scenes HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            s.addr
        ),
        format!(
            "GET http://{}/scenes HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
            s.addr, s.addr
        ),
        "GET /scenes HTTP/1.0\r\n\r\n".to_string(),
    ];
    for req in &served {
        assert_eq!(raw(s.addr, req).0, 200, "{req:?}");
    }
}

/// A body declared past the limit is answered 413 at once (it waited for the body deadline and
/// answered 408), and nothing is created.
#[test]
fn a_body_declared_too_large_is_refused_at_once() {
    let s = start(Setup {
        serve: ServeOptions {
            body_timeout: Duration::from_secs(30),
            ..ServeOptions::default()
        },
        ..Setup::default()
    });
    let mut c = std::net::TcpStream::connect(s.addr).unwrap();
    c.set_read_timeout(Some(Duration::from_secs(10))).unwrap();
    write!(
        c,
        "POST /deployments HTTP/1.1\r\nHost: {}\r\nContent-Type: application/json\r\nContent-Length: 1000000000000\r\n\r\n{{",
        s.addr
    )
    .unwrap();
    let started = std::time::Instant::now();
    let mut reply = [0u8; 512];
    let n = c.read(&mut reply).unwrap();
    let text = String::from_utf8_lossy(&reply[..n]);
    assert!(text.starts_with("HTTP/1.1 413"), "{text}");
    // Not the 30 s body deadline: answered as soon as the headers were read.
    assert!(started.elapsed() < Duration::from_secs(10));
    let (_, listed) = get(&s, "/deployments/1", &[]);
    assert!(
        String::from_utf8_lossy(&listed).contains("no deployment"),
        "{}",
        String::from_utf8_lossy(&listed)
    );
}

/// The IETF draft's `Idempotency-Key` header means what the `request_id` field means (it was
/// ignored: two identical POSTs made two deployments); both given and different is a 400.
#[test]
fn the_idempotency_key_header_is_a_request_id() {
    let s = start(Setup::default());
    let json = "Content-Type: application/json";
    let (st, first) = post(
        &s,
        "/deployments",
        &[json, "Idempotency-Key: \"k-1\""],
        "{}",
    );
    assert_eq!(st, 201, "{first}");
    for key in ["Idempotency-Key: \"k-1\"", "idempotency-key: \"k-1\""] {
        let (st, again) = post(&s, "/deployments", &[json, key], "{}");
        assert_eq!((st, &again), (201, &first), "{key}");
    }
    // A bare value, and the same id in the body: one request, as with the field alone.
    let (_, bare) = post(&s, "/deployments", &[json, "Idempotency-Key: k-2"], "{}");
    let (_, field) = post(&s, "/deployments", &[json], r#"{"request_id":"k-2"}"#);
    assert_ne!(bare["id"], first["id"]);
    assert_eq!(
        field["id"],
        json!(null),
        "the field's body differs: 422, not a new deployment"
    );
    let (st, both) = post(
        &s,
        "/deployments",
        &[json, "Idempotency-Key: k-2"],
        r#"{"request_id":"k-2"}"#,
    );
    assert_eq!(st, 422, "the same id for another body: {both}");
    let (st, differ) = post(
        &s,
        "/deployments",
        &[json, "Idempotency-Key: k-3"],
        r#"{"request_id":"k-4"}"#,
    );
    assert_eq!(st, 400, "{differ}");
    assert_eq!(differ["error"]["field"], "request_id");
    let (st, twice) = post(
        &s,
        "/deployments",
        &[json, "Idempotency-Key: a", "Idempotency-Key: b"],
        "{}",
    );
    assert_eq!(st, 400, "{twice}");
    let (st, _) = post(&s, "/deployments", &[json, "Idempotency-Key: \"\""], "{}");
    assert_eq!(st, 400, "an empty key");
    // Two deployments in all: k-1 and k-2.
    let (_, third) = post(&s, "/deployments", &[json], "{}");
    assert_eq!(third["id"].as_i64(), Some(3), "{third}");
}

/// An SQLite file emptied (`truncate -s 0`) or replaced while the server runs: `/health` stayed
/// 200 and writes were acknowledged and then lost. Now `/health` is 503 and writes are refused
/// (503, to be retried once the database is back), nothing acknowledged that cannot be kept.
#[test]
fn a_database_file_emptied_or_replaced_underneath_is_not_written_to() {
    for (how, says) in [("emptied", "emptied"), ("replaced", "put in its place")] {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("s.sqlite");
        let s = start(Setup {
            db: Some(db.clone()),
            ..Setup::default()
        });
        let (st, _) = post_json(&s, "/deployments", &json!({}));
        assert_eq!(st, 201);
        assert_eq!(get(&s, "/health", &[]).0, 200, "{how}: before");
        match how {
            "emptied" => std::fs::OpenOptions::new()
                .write(true)
                .open(&db)
                .unwrap()
                .set_len(0)
                .unwrap(),
            _ => {
                let other = dir.path().join("other.sqlite");
                std::fs::copy(&db, &other).unwrap();
                std::fs::rename(&other, &db).unwrap();
            }
        }
        let (st, body) = get(&s, "/health", &[]);
        assert_eq!(st, 503, "{how}: {}", String::from_utf8_lossy(&body));
        for _ in 0..3 {
            let (st, reply) = post_json(&s, "/deployments", &json!({}));
            assert_eq!(st, 503, "{how}: {reply}");
            assert!(
                reply["error"]["message"].as_str().unwrap().contains(says),
                "{how}: {reply}"
            );
        }
    }
}

/// A server stopped gracefully after its SQLite file was emptied or replaced underneath: closing
/// used to copy the log into the emptied file (which the next start called malformed) or delete
/// the log beside the file put in its place. Now it closes without writing: the emptied file
/// stays empty, the replaced one byte for byte as it was, and the log keeps the last writes.
#[test]
fn a_lost_database_file_is_not_written_to_when_the_server_stops() {
    use ferret_serve::model::DeploymentSpec;
    let spec = DeploymentSpec {
        strategies: vec!["optimistic+greedy".into()],
        selector: ferret_select::Method::ReplaySelection,
        c: 5.0,
        seed: 0,
        sequential: false,
    };
    for how in ["emptied", "replaced"] {
        let dir = tempfile::tempdir().unwrap();
        let db = dir.path().join("s.sqlite");
        let wal = dir.path().join("s.sqlite-wal");
        let store = ferret_serve::Store::open(&db).unwrap();
        // Some writes copied into the file, then some only in the log.
        for _ in 0..3 {
            store.write(|w| w.insert_deployment(&spec)).unwrap();
        }
        let checkpoint = rusqlite::Connection::open(&db).unwrap();
        checkpoint
            .query_row("PRAGMA wal_checkpoint(TRUNCATE)", [], |_| Ok(()))
            .unwrap();
        drop(checkpoint);
        for _ in 0..3 {
            store.write(|w| w.insert_deployment(&spec)).unwrap();
        }
        let logged = std::fs::metadata(&wal).unwrap().len();
        assert!(logged > 0, "{how}: the last writes are in the log");
        let replacement = match how {
            "emptied" => {
                std::fs::OpenOptions::new()
                    .write(true)
                    .open(&db)
                    .unwrap()
                    .set_len(0)
                    .unwrap();
                Vec::new()
            }
            _ => {
                let other = dir.path().join("other.sqlite");
                std::fs::copy(&db, &other).unwrap();
                std::fs::rename(&other, &db).unwrap();
                std::fs::read(&db).unwrap()
            }
        };
        drop(store);
        let after = std::fs::read(&db).unwrap();
        assert!(
            after == replacement,
            "{how}: closing wrote into the file ({} bytes, {} before)",
            after.len(),
            replacement.len()
        );
        assert_eq!(
            std::fs::metadata(&wal).map(|m| m.len()).ok(),
            Some(logged),
            "{how}: the log was not kept as it was"
        );
    }
}
