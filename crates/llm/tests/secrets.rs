//! The API key's value never reaches the cache file or the logs, whatever happens on the way.
//! (Its own test binary: it installs a global subscriber that records everything, dependencies'
//! `log` records included.)

mod common;

use std::io::Write;
use std::sync::{Arc, Mutex};

use common::{KEY, completion, endpoint};
use ferret_llm::{ChatMessage, Ledger, Llm, Question, ResponseCache};
use wiremock::matchers::{body_string_contains, method};
use wiremock::{Mock, MockServer, ResponseTemplate};

#[derive(Clone, Default)]
struct Captured(Arc<Mutex<Vec<u8>>>);

impl Write for Captured {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0.lock().unwrap().extend_from_slice(buf);
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn contains(hay: &[u8], needle: &str) -> bool {
    hay.windows(needle.len()).any(|w| w == needle.as_bytes())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn key_is_absent_from_cache_file_and_logs() {
    let logs = Captured::default();
    let sink = logs.clone();
    tracing_subscriber::fmt()
        .with_max_level(tracing::Level::TRACE)
        .with_ansi(false)
        .with_writer(move || sink.clone())
        .try_init()
        .unwrap();

    let server = MockServer::start().await;
    // A flaky server: one 500, then answers; a question it refuses, echoing the key.
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(500).set_body_string("try again"))
        .up_to_n_times(1)
        .mount(&server)
        .await;
    Mock::given(method("POST"))
        .and(body_string_contains("forbidden"))
        .respond_with(
            ResponseTemplate::new(403).set_body_string(format!("key {KEY} may not ask this")),
        )
        .mount(&server)
        .await;
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_json(completion("70%", 50, 2)))
        .mount(&server)
        .await;

    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cache.sqlite");
    let llm = Llm::new(
        endpoint(&server),
        Some(Arc::new(ResponseCache::open(&path).unwrap())),
        false,
        Arc::new(Ledger::new()),
    )
    .unwrap();
    for q in ["Is the remote on the sofa?", "Is the egg in the fridge?"] {
        let a = llm
            .ask(&Question::free(vec![ChatMessage::user(q)]), "s")
            .await
            .unwrap();
        assert_eq!(a.text, "70%");
    }
    let err = llm
        .ask(
            &Question::free(vec![ChatMessage::user("forbidden question")]),
            "s",
        )
        .await
        .unwrap_err();
    tracing::error!("run failed: {err}; {err:?}");
    drop(llm);

    // The key really went out, in the Authorization header.
    let sent = server.received_requests().await.unwrap();
    assert!(sent.iter().all(
        |r| r.headers.get("authorization").unwrap().to_str().unwrap() == format!("Bearer {KEY}")
    ));

    let logs = logs.0.lock().unwrap().clone();
    let text = String::from_utf8_lossy(&logs);
    assert!(text.contains("retrying"), "the logs were captured: {text}");
    assert!(text.contains("[redacted] may not ask this"), "{text}");
    assert!(
        text.contains("hyper_util") && text.contains("reqwest"),
        "dependencies' records were captured too"
    );
    assert!(!contains(&logs, KEY), "the key is in the logs:\n{text}");

    let mut files = 0;
    for entry in std::fs::read_dir(dir.path()).unwrap() {
        let bytes = std::fs::read(entry.unwrap().path()).unwrap();
        assert!(!contains(&bytes, KEY), "the key is in the cache files");
        files += 1;
    }
    assert!(files >= 1);
    let all: Vec<u8> = std::fs::read_dir(dir.path())
        .unwrap()
        .flat_map(|e| std::fs::read(e.unwrap().path()).unwrap())
        .collect();
    assert!(
        contains(&all, "Is the egg in the fridge?"),
        "the answers were stored"
    );
}
