//! How endpoint failures are met: the circuit breaker of long-running servers next to the
//! run-wide stop of batch commands, servers that accept connections and never answer, replies
//! holding terminal escapes, and keys pasted where a variable's name belongs.

mod common;

use std::path::Path;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use common::{JsonServer as Server, completion, small_scene};
use ferret_llm::{
    ChatMessage, Endpoint, EndpointClient, EndpointConfig, FailurePolicy, LlmConfig, LlmError,
    LlmLikelihood, LlmOptions, LlmService, Request,
};
use ferret_world::ObjectType;
use wiremock::ResponseTemplate;

/// A server that answers 503 until `up` is set, then a percentage.
fn flaky(up: Arc<AtomicBool>) -> Server {
    Server::start(move |_| {
        if up.load(Ordering::SeqCst) {
            ResponseTemplate::new(200).set_body_json(completion("40%", 10, 2))
        } else {
            ResponseTemplate::new(503).set_body_string("overloaded")
        }
    })
}

fn ask(service: &Arc<LlmService>) -> Result<(), LlmError> {
    let source = LlmLikelihood::new(service.clone(), "p-minimal", "mock", "t").unwrap();
    let (house, _) = small_scene("h#0");
    service
        .block_on(source.likelihoods_async(&house, &ObjectType::new("RemoteControl")))
        .map(|_| ())
}

/// In `ferret serve` one failure used to block the endpoint until restart: every later trial
/// was a 503 after the endpoint was back.
#[test]
fn the_breaker_fails_fast_while_open_and_closes_when_the_endpoint_is_back() {
    let up = Arc::new(AtomicBool::new(false));
    let server = flaky(up.clone());
    let pause = Duration::from_millis(400);
    let service = server.service_with(
        |c| c.max_attempts = 1,
        LlmOptions {
            on_failure: FailurePolicy::Breaker { pause },
            ..LlmOptions::default()
        },
    );
    let e = ask(&service).unwrap_err();
    assert!(e.to_string().contains("503"), "{e}");
    let sent = server.bodies().len();
    // Open: fails at once, nothing sent.
    let started = Instant::now();
    let e = ask(&service).unwrap_err();
    assert!(matches!(e, LlmError::EndpointPaused { .. }), "{e}");
    assert!(started.elapsed() < Duration::from_millis(200));
    assert_eq!(server.bodies().len(), sent);
    // Still failing after the pause: open again.
    std::thread::sleep(pause + Duration::from_millis(50));
    let e = ask(&service).unwrap_err();
    assert!(e.to_string().contains("503"), "{e}");
    assert!(server.bodies().len() > sent);
    // Back: the next probe succeeds and the circuit closes.
    up.store(true, Ordering::SeqCst);
    assert!(matches!(
        ask(&service),
        Err(LlmError::EndpointPaused { .. })
    ));
    std::thread::sleep(pause + Duration::from_millis(50));
    ask(&service).unwrap();
    ask(&service).unwrap();
    assert!(service.failed_llms().is_empty());
}

/// Batch commands keep their fast stop: once down, down for the run.
#[test]
fn batch_commands_stop_asking_a_failed_endpoint_for_the_run() {
    let up = Arc::new(AtomicBool::new(false));
    let server = flaky(up.clone());
    let service = server.service(|c| c.max_attempts = 1);
    ask(&service).unwrap_err();
    up.store(true, Ordering::SeqCst);
    std::thread::sleep(Duration::from_millis(100));
    let e = ask(&service).unwrap_err();
    assert!(matches!(e, LlmError::EndpointDown { .. }), "{e}");
}

/// A loopback port that accepts connections and never answers; connections stay open while the
/// returned runtime lives.
fn silent_server() -> (tokio::runtime::Runtime, String) {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let url = format!("http://{}/v1", listener.local_addr().unwrap());
    rt.spawn(async move {
        let mut held = Vec::new();
        while let Ok((s, _)) = listener.accept().await {
            held.push(s);
        }
    });
    (rt, url)
}

/// A server that accepts and never answers used to hold a request for timeout × max_attempts
/// (120 s × 5 by default).
#[test]
fn a_server_that_never_answers_is_given_up_on_after_two_timeouts() {
    let (_rt, url) = silent_server();
    let mut c = EndpointConfig::new(url, "m");
    c.timeout_secs = 1.0;
    c.max_attempts = 5;
    c.retry_base_ms = 10;
    let client = EndpointClient::new(Endpoint::with_key("silent", c, None)).unwrap();
    let rt = tokio::runtime::Runtime::new().unwrap();
    let started = Instant::now();
    let e = rt
        .block_on(client.complete(&Request::plain(vec![ChatMessage::user("hi")])))
        .unwrap_err();
    let took = started.elapsed();
    match e {
        LlmError::Timeout { attempts, .. } => assert_eq!(attempts, 2),
        other => panic!("{other}"),
    }
    assert!(took < Duration::from_millis(3500), "{took:?}");
    // A single check gives up after its own, shorter timeout.
    let started = Instant::now();
    let e = rt
        .block_on(client.complete_once(
            &Request::plain(vec![ChatMessage::user("hi")]),
            Duration::from_millis(300),
        ))
        .unwrap_err();
    assert!(matches!(e, LlmError::Timeout { attempts: 1, .. }), "{e}");
    assert!(started.elapsed() < Duration::from_millis(900));
}

/// Control characters of a reply were echoed raw to the terminal (`reply began: ^[[2J…`).
#[test]
fn control_characters_of_a_reply_are_escaped_in_errors() {
    let server = Server::start(|_| {
        ResponseTemplate::new(200).set_body_string("\u{1b}[2J\u{1b}[31mowned\r\u{7}\u{202e}txt")
    });
    let service = server.service(|c| c.max_attempts = 1);
    let e = ask(&service).unwrap_err().to_string();
    assert!(e.contains("reply began"), "{e}");
    for raw in ['\u{1b}', '\r', '\u{7}', '\u{202e}'] {
        assert!(!e.contains(raw), "{e:?}");
    }
    assert!(e.contains("\\u{1b}[2J"), "{e}");
}

/// A key pasted into `api_key_env` was accepted and then printed as a variable name.
#[test]
fn a_key_in_api_key_env_is_refused_without_being_repeated() {
    for key in [
        "sk-proj-Ab12Cd34Ef56Gh78Ij90",
        "hf_AbCdEfGhIjKlMnOpQrStUvWx",
        "AIzaSyA1b2C3d4E5f6G7h8I9j0K",
        "Ab12Cd34Ef56Gh78Ij90Kl12",
    ] {
        let text = format!(
            "[llm.x]\nbase_url = \"http://127.0.0.1:9/v1\"\nmodel = \"m\"\napi_key_env = \"{key}\"\n"
        );
        let e = LlmConfig::parse(&text, Path::new("ferret.toml"))
            .unwrap_err()
            .to_string();
        assert!(!e.contains(key) && !e.contains(&key[..10]), "{e}");
        assert!(e.contains("api_key_env"), "{e}");
    }
    for name in ["OPENAI_API_KEY", "my_key", "GEMINI_API_KEY_2"] {
        let text = format!(
            "[llm.x]\nbase_url = \"http://127.0.0.1:9/v1\"\nmodel = \"m\"\napi_key_env = \"{name}\"\n"
        );
        LlmConfig::parse(&text, Path::new("ferret.toml")).unwrap();
    }
}

/// Questions asked together queue for the endpoint's concurrency permits; once the first found
/// the endpoint down, the others were still sent, each for its own timeouts (a silent endpoint
/// with a 5 s timeout and two attempts held a trial start for 30 s instead of 10).
#[test]
fn questions_queued_behind_a_failure_are_not_sent() {
    let mut sent = Vec::new();
    for policy in [
        FailurePolicy::Breaker {
            pause: Duration::from_secs(600),
        },
        FailurePolicy::StopForRun,
    ] {
        let server = flaky(Arc::new(AtomicBool::new(false)));
        let service = server.service_with(
            |c| {
                c.max_attempts = 1;
                c.concurrency = 1;
            },
            LlmOptions {
                on_failure: policy,
                ..LlmOptions::default()
            },
        );
        let e = ask(&service).unwrap_err();
        assert!(e.to_string().contains("503"), "{policy:?}: {e}");
        sent.push(server.bodies().len());
    }
    assert_eq!(sent, [1, 1]);
}

/// The same with a server that accepts connections and never answers, as a serve trial met it:
/// only the first question's attempts reach it.
#[test]
fn questions_queued_behind_a_silent_endpoint_are_not_sent() {
    let rt = tokio::runtime::Runtime::new().unwrap();
    let listener = rt
        .block_on(tokio::net::TcpListener::bind("127.0.0.1:0"))
        .unwrap();
    let url = format!("http://{}/v1", listener.local_addr().unwrap());
    let connections = Arc::new(std::sync::atomic::AtomicUsize::new(0));
    let counted = connections.clone();
    rt.spawn(async move {
        let mut held = Vec::new();
        while let Ok((s, _)) = listener.accept().await {
            counted.fetch_add(1, Ordering::SeqCst);
            held.push(s);
        }
    });
    let mut c = EndpointConfig::new(url, "m");
    c.timeout_secs = 0.3;
    c.max_attempts = 2;
    c.retry_base_ms = 10;
    c.concurrency = 1;
    let config = LlmConfig {
        file: "test.toml".into(),
        endpoints: std::collections::BTreeMap::from([("mock".to_string(), c)]),
        prompts: std::collections::BTreeMap::new(),
    };
    let service = Arc::new(
        LlmService::new(
            config,
            LlmOptions {
                on_failure: FailurePolicy::Breaker {
                    pause: Duration::from_secs(600),
                },
                ..LlmOptions::default()
            },
        )
        .unwrap(),
    );
    let e = ask(&service).unwrap_err();
    assert!(matches!(e, LlmError::Timeout { .. }), "{e}");
    // Two attempts of the first question, each on a connection of its own.
    assert!(connections.load(Ordering::SeqCst) <= 2, "{connections:?}");
}
