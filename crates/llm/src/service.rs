//! LLMs with their response cache and accounting, and the runtime that serves synchronous
//! callers.

use std::collections::{BTreeMap, HashMap};
use std::future::Future;
use std::path::PathBuf;
use std::sync::{Arc, Mutex, MutexGuard, RwLock, RwLockReadGuard};
use std::time::{Duration, Instant};

use crate::cache::{CachedReply, ResponseCache, cache_key, now_unix};
use crate::client::{EndpointClient, TokenUsage};
use crate::config::{Endpoint, LlmConfig};
use crate::error::{LlmError, Result};
use crate::ledger::{Ledger, TokenReport};
use crate::logprobs::TokenLogprob;
use crate::message::prompt_start;
use crate::prompts::PromptLibrary;
use crate::question::{Question, Request};

/// Characters of a prompt shown when it is missing from the cache.
const PROMPT_PREVIEW_CHARS: usize = 160;

/// An answer and where it came from.
#[derive(Clone, Debug, PartialEq)]
pub struct Answer {
    /// The answer text.
    pub text: String,
    /// Tokens it took when it was asked.
    pub usage: TokenUsage,
    /// USD it cost when it was asked, at the endpoint's current prices.
    pub cost_usd: f64,
    /// True when it came from the response cache.
    pub from_cache: bool,
    /// Latency of the request that produced it.
    pub latency: Duration,
    /// Its cache key.
    pub key: String,
    /// Token log-probabilities, when they were asked for and the server sent them.
    pub logprobs: Option<Vec<TokenLogprob>>,
}

/// One LLM endpoint with the response cache in front of it.
#[derive(Debug)]
pub struct Llm {
    client: EndpointClient,
    cache: Option<Arc<ResponseCache>>,
    offline: bool,
    ledger: Arc<Ledger>,
    /// One lock per prompt being asked, so concurrent askers of the same prompt send it once.
    inflight: Mutex<HashMap<String, Arc<tokio::sync::Mutex<()>>>>,
    /// Set when a request failed after all its retries in a way that says the endpoint is down
    /// (refused or cut connections, timeouts, 429/5xx): later questions then fail at once instead
    /// of going through the same retries again, for the run or for a pause (see
    /// [`FailurePolicy`]).
    down: Mutex<Option<Down>>,
    policy: FailurePolicy,
    /// Held by the question that checks whether a down endpoint is back; the others wait for
    /// its outcome.
    probe: tokio::sync::Mutex<()>,
}

/// What a failure of an endpoint after all its retries means for the questions after it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FailurePolicy {
    /// Nothing more is sent to it in this run: every later question fails at once. For batch
    /// commands, which then stop (or go on without its strategies) instead of waiting through
    /// every question's retries.
    #[default]
    StopForRun,
    /// A circuit breaker, for a server that runs for days: after a failure, questions fail at
    /// once for `pause`; then one question is let through while the others wait for it, and its
    /// success closes the circuit (the others go on) while its failure opens it for another
    /// pause (the others fail at once).
    Breaker {
        /// How long questions fail at once after a failure.
        pause: Duration,
    },
}

/// Why and since when an endpoint is considered down.
#[derive(Clone, Debug)]
struct Down {
    reason: String,
    since: Instant,
}

impl Llm {
    /// An LLM behind `cache` (none: every question goes to the server). `offline` answers from
    /// the cache only.
    pub fn new(
        endpoint: Endpoint,
        cache: Option<Arc<ResponseCache>>,
        offline: bool,
        ledger: Arc<Ledger>,
    ) -> Result<Self> {
        Self::with_policy(endpoint, cache, offline, ledger, FailurePolicy::default())
    }

    /// The same, with what a failure of the endpoint means for later questions.
    pub fn with_policy(
        endpoint: Endpoint,
        cache: Option<Arc<ResponseCache>>,
        offline: bool,
        ledger: Arc<Ledger>,
        policy: FailurePolicy,
    ) -> Result<Self> {
        Ok(Self {
            client: EndpointClient::new(endpoint)?,
            cache,
            offline,
            ledger,
            inflight: Mutex::new(HashMap::new()),
            down: Mutex::new(None),
            policy,
            probe: tokio::sync::Mutex::new(()),
        })
    }

    /// The endpoint's name.
    pub fn name(&self) -> &str {
        &self.client.endpoint().name
    }

    /// The endpoint.
    pub fn endpoint(&self) -> &Endpoint {
        self.client.endpoint()
    }

    /// The HTTP client.
    pub fn client(&self) -> &EndpointClient {
        &self.client
    }

    /// Why the endpoint is considered down (given up on for the run, or its circuit open), if
    /// it is.
    pub fn down(&self) -> Option<String> {
        self.lock_down().as_ref().map(|d| d.reason.clone())
    }

    fn lock_down(&self) -> MutexGuard<'_, Option<Down>> {
        self.down.lock().unwrap_or_else(|p| p.into_inner())
    }

    /// Whether a question may go to the server now. With the breaker, after the pause, the
    /// first question holds the returned guard while it checks whether the endpoint is back;
    /// the others wait for it and then go on or fail as it found.
    async fn admit(&self) -> Result<Option<tokio::sync::MutexGuard<'_, ()>>> {
        let mut probe = None;
        loop {
            if self.lock_down().is_none() {
                return Ok(None);
            }
            if let Some(e) = self.refusal() {
                return Err(e);
            }
            if probe.is_some() {
                return Ok(probe);
            }
            // Half open: whoever gets the gate first probes; the state is read again after it.
            probe = Some(self.probe.lock().await);
        }
    }

    /// Why a question may not go to the server now: the endpoint is down for the run, or the
    /// breaker is open and its pause not over. `None` when the circuit is closed or half open.
    fn refusal(&self) -> Option<LlmError> {
        let down = self.lock_down();
        let d = down.as_ref()?;
        let endpoint = self.name().to_string();
        match self.policy {
            FailurePolicy::StopForRun => Some(LlmError::EndpointDown {
                endpoint,
                reason: d.reason.clone(),
            }),
            FailurePolicy::Breaker { pause } => {
                let waited = d.since.elapsed();
                (waited < pause).then(|| LlmError::EndpointPaused {
                    endpoint,
                    reason: d.reason.clone(),
                    retry_in_secs: pause.saturating_sub(waited).as_secs_f64().ceil(),
                })
            }
        }
    }

    /// The ledger it counts into.
    pub fn ledger(&self) -> &Arc<Ledger> {
        &self.ledger
    }

    /// The request this endpoint receives for `question`.
    pub fn request(&self, question: &Question) -> Request {
        Request::new(&self.endpoint().config, question)
    }

    /// The cache key `question` has at this endpoint.
    pub fn key(&self, question: &Question) -> String {
        cache_key(&self.endpoint().config, &self.request(question))
    }

    /// True when the answer to `question` is in the cache (nothing is counted).
    pub fn is_cached(&self, question: &Question) -> Result<bool> {
        match &self.cache {
            Some(c) => Ok(c.get(&self.key(question))?.is_some()),
            None => Ok(false),
        }
    }

    fn cost(&self, usage: &TokenUsage) -> f64 {
        self.endpoint().config.cost_usd(
            usage.prompt_tokens,
            usage.cached_tokens.unwrap_or(0),
            usage.completion_tokens,
        )
    }

    fn cached(&self, key: &str, strategy: &str) -> Result<Option<Answer>> {
        let Some(cache) = &self.cache else {
            return Ok(None);
        };
        // SQLite calls block the thread briefly (an indexed lookup; a busy wait only while another
        // process commits); cheap next to an HTTP request.
        Ok(cache.get(key)?.map(|hit| {
            self.ledger.record_cache_hit(self.name(), strategy, key);
            Answer {
                logprobs: hit.logprobs,
                cost_usd: self.cost(&hit.usage),
                text: hit.reply,
                usage: hit.usage,
                from_cache: true,
                latency: hit.latency,
                key: key.to_string(),
            }
        }))
    }

    /// The answer to `question`, from the cache if it is there, else from the server (then stored
    /// in the cache before it is returned). `strategy` names who asks, for accounting.
    pub async fn ask(&self, question: &Question, strategy: &str) -> Result<Answer> {
        let request = self.request(question);
        let key = cache_key(&self.endpoint().config, &request);
        if let Some(hit) = self.cached(&key, strategy)? {
            return Ok(hit);
        }
        if self.offline {
            return Err(LlmError::NotCached {
                endpoint: self.name().to_string(),
                model: self.endpoint().config.model.clone(),
                about: question.about.clone(),
                prompt_start: prompt_start(&request.messages, PROMPT_PREVIEW_CHARS),
            });
        }
        let gate = {
            let mut inflight = self.inflight.lock().unwrap_or_else(|p| p.into_inner());
            inflight.entry(key.clone()).or_default().clone()
        };
        let answer = {
            let _asking = gate.lock().await;
            // Someone may have answered it while we waited.
            match self.cached(&key, strategy)? {
                Some(hit) => Ok(hit),
                None => self.ask_server(&request, &key, strategy).await,
            }
        };
        self.inflight
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .remove(&key);
        answer
    }

    async fn ask_server(&self, request: &Request, key: &str, strategy: &str) -> Result<Answer> {
        let probe = self.admit().await?;
        // Questions asked together wait for the client's concurrency permits; once one of them
        // finds the endpoint down, the others waiting are refused instead of each spending its
        // own timeouts on it. The probe of a half-open breaker goes whatever the state says.
        let probing = probe.is_some();
        let result = self
            .client
            .complete_admitted(request, || match self.refusal() {
                Some(e) if !probing => Err(e),
                _ => Ok(()),
            })
            .await;
        if let Err(e @ (LlmError::EndpointDown { .. } | LlmError::EndpointPaused { .. })) = result {
            // Refused before it was sent: says nothing new about the endpoint.
            return Err(e);
        }
        let endpoint_down = match &result {
            Err(LlmError::Timeout { .. } | LlmError::Connection { .. }) => true,
            Err(LlmError::Status { status, .. }) => {
                *status == 429 || *status == 408 || *status >= 500
            }
            _ => false,
        };
        {
            let mut down = self.lock_down();
            match (&result, self.policy) {
                (Err(e), FailurePolicy::StopForRun) if endpoint_down => {
                    down.get_or_insert_with(|| Down {
                        reason: e.to_string(),
                        since: Instant::now(),
                    });
                }
                (Err(e), FailurePolicy::Breaker { .. }) if endpoint_down => {
                    *down = Some(Down {
                        reason: e.to_string(),
                        since: Instant::now(),
                    });
                }
                // Any answer, even an unusable one, shows the endpoint is up again.
                (_, FailurePolicy::Breaker { .. }) => *down = None,
                _ => {}
            }
        }
        drop(probe);
        let reply = result?;
        let cost = self.cost(&reply.usage);
        self.ledger.record_sent(
            self.name(),
            strategy,
            key,
            &reply.usage,
            cost,
            reply.latency.as_secs_f64(),
        );
        let mut answer = Answer {
            text: reply.text,
            usage: reply.usage,
            cost_usd: cost,
            from_cache: false,
            latency: reply.latency,
            key: key.to_string(),
            logprobs: reply.logprobs,
        };
        if let Some(cache) = &self.cache {
            let config = &self.endpoint().config;
            let stored = cache.put(&CachedReply {
                key: key.to_string(),
                endpoint: self.name().to_string(),
                model: config.model.clone(),
                server: config
                    .cache_id
                    .clone()
                    .unwrap_or_else(|| config.normalized_base_url()),
                messages: request.messages.clone(),
                reply: answer.text.clone(),
                usage: answer.usage,
                latency: answer.latency,
                created_unix: now_unix(),
                logprobs: answer.logprobs.clone(),
            })?;
            // Another process may have stored its answer first; use the stored one so that every
            // run and every replay sees the same answer.
            answer.text = stored.reply;
            answer.logprobs = stored.logprobs;
        }
        Ok(answer)
    }
}

/// How a [`LlmService`] uses the response cache.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct LlmOptions {
    /// The cache file; `None` disables caching (not allowed with `offline`).
    pub cache_path: Option<PathBuf>,
    /// Answer from the cache only; a missing answer is an error.
    pub offline: bool,
    /// What a failed endpoint means for later questions.
    pub on_failure: FailurePolicy,
}

/// A tokio runtime that may be dropped anywhere, even inside another runtime.
#[derive(Debug)]
struct OwnedRuntime(Option<tokio::runtime::Runtime>);

impl Drop for OwnedRuntime {
    fn drop(&mut self) {
        if let Some(rt) = self.0.take() {
            rt.shutdown_background();
        }
    }
}

/// Every configured LLM, the shared response cache, the prompt library, the ledger, and a tokio
/// runtime through which synchronous code (rayon threads running trials) asks.
#[derive(Debug)]
pub struct LlmService {
    runtime: OwnedRuntime,
    handle: tokio::runtime::Handle,
    config: LlmConfig,
    cache_path: Option<PathBuf>,
    /// Opened on first use, so runs without LLM strategies leave no cache file behind.
    cache: Mutex<Option<Arc<ResponseCache>>>,
    offline: bool,
    on_failure: FailurePolicy,
    ledger: Arc<Ledger>,
    llms: Mutex<BTreeMap<String, Arc<Llm>>>,
    prompts: RwLock<PromptLibrary>,
}

impl LlmService {
    /// A service over the endpoints of `config`, with the cache and mode of `options`. Also loads
    /// the templates named in the config's `[prompts]` table. The cache file is opened when the
    /// first LLM is used.
    pub fn new(config: LlmConfig, options: LlmOptions) -> Result<Self> {
        if options.offline {
            match &options.cache_path {
                None => {
                    return Err(LlmError::Options(
                        "offline mode answers from the response cache, but no cache file is set"
                            .into(),
                    ));
                }
                Some(p) if !p.exists() => {
                    return Err(LlmError::Options(format!(
                        "offline mode answers from the response cache, but {} does not exist",
                        p.display()
                    )));
                }
                Some(_) => {}
            }
        }
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(2)
            .thread_name("ferret-llm")
            .enable_all()
            .build()
            .map_err(LlmError::Runtime)?;
        let handle = runtime.handle().clone();
        let mut prompts = PromptLibrary::new();
        for (name, path) in &config.prompts {
            prompts.add_file(name, path)?;
        }
        Ok(Self {
            runtime: OwnedRuntime(Some(runtime)),
            handle,
            config,
            cache_path: options.cache_path,
            cache: Mutex::new(None),
            offline: options.offline,
            on_failure: options.on_failure,
            ledger: Arc::new(Ledger::new()),
            llms: Mutex::new(BTreeMap::new()),
            prompts: RwLock::new(prompts),
        })
    }

    /// The LLM called `name` in the config (created on first use).
    pub fn llm(&self, name: &str) -> Result<Arc<Llm>> {
        let mut llms = self.llms.lock().unwrap_or_else(|p| p.into_inner());
        if let Some(l) = llms.get(name) {
            return Ok(l.clone());
        }
        let endpoint = self.config.endpoint(name)?;
        let llm = Arc::new(Llm::with_policy(
            endpoint,
            self.cache()?,
            self.offline,
            self.ledger.clone(),
            self.on_failure,
        )?);
        llms.insert(name.to_string(), llm.clone());
        Ok(llm)
    }

    /// The LLMs given up on in this run, with the failure that stopped each.
    pub fn failed_llms(&self) -> Vec<(String, String)> {
        self.llms
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .iter()
            .filter_map(|(name, llm)| llm.down().map(|why| (name.clone(), why)))
            .collect()
    }

    /// The config.
    pub fn config(&self) -> &LlmConfig {
        &self.config
    }

    /// The response cache (opened now if it was not yet), if one is used.
    pub fn cache(&self) -> Result<Option<Arc<ResponseCache>>> {
        let Some(path) = &self.cache_path else {
            return Ok(None);
        };
        let mut cache = self.cache.lock().unwrap_or_else(|p| p.into_inner());
        if cache.is_none() {
            *cache = Some(Arc::new(ResponseCache::open(path)?));
        }
        Ok(cache.clone())
    }

    /// True in offline mode.
    pub fn is_offline(&self) -> bool {
        self.offline
    }

    /// The prompt templates.
    pub fn prompts(&self) -> RwLockReadGuard<'_, PromptLibrary> {
        self.prompts.read().unwrap_or_else(|p| p.into_inner())
    }

    /// The template a strategy names: a known name, or a path to a template file, loaded on
    /// first use. Returns the name to render it by.
    pub fn resolve_prompt(&self, name_or_path: &str) -> Result<String> {
        if self.prompts().contains(name_or_path) {
            return Ok(name_or_path.to_string());
        }
        self.prompts
            .write()
            .unwrap_or_else(|p| p.into_inner())
            .resolve(name_or_path)
    }

    /// The shared ledger.
    pub fn ledger(&self) -> &Arc<Ledger> {
        &self.ledger
    }

    /// Tokens, requests, cache hits and costs so far.
    pub fn report(&self) -> TokenReport {
        self.ledger.report()
    }

    /// A handle to the service's runtime.
    pub fn handle(&self) -> &tokio::runtime::Handle {
        &self.handle
    }

    /// Runs `future` to completion on the service's runtime, blocking this thread. For
    /// synchronous callers (rayon threads); it must not be called from inside an async task.
    pub fn block_on<F: Future>(&self, future: F) -> F::Output {
        debug_assert!(self.runtime.0.is_some());
        self.handle.block_on(future)
    }
}
