//! Schema versions: a database written by an older server is migrated (its trials keep their
//! order, so its deployments replay to the same choices), one written by a newer server is
//! refused with a message saying so, on both backends.

mod support;

use ferret_serve::Store;
use ferret_serve::store::{SCHEMA_VERSION, StoreError};

/// The first servers' schema, as their SQLite files hold it (no recorded version).
const SQLITE_V1: &str = "
CREATE TABLE scenes (name TEXT PRIMARY KEY, body TEXT NOT NULL);
CREATE TABLE deployments (id INTEGER PRIMARY KEY AUTOINCREMENT, spec TEXT NOT NULL);
CREATE TABLE trials (
    id INTEGER PRIMARY KEY AUTOINCREMENT,
    deployment INTEGER NOT NULL REFERENCES deployments(id),
    k INTEGER NOT NULL, scene TEXT NOT NULL, target TEXT NOT NULL, pose TEXT,
    chosen INTEGER NOT NULL, status TEXT NOT NULL, cost REAL, replays TEXT,
    UNIQUE (deployment, k));
CREATE TABLE observations (
    trial INTEGER NOT NULL REFERENCES trials(id), seq INTEGER NOT NULL,
    container TEXT NOT NULL, found INTEGER NOT NULL, objects TEXT NOT NULL,
    travelled REAL, leg REAL NOT NULL, PRIMARY KEY (trial, seq));
CREATE TABLE requests (
    id TEXT PRIMARY KEY, fingerprint TEXT NOT NULL, status INTEGER NOT NULL, body TEXT NOT NULL);
";

/// A sequential deployment of the old kind: two trials done, one abandoned, one open.
const V1_ROWS: &str = r#"
INSERT INTO deployments (id, spec) VALUES (1, '{"strategies":["a","b"],"selector":"replay","c":5.0,"seed":0}');
INSERT INTO trials (deployment, k, scene, target, chosen, status, cost, replays) VALUES
    (1, 1, 'flat', 'Egg', 0, 'done', 3.0, '[3.0, 4.0]'),
    (1, 2, 'flat', 'Egg', 1, 'exhausted', 9.0, NULL),
    (1, 3, 'flat', 'Egg', 0, 'done', 2.0, '[2.0, 1.0]'),
    (1, 4, 'flat', 'Egg', 1, 'searching', NULL, NULL);
"#;

/// (k, started_after, end_seq) of the migrated trials: each started after the ones before it
/// ended, and they ended in the order they started.
fn expected() -> Vec<(i64, i64, Option<i64>)> {
    vec![
        (1, 0, Some(1)),
        (2, 1, Some(2)),
        (3, 2, Some(3)),
        (4, 3, None),
    ]
}

fn order(store: &Store) -> Vec<(i64, i64, Option<i64>)> {
    store
        .read(|r| r.trials_of(1))
        .unwrap()
        .iter()
        .map(|t| (t.k, t.started_after, t.end_seq))
        .collect()
}

#[test]
fn an_sqlite_file_of_the_first_servers_is_migrated_in_order() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("old.sqlite");
    {
        let conn = rusqlite::Connection::open(&path).unwrap();
        conn.execute_batch(SQLITE_V1).unwrap();
        conn.execute_batch(V1_ROWS).unwrap();
    }
    let store = Store::open(&path).unwrap();
    assert_eq!(store.schema_version().unwrap(), SCHEMA_VERSION);
    assert_eq!(order(&store), expected());
    let spec = store.read(|r| r.deployment(1)).unwrap().unwrap().spec;
    assert!(!spec.sequential, "old specs read with the default");
    drop(store);
    // Opening again changes nothing.
    let store = Store::open(&path).unwrap();
    assert_eq!(order(&store), expected());
}

#[test]
fn an_sqlite_file_of_a_newer_server_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("new.sqlite");
    drop(Store::open(&path).unwrap());
    {
        let conn = rusqlite::Connection::open(&path).unwrap();
        conn.pragma_update(None, "user_version", SCHEMA_VERSION + 1)
            .unwrap();
    }
    let e = Store::open(&path).err().expect("a newer schema is refused");
    assert!(matches!(e, StoreError::Schema { .. }), "{e}");
    let message = e.to_string();
    assert!(message.contains("newer ferret"), "{message}");
    assert!(message.contains("new.sqlite"), "{message}");
}

#[test]
fn a_postgres_database_at_version_1_is_migrated_and_a_newer_one_refused() {
    let Some(url) = support::postgres_or_skip("postgres migrations") else {
        return;
    };
    let v1 = SQLITE_V1
        .replace("INTEGER PRIMARY KEY AUTOINCREMENT", "BIGSERIAL PRIMARY KEY")
        .replace("INTEGER", "BIGINT")
        .replace("REAL", "DOUBLE PRECISION")
        .replace("found BIGINT", "found BOOLEAN");
    support::psql(
        &url,
        &format!(
            "{v1} CREATE TABLE ferret_schema (version BIGINT NOT NULL);
             INSERT INTO ferret_schema VALUES (1); {V1_ROWS}"
        ),
    );
    let store = support::connect(&url);
    assert_eq!(store.schema_version().unwrap(), SCHEMA_VERSION);
    assert_eq!(order(&store), expected());
    drop(store);
    support::psql(
        &url,
        &format!("UPDATE ferret_schema SET version = {}", SCHEMA_VERSION + 1),
    );
    let url2 = url.clone();
    let e = std::thread::spawn(move || {
        Store::connect(&url2, ferret_serve::PostgresOptions::default()).err()
    })
    .join()
    .unwrap()
    .expect("a newer schema is refused");
    assert!(matches!(e, StoreError::Schema { .. }), "{e}");
    assert!(e.to_string().contains("upgrade every replica"), "{e}");
    assert!(
        e.to_string().contains("postgres://"),
        "names the database: {e}"
    );
}
