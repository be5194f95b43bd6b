//! The HTTP client against loopback OpenAI-compatible servers: what it sends, what it accepts,
//! and how it fails.

mod common;

use std::time::{Duration, Instant};

use common::{KEY, completion, config, endpoint, message_content};
use ferret_llm::{
    ChatMessage, Endpoint, EndpointClient, LlmError, MaxTokensParam, Request, TokenUsage,
};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use wiremock::matchers::{bearer_token, body_partial_json, header, method, path};
use wiremock::{Mock, MockServer, ResponseTemplate};

fn question() -> Request {
    Request::plain(vec![
        ChatMessage::system("You help a robot."),
        ChatMessage::user("Is the remote on the sofa?"),
    ])
}

#[tokio::test]
async fn request_carries_model_messages_settings_and_key() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .and(path("/v1/chat/completions"))
        .and(bearer_token(KEY))
        .and(header("content-type", "application/json"))
        .and(body_partial_json(json!({
            "model": "test-model",
            "messages": [
                {"role": "system", "content": "You help a robot."},
                {"role": "user", "content": "Is the remote on the sofa?"}
            ],
            "temperature": 0.25,
            "seed": 42,
            "max_completion_tokens": 64,
            "reasoning_effort": "low"
        })))
        .respond_with(ResponseTemplate::new(200).set_body_json(completion("70%", 21, 2)))
        .expect(1)
        .mount(&server)
        .await;
    let mut c = config(&server);
    c.temperature = Some(0.25);
    c.seed = Some(42);
    c.max_output_tokens = Some(64);
    c.reasoning_effort = Some(ferret_llm::ReasoningEffort::Low);
    let client = EndpointClient::new(Endpoint::with_key("mock", c, Some(KEY.into()))).unwrap();
    let reply = client.complete(&question()).await.unwrap();
    assert_eq!(reply.text, "70%");
    assert_eq!(
        reply.usage,
        TokenUsage {
            prompt_tokens: 21,
            completion_tokens: 2,
            cached_tokens: None
        }
    );
    assert_eq!(reply.attempts, 1);
    // Settings left unset are not sent at all.
    let body: Value = server.received_requests().await.unwrap()[0]
        .body_json()
        .unwrap();
    assert!(
        body.get("max_tokens").is_none() && body.get("top_p").is_none(),
        "{body}"
    );
}

#[tokio::test]
async fn keyless_endpoint_sends_no_authorization_and_max_tokens_when_asked() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .and(body_partial_json(json!({"max_tokens": 5})))
        .respond_with(ResponseTemplate::new(200).set_body_json(completion("0.4", 3, 1)))
        .expect(1)
        .mount(&server)
        .await;
    let mut c = config(&server);
    c.api_key_env = None;
    c.max_output_tokens = Some(5);
    c.max_tokens_param = MaxTokensParam::MaxTokens;
    let client = EndpointClient::new(Endpoint::with_key("local", c, None)).unwrap();
    assert_eq!(client.complete(&question()).await.unwrap().text, "0.4");
    let req = &server.received_requests().await.unwrap()[0];
    assert!(req.headers.get("authorization").is_none());
    let body: Value = req.body_json().unwrap();
    assert!(body.get("max_completion_tokens").is_none(), "{body}");
}

#[tokio::test]
async fn replies_with_extra_fields_parse() {
    // As vLLM answers: reasoning_content, stop_reason, prompt_logprobs, kv_transfer_params, ...
    let vllm = json!({
        "id": "chatcmpl-9f", "object": "chat.completion", "created": 1_752_000_000u32,
        "model": "openai/gpt-oss-120b",
        "choices": [{
            "index": 0,
            "message": {"role": "assistant", "reasoning_content": "Remotes live near sofas.",
                        "content": "65%", "tool_calls": [], "refusal": null, "annotations": null,
                        "audio": null, "function_call": null},
            "logprobs": null, "finish_reason": "stop", "stop_reason": null
        }],
        "service_tier": null, "system_fingerprint": null,
        "usage": {"prompt_tokens": 310, "total_tokens": 330, "completion_tokens": 20,
                  "prompt_tokens_details": {"cached_tokens": 256}},
        "prompt_logprobs": null, "kv_transfer_params": null
    });
    // As Gemini's OpenAI-compatible endpoint answers: extra_content, thought fields, no index.
    let gemini = json!({
        "choices": [{"finish_reason": "stop", "index": 0,
                     "message": {"content": "around 70 percent", "role": "assistant",
                                 "extra_content": {"google": {"thought": true}}}}],
        "created": 1_752_000_000u32, "id": "gem-1", "model": "gemini-2.5-flash",
        "object": "chat.completion",
        "usage": {"completion_tokens": 4, "prompt_tokens": 280, "total_tokens": 300,
                  "completion_tokens_details": {"reasoning_tokens": 16}}
    });
    for (body, text, usage) in [
        (
            vllm,
            "65%",
            TokenUsage {
                prompt_tokens: 310,
                completion_tokens: 20,
                cached_tokens: Some(256),
            },
        ),
        (
            gemini,
            "around 70 percent",
            TokenUsage {
                prompt_tokens: 280,
                completion_tokens: 4,
                cached_tokens: None,
            },
        ),
    ] {
        let server = MockServer::start().await;
        Mock::given(method("POST"))
            .respond_with(ResponseTemplate::new(200).set_body_json(body))
            .mount(&server)
            .await;
        let client = EndpointClient::new(endpoint(&server)).unwrap();
        let reply = client.complete(&question()).await.unwrap();
        assert_eq!(reply.text, text);
        assert_eq!(reply.usage, usage);
    }
}

#[tokio::test]
async fn rate_limit_then_success_honours_retry_after() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(
            ResponseTemplate::new(429)
                .insert_header("retry-after", "1")
                .set_body_json(
                    json!({"error": {"message": "Rate limit reached", "type": "requests"}}),
                ),
        )
        .up_to_n_times(1)
        .expect(1)
        .mount(&server)
        .await;
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_json(completion("85%", 10, 2)))
        .expect(1)
        .mount(&server)
        .await;
    let client = EndpointClient::new(endpoint(&server)).unwrap();
    let started = Instant::now();
    let reply = client.complete(&question()).await.unwrap();
    let waited = started.elapsed();
    assert_eq!(reply.text, "85%");
    assert_eq!(reply.attempts, 2);
    // retry_base_ms is 10 ms: only Retry-After explains a wait of a second.
    assert!(
        waited >= Duration::from_millis(950),
        "retried after {waited:?}"
    );
    assert!(waited < Duration::from_secs(4), "retried after {waited:?}");
}

#[tokio::test]
async fn server_errors_until_attempts_are_exhausted() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(
            ResponseTemplate::new(500)
                .set_body_string("upstream model crashed: CUDA out of memory"),
        )
        .expect(3)
        .mount(&server)
        .await;
    let mut c = config(&server);
    c.max_attempts = 3;
    let client = EndpointClient::new(Endpoint::with_key("vllm-box", c, Some(KEY.into()))).unwrap();
    let e = client.complete(&question()).await.unwrap_err();
    assert!(
        matches!(
            e,
            LlmError::Status {
                status: 500,
                attempts: 3,
                ..
            }
        ),
        "{e:?}"
    );
    let msg = e.to_string();
    assert!(msg.contains("vllm-box"), "{msg}");
    assert!(msg.contains(&server.uri()), "{msg}");
    assert!(msg.contains("HTTP 500"), "{msg}");
    assert!(msg.contains("CUDA out of memory"), "{msg}");
    assert!(!msg.contains(KEY));
}

#[tokio::test]
async fn client_errors_fail_at_once_and_never_show_the_key() {
    let server = MockServer::start().await;
    // A server that echoes the key it was given.
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(401).set_body_string(format!(
            "{{\"error\":{{\"message\":\"Incorrect API key provided: {KEY}\"}}}}"
        )))
        .expect(1)
        .mount(&server)
        .await;
    let client = EndpointClient::new(endpoint(&server)).unwrap();
    let e = client.complete(&question()).await.unwrap_err();
    assert!(
        matches!(
            e,
            LlmError::Status {
                status: 401,
                attempts: 1,
                ..
            }
        ),
        "{e:?}"
    );
    let msg = e.to_string();
    assert!(
        msg.contains("Incorrect API key provided: [redacted]"),
        "{msg}"
    );
    assert!(
        !msg.contains(KEY) && !format!("{e:?}").contains(KEY),
        "{msg}"
    );
}

#[tokio::test]
async fn timeouts_are_retried_then_reported() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(
            ResponseTemplate::new(200)
                .set_body_json(completion("50%", 1, 1))
                .set_delay(Duration::from_secs(3)),
        )
        .expect(2)
        .mount(&server)
        .await;
    let mut c = config(&server);
    c.timeout_secs = 0.3;
    c.max_attempts = 2;
    let client = EndpointClient::new(Endpoint::with_key("slow", c, Some(KEY.into()))).unwrap();
    let started = Instant::now();
    let e = client.complete(&question()).await.unwrap_err();
    assert!(matches!(e, LlmError::Timeout { attempts: 2, .. }), "{e:?}");
    assert!(
        e.to_string().contains("slow") && e.to_string().contains("0.3 s"),
        "{e}"
    );
    assert!(
        started.elapsed() < Duration::from_secs(3),
        "{:?}",
        started.elapsed()
    );
}

#[tokio::test]
async fn timeout_then_success() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(
            ResponseTemplate::new(200)
                .set_body_json(completion("10%", 1, 1))
                .set_delay(Duration::from_secs(3)),
        )
        .up_to_n_times(1)
        .mount(&server)
        .await;
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_json(completion("20%", 1, 1)))
        .mount(&server)
        .await;
    let mut c = config(&server);
    c.timeout_secs = 0.5;
    let client = EndpointClient::new(Endpoint::with_key("slow", c, Some(KEY.into()))).unwrap();
    let reply = client.complete(&question()).await.unwrap();
    assert_eq!((reply.text.as_str(), reply.attempts), ("20%", 2));
}

#[tokio::test]
async fn truncated_json_is_retried_then_a_clear_error() {
    let server = MockServer::start().await;
    let full = completion("70%", 5, 1).to_string();
    let cut = &full[..full.len() / 2];
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_raw(cut.to_string(), "application/json"))
        // A half-written reply under a 200 is retried like a 5xx, up to max_attempts (5).
        .expect(5)
        .mount(&server)
        .await;
    let client = EndpointClient::new(endpoint(&server)).unwrap();
    let e = client.complete(&question()).await.unwrap_err();
    assert!(matches!(e, LlmError::InvalidReply { .. }), "{e:?}");
    let msg = e.to_string();
    assert!(
        msg.contains("mock") && msg.contains("truncated JSON"),
        "{msg}"
    );
    assert!(
        msg.contains("reply began: {\"choices\":[{"),
        "the reply's start is shown: {msg}"
    );
}

#[tokio::test]
async fn not_a_completion_is_a_clear_error() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_string("<html>proxy login</html>"))
        .mount(&server)
        .await;
    let client = EndpointClient::new(endpoint(&server)).unwrap();
    let msg = client.complete(&question()).await.unwrap_err().to_string();
    assert!(
        msg.contains("not JSON") && msg.contains("<html>proxy login"),
        "{msg}"
    );
}

#[tokio::test]
async fn a_proxy_page_under_200_is_retried_like_a_server_error() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_string("<html>proxy hiccup</html>"))
        .up_to_n_times(1)
        .mount(&server)
        .await;
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_json(completion("35%", 5, 1)))
        .mount(&server)
        .await;
    let client = EndpointClient::new(endpoint(&server)).unwrap();
    let reply = client.complete(&question()).await.unwrap();
    assert_eq!((reply.text.as_str(), reply.attempts), ("35%", 2));
}

#[tokio::test]
async fn huge_bodies_and_answers_are_capped() {
    let server = MockServer::start().await;
    let huge = "x".repeat(ferret_llm::client::MAX_REPLY_BYTES + 1);
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_string(huge))
        .up_to_n_times(1)
        .mount(&server)
        .await;
    let long_answer = "7".repeat(ferret_llm::client::MAX_ANSWER_BYTES * 3);
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200).set_body_json(completion(&long_answer, 5, 1)))
        .mount(&server)
        .await;
    let client = EndpointClient::new(endpoint(&server)).unwrap();
    let e = client.complete(&question()).await.unwrap_err();
    assert!(e.to_string().contains("larger than 8 MiB"), "{e}");
    let reply = client.complete(&question()).await.unwrap();
    assert_eq!(reply.text.len(), ferret_llm::client::MAX_ANSWER_BYTES);
}

#[tokio::test]
async fn a_key_in_the_query_reaches_the_server_and_nothing_else() {
    let server = MockServer::start().await;
    // The gateway echoes its key lower-cased in a 403.
    Mock::given(method("POST"))
        .and(path("/v1/chat/completions"))
        .and(wiremock::matchers::query_param("key", "GwKey-9f8e7d6c5b4a"))
        .respond_with(
            ResponseTemplate::new(403).set_body_string("forbidden for key gwkey-9f8e7d6c5b4a"),
        )
        .expect(1)
        .mount(&server)
        .await;
    let mut c = config(&server);
    c.base_url = format!("{}/v1/?key=GwKey-9f8e7d6c5b4a", server.uri());
    let client = EndpointClient::new(Endpoint::with_key("gw", c, Some(KEY.into()))).unwrap();
    let e = client.complete(&question()).await.unwrap_err();
    let msg = format!("{e} {e:?}");
    assert!(
        msg.contains("403") && msg.contains("key=[redacted]"),
        "{msg}"
    );
    assert!(!msg.to_lowercase().contains("9f8e7d6c5b4a"), "{msg}");
}

/// A loopback server that drops the first connection after reading the request (no reply), then
/// answers the next one properly.
async fn cutting_server(reply: String) -> (String, tokio::task::JoinHandle<usize>) {
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0").await.unwrap();
    let addr = listener.local_addr().unwrap();
    let task = tokio::spawn(async move {
        let mut served = 0;
        for i in 0..2 {
            let (mut sock, _) = listener.accept().await.unwrap();
            let mut buf = vec![0u8; 64 * 1024];
            let mut got = 0;
            // Read until the end of the headers and the body (Content-Length) have arrived.
            loop {
                let n = sock.read(&mut buf[got..]).await.unwrap();
                got += n;
                let text = String::from_utf8_lossy(&buf[..got]);
                if let Some(h) = text.find("\r\n\r\n") {
                    let len = text[..h]
                        .lines()
                        .find_map(|l| {
                            l.to_ascii_lowercase()
                                .strip_prefix("content-length:")
                                .map(|v| v.trim().parse::<usize>().unwrap())
                        })
                        .unwrap_or(0);
                    if got >= h + 4 + len {
                        break;
                    }
                }
                if n == 0 {
                    break;
                }
            }
            if i == 0 {
                drop(sock); // cut: no status line at all
            } else {
                let resp = format!(
                    "HTTP/1.1 200 OK\r\ncontent-type: application/json\r\ncontent-length: {}\r\nconnection: close\r\n\r\n{}",
                    reply.len(),
                    reply
                );
                sock.write_all(resp.as_bytes()).await.unwrap();
                sock.shutdown().await.unwrap();
            }
            served += 1;
        }
        served
    });
    (format!("http://{addr}/v1"), task)
}

#[tokio::test]
async fn cut_connection_is_retried() {
    let (url, server) = cutting_server(completion("30%", 4, 1).to_string()).await;
    let mut c = ferret_llm::EndpointConfig::new(url, "test-model");
    c.retry_base_ms = 10;
    let client = EndpointClient::new(Endpoint::with_key("flaky", c, None)).unwrap();
    let reply = client.complete(&question()).await.unwrap();
    assert_eq!((reply.text.as_str(), reply.attempts), ("30%", 2));
    assert_eq!(server.await.unwrap(), 2);
}

#[tokio::test]
async fn refused_connection_names_the_endpoint() {
    // Bind then drop a listener: nothing listens on that port any more.
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let mut c = ferret_llm::EndpointConfig::new(format!("http://127.0.0.1:{port}/v1"), "m");
    c.retry_base_ms = 1;
    c.max_attempts = 2;
    let client = EndpointClient::new(Endpoint::with_key("gone", c, None)).unwrap();
    let e = client.complete(&question()).await.unwrap_err();
    assert!(
        matches!(e, LlmError::Connection { attempts: 2, .. }),
        "{e:?}"
    );
    assert!(
        e.to_string().contains("gone") && e.to_string().contains(&port.to_string()),
        "{e}"
    );
}

#[tokio::test]
async fn missing_key_variable_is_named_without_a_request() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(ResponseTemplate::new(200))
        .expect(0)
        .mount(&server)
        .await;
    let mut c = config(&server);
    c.api_key_env = Some("FERRET_SURELY_UNSET_KEY_VAR".into());
    let client = EndpointClient::new(Endpoint::new("hosted", c)).unwrap();
    let e = client.complete(&question()).await.unwrap_err();
    assert!(matches!(e, LlmError::MissingKey { .. }), "{e:?}");
    assert!(
        e.to_string().contains("FERRET_SURELY_UNSET_KEY_VAR") && e.to_string().contains("hosted"),
        "{e}"
    );
}

#[tokio::test]
async fn concurrency_limit_holds() {
    let server = MockServer::start().await;
    Mock::given(method("POST"))
        .respond_with(
            ResponseTemplate::new(200)
                .set_body_json(completion("5%", 1, 1))
                .set_delay(Duration::from_millis(300)),
        )
        .expect(4)
        .mount(&server)
        .await;
    let mut c = config(&server);
    c.concurrency = 2;
    let client = std::sync::Arc::new(
        EndpointClient::new(Endpoint::with_key("two", c, Some(KEY.into()))).unwrap(),
    );
    let started = Instant::now();
    let tasks: Vec<_> = (0..4)
        .map(|i| {
            let client = client.clone();
            tokio::spawn(async move {
                client
                    .complete(&Request::plain(vec![ChatMessage::user(format!("q{i}"))]))
                    .await
            })
        })
        .collect();
    for t in tasks {
        t.await.unwrap().unwrap();
    }
    // Four 300 ms requests, two at a time: at least two rounds.
    assert!(
        started.elapsed() >= Duration::from_millis(590),
        "{:?}",
        started.elapsed()
    );
    let bodies: Vec<String> = server
        .received_requests()
        .await
        .unwrap()
        .iter()
        .map(|r| message_content(&r.body_json::<Value>().unwrap(), 0))
        .collect();
    assert_eq!(bodies.len(), 4);
}
