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
/// Largest reply body read; a larger one is an error (a chat completion for ferret's prompts is a
/// few kilobytes, 20 alternatives per token included).
pub const MAX_REPLY_BYTES: usize = 8 << 20;
/// Longest answer text kept (and cached); a longer one is cut here.
pub const MAX_ANSWER_BYTES: usize = 64 << 10;
/// Attempts in a row that may run out of time before a request gives up, whatever
/// `max_attempts` says: a server that accepts connections and answers nothing within the timeout
/// twice is not answering (a cut connection or a 5xx, which come fast, are retried as configured).
pub const MAX_TIMEOUTS_IN_A_ROW: u32 = 2;
/// Shortest run of a secret's characters that is redacted wherever it shows up.
const MIN_SECRET_RUN: usize = 8;

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
    Status {
        status: StatusCode,
        body: String,
    },
    Timeout,
    Connection(String),
    /// A success status with a body that is no chat completion (an HTML page from a proxy).
    Invalid {
        message: String,
        body: String,
    },
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
            .connect_timeout(endpoint.config.connect_timeout())
            .build()
            .map_err(|e| LlmError::Connection {
                endpoint: endpoint.name.clone(),
                url: endpoint.config.normalized_base_url(),
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
        let limit = request.max_output_tokens(c);
        let (max_completion_tokens, max_tokens) = match c.max_tokens_param {
            MaxTokensParam::MaxCompletionTokens => (limit, None),
            MaxTokensParam::MaxTokens => (None, limit),
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

    /// The endpoint's key, or the error naming the variable it was to be read from.
    fn api_key(&self) -> Result<Option<&secrecy::SecretString>> {
        match (&self.endpoint.config.api_key_env, self.endpoint.key()) {
            (Some(var), None) => Err(LlmError::MissingKey {
                endpoint: self.endpoint.name.clone(),
                url: self.endpoint.config.normalized_base_url().to_string(),
                var: var.clone(),
            }),
            (_, key) => Ok(key),
        }
    }

    /// Asks the endpoint, retrying 429, 5xx, 408, timeouts and cut connections up to
    /// `max_attempts` times with exponential backoff and jitter (or as long as `Retry-After`
    /// says, up to `retry_max_secs`). Waits for a concurrency permit first.
    pub async fn complete(&self, request: &Request) -> Result<Reply> {
        self.complete_admitted(request, || Ok(())).await
    }

    /// [`complete`](Self::complete), asking `admit` whether the request may still go once it
    /// has its concurrency permit and before every retry: requests queued behind others for a
    /// permit are not sent (each for its own timeouts) after the endpoint was found down
    /// meanwhile. An error from `admit` is returned as it is.
    pub async fn complete_admitted(
        &self,
        request: &Request,
        admit: impl Fn() -> Result<()>,
    ) -> Result<Reply> {
        let name = &self.endpoint.name;
        let url = self.endpoint.config.normalized_base_url();
        let key = self.api_key()?;
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
        let mut timeouts = 0;
        loop {
            admit()?;
            let (failure, retry_after) = match self.attempt(&body, key, attempt).await {
                Attempt::Done(reply) => return Ok(reply),
                Attempt::Fatal(e) => return Err(e),
                Attempt::Retry {
                    failure,
                    retry_after,
                } => (failure, retry_after),
            };
            timeouts = if matches!(failure, Failure::Timeout) {
                timeouts + 1
            } else {
                0
            };
            if attempt >= max_attempts || timeouts >= MAX_TIMEOUTS_IN_A_ROW {
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

    /// Sends `request` once, without retries, giving up after `timeout` (or the endpoint's own
    /// timeout, if shorter): a check that the endpoint answers (`ferret llm ping`).
    pub async fn complete_once(&self, request: &Request, timeout: Duration) -> Result<Reply> {
        let name = &self.endpoint.name;
        let url = self.endpoint.config.normalized_base_url();
        let key = self.api_key()?;
        let body = self.request_body(request);
        let timeout = timeout.min(self.endpoint.config.timeout());
        match tokio::time::timeout(timeout, self.attempt(&body, key, 1)).await {
            Ok(Attempt::Done(reply)) => Ok(reply),
            Ok(Attempt::Fatal(e)) => Err(e),
            Ok(Attempt::Retry { failure, .. }) => Err(self.final_error(failure, 1)),
            Err(_) => Err(LlmError::Timeout {
                endpoint: name.clone(),
                url,
                timeout_secs: timeout.as_secs_f64(),
                attempts: 1,
            }),
        }
    }

    async fn attempt(
        &self,
        body: &serde_json::Value,
        key: Option<&secrecy::SecretString>,
        attempt: u32,
    ) -> Attempt {
        let started = Instant::now();
        let url = match self.endpoint.config.completions_url() {
            Ok(u) => u,
            Err(message) => {
                return Attempt::Fatal(LlmError::Connection {
                    endpoint: self.endpoint.name.clone(),
                    url: self.endpoint.config.normalized_base_url(),
                    message,
                    attempts: attempt,
                });
            }
        };
        let mut request = self.http.post(url).json(body);
        if let Some(key) = key {
            // bearer_auth marks the header sensitive, so reqwest/hyper never print it.
            request = request.bearer_auth(key.expose_secret());
        }
        let mut response = match request.send().await {
            Ok(r) => r,
            Err(e) => {
                return Attempt::Retry {
                    failure: self.transport_failure(e),
                    retry_after: None,
                };
            }
        };
        let status = response.status();
        let retry_after = retry_after(response.headers());
        // Read chunk by chunk so that a huge (or endless) body stops at MAX_REPLY_BYTES instead
        // of filling memory.
        let mut bytes: Vec<u8> = Vec::new();
        loop {
            match response.chunk().await {
                Ok(Some(chunk)) => {
                    if bytes.len() + chunk.len() > MAX_REPLY_BYTES {
                        return Attempt::Fatal(LlmError::InvalidReply {
                            endpoint: self.endpoint.name.clone(),
                            url: self.endpoint.config.normalized_base_url(),
                            message: format!(
                                "the reply body is larger than {} MiB",
                                MAX_REPLY_BYTES >> 20
                            ),
                            body: self.snippet(&bytes),
                        });
                    }
                    bytes.extend_from_slice(&chunk);
                }
                Ok(None) => break,
                // A body cut off mid-way (or too slow) is a transport failure, not a bad reply.
                Err(e) => {
                    return Attempt::Retry {
                        failure: self.transport_failure(e),
                        retry_after: None,
                    };
                }
            }
        }
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
            Ok((mut text, usage, logprobs)) => {
                if text.len() > MAX_ANSWER_BYTES {
                    let mut cut = MAX_ANSWER_BYTES;
                    while !text.is_char_boundary(cut) {
                        cut -= 1;
                    }
                    tracing::warn!(endpoint = %self.endpoint.name, bytes = text.len(), "answer longer than {MAX_ANSWER_BYTES} bytes; keeping its start");
                    text.truncate(cut);
                }
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
            // A proxy's HTML page or a half-written reply under a 200: worth another try, like
            // a 5xx.
            Err(message) => Attempt::Retry {
                failure: Failure::Invalid {
                    message,
                    body: self.snippet(&bytes),
                },
                retry_after: None,
            },
        }
    }

    fn transport_failure(&self, e: reqwest::Error) -> Failure {
        if e.is_timeout() {
            Failure::Timeout
        } else {
            // The URL may carry a gateway's key in its query.
            Failure::Connection(self.scrub(&error_chain(&e.without_url())))
        }
    }

    fn final_error(&self, failure: Failure, attempts: u32) -> LlmError {
        let endpoint = self.endpoint.name.clone();
        let url = self.endpoint.config.normalized_base_url();
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
            Failure::Invalid { message, body } => LlmError::InvalidReply {
                endpoint,
                url,
                message: format!("{message} (after {attempts} attempts)"),
                body,
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

    /// The start of a body, with the API key (should a server echo it) blanked out and control
    /// characters escaped (a reply may hold terminal escape sequences).
    fn snippet(&self, bytes: &[u8]) -> String {
        let text = String::from_utf8_lossy(bytes);
        let mut s =
            crate::message::printable(&text.chars().take(BODY_SNIPPET_CHARS).collect::<String>());
        if text.chars().count() > BODY_SNIPPET_CHARS {
            s.push('…');
        }
        if s.is_empty() {
            s.push_str("(empty body)");
        }
        self.scrub(&s)
    }

    /// `text` with anything that looks like a secret blanked out: every run of 8 or more
    /// characters that also occurs in the API key or in a query value of the base URL, compared
    /// without case (servers echo keys masked, truncated or lower-cased).
    fn scrub(&self, text: &str) -> String {
        let mut secrets: Vec<String> = Vec::new();
        if let Some(key) = self.endpoint.key() {
            secrets.push(key.expose_secret().to_string());
        }
        if let Some((_, query)) = self.endpoint.config.base_url.split_once('?') {
            secrets.extend(
                query
                    .split('&')
                    .filter_map(|kv| kv.split_once('=').map(|(_, v)| v.to_string())),
            );
        }
        redact(text, &secrets)
    }
}

fn failure_summary(f: &Failure) -> String {
    match f {
        Failure::Status { status, .. } => format!("HTTP {}", status.as_u16()),
        Failure::Timeout => "timeout".into(),
        Failure::Connection(m) => m.clone(),
        Failure::Invalid { message, .. } => format!("HTTP 200 but {message}"),
    }
}

/// `text` with every run of at least [`MIN_SECRET_RUN`] characters that also occurs in one of
/// `secrets` (ignoring case) replaced by `[redacted]`. Hand-written: redaction crates match
/// whole known strings, not fragments of them.
pub(crate) fn redact(text: &str, secrets: &[String]) -> String {
    let chars: Vec<char> = text.chars().collect();
    let lower: Vec<char> = chars.iter().flat_map(|c| c.to_lowercase()).collect();
    // Lower-casing changes the length of a few non-ASCII characters; fall back to exact
    // matching of whole secrets then.
    if lower.len() != chars.len() {
        return secrets
            .iter()
            .filter(|s| !s.is_empty())
            .fold(text.to_string(), |t, s| t.replace(s.as_str(), "[redacted]"));
    }
    let mut hidden = vec![false; chars.len()];
    for secret in secrets {
        let secret: Vec<char> = secret.to_lowercase().chars().collect();
        if secret.len() < MIN_SECRET_RUN {
            continue;
        }
        let windows: std::collections::HashSet<&[char]> = secret.windows(MIN_SECRET_RUN).collect();
        for i in 0..lower.len().saturating_sub(MIN_SECRET_RUN - 1) {
            if windows.contains(&lower[i..i + MIN_SECRET_RUN]) {
                hidden[i..i + MIN_SECRET_RUN]
                    .iter_mut()
                    .for_each(|h| *h = true);
            }
        }
    }
    let mut out = String::with_capacity(text.len());
    let mut in_secret = false;
    for (c, h) in chars.iter().zip(&hidden) {
        if *h {
            if !in_secret {
                out.push_str("[redacted]");
            }
        } else {
            out.push(*c);
        }
        in_secret = *h;
    }
    out
}

/// reqwest's top-level message is often just "error sending request"; the cause chain says why.
fn error_chain(e: &reqwest::Error) -> String {
    ferret_world::error_chain(e)
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
    fn secrets_are_redacted_in_pieces_and_any_case() {
        let key = vec!["sk-Live-ABCDEFGH12345678".to_string()];
        assert_eq!(
            redact("bad key sk-live-abcdefgh12345678 given", &key),
            "bad key [redacted] given"
        );
        // A masked echo keeps 8+ characters of the key: those go too.
        assert_eq!(
            redact("Incorrect API key provided: sk-Live-ABCD****5678", &key),
            "Incorrect API key provided: [redacted]****5678"
        );
        assert_eq!(redact("short sk-L is fine", &key), "short sk-L is fine");
        assert_eq!(redact("nothing here", &[]), "nothing here");
    }

    proptest::proptest! {
        #[test]
        fn no_eight_characters_of_a_secret_survive(
            secret in "[A-Za-z0-9_-]{8,40}",
            pre in "[ -~]{0,20}",
            post in "[ -~]{0,20}",
            upper in proptest::bool::ANY,
        ) {
            let shown = if upper { secret.to_uppercase() } else { secret.clone() };
            let out = redact(&format!("{pre}{shown}{post}"), std::slice::from_ref(&secret));
            let lower = out.to_lowercase();
            let s = secret.to_lowercase();
            for w in s.as_bytes().windows(8) {
                proptest::prop_assert!(!lower.contains(std::str::from_utf8(w).unwrap()), "{}", out);
            }
        }
    }

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
