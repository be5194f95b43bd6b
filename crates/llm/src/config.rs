//! Endpoint configuration: the `[llm.<name>]` tables of `ferret.toml`.
//!
//! ```toml
//! [llm.gpt-5-mini]
//! base_url = "https://api.openai.com/v1"
//! model = "gpt-5-mini"
//! api_key_env = "OPENAI_API_KEY"   # the NAME of the variable; the key never goes in the file
//! reasoning_effort = "minimal"
//! max_output_tokens = 2000
//! concurrency = 8
//! price_input_per_mtok = 0.25
//! price_output_per_mtok = 2.0
//! ```
//!
//! User prompt templates may be named in a `[prompts]` table (`p-mine = "prompts/mine.j2"`,
//! relative to the file). Other top-level tables belong to other parts of ferret and are ignored
//! here.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};
use std::time::Duration;

use async_openai::types::chat::ReasoningEffort;
use secrecy::SecretString;
use serde::{Deserialize, Serialize};

use crate::error::ConfigError;

/// The default config file name, looked up in the working directory.
pub const DEFAULT_CONFIG_FILE: &str = "ferret.toml";

/// Which request field carries the output-token limit. OpenAI's reasoning models accept only
/// `max_completion_tokens`; some OpenAI-compatible servers (older Ollama, Gemini's compatibility
/// layer) document only the older `max_tokens`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum MaxTokensParam {
    /// Send `max_completion_tokens` (OpenAI's current name).
    #[default]
    MaxCompletionTokens,
    /// Send the deprecated `max_tokens`.
    MaxTokens,
}

/// How the endpoint is asked to shape its answers.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum AnswerFormat {
    /// Free text, read by [`crate::answer`]; the prompt says in words what to answer.
    #[default]
    Text,
    /// `response_format: {"type": "json_schema", ...}` (OpenAI, Gemini's OpenAI-compatible API,
    /// vLLM, Ollama, llama.cpp's `llama-server`): probability prompts answer
    /// `{"percent": "1%" … "100%"}`, P-DIRECT `{"location": <one of the listed labels>}`.
    JsonSchema,
    /// The same schemas in the older dialect `{"type": "json_object", "schema": ...}`, which is
    /// what llama-cpp-python's server reads (it refuses `json_schema`).
    JsonObject,
}

/// Where a probability comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ProbabilityFrom {
    /// The percentage the answer text states.
    #[default]
    Text,
    /// The probability-weighted mean of the percentages the model would have written, from the
    /// token log-probabilities of the answer's number (see [`crate::logprobs`]); the text when
    /// the server returns none (counted).
    Logprobs,
}

/// How the role text (system messages) reaches the model.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SystemRole {
    /// As system messages.
    #[default]
    System,
    /// At the top of the first user message, for chat templates without a system turn (Gemma's
    /// drops system messages silently).
    Merge,
}

/// Most alternatives per token OpenAI's API returns.
pub const MAX_TOP_LOGPROBS: u8 = 20;
/// Most re-asks allowed per question.
pub const MAX_REASKS: u32 = 5;
/// Longest time one attempt may be given, seconds (a day).
pub const MAX_TIMEOUT_SECS: f64 = 86_400.0;
/// Longest wait between attempts, seconds (an hour).
pub const MAX_RETRY_MAX_SECS: f64 = 3_600.0;
/// Largest config file read, bytes (a config is a few kilobytes).
pub const MAX_CONFIG_BYTES: u64 = 1 << 20;
/// Most attempts per request.
pub const MAX_ATTEMPTS: u32 = 20;
/// Longest first retry delay, milliseconds (ten minutes).
pub const MAX_RETRY_BASE_MS: u64 = 600_000;
/// Fields that would hold a secret; refused in the file, and named without their value.
const SECRET_FIELDS: [&str; 6] = ["api_key", "apikey", "key", "token", "secret", "password"];

/// One OpenAI-compatible chat-completions endpoint, as written in the config file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct EndpointConfig {
    /// The API base, up to and including `/v1` (the client appends `/chat/completions`).
    pub base_url: String,
    /// The model name the server expects.
    pub model: String,
    /// Name of the environment variable holding the API key; `None` for servers without keys
    /// (a local vLLM or Ollama).
    #[serde(default)]
    pub api_key_env: Option<String>,
    /// Sampling temperature; `None` sends none (OpenAI's reasoning models accept only the
    /// default).
    #[serde(default)]
    pub temperature: Option<f32>,
    /// Sampling seed, for servers that honour one.
    #[serde(default)]
    pub seed: Option<i64>,
    /// Limit on output tokens (reasoning tokens included, for reasoning models).
    #[serde(default)]
    pub max_output_tokens: Option<u32>,
    /// Which request field carries `max_output_tokens`.
    #[serde(default)]
    pub max_tokens_param: MaxTokensParam,
    /// Reasoning effort (`none`, `minimal`, `low`, `medium`, `high`) for models that take one.
    #[serde(default)]
    pub reasoning_effort: Option<ReasoningEffort>,
    /// Requests in flight at once to this endpoint.
    #[serde(default = "default_concurrency")]
    pub concurrency: usize,
    /// Seconds one attempt may take, reply body included.
    #[serde(default = "default_timeout_secs")]
    pub timeout_secs: f64,
    /// Seconds to wait for the connection to the server (a host that drops packets).
    #[serde(default = "default_connect_timeout_secs")]
    pub connect_timeout_secs: f64,
    /// Attempts per request before giving up (1 = no retries).
    #[serde(default = "default_max_attempts")]
    pub max_attempts: u32,
    /// First retry delay in milliseconds; doubled on every further retry, with jitter.
    #[serde(default = "default_retry_base_ms")]
    pub retry_base_ms: u64,
    /// Longest wait between attempts, seconds, whatever `Retry-After` asks for.
    #[serde(default = "default_retry_max_secs")]
    pub retry_max_secs: f64,
    /// USD per million input tokens.
    #[serde(default)]
    pub price_input_per_mtok: f64,
    /// USD per million cached input tokens; the input price when absent.
    #[serde(default)]
    pub price_cached_input_per_mtok: Option<f64>,
    /// USD per million output tokens.
    #[serde(default)]
    pub price_output_per_mtok: f64,
    /// Stands for the server in the response-cache key instead of `base_url`: set the same value
    /// on two endpoints that serve the same weights at different addresses to share answers.
    #[serde(default)]
    pub cache_id: Option<String>,
    /// How answers are requested: free text, or structured output with a JSON schema.
    #[serde(default)]
    pub answer_format: AnswerFormat,
    /// Where probabilities come from: the answer text or the token log-probabilities.
    #[serde(default)]
    pub probability_from: ProbabilityFrom,
    /// Alternatives per token to request with `logprobs` (1..=20). Requested whenever set, and
    /// 20 when `probability_from = "logprobs"` leaves it unset; endpoints that set the same value
    /// share cached answers whatever they read from them.
    #[serde(default)]
    pub top_logprobs: Option<u8>,
    /// Times an unusable answer is asked again with a short format reminder (0..=5).
    #[serde(default = "default_max_reasks")]
    pub max_reasks: u32,
    /// P-YESNO and P-CHOICE read their probability from the answer token's log-probabilities.
    /// When a reply has none, the word the model wrote is used instead: Yes gives this
    /// probability and No one minus it; the chosen letter gets this share and the other places
    /// the rest (0.5..=0.99; counted as answers without log-probabilities).
    #[serde(default = "default_word_answer_mass")]
    pub word_answer_mass: f64,
    /// How the role text is sent.
    #[serde(default)]
    pub system_role: SystemRole,
}

fn default_max_reasks() -> u32 {
    1
}

fn default_word_answer_mass() -> f64 {
    0.8
}

fn default_concurrency() -> usize {
    4
}
fn default_timeout_secs() -> f64 {
    120.0
}
fn default_connect_timeout_secs() -> f64 {
    10.0
}
fn default_max_attempts() -> u32 {
    5
}
fn default_retry_base_ms() -> u64 {
    1000
}
fn default_retry_max_secs() -> f64 {
    60.0
}

impl EndpointConfig {
    /// A config with defaults for everything but the server and model (for tests and examples).
    pub fn new(base_url: impl Into<String>, model: impl Into<String>) -> Self {
        Self {
            base_url: base_url.into(),
            model: model.into(),
            api_key_env: None,
            temperature: None,
            seed: None,
            max_output_tokens: None,
            max_tokens_param: MaxTokensParam::default(),
            reasoning_effort: None,
            concurrency: default_concurrency(),
            timeout_secs: default_timeout_secs(),
            connect_timeout_secs: default_connect_timeout_secs(),
            max_attempts: default_max_attempts(),
            retry_base_ms: default_retry_base_ms(),
            retry_max_secs: default_retry_max_secs(),
            price_input_per_mtok: 0.0,
            price_cached_input_per_mtok: None,
            price_output_per_mtok: 0.0,
            cache_id: None,
            answer_format: AnswerFormat::default(),
            probability_from: ProbabilityFrom::default(),
            top_logprobs: None,
            max_reasks: default_max_reasks(),
            word_answer_mass: default_word_answer_mass(),
            system_role: SystemRole::default(),
        }
    }

    /// Alternatives per token to request, if log-probabilities are requested at all.
    pub fn requested_top_logprobs(&self) -> Option<u8> {
        match (self.top_logprobs, self.probability_from) {
            (Some(n), _) => Some(n),
            (None, ProbabilityFrom::Logprobs) => Some(MAX_TOP_LOGPROBS),
            (None, ProbabilityFrom::Text) => None,
        }
    }

    /// The base URL without trailing slashes and with every query value replaced by
    /// `[redacted]` (some gateways take their key as `?key=...`): what messages, `ferret llm
    /// list`, the cache's `server` column and the cache key show. Without a query it is the
    /// base URL as written, so cache keys made before queries were redacted stay valid.
    pub fn normalized_base_url(&self) -> String {
        let (base, query) = match self.base_url.split_once('?') {
            Some((b, q)) => (b, Some(q)),
            None => (self.base_url.as_str(), None),
        };
        let base = base.trim_end_matches('/');
        match query {
            None => base.to_string(),
            Some(q) => {
                let redacted: Vec<String> = q
                    .split('&')
                    .filter(|kv| !kv.is_empty())
                    .map(|kv| match kv.split_once('=') {
                        Some((k, _)) => format!("{k}=[redacted]"),
                        None => kv.to_string(),
                    })
                    .collect();
                format!("{base}?{}", redacted.join("&"))
            }
        }
    }

    /// The chat-completions URL: `/chat/completions` appended to the base URL's path, its query
    /// kept (it may hold a gateway's key, so this URL is never shown).
    pub fn completions_url(&self) -> Result<reqwest::Url, String> {
        let mut url = reqwest::Url::parse(&self.base_url)
            .map_err(|e| format!("base_url is not a URL: {e}"))?;
        let path = format!("{}/chat/completions", url.path().trim_end_matches('/'));
        url.set_path(&path);
        Ok(url)
    }

    /// One attempt's time limit (validated configs stay far below `Duration`'s range; others
    /// saturate instead of panicking).
    pub fn timeout(&self) -> Duration {
        Duration::try_from_secs_f64(self.timeout_secs).unwrap_or(Duration::MAX)
    }

    /// [`connect_timeout_secs`](Self::connect_timeout_secs) as a duration.
    pub fn connect_timeout(&self) -> Duration {
        Duration::try_from_secs_f64(self.connect_timeout_secs).unwrap_or(Duration::MAX)
    }

    /// USD for a request with these token counts.
    pub fn cost_usd(&self, input: u64, cached_input: u64, output: u64) -> f64 {
        let cached = cached_input.min(input);
        let cached_price = self
            .price_cached_input_per_mtok
            .unwrap_or(self.price_input_per_mtok);
        ((input - cached) as f64 * self.price_input_per_mtok
            + cached as f64 * cached_price
            + output as f64 * self.price_output_per_mtok)
            / 1e6
    }

    /// Checks ranges; `key` is the table's path in the file (`llm.gpt-5-mini`).
    fn validate(&self, file: &Path, key: &str) -> Result<(), ConfigError> {
        let bad = |field: &str, message: String| ConfigError::Invalid {
            file: file.to_path_buf(),
            key: format!("{key}.{field}"),
            message,
        };
        let url = reqwest::Url::parse(&self.base_url)
            .map_err(|e| bad("base_url", format!("`{}` is not a URL: {e}", self.base_url)))?;
        if !matches!(url.scheme(), "http" | "https") {
            return Err(bad(
                "base_url",
                format!("`{}` is not an http(s) URL", self.base_url),
            ));
        }
        if !url.username().is_empty() || url.password().is_some() {
            return Err(bad(
                "base_url",
                "must not carry credentials; name the key's environment variable in api_key_env"
                    .into(),
            ));
        }
        if self.model.trim().is_empty() {
            return Err(bad("model", "is empty".into()));
        }
        // The value is never repeated: a key pasted here by mistake would be printed.
        if let Some(var) = &self.api_key_env
            && let Some(why) = not_a_variable_name(var)
        {
            return Err(bad(
                "api_key_env",
                format!(
                    "{why}; it must name the environment variable that holds the key (put the key itself in the environment, never in this file; the value is not shown)"
                ),
            ));
        }
        if let Some(t) = self.temperature
            && !(0.0..=2.0).contains(&t)
        {
            return Err(bad("temperature", format!("{t} is outside [0, 2]")));
        }
        if self.max_output_tokens == Some(0) {
            return Err(bad("max_output_tokens", "must be at least 1".into()));
        }
        if self.concurrency == 0 {
            return Err(bad("concurrency", "must be at least 1".into()));
        }
        if !(self.timeout_secs.is_finite()
            && self.timeout_secs > 0.0
            && self.timeout_secs <= MAX_TIMEOUT_SECS)
        {
            return Err(bad(
                "timeout_secs",
                format!(
                    "{} is not a number of seconds in (0, {MAX_TIMEOUT_SECS}]",
                    self.timeout_secs
                ),
            ));
        }
        if !(self.connect_timeout_secs.is_finite()
            && self.connect_timeout_secs > 0.0
            && self.connect_timeout_secs <= MAX_TIMEOUT_SECS)
        {
            return Err(bad(
                "connect_timeout_secs",
                format!(
                    "{} is not a number of seconds in (0, {MAX_TIMEOUT_SECS}]",
                    self.connect_timeout_secs
                ),
            ));
        }
        if self.max_attempts > MAX_ATTEMPTS {
            return Err(bad(
                "max_attempts",
                format!("{} is more than {MAX_ATTEMPTS}", self.max_attempts),
            ));
        }
        if self.retry_base_ms > MAX_RETRY_BASE_MS {
            return Err(bad(
                "retry_base_ms",
                format!("{} is more than {MAX_RETRY_BASE_MS}", self.retry_base_ms),
            ));
        }
        if let Some(n) = self.top_logprobs
            && !(1..=MAX_TOP_LOGPROBS).contains(&n)
        {
            return Err(bad(
                "top_logprobs",
                format!("{n} is outside 1..={MAX_TOP_LOGPROBS}"),
            ));
        }
        if self.max_reasks > MAX_REASKS {
            return Err(bad(
                "max_reasks",
                format!("{} is more than {MAX_REASKS}", self.max_reasks),
            ));
        }
        if !(0.5..=0.99).contains(&self.word_answer_mass) {
            return Err(bad(
                "word_answer_mass",
                format!("{} is outside [0.5, 0.99]", self.word_answer_mass),
            ));
        }
        if self.max_attempts == 0 {
            return Err(bad("max_attempts", "must be at least 1".into()));
        }
        if !(self.retry_max_secs.is_finite()
            && self.retry_max_secs >= 0.0
            && self.retry_max_secs <= MAX_RETRY_MAX_SECS)
        {
            return Err(bad(
                "retry_max_secs",
                format!(
                    "{} is not a number of seconds in [0, {MAX_RETRY_MAX_SECS}]",
                    self.retry_max_secs
                ),
            ));
        }
        for (field, price) in [
            ("price_input_per_mtok", Some(self.price_input_per_mtok)),
            ("price_output_per_mtok", Some(self.price_output_per_mtok)),
            (
                "price_cached_input_per_mtok",
                self.price_cached_input_per_mtok,
            ),
        ] {
            if let Some(p) = price
                && !(p.is_finite() && p >= 0.0)
            {
                return Err(bad(field, format!("{p} is not a price in USD")));
            }
        }
        Ok(())
    }
}

/// A named endpoint with its API key, if it has one, read from the environment.
#[derive(Clone)]
pub struct Endpoint {
    /// The name in the config (`gpt-5-mini`), used in strategy names.
    pub name: String,
    /// Its settings.
    pub config: EndpointConfig,
    key: Option<SecretString>,
}

impl fmt::Debug for Endpoint {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("Endpoint")
            .field("name", &self.name)
            .field("config", &self.config)
            .field("key", &self.key.as_ref().map(|_| "[redacted]"))
            .finish()
    }
}

impl Endpoint {
    /// An endpoint, reading its key from the variable named in `api_key_env` if that is set.
    /// A missing variable is not an error here: offline runs need no key. It is one when a
    /// request must be sent ([`LlmError::MissingKey`](crate::LlmError::MissingKey)).
    pub fn new(name: impl Into<String>, config: EndpointConfig) -> Self {
        let key = config
            .api_key_env
            .as_deref()
            .and_then(|var| std::env::var(var).ok())
            .filter(|k| !k.is_empty())
            .map(SecretString::from);
        Self {
            name: name.into(),
            config,
            key,
        }
    }

    /// An endpoint with an explicit key (tests; programs that hold keys elsewhere).
    pub fn with_key(name: impl Into<String>, config: EndpointConfig, key: Option<String>) -> Self {
        Self {
            name: name.into(),
            config,
            key: key.map(SecretString::from),
        }
    }

    /// The key, if one was found.
    pub(crate) fn key(&self) -> Option<&SecretString> {
        self.key.as_ref()
    }

    /// True when the endpoint needs no key or its key was found.
    pub fn has_key(&self) -> bool {
        self.config.api_key_env.is_none() || self.key.is_some()
    }
}

#[derive(Debug, Default, Deserialize)]
struct FileConfig {
    #[serde(default)]
    llm: BTreeMap<String, EndpointConfig>,
    #[serde(default)]
    prompts: BTreeMap<String, PathBuf>,
}

/// Every endpoint of a config file, by name.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct LlmConfig {
    /// The file they came from (for messages).
    pub file: PathBuf,
    /// Endpoints by name, sorted.
    pub endpoints: BTreeMap<String, EndpointConfig>,
    /// User prompt templates from the `[prompts]` table (`name = "path.j2"`), paths resolved
    /// against the config file's directory.
    pub prompts: BTreeMap<String, PathBuf>,
}

impl LlmConfig {
    /// Reads the `[llm.*]` tables of a TOML file.
    pub fn load(file: &Path) -> Result<Self, ConfigError> {
        let text = ferret_world::input::read_text(file, MAX_CONFIG_BYTES).map_err(|source| {
            ConfigError::Read {
                file: file.to_path_buf(),
                source,
            }
        })?;
        Self::parse(&text, file)
    }

    /// Reads `explicit` if given, else `ferret.toml` in the working directory if it exists, else
    /// an empty config.
    pub fn load_default(explicit: Option<&Path>) -> Result<Self, ConfigError> {
        match explicit {
            Some(p) => Self::load(p),
            None => {
                let p = Path::new(DEFAULT_CONFIG_FILE);
                if p.exists() {
                    Self::load(p)
                } else {
                    Ok(Self::default())
                }
            }
        }
    }

    /// Parses config text; `file` names it in errors.
    pub fn parse(text: &str, file: &Path) -> Result<Self, ConfigError> {
        refuse_secrets(text, file)?;
        let parsed: FileConfig = toml::from_str(text).map_err(|e| ConfigError::Parse {
            file: file.to_path_buf(),
            // The message and position only: toml's own rendering quotes the offending line,
            // which could hold a secret.
            message: match e.span() {
                Some(span) => {
                    let line = text[..span.start.min(text.len())].lines().count().max(1);
                    format!("line {line}: {}", e.message())
                }
                None => e.message().to_string(),
            },
        })?;
        for (name, endpoint) in &parsed.llm {
            let key = format!("llm.{name}");
            validate_name(name).map_err(|message| ConfigError::Invalid {
                file: file.to_path_buf(),
                key: key.clone(),
                message,
            })?;
            endpoint.validate(file, &key)?;
        }
        let dir = file.parent().unwrap_or(Path::new(""));
        let mut prompts = BTreeMap::new();
        for (name, path) in parsed.prompts {
            validate_name(&name).map_err(|message| ConfigError::Invalid {
                file: file.to_path_buf(),
                key: format!("prompts.{name}"),
                message: message.replace("endpoint", "prompt"),
            })?;
            prompts.insert(
                name,
                if path.is_absolute() {
                    path
                } else {
                    dir.join(path)
                },
            );
        }
        Ok(Self {
            file: file.to_path_buf(),
            endpoints: parsed.llm,
            prompts,
        })
    }

    /// The endpoint called `name`, with its key read from the environment.
    pub fn endpoint(&self, name: &str) -> Result<Endpoint, ConfigError> {
        self.endpoints
            .get(name)
            .map(|c| Endpoint::new(name, c.clone()))
            .ok_or_else(|| ConfigError::UnknownEndpoint {
                name: name.to_string(),
                file: self.file.clone(),
                known: self.endpoints.keys().cloned().collect(),
            })
    }
}

/// Refuses a secret written into the file (`api_key = "sk-..."` and the like), naming the line
/// and field but never the value.
fn refuse_secrets(text: &str, file: &Path) -> Result<(), ConfigError> {
    for (i, line) in text.lines().enumerate() {
        let Some((field, _)) = line.split_once('=') else {
            continue;
        };
        let field = field.trim().trim_matches('"').to_ascii_lowercase();
        if SECRET_FIELDS.contains(&field.as_str()) {
            return Err(ConfigError::Invalid {
                file: file.to_path_buf(),
                key: format!("line {}: {field}", i + 1),
                message: "API keys never go in the config file: put the key in an environment variable and name that variable in api_key_env (the value was not read)".into(),
            });
        }
    }
    Ok(())
}

/// Why `var` is no environment variable name, or looks like an API key instead of one (a name
/// is letters, digits and `_`, not starting with a digit; keys are long mixes of upper- and
/// lower-case letters and digits, or start with a provider's prefix).
fn not_a_variable_name(var: &str) -> Option<&'static str> {
    let valid = var
        .chars()
        .next()
        .is_some_and(|c| c.is_ascii_alphabetic() || c == '_')
        && var.chars().all(|c| c.is_ascii_alphanumeric() || c == '_');
    if !valid {
        return Some("is not an environment variable name (letters, digits and _)");
    }
    let has = |f: fn(&char) -> bool| var.chars().any(|c| f(&c));
    let mixed =
        has(char::is_ascii_lowercase) && has(char::is_ascii_uppercase) && has(char::is_ascii_digit);
    let prefixed = ["hf_", "gsk_", "ghp_", "xai_", "pplx_", "r8_"]
        .iter()
        .any(|p| var.starts_with(p));
    if var.len() >= 20 && (mixed || prefixed) {
        return Some("looks like an API key, not the name of a variable");
    }
    None
}

/// Endpoint names appear in strategy specs (`llm+model/p-context-a/<name>`), so they must not
/// hold `/` or spaces.
fn validate_name(name: &str) -> Result<(), String> {
    if name.is_empty() {
        return Err("an endpoint name is empty".into());
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || matches!(c, '-' | '_' | '.' | ':')))
    {
        return Err(format!(
            "endpoint name `{name}` holds `{c}`; use letters, digits and - _ . : (it appears in strategy names)"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn parse(text: &str) -> Result<LlmConfig, ConfigError> {
        LlmConfig::parse(text, Path::new("ferret.toml"))
    }

    #[test]
    fn reads_endpoints_and_defaults() {
        let c = parse(
            r#"
            [other]
            x = 1
            [llm.local]
            base_url = "http://localhost:8000/v1/"
            model = "openai/gpt-oss-120b"
            temperature = 0.0
            seed = 7
            [llm.gpt-5-mini]
            base_url = "https://api.openai.com/v1"
            model = "gpt-5-mini"
            api_key_env = "OPENAI_API_KEY"
            reasoning_effort = "minimal"
            price_input_per_mtok = 0.25
            price_output_per_mtok = 2.0
            "#,
        )
        .unwrap();
        assert_eq!(
            c.endpoints.keys().collect::<Vec<_>>(),
            ["gpt-5-mini", "local"]
        );
        let local = &c.endpoints["local"];
        assert_eq!(
            local.completions_url().unwrap().as_str(),
            "http://localhost:8000/v1/chat/completions"
        );
        assert_eq!(local.concurrency, 4);
        assert_eq!(local.max_attempts, 5);
        assert_eq!(local.seed, Some(7));
        let g = &c.endpoints["gpt-5-mini"];
        assert_eq!(g.reasoning_effort, Some(ReasoningEffort::Minimal));
        assert!((g.cost_usd(1_000_000, 0, 1_000_000) - 2.25).abs() < 1e-12);
    }

    #[test]
    fn errors_name_file_and_key() {
        let e = parse("[llm.a]\nbase_url = \"http://x/v1\"\nmodel = \"m\"\nconcurrency = 0\n")
            .unwrap_err();
        let s = e.to_string();
        assert!(
            s.contains("ferret.toml") && s.contains("llm.a.concurrency"),
            "{s}"
        );

        let e = parse("[llm.a]\nbase_url = \"http://x/v1\"\nmodel = \"m\"\ntemprature = 0.2\n")
            .unwrap_err();
        let s = e.to_string();
        assert!(s.contains("ferret.toml") && s.contains("temprature"), "{s}");

        let e = parse("[llm.a]\nmodel = \"m\"\n").unwrap_err();
        assert!(e.to_string().contains("base_url"), "{e}");

        let e = parse("[llm.a]\nbase_url = \"ftp://x\"\nmodel = \"m\"\n").unwrap_err();
        assert!(e.to_string().contains("llm.a.base_url"), "{e}");

        let e = parse("[llm.\"a/b\"]\nbase_url = \"http://x\"\nmodel = \"m\"\n").unwrap_err();
        assert!(e.to_string().contains("llm.a/b"), "{e}");

        let e = parse(
            "[llm.a]\nbase_url = \"http://x\"\nmodel = \"m\"\napi_key_env = \"KEY=sk-123\"\n",
        )
        .unwrap_err();
        assert!(e.to_string().contains("llm.a.api_key_env"), "{e}");
    }

    #[test]
    fn answer_settings_parse_and_are_checked() {
        let c = parse(
            "[llm.a]\nbase_url = \"http://x/v1\"\nmodel = \"m\"\nanswer_format = \"json_schema\"\nsystem_role = \"merge\"\nmax_reasks = 2\ntop_logprobs = 5\n",
        )
        .unwrap();
        let a = &c.endpoints["a"];
        assert_eq!(a.answer_format, AnswerFormat::JsonSchema);
        assert_eq!(a.system_role, SystemRole::Merge);
        assert_eq!((a.max_reasks, a.requested_top_logprobs()), (2, Some(5)));
        for (field, value) in [
            ("top_logprobs", "0"),
            ("top_logprobs", "21"),
            ("max_reasks", "6"),
        ] {
            let e = parse(&format!(
                "[llm.a]\nbase_url = \"http://x/v1\"\nmodel = \"m\"\n{field} = {value}\n"
            ))
            .unwrap_err()
            .to_string();
            assert!(e.contains(&format!("llm.a.{field}")), "{e}");
        }
        let e =
            parse("[llm.a]\nbase_url = \"http://x/v1\"\nmodel = \"m\"\nanswer_format = \"yaml\"\n")
                .unwrap_err()
                .to_string();
        assert!(e.contains("answer_format") || e.contains("yaml"), "{e}");
    }

    #[test]
    fn huge_numbers_are_refused_not_panicked_on() {
        for (field, value) in [
            ("timeout_secs", "18446744073709551615"),
            ("timeout_secs", "1e300"),
            ("retry_max_secs", "1e300"),
            ("max_attempts", "1000000"),
            ("retry_base_ms", "18446744073709551615"),
        ] {
            let e = parse(&format!(
                "[llm.a]\nbase_url = \"http://x/v1\"\nmodel = \"m\"\n{field} = {value}\n"
            ))
            .unwrap_err()
            .to_string();
            assert!(e.contains(&format!("llm.a.{field}")), "{field}: {e}");
        }
        let mut c = EndpointConfig::new("http://x/v1", "m");
        c.timeout_secs = 1e300;
        assert_eq!(c.timeout(), Duration::MAX);
    }

    #[test]
    fn query_keys_are_kept_in_requests_and_redacted_everywhere_else() {
        let c = EndpointConfig::new("https://gw.example/v1/?key=SECRET123&region=eu", "m");
        assert_eq!(
            c.completions_url().unwrap().as_str(),
            "https://gw.example/v1/chat/completions?key=SECRET123&region=eu"
        );
        assert_eq!(
            c.normalized_base_url(),
            "https://gw.example/v1?key=[redacted]&region=[redacted]"
        );
        let plain = EndpointConfig::new("http://h:8000/v1/", "m");
        assert_eq!(plain.normalized_base_url(), "http://h:8000/v1");
    }

    #[test]
    fn a_key_written_into_the_file_is_refused_without_repeating_it() {
        for line in [
            "api_key = \"sk-live-abcdef123456\"",
            "API_KEY=\"sk-live-abcdef123456\"",
            "token = \"sk-live-abcdef123456\"",
        ] {
            let e = parse(&format!(
                "[llm.a]\nbase_url = \"http://x/v1\"\nmodel = \"m\"\n{line}\n"
            ))
            .unwrap_err()
            .to_string();
            assert!(!e.contains("abcdef123456"), "{e}");
            assert!(e.contains("line 4") && e.contains("api_key_env"), "{e}");
        }
        // Other parse errors name the line without quoting it.
        let e = parse("[llm.a]\nbase_url = \"http://x/v1\nmodel = \"sk-zzzzzzzz999\"\n")
            .unwrap_err()
            .to_string();
        assert!(!e.contains("sk-zzzzzzzz999") && e.contains("line"), "{e}");
    }

    #[test]
    fn unknown_endpoint_lists_known_ones() {
        let c = parse("[llm.a]\nbase_url = \"http://x\"\nmodel = \"m\"\n").unwrap();
        let e = c.endpoint("b").unwrap_err().to_string();
        assert!(e.contains("`b`") && e.contains("a"), "{e}");
    }

    #[test]
    fn example_config_parses() {
        let text = include_str!("../../../ferret.example.toml");
        let c = LlmConfig::parse(text, Path::new("ferret.example.toml")).unwrap();
        assert_eq!(
            c.endpoints.keys().collect::<Vec<_>>(),
            [
                "gemini-2.5-flash",
                "gpt-5-mini",
                "gpt-oss-120b",
                "llama3.2-3b",
                "qwen-local"
            ]
        );
        let q = &c.endpoints["qwen-local"];
        assert_eq!(
            (
                q.answer_format,
                q.probability_from,
                q.requested_top_logprobs()
            ),
            (
                AnswerFormat::JsonObject,
                ProbabilityFrom::Logprobs,
                Some(20)
            )
        );
        assert_eq!(c.endpoints["gpt-5-mini"].answer_format, AnswerFormat::Text);
        assert_eq!(c.endpoints["gpt-5-mini"].max_reasks, 1);
        assert_eq!(
            c.endpoints["gemini-2.5-flash"]
                .completions_url()
                .unwrap()
                .as_str(),
            "https://generativelanguage.googleapis.com/v1beta/openai/chat/completions"
        );
        assert_eq!(c.endpoints["llama3.2-3b"].model, "llama3.2:3b");
        assert_eq!(
            c.endpoints["gpt-oss-120b"].base_url,
            "http://localhost:8000/v1"
        );
        assert_eq!(
            c.endpoints["gpt-5-mini"].api_key_env.as_deref(),
            Some("OPENAI_API_KEY")
        );
    }

    #[test]
    fn debug_output_hides_the_key() {
        let e = Endpoint::with_key(
            "a",
            EndpointConfig::new("http://x", "m"),
            Some("sk-secret-123".into()),
        );
        assert!(!format!("{e:?}").contains("sk-secret-123"));
    }
}
