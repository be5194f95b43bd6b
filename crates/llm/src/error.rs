//! Errors of the llm crate. None of them ever holds an API key: endpoints are named by their
//! config name and URL, and reply bodies are scrubbed of the key before they are kept.

use std::path::PathBuf;

/// A config file could not be used.
#[derive(Debug, thiserror::Error)]
pub enum ConfigError {
    /// The file could not be read.
    #[error("{}: {source}", file.display())]
    Read {
        /// The file.
        file: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file is not valid TOML or has a field of the wrong type, a missing or unknown field.
    #[error("{}: {message}", file.display())]
    Parse {
        /// The file.
        file: PathBuf,
        /// The TOML parser's message (with line, column and key).
        message: String,
    },
    /// A value is out of range.
    #[error("{}: `{key}` {message}", file.display())]
    Invalid {
        /// The file.
        file: PathBuf,
        /// The key's dotted path, e.g. `llm.gpt-5-mini.concurrency`.
        key: String,
        /// What is wrong with it.
        message: String,
    },
    /// No endpoint has this name.
    #[error("no LLM endpoint `{name}` in {} (known: {})", file.display(), if known.is_empty() { "none; add an [llm.<name>] table".to_string() } else { known.join(", ") })]
    UnknownEndpoint {
        /// The name asked for.
        name: String,
        /// The config file.
        file: PathBuf,
        /// The names it defines.
        known: Vec<String>,
    },
}

/// A failure of the response cache.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// SQLite failed.
    #[error("response cache {}: {source}", file.display())]
    Sqlite {
        /// The cache file.
        file: PathBuf,
        /// The cause.
        source: rusqlite::Error,
    },
    /// A stored row could not be decoded.
    #[error("response cache {}: corrupt entry {key}: {message}", file.display())]
    Corrupt {
        /// The cache file.
        file: PathBuf,
        /// The entry's key.
        key: String,
        /// What is wrong.
        message: String,
    },
    /// The cache file was written by a newer ferret.
    #[error("response cache {}: schema version {found}, this ferret reads {expected}", file.display())]
    Version {
        /// The cache file.
        file: PathBuf,
        /// Version found.
        found: i64,
        /// Version understood.
        expected: i64,
    },
}

/// A failure asking an LLM.
#[derive(Debug, thiserror::Error)]
pub enum LlmError {
    /// The endpoint needs a key and its environment variable is not set.
    #[error("LLM `{endpoint}` ({url}): the API key variable `{var}` is not set in the environment")]
    MissingKey {
        /// Endpoint name.
        endpoint: String,
        /// Its base URL.
        url: String,
        /// The variable's name.
        var: String,
    },
    /// The server kept answering with an error status.
    #[error("LLM `{endpoint}` ({url}) answered HTTP {status} after {attempts} attempt(s): {body}")]
    Status {
        /// Endpoint name.
        endpoint: String,
        /// Its base URL.
        url: String,
        /// The last HTTP status.
        status: u16,
        /// The start of the last reply body.
        body: String,
        /// Attempts made.
        attempts: u32,
    },
    /// Every attempt timed out.
    #[error(
        "LLM `{endpoint}` ({url}) did not answer within {timeout_secs} s, {attempts} attempt(s)"
    )]
    Timeout {
        /// Endpoint name.
        endpoint: String,
        /// Its base URL.
        url: String,
        /// The per-attempt limit.
        timeout_secs: f64,
        /// Attempts made.
        attempts: u32,
    },
    /// The connection failed or was cut on every attempt.
    #[error("LLM `{endpoint}` ({url}): connection failed after {attempts} attempt(s): {message}")]
    Connection {
        /// Endpoint name.
        endpoint: String,
        /// Its base URL.
        url: String,
        /// The last failure.
        message: String,
        /// Attempts made.
        attempts: u32,
    },
    /// The server answered 200 with something that is not a chat completion (truncated or
    /// malformed JSON, no choices, no text).
    #[error("LLM `{endpoint}` ({url}) sent an unusable reply: {message}; reply began: {body}")]
    InvalidReply {
        /// Endpoint name.
        endpoint: String,
        /// Its base URL.
        url: String,
        /// What is wrong.
        message: String,
        /// The start of the body.
        body: String,
    },
    /// The endpoint failed earlier in this run after all its retries; nothing more is sent to it.
    #[error(
        "LLM `{endpoint}` is not asked again in this run: it failed after all its retries ({reason})"
    )]
    EndpointDown {
        /// Endpoint name.
        endpoint: String,
        /// The failure that stopped it.
        reason: String,
    },
    /// The endpoint failed a moment ago; questions fail at once until its pause is over (the
    /// circuit breaker of long-running servers).
    #[error(
        "LLM `{endpoint}` failed a moment ago and is asked again in {retry_in_secs} s ({reason})"
    )]
    EndpointPaused {
        /// Endpoint name.
        endpoint: String,
        /// The failure that opened the circuit.
        reason: String,
        /// Seconds until a question is let through again.
        retry_in_secs: f64,
    },
    /// Offline mode and the prompt is not in the cache.
    #[error(
        "offline: no cached answer from LLM `{endpoint}` (model {model}) for {about}; the prompt begins: {prompt_start}"
    )]
    NotCached {
        /// Endpoint name.
        endpoint: String,
        /// Model.
        model: String,
        /// Which question it is (house, target, container, room).
        about: String,
        /// The first characters of the prompt.
        prompt_start: String,
    },
    /// The response cache failed.
    #[error(transparent)]
    Cache(#[from] CacheError),
    /// A prompt template failed to render or does not exist.
    #[error("prompt {name}: {message}")]
    Prompt {
        /// The template's name or path.
        name: String,
        /// What went wrong.
        message: String,
    },
    /// A config problem.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The house cannot be described (e.g. a container index out of range).
    #[error("{0}")]
    Context(String),
    /// Contradictory options.
    #[error("{0}")]
    Options(String),
    /// The async runtime could not be started.
    #[error("starting the LLM runtime: {0}")]
    Runtime(std::io::Error),
}

/// Result with [`LlmError`].
pub type Result<T, E = LlmError> = std::result::Result<T, E>;
