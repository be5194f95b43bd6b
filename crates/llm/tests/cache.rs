//! The response cache in front of a loopback server: repeat runs send nothing, offline mode
//! answers only from the cache, answers are committed before use, and many writers share a file.

mod common;

use std::sync::Arc;
use std::time::Duration;

use common::{completion, endpoint};
use ferret_llm::{
    CachedReply, ChatMessage, Ledger, Llm, LlmError, Question, ResponseCache, TokenUsage, cache_key,
};
use serde_json::Value;
use wiremock::matchers::method;
use wiremock::{Mock, MockServer, Request, ResponseTemplate};

/// Answers "<n>%" where n is the length of the last message, so different prompts get different
/// answers.
fn echo_length(req: &Request) -> ResponseTemplate {
    let body: Value = req.body_json().unwrap_or_default();
    let n = body["messages"]
        .as_array()
        .and_then(|m| m.last())
        .and_then(|m| m["content"].as_str())
        .map_or(0, str::len);
    ResponseTemplate::new(200).set_body_json(completion(&format!("{n}%"), 100 + n as u32, 2))
}

fn prompts() -> Vec<Question> {
    [
        "Is the remote on the sofa?",
        "Is the egg in the fridge?",
        "Is the book on the shelf?",
    ]
    .iter()
    .map(|q| {
        Question::free(vec![
            ChatMessage::system("Answer with a percentage."),
            ChatMessage::user(*q),
        ])
    })
    .collect()
}

#[tokio::test]
async fn second_identical_run_sends_nothing_and_offline_replays_it() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(echo_length)
        .expect(3)
        .mount(&server)
        .await;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("cache.sqlite");

    // First run: three distinct prompts, one of them asked twice.
    let ledger = Arc::new(Ledger::new());
    let cache = Arc::new(ResponseCache::open(&path).unwrap());
    let llm = Llm::new(endpoint(&server), Some(cache), false, ledger.clone()).unwrap();
    let mut first = Vec::new();
    for p in prompts().iter().chain(prompts().iter().take(1)) {
        first.push(llm.ask(p, "s").await.unwrap());
    }
    assert_eq!(server.received_requests().await.unwrap().len(), 3);
    assert!(!first[0].from_cache && first[3].from_cache);
    assert_eq!(first[0].text, first[3].text);
    let report = ledger.report();
    let row = report.row("mock", "s").unwrap();
    // The repeated prompt was sent in this very run: reading it again is not a cache hit.
    assert_eq!((row.sent.requests, row.cache_hits), (3, 0));
    assert_eq!(
        row.sent.input_tokens,
        first[..3]
            .iter()
            .map(|a| a.usage.prompt_tokens)
            .sum::<u64>()
    );
    drop(llm);

    // Second run, a fresh process's worth of state: zero HTTP requests, same answers.
    let ledger2 = Arc::new(Ledger::new());
    let llm = Llm::new(
        endpoint(&server),
        Some(Arc::new(ResponseCache::open(&path).unwrap())),
        false,
        ledger2.clone(),
    )
    .unwrap();
    for (p, a) in prompts().iter().zip(&first) {
        let again = llm.ask(p, "s").await.unwrap();
        assert!(again.from_cache);
        assert_eq!((&again.text, again.usage), (&a.text, a.usage));
    }
    assert_eq!(
        server.received_requests().await.unwrap().len(),
        3,
        "the second run asked the server"
    );
    let row2 = ledger2.report().row("mock", "s").unwrap().clone();
    assert_eq!((row2.sent.requests, row2.cache_hits), (0, 3));

    // Offline: the same answers, and still nothing sent.
    let llm = Llm::new(
        endpoint(&server),
        Some(Arc::new(ResponseCache::open(&path).unwrap())),
        true,
        Arc::new(Ledger::new()),
    )
    .unwrap();
    for (p, a) in prompts().iter().zip(&first) {
        assert_eq!(llm.ask(p, "s").await.unwrap().text, a.text);
    }
    assert_eq!(server.received_requests().await.unwrap().len(), 3);
}

#[tokio::test]
async fn offline_with_an_empty_cache_names_endpoint_and_prompt() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(echo_length)
        .expect(0)
        .mount(&server)
        .await;
    let dir = tempfile::tempdir().unwrap();
    let cache = Arc::new(ResponseCache::open(&dir.path().join("empty.sqlite")).unwrap());
    let llm = Llm::new(
        endpoint(&server),
        Some(cache),
        true,
        Arc::new(Ledger::new()),
    )
    .unwrap();
    let e = llm.ask(&prompts()[1], "s").await.unwrap_err();
    assert!(matches!(e, LlmError::NotCached { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("offline") && msg.contains("`mock`") && msg.contains("test-model"),
        "{msg}"
    );
    assert!(
        msg.contains("Answer with a percentage. Is the egg in the fridge?"),
        "{msg}"
    );
}

#[tokio::test]
async fn answer_is_committed_before_it_is_returned() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(echo_length)
        .mount(&server)
        .await;
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.sqlite");
    let llm = Llm::new(
        endpoint(&server),
        Some(Arc::new(ResponseCache::open(&path).unwrap())),
        false,
        Arc::new(Ledger::new()),
    )
    .unwrap();
    let p = &prompts()[2];
    let answer = llm.ask(p, "s").await.unwrap();
    // Another connection (as another process would) sees it at once, with what was sent.
    let other = ResponseCache::open(&path).unwrap();
    let stored = other
        .get(&cache_key(&llm.endpoint().config, &llm.request(p)))
        .unwrap()
        .unwrap();
    assert_eq!(stored.reply, answer.text);
    assert_eq!(stored.messages, p.messages);
    assert_eq!(stored.endpoint, "mock");
    assert_eq!(stored.model, "test-model");
    assert_eq!(stored.usage, answer.usage);
    assert!(stored.created_unix > 1_700_000_000);
}

#[tokio::test]
async fn concurrent_askers_of_one_prompt_send_it_once() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(
            ResponseTemplate::new(200)
                .set_body_json(completion("40%", 9, 1))
                .set_delay(Duration::from_millis(200)),
        )
        .expect(1)
        .mount(&server)
        .await;
    let dir = tempfile::tempdir().unwrap();
    let cache = Arc::new(ResponseCache::open(&dir.path().join("c.sqlite")).unwrap());
    let llm = Arc::new(
        Llm::new(
            endpoint(&server),
            Some(cache),
            false,
            Arc::new(Ledger::new()),
        )
        .unwrap(),
    );
    let tasks: Vec<_> = (0..8)
        .map(|_| {
            let llm = llm.clone();
            tokio::spawn(async move { llm.ask(&prompts()[0], "s").await })
        })
        .collect();
    for t in tasks {
        assert_eq!(t.await.unwrap().unwrap().text, "40%");
    }
    assert_eq!(server.received_requests().await.unwrap().len(), 1);
}

#[test]
fn concurrent_writers_share_one_cache_file() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("shared.sqlite");
    let writers = 6;
    let keys = 120;
    // Each writer is its own connection, as separate ferret processes would be; every writer
    // stores an answer for every key, each its own, interleaved.
    let seen: Vec<Vec<String>> = std::thread::scope(|s| {
        let handles: Vec<_> = (0..writers)
            .map(|w| {
                let path = path.clone();
                s.spawn(move || {
                    let cache = ResponseCache::open(&path).unwrap();
                    (0..keys)
                        .map(|k| {
                            // 7 is coprime with 120: a permutation, a different order per writer.
                            let k = (k * 7 + w * 31) % keys;
                            cache
                                .put(&CachedReply {
                                    key: format!("key{k}"),
                                    endpoint: format!("writer{w}"),
                                    model: "m".into(),
                                    server: "http://x".into(),
                                    messages: vec![ChatMessage::user(format!("q{k}"))],
                                    reply: format!("{w}"),
                                    usage: TokenUsage {
                                        prompt_tokens: k as u64,
                                        completion_tokens: 1,
                                        cached_tokens: None,
                                    },
                                    latency: Duration::from_millis(1),
                                    created_unix: 1,
                                    logprobs: None,
                                })
                                .map(|stored| (k, stored.reply))
                                .unwrap()
                        })
                        .fold(vec![String::new(); keys], |mut v, (k, r)| {
                            v[k] = r;
                            v
                        })
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap()).collect()
    });
    let cache = ResponseCache::open(&path).unwrap();
    cache.integrity_check().unwrap();
    assert_eq!(cache.len().unwrap(), keys as u64);
    for k in 0..keys {
        let stored = cache.get(&format!("key{k}")).unwrap().unwrap();
        assert_eq!(stored.usage.prompt_tokens, k as u64);
        // Every writer was handed the one stored answer, whoever wrote first.
        for (w, replies) in seen.iter().enumerate() {
            assert_eq!(replies[k], stored.reply, "writer {w}, key {k}");
        }
    }
}
