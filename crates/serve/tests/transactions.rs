//! The store's transactions on the backend under test (SQLite by default, PostgreSQL with
//! `FERRET_SERVE_TEST_BACKEND=postgres`): a write that fails or panics leaves nothing behind,
//! not even on a connection the pool hands out later, and a failed final statement rolls back
//! the statements before it.

mod support;

use ferret_serve::Outcome;
use ferret_serve::model::StoredReply;
use ferret_serve::store::{StoreError, store_reply};

fn scene_names(store: &ferret_serve::Store) -> Vec<String> {
    store
        .read(|r| r.scenes())
        .unwrap()
        .into_iter()
        .map(|(name, _)| name)
        .collect()
}

#[test]
fn a_write_that_fails_or_panics_leaves_nothing_even_on_a_reused_connection() {
    let store = support::store();
    let failed: Result<(), StoreError> = store.write(|w| {
        w.insert_scene("failed", "{}")?;
        Err(StoreError::Corrupt {
            file: "test".into(),
            what: "the write gives up".into(),
        })
    });
    assert!(failed.is_err());
    let panicked = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        let _: Result<(), StoreError> = store.write(|w| {
            w.insert_scene("panicked", "{}")?;
            panic!("a bug in the middle of a write");
        });
    }));
    assert!(panicked.is_err());
    // More writes than the pool has connections: a connection handed back in the middle of
    // the panicked transaction would commit its row with one of these.
    for i in 0..40 {
        store
            .write(|w| w.insert_scene(&format!("kept-{i}"), "{}"))
            .unwrap();
    }
    let names = scene_names(&store);
    assert_eq!(names.len(), 40, "{names:?}");
    assert!(names.iter().all(|n| n.starts_with("kept-")), "{names:?}");
}

#[test]
fn a_failed_final_statement_rolls_back_the_statements_before_it() {
    let store = support::store();
    let reply = StoredReply {
        fingerprint: "f".into(),
        outcome: Outcome::Created,
        body: "{}".into(),
    };
    store
        .write_finishing(|_| Ok::<_, StoreError>(((), vec![store_reply("id-1", &reply)])))
        .unwrap()
        .unwrap();
    let done = store
        .write_finishing(|w| {
            w.insert_scene("second", "{}")?;
            Ok::<_, StoreError>(((), vec![store_reply("id-1", &reply)]))
        })
        .unwrap();
    let failed = done.expect_err("a second reply to one id is refused");
    assert_eq!(failed.index, 0);
    assert!(failed.error.is_duplicate(), "{}", failed.error);
    assert!(scene_names(&store).is_empty());
    // A write with nothing but its final statements stores them.
    store
        .write_finishing(|_| Ok::<_, StoreError>(((), vec![store_reply("id-2", &reply)])))
        .unwrap()
        .unwrap();
    assert_eq!(
        store.read(|r| r.reply("id-2")).unwrap().map(|r| r.body),
        Some("{}".to_string())
    );
}

#[test]
fn a_replaced_reply_is_read_back_and_an_unknown_id_changes_nothing() {
    let store = support::store();
    let reply = StoredReply {
        fingerprint: "f".into(),
        outcome: Outcome::Created,
        body: "{\"unplanned_trial\": 1}".into(),
    };
    store
        .write_finishing(|_| Ok::<_, StoreError>(((), vec![store_reply("start-1", &reply)])))
        .unwrap()
        .unwrap();
    store.replace_reply("start-1", "{\"trial\": 1}").unwrap();
    store.replace_reply("start-2", "{\"trial\": 2}").unwrap();
    let read = |id: &str| store.read(|r| r.reply(id)).unwrap().map(|r| r.body);
    assert_eq!(read("start-1").as_deref(), Some("{\"trial\": 1}"));
    assert_eq!(read("start-2"), None);
}
