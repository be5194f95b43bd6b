//! The database a test runs on. By default a new in-memory SQLite database; with
//! `FERRET_SERVE_TEST_BACKEND=postgres` a new database on the PostgreSQL server that
//! `FERRET_TEST_POSTGRES` names (`scripts/postgres.sh start` starts a throwaway one and prints
//! both), so the same tests check both backends.
#![allow(dead_code)]

pub mod events;
pub mod server;

use std::sync::atomic::{AtomicUsize, Ordering};

use std::sync::Arc;

use ferret_plan::{PlannerConfig, Strategy, StrategyRegistry};
use ferret_serve::{PostgresOptions, Store};

/// True when the tests run on PostgreSQL.
pub fn on_postgres() -> bool {
    std::env::var("FERRET_SERVE_TEST_BACKEND").as_deref() == Ok("postgres")
}

/// A new, empty store of the backend under test.
pub fn store() -> Store {
    if on_postgres() {
        let url = fresh_postgres().expect(
            "FERRET_SERVE_TEST_BACKEND=postgres needs FERRET_TEST_POSTGRES (scripts/postgres.sh start prints it)",
        );
        connect(&url)
    } else {
        Store::in_memory().unwrap()
    }
}

/// Connects to `url` from a thread of its own: the store drives its connections on a runtime
/// of its own, which cannot be started from inside a test's runtime.
pub fn connect(url: &str) -> Store {
    let url = url.to_string();
    std::thread::spawn(move || Store::connect(&url, PostgresOptions::default()))
        .join()
        .unwrap()
        .unwrap()
}

/// The server of `FERRET_TEST_POSTGRES`, with a new empty database on it; `None` without it.
pub fn fresh_postgres() -> Option<String> {
    static N: AtomicUsize = AtomicUsize::new(0);
    let admin = std::env::var("FERRET_TEST_POSTGRES").ok()?;
    let name = format!(
        "ferret_test_{}_{}",
        std::process::id(),
        N.fetch_add(1, Ordering::Relaxed)
    );
    let (base, _) = admin
        .rsplit_once('/')
        .expect("FERRET_TEST_POSTGRES is a URL ending in /database");
    psql(&admin, &format!("CREATE DATABASE {name}"));
    Some(format!("{base}/{name}"))
}

/// Runs `sql` on the PostgreSQL database at `url`, from a thread of its own (as [`connect`]).
pub fn psql(url: &str, sql: &str) {
    let (url, sql) = (url.to_string(), sql.to_string());
    std::thread::spawn(move || {
        let rt = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        rt.block_on(async move {
            let (client, connection) = tokio_postgres::connect(&url, tokio_postgres::NoTls)
                .await
                .unwrap();
            tokio::spawn(connection);
            client.batch_execute(&sql).await.unwrap();
        });
    })
    .join()
    .unwrap();
}

/// The scene `flat` of [`SCENE`].
pub fn flat() -> ferret_world::Scene {
    let file = std::path::Path::new("flat.json");
    ferret_world::SceneFile::parse(SCENE, file)
        .unwrap()
        .to_scene(file, None)
        .unwrap()
}

/// The PostgreSQL server of `FERRET_TEST_POSTGRES`, or a message on stderr saying how to give
/// one and `None` (the test then checks nothing and says so).
pub fn postgres_or_skip(test: &str) -> Option<String> {
    let url = fresh_postgres();
    if url.is_none() {
        eprintln!(
            "{test}: skipped: set FERRET_TEST_POSTGRES to a PostgreSQL URL (eval \"$(scripts/postgres.sh start)\" starts a throwaway server and sets it)"
        );
    }
    url
}

/// Three rooms in a row with doors, seven containers, targets in several places.
pub const SCENE: &str = r#"{
  "ferret_scene": 1, "name": "flat",
  "rooms": [
    {"name": "kitchen", "type": "Kitchen", "polygon": [[0,0],[4,0],[4,4],[0,4]]},
    {"name": "living room", "type": "LivingRoom", "polygon": [[4,0],[9,0],[9,4],[4,4]]},
    {"name": "bedroom", "type": "Bedroom", "polygon": [[9,0],[13,0],[13,4],[9,4]]}
  ],
  "doors": [{"from": [4, 1], "to": [4, 2]}, {"from": [9, 2.5], "to": [9, 3.5]}],
  "containers": [
    {"id": "fridge", "type": "Fridge", "pose": [0.5, 3.4, 0], "size": [0.7, 0.7], "contents": ["Egg", "Apple"]},
    {"id": "counter", "type": "CounterTop", "pose": [2.5, 3.6, 0], "size": [1.5, 0.6], "contents": ["Mug", "CellPhone"]},
    {"id": "sofa", "type": "Sofa", "pose": [6.5, 3.5, 0], "size": [2.0, 0.8], "contents": ["Pillow", "RemoteControl"]},
    {"id": "table", "type": "CoffeeTable", "pose": [6.5, 1.5, 0], "size": [1.0, 0.6], "contents": ["Book", "RemoteControl"]},
    {"id": "tv", "type": "TVStand", "pose": [8.6, 1.0, 90], "size": [1.2, 0.4], "contents": []},
    {"id": "bed", "type": "Bed", "pose": [11.5, 2.0, 0], "size": [2.0, 1.6], "contents": ["Pillow", "CellPhone"]},
    {"id": "dresser", "type": "Dresser", "pose": [12.6, 0.5, 0], "size": [0.6, 0.5], "contents": ["Wallet"]}
  ],
  "start": [5.0, 2.0, 0]
}"#;

pub const TARGETS: [&str; 5] = [
    "CellPhone",
    "RemoteControl",
    "Pillow",
    "Wallet",
    "CellPhone",
];

/// What a simulated robot sees in `container` of `scene` (as `GET /scenes/{name}` lists it):
/// the scene file's contents.
pub fn contents(scene: &serde_json::Value, container: &str) -> Vec<String> {
    scene["containers"]
        .as_array()
        .into_iter()
        .flatten()
        .find(|c| c["id"] == container)
        .and_then(|c| c["contents"].as_array())
        .map(|c| {
            c.iter()
                .filter_map(|v| v.as_str().map(str::to_string))
                .collect()
        })
        .unwrap_or_default()
}

pub fn strategies() -> Vec<Arc<dyn Strategy>> {
    let registry = StrategyRegistry::builtin(None, PlannerConfig::default(), 10);
    ["optimistic+greedy", "model/uniform", "model/uniform/k2"]
        .iter()
        .map(|s| registry.build(s).unwrap())
        .collect()
}
