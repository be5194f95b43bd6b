//! # ferret-llm
//!
//! LLMs as likelihood sources and as policies for object search.
//!
//! - [`config`]: endpoints named in `ferret.toml` (`[llm.<name>]`: base URL, model, the *name* of
//!   the environment variable holding the API key, sampling settings, concurrency, timeout,
//!   retries, prices).
//! - [`client`]: OpenAI-compatible chat completions (async-openai's request and response types
//!   over reqwest), with a per-endpoint concurrency limit, timeouts, and retries with exponential
//!   backoff and jitter on 429, 5xx, timeouts and cut connections, honouring `Retry-After`.
//! - [`cache`]: the SQLite response cache (one file, WAL, committed before an answer is used);
//!   [`service`] puts it in front of every endpoint ([`Llm`]), with an offline mode.
//! - [`prompts`] and [`context`]: P-CONTEXT-A, P-CONTEXT-B, P-MINIMAL, P-DIRECT, P-YESNO,
//!   P-CHOICE and P-BATCH as minijinja templates compiled into the binary (users add their own by
//!   path), rendered from a house in words.
//! - [`question`]: a question and the request an endpoint receives for it (role text merged for
//!   models without a system turn, structured output with a JSON schema, log-probabilities).
//! - [`answer`]: probability parsing into answer classes, yes/no and letter answers, P-DIRECT
//!   matching; [`logprobs`]: the expected percentage, P(Yes) and the letter distribution from
//!   token log-probabilities.
//! - [`likelihood`]: [`LlmLikelihood`], the LLM as a likelihood source, asking and reading each
//!   kind of prompt (one question per container type and room, per room type, or per house).
//! - [`ledger`]: tokens, requests, cache hits and USD per LLM and strategy (`tokens.csv`, the
//!   paper's table V).
//! - [`strategy`]: `llm+model/<prompt>/<llm>`, `fused/<prompt>/<llm>` and
//!   `llm-direct/<prompt>/<llm>` for the plan crate's
//!   [`StrategyRegistry`](ferret_plan::StrategyRegistry), and concurrent prefetching of every
//!   probability question before trials run.
//!
//! API keys never leave the endpoint: they are not in the cache, the logs, reports or errors.

#![warn(missing_docs)]

pub mod answer;
pub mod cache;
pub mod client;
pub mod config;
pub mod context;
pub mod error;
pub mod ledger;
pub mod likelihood;
pub mod logprobs;
pub mod message;
pub mod prompts;
pub mod question;
pub mod service;
pub mod strategy;

pub use answer::{
    AnswerClass, FALLBACK_PROBABILITY, MatchKind, ProbabilityReading, WordReading, WorkedExample,
    batch_entries, match_location, parse_probability, read_batch, read_batch_yes_no, read_label,
    read_probability, read_yes_no,
};
pub use async_openai::types::chat::ReasoningEffort;
pub use cache::{
    CacheConflict, CacheMerge, CachedReply, DEFAULT_CACHE_PATH, ResponseCache, cache_key,
};
pub use client::{EndpointClient, Reply, TokenUsage};
pub use config::{
    AnswerFormat, DEFAULT_CONFIG_FILE, Endpoint, EndpointConfig, LlmConfig, MaxTokensParam,
    ProbabilityFrom, SystemRole,
};
pub use context::{
    DirectContext, HouseContext, LABELS, ListedOption, ListedPlace, Listing, ListingContext,
    MAX_LISTED, ProbabilityContext, ProbabilityQuery, QueryPlan,
};
pub use error::{CacheError, ConfigError, LlmError, Result};
pub use ledger::{
    AnswerCounts, AnswerOutcome, Ledger, LogprobUse, Spent, TokenCounts, TokenReport, UsageRow,
};
pub use likelihood::{Asked, LlmLikelihood, QuestionSet, Resolved, Shape, question_set};
pub use logprobs::{
    TokenLogprob, TopLogprob, expected_percentage, label_distribution, yes_probability,
};
pub use message::{ChatMessage, MessageRole, printable};
pub use prompts::{
    P_BATCH, P_CHOICE, P_CONTEXT_A, P_CONTEXT_B, P_DIRECT, P_MINIMAL, P_YESNO, PromptKind,
    PromptLibrary,
};
pub use question::{Expect, Question, Request};
pub use service::{Answer, FailurePolicy, Llm, LlmOptions, LlmService};
pub use strategy::{
    FUSED, FUSED_LEARNED, LLM_DIRECT, LLM_MODEL, LlmDirectPolicy, LlmDirectStrategy, LlmSpec,
    PrefetchProgress, PrefetchSummary, Prefetched, asks_probabilities, control_source, fusion_base,
    prefetch_probabilities, prefetch_probabilities_after, register_fused, register_strategies,
};
