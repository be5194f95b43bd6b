//! The HTTP client for one OpenAI-compatible chat-completions endpoint: concurrency limit,
//! timeouts, and retries with exponential backoff and jitter.
//!
//! Requests and replies are async-openai's types (`CreateChatCompletionRequest`,
//! `CreateChatCompletionResponse`), but the HTTP exchange is made with reqwest directly:
//! async-openai 0.43's `Client` turns a failed response into `OpenAIError::ApiError` keeping only
//! the status and a parsed error object — the response headers (`Retry-After`, `retry-after-ms`)
//! are dropped, a non-JSON 4xx body becomes a deserialisation error without its status, and a cut
//! connection and a timeout arrive as the same opaque `reqwest::Error` after its own handling.
//! Honouring `Retry-After` and reporting "what the server answered" need all three, so this module
//! sends the request itself (with the same reqwest and TLS stack async-openai uses).

use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use async_openai::types::chat::{CreateChatCompletionRequest, CreateChatCompletionResponse};
use rand::Rng;
use reqwest::StatusCode;
use reqwest::header::{HeaderMap, RETRY_AFTER};
use secrecy::ExposeSecret;
use serde::{Deserialize, Serialize};
use tokio::sync::Semaphore;

use crate::config::{Endpoint, MaxTokensParam};
use crate::error::{LlmError, Result};
use crate::logprobs::TokenLogprob;
use crate::question::Request;

/// Characters of a reply body kept in error messages.
const BODY_SNIPPET_CHARS: usize = 300;

/// Token counts of one request, as the server reported them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct TokenUsage {
    /// Input (prompt) tokens.
    pub prompt_tokens: u64,
    /// Output tokens (reasoning included).
    pub completion_tokens: u64,
    /// Input tokens served from the provider's prompt cache, when it reports them.
    pub cached_tokens: Option<u64>,
}

/// A chat completion's text and what it cost.
#[derive(Clone, Debug, PartialEq)]
pub struct Reply {
    /// The answer text (the first choice's content).
    pub text: String,
    /// Token counts.
    pub usage: TokenUsage,
    /// Time of the successful attempt, request sent to body read.
    pub latency: Duration,
    /// Attempts it took (1 = no retry).
    pub attempts: u32,
    /// The answer's token log-probabilities, when they were asked for and the server sent them.
    pub logprobs: Option<Vec<TokenLogprob>>,
}

/// What one attempt came to.
enum Attempt {
    Done(Reply),
    /// Worth another try: 429, 5xx, 408, timeouts, cut connections.
    Retry {
        failure: Failure,
        retry_after: Option<Duration>,
    },
    Fatal(LlmError),
}

/// The last retryable failure, kept to build the final error.
enum Failure {
    Status { status: StatusCode, body: String },
    Timeout,
    Connection(String),
}

/// A client for one endpoint. Cheap to share behind an `Arc`; the concurrency limit applies to
/// all users of the same client.
#[derive(Debug)]
pub struct EndpointClient {
    endpoint: Endpoint,
    http: reqwest::Client,
    permits: Arc<Semaphore>,
}

impl EndpointClient {
    /// A client for `endpoint`.
    pub fn new(endpoint: Endpoint) -> Result<Self> {
        let http = reqwest::Client::builder()
            .timeout(endpoint.config.timeout())
            .build()
            .map_err(|e| LlmError::Connection {
                endpoint: endpoint.name.clone(),
                url: endpoint.config.normalized_base_url().to_string(),
                message: format!("cannot build an HTTP client: {e}"),
                attempts: 0,
            })?;
        let permits = Arc::new(Semaphore::new(endpoint.config.concurrency));
        Ok(Self {
            endpoint,
            http,
            permits,
        })
    }

    /// The endpoint.
    pub fn endpoint(&self) -> &Endpoint {
        &self.endpoint
    }

    /// The request body for `request` under this endpoint's settings: async-openai's request
    /// type as JSON, with `response_format` set by ferret (async-openai's type has no place for
    /// the `json_object` dialect's `schema`) and `logprobs`/`top_logprobs` when asked for.
    pub fn request_body(&self, request: &Request) -> serde_json::Value {
        let mut body =
            serde_json::to_value(self.openai_request(request)).unwrap_or(serde_json::Value::Null);
        if let Some(map) = body.as_object_mut() {
            if let Some(format) = &request.response_format {
                map.insert("response_format".into(), format.clone());
            }
            if let Some(n) = request.top_logprobs {
                map.insert("logprobs".into(), true.into());
                map.insert("top_logprobs".into(), n.into());
            }
        }
        body
    }

    #[allow(deprecated)] // `seed` and `max_tokens` are deprecated by OpenAI but still what many servers read.
    fn openai_request(&self, request: &Request) -> CreateChatCompletionRequest {
        let messages = &request.messages;
        let c = &self.endpoint.config;
        let (max_completion_tokens, max_tokens) = match c.max_tokens_param {
            MaxTokensParam::MaxCompletionTokens => (c.max_output_tokens, None),
            MaxTokensParam::MaxTokens => (None, c.max_output_tokens),
        };
        CreateChatCompletionRequest {
            messages: messages.iter().map(Into::into).collect(),
            model: c.model.clone(),
            temperature: c.temperature,
            seed: c.seed,
            max_completion_tokens,
            max_tokens,
            reasoning_effort: c.reasoning_effort.clone(),
            ..Default::default()
        }
    }

    /// Asks the endpoint, retrying 429, 5xx, 408, timeouts and cut connections up to
    /// `max_attempts` times with exponential backoff and jitter (or as long as `Retry-After`
    /// says, up to `retry_max_secs`). Waits for a concurrency permit first.
    pub async fn complete(&self, request: &Request) -> Result<Reply> {
        let name = &self.endpoint.name;
        let url = self.endpoint.config.normalized_base_url();
        let key = match (&self.endpoint.config.api_key_env, self.endpoint.key()) {
            (Some(var), None) => {
                return Err(LlmError::MissingKey {
                    endpoint: name.clone(),
                    url: url.to_string(),
                    var: var.clone(),
                });
            }
            (_, key) => key,
        };
        let body = self.request_body(request);
        // Holding the permit across backoff sleeps keeps a rate-limited server from being hit by
        // the other waiting requests in the meantime.
        let _permit = self
            .permits
            .acquire()
            .await
            .map_err(|_| LlmError::Connection {
                endpoint: name.clone(),
                url: url.to_string(),
                message: "client shut down".into(),
                attempts: 0,
            })?;
        let max_attempts = self.endpoint.config.max_attempts.max(1);
        let mut attempt = 1;
        loop {
            let (failure, retry_after) = match self.attempt(&body, key, attempt).await {
                Attempt::Done(reply) => return Ok(reply),
                Attempt::Fatal(e) => return Err(e),
                Attempt::Retry {
                    failure,
                    retry_after,
                } => (failure, retry_after),
            };
            if attempt >= max_attempts {
                return Err(self.final_error(failure, attempt));
            }
            let delay = self.backoff(attempt, retry_after);
            tracing::warn!(
                endpoint = %name,
                attempt,
                max_attempts,
                delay_ms = delay.as_millis() as u64,
                "LLM request failed ({}); retrying",
                failure_summary(&failure)
            );
            tokio::time::sleep(delay).await;
            attempt += 1;
        }
    }

    async fn attempt(
        &self,
        body: &serde_json::Value,
        key: Option<&secrecy::SecretString>,
        attempt: u32,
    ) -> Attempt {
        let started = Instant::now();
        let mut request = self
            .http
            .post(self.endpoint.config.completions_url())
            .json(body);
        if let Some(key) = key {
            // bearer_auth marks the header sensitive, so reqwest/hyper never print it.
            request = request.bearer_auth(key.expose_secret());
        }
        let response = match request.send().await {
            Ok(r) => r,
            Err(e) => {
                return Attempt::Retry {
                    failure: self.transport_failure(&e),
                    retry_after: None,
                };
            }
        };
        let status = response.status();
        let retry_after = retry_after(response.headers());
        let bytes = match response.bytes().await {
            Ok(b) => b,
            // A body cut off mid-way (or too slow) is a transport failure, not a bad reply.
            Err(e) => {
                return Attempt::Retry {
                    failure: self.transport_failure(&e),
                    retry_after: None,
                };
            }
        };
        let latency = started.elapsed();
        if !status.is_success() {
            let body = self.snippet(&bytes);
            let retryable = status == StatusCode::TOO_MANY_REQUESTS
                || status == StatusCode::REQUEST_TIMEOUT
                || status.is_server_error();
            return if retryable {
                Attempt::Retry {
                    failure: Failure::Status { status, body },
                    retry_after,
                }
            } else {
                Attempt::Fatal(self.final_error(Failure::Status { status, body }, attempt))
            };
        }
        match parse_completion(&bytes) {
            Ok((text, usage, logprobs)) => {
                tracing::debug!(
                    endpoint = %self.endpoint.name,
                    latency_ms = latency.as_millis() as u64,
                    prompt_tokens = usage.prompt_tokens,
                    completion_tokens = usage.completion_tokens,
                    attempt,
                    "LLM answered"
                );
                Attempt::Done(Reply {
                    text,
                    usage,
                    latency,
                    attempts: attempt,
                    logprobs,
                })
            }
            Err(message) => Attempt::Fatal(LlmError::InvalidReply {
                endpoint: self.endpoint.name.clone(),
                url: self.endpoint.config.normalized_base_url().to_string(),
                message,
                body: self.snippet(&bytes),
            }),
        }
    }

    fn transport_failure(&self, e: &reqwest::Error) -> Failure {
        if e.is_timeout() {
            Failure::Timeout
        } else {
            Failure::Connection(self.scrub(&error_chain(e)))
        }
    }

    fn final_error(&self, failure: Failure, attempts: u32) -> LlmError {
        let endpoint = self.endpoint.name.clone();
        let url = self.endpoint.config.normalized_base_url().to_string();
        match failure {
            Failure::Status { status, body } => LlmError::Status {
                endpoint,
                url,
                status: status.as_u16(),
                body,
                attempts,
            },
            Failure::Timeout => LlmError::Timeout {
                endpoint,
                url,
                timeout_secs: self.endpoint.config.timeout_secs,
                attempts,
            },
            Failure::Connection(message) => LlmError::Connection {
                endpoint,
                url,
                message,
                attempts,
            },
        }
    }

    /// Delay before attempt `attempt + 1`: `Retry-After` if the server sent one, else
    /// `retry_base_ms · 2^(attempt−1)` with "equal jitter" (half fixed, half random) so that
    /// many clients rate-limited together do not return together; both capped at
    /// `retry_max_secs`.
    fn backoff(&self, attempt: u32, retry_after: Option<Duration>) -> Duration {
        let c = &self.endpoint.config;
        let cap = Duration::from_secs_f64(c.retry_max_secs);
        if let Some(wait) = retry_after {
            return wait.min(cap);
        }
        let exp = c
            .retry_base_ms
            .saturating_mul(1u64 << (attempt - 1).min(30));
        let ms = exp.min(cap.as_millis() as u64);
        let half = ms / 2;
        let jitter = if ms > half {
            rand::rng().random_range(0..=ms - half)
        } else {
            0
        };
        Duration::from_millis(half + jitter)
    }

    /// The start of a body, with the API key (should a server echo it) blanked out.
    fn snippet(&self, bytes: &[u8]) -> String {
        let text = String::from_utf8_lossy(bytes);
        let mut s: String = text.chars().take(BODY_SNIPPET_CHARS).collect();
        if text.chars().count() > BODY_SNIPPET_CHARS {
            s.push('…');
        }
        if s.is_empty() {
            s.push_str("(empty body)");
        }
        self.scrub(&s)
    }

    fn scrub(&self, text: &str) -> String {
        match self.endpoint.key() {
            Some(key) if !key.expose_secret().is_empty() => {
                text.replace(key.expose_secret(), "[redacted]")
            }
            _ => text.to_string(),
        }
    }
}

fn failure_summary(f: &Failure) -> String {
    match f {
        Failure::Status { status, .. } => format!("HTTP {}", status.as_u16()),
        Failure::Timeout => "timeout".into(),
        Failure::Connection(m) => m.clone(),
    }
}

/// reqwest's top-level message is often just "error sending request"; the cause chain says why.
fn error_chain(e: &reqwest::Error) -> String {
    let mut s = e.to_string();
    let mut source = std::error::Error::source(e);
    while let Some(inner) = source {
        s.push_str(": ");
        s.push_str(&inner.to_string());
        source = inner.source();
    }
    s
}

/// `Retry-After` (seconds or an HTTP date) or OpenAI's `retry-after-ms`.
fn retry_after(headers: &HeaderMap) -> Option<Duration> {
    if let Some(ms) = headers
        .get("retry-after-ms")
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.trim().parse::<f64>().ok())
        .filter(|ms| ms.is_finite() && *ms >= 0.0)
    {
        return Some(Duration::from_secs_f64(ms / 1000.0));
    }
    let value = headers.get(RETRY_AFTER)?.to_str().ok()?.trim();
    if let Ok(secs) = value.parse::<f64>() {
        return (secs.is_finite() && secs >= 0.0).then(|| Duration::from_secs_f64(secs));
    }
    let when = httpdate::parse_http_date(value).ok()?;
    Some(
        when.duration_since(SystemTime::now())
            .unwrap_or(Duration::ZERO),
    )
}

/// The parts of a chat completion ferret needs, read leniently: the fallback when a server's
/// reply does not fit async-openai's stricter types (a missing `id`, an unknown `finish_reason`).
#[derive(Deserialize)]
struct LenientCompletion {
    choices: Vec<LenientChoice>,
    #[serde(default)]
    usage: Option<LenientUsage>,
}

#[derive(Deserialize)]
struct LenientChoice {
    message: LenientMessage,
    #[serde(default)]
    finish_reason: Option<String>,
}

#[derive(Deserialize)]
struct LenientMessage {
    #[serde(default)]
    content: Option<String>,
}

#[derive(Deserialize)]
struct LenientUsage {
    #[serde(default)]
    prompt_tokens: u64,
    #[serde(default)]
    completion_tokens: u64,
    #[serde(default)]
    prompt_tokens_details: Option<LenientDetails>,
}

#[derive(Deserialize)]
struct LenientDetails {
    #[serde(default)]
    cached_tokens: Option<u64>,
}

/// What a completion gives: the first choice's text, the token usage and the token
/// log-probabilities if any.
pub(crate) type Completion = (String, TokenUsage, Option<Vec<TokenLogprob>>);

/// The first choice's text, the token usage and any log-probabilities, or why the body is not a
/// usable completion.
pub(crate) fn parse_completion(bytes: &[u8]) -> std::result::Result<Completion, String> {
    let value: serde_json::Value = serde_json::from_slice(bytes).map_err(|e| {
        if e.is_eof() {
            format!(
                "truncated JSON (the body ends after {} bytes, inside a value)",
                bytes.len()
            )
        } else {
            format!("not JSON ({e})")
        }
    })?;
    // Read apart from async-openai's types: servers differ in what they put beside each token
    // (llama-cpp-python sends `bytes: null`, some send null `top_logprobs`).
    let logprobs = value
        .pointer("/choices/0/logprobs/content")
        .filter(|v| v.is_array())
        .and_then(|v| serde_json::from_value::<Vec<TokenLogprob>>(v.clone()).ok())
        .filter(|v| !v.is_empty());
    let (content, finish_reason, usage) =
        match serde_json::from_value::<CreateChatCompletionResponse>(value.clone()) {
            Ok(r) => {
                let choice = r
                    .choices
                    .into_iter()
                    .next()
                    .ok_or("no choices in the reply")?;
                let finish = choice
                    .finish_reason
                    .map(|f| format!("{f:?}").to_lowercase());
                let usage = r.usage.map(|u| TokenUsage {
                    prompt_tokens: u64::from(u.prompt_tokens),
                    completion_tokens: u64::from(u.completion_tokens),
                    cached_tokens: u
                        .prompt_tokens_details
                        .and_then(|d| d.cached_tokens)
                        .map(u64::from),
                });
                (choice.message.content, finish, usage)
            }
            Err(strict) => {
                let r: LenientCompletion = serde_json::from_value(value)
                    .map_err(|e| format!("not a chat completion ({strict}; {e})"))?;
                tracing::debug!("reply parsed leniently: {strict}");
                let choice = r
                    .choices
                    .into_iter()
                    .next()
                    .ok_or("no choices in the reply")?;
                let usage = r.usage.map(|u| TokenUsage {
                    prompt_tokens: u.prompt_tokens,
                    completion_tokens: u.completion_tokens,
                    cached_tokens: u.prompt_tokens_details.and_then(|d| d.cached_tokens),
                });
                (choice.message.content, choice.finish_reason, usage)
            }
        };
    let text = content.unwrap_or_default();
    if text.trim().is_empty() && finish_reason.as_deref() == Some("length") {
        return Err("empty answer: the output-token limit was reached (for reasoning models, raise max_output_tokens or lower reasoning_effort)".into());
    }
    Ok((text, usage.unwrap_or_default(), logprobs))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn retry_after_reads_seconds_dates_and_ms() {
        let mut h = HeaderMap::new();
        h.insert(RETRY_AFTER, "2".parse().unwrap());
        assert_eq!(retry_after(&h), Some(Duration::from_secs(2)));
        h.insert("retry-after-ms", "150".parse().unwrap());
        assert_eq!(retry_after(&h), Some(Duration::from_millis(150)));
        let mut h = HeaderMap::new();
        let later = httpdate::fmt_http_date(SystemTime::now() + Duration::from_secs(30));
        h.insert(RETRY_AFTER, later.parse().unwrap());
        let d = retry_after(&h).unwrap();
        assert!(
            d > Duration::from_secs(27) && d <= Duration::from_secs(30),
            "{d:?}"
        );
        h.insert(RETRY_AFTER, "soon".parse().unwrap());
        assert_eq!(retry_after(&h), None);
    }

    #[test]
    fn backoff_doubles_with_jitter_and_caps() {
        let mut c = crate::EndpointConfig::new("http://x", "m");
        c.retry_base_ms = 100;
        c.retry_max_secs = 1.0;
        let client = EndpointClient::new(Endpoint::with_key("x", c, None)).unwrap();
        for _ in 0..50 {
            let d1 = client.backoff(1, None).as_millis();
            let d3 = client.backoff(3, None).as_millis();
            let d9 = client.backoff(9, None).as_millis();
            assert!((50..=100).contains(&d1), "{d1}");
            assert!((200..=400).contains(&d3), "{d3}");
            assert!((500..=1000).contains(&d9), "{d9}");
        }
        assert_eq!(
            client.backoff(1, Some(Duration::from_secs(30))),
            Duration::from_secs(1)
        );
    }

    #[test]
    fn parses_strict_and_lenient_replies() {
        let strict = br#"{"id":"x","object":"chat.completion","created":1,"model":"m",
            "choices":[{"index":0,"message":{"role":"assistant","content":"70%"},"finish_reason":"stop"}],
            "usage":{"prompt_tokens":10,"completion_tokens":2,"total_tokens":12,"prompt_tokens_details":{"cached_tokens":4}}}"#;
        let (text, usage, logprobs) = parse_completion(strict).unwrap();
        assert_eq!(text, "70%");
        assert_eq!(logprobs, None);
        assert_eq!(
            usage,
            TokenUsage {
                prompt_tokens: 10,
                completion_tokens: 2,
                cached_tokens: Some(4)
            }
        );
        // No id, an unknown finish reason: async-openai refuses it, the lenient reader does not.
        let odd = br#"{"choices":[{"message":{"content":"0.4"},"finish_reason":"eos"}],"usage":{"prompt_tokens":3,"completion_tokens":1}}"#;
        let (text, usage, _) = parse_completion(odd).unwrap();
        assert_eq!(text, "0.4");
        assert_eq!(usage.prompt_tokens, 3);
        assert!(
            parse_completion(br#"{"choices":[{"message":{"con"#)
                .unwrap_err()
                .contains("truncated")
        );
        assert!(
            parse_completion(br#"{"error":"x"}"#)
                .unwrap_err()
                .contains("not a chat completion")
        );
        assert!(
            parse_completion(br#"{"choices":[]}"#)
                .unwrap_err()
                .contains("no choices")
        );
        // llama-cpp-python's shape: bytes null, a logprobs object beside the message.
        let lp = br#"{"choices":[{"message":{"content":"7"},"finish_reason":"stop",
            "logprobs":{"content":[{"token":"7","logprob":-0.5,"bytes":null,
            "top_logprobs":[{"token":"7","logprob":-0.5,"bytes":null},{"token":"3","logprob":-1.2,"bytes":null}]}],"refusal":null}}]}"#;
        let (_, _, logprobs) = parse_completion(lp).unwrap();
        let logprobs = logprobs.unwrap();
        assert_eq!(logprobs[0].token, "7");
        assert_eq!(logprobs[0].top_logprobs[1].logprob, -1.2);
        let cut = br#"{"choices":[{"message":{"content":""},"finish_reason":"length"}]}"#;
        assert!(
            parse_completion(cut)
                .unwrap_err()
                .contains("max_output_tokens")
        );
    }
}
