//! LLMs in the plan crate's terms: a likelihood source ([`LlmLikelihood`], behind the strategy
//! `llm+model/<prompt>/<llm>[/k<N>|/exact]`), a policy ([`LlmDirectPolicy`], behind
//! `llm-direct/<prompt>/<llm>`), their registration in a [`StrategyRegistry`], and
//! [`prefetch_probabilities`], which asks every probability question of a set of trials
//! concurrently before the trials run so that they find every answer in the cache.
//!
//! The plan crate's traits are synchronous (trials run on rayon threads); these types reach the
//! async client through the [`LlmService`]'s runtime with `block_on`.

use std::collections::{HashMap, HashSet};
use std::sync::{Arc, Mutex};

use ferret_plan::policy::nearest;
use ferret_plan::strategy::parse_limit;
use ferret_plan::{
    Belief, LikelihoodSource, ModelStrategy, PlanError, PlannerConfig, Policy, Probability,
    Strategy, StrategyRegistry, StrategySpec, TrialContext,
};
use ferret_world::{House, ObjectType};
use futures::future::join_all;
use futures::stream::{self, StreamExt};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::answer::{
    AnswerClass, FALLBACK_PROBABILITY, MatchKind, WorkedExample, contains_phrase, match_location,
    read_probability,
};
use crate::client::TokenUsage;
use crate::config::ProbabilityFrom;
use crate::context::{DirectContext, HouseContext, ProbabilityQuery, QueryPlan};
use crate::error::{LlmError, Result};
use crate::ledger::{AnswerOutcome, LogprobUse};
use crate::logprobs::expected_percentage;
use crate::message::ChatMessage;
use crate::question::{Expect, LOCATION_REMINDER, PROBABILITY_REMINDER, Question};
use crate::service::{Answer, Llm, LlmService};

/// The strategy kind of the LLM-informed planner.
pub const LLM_MODEL: &str = "llm+model";
/// The strategy kind of the LLM-direct baseline.
pub const LLM_DIRECT: &str = "llm-direct";

/// A parsed LLM strategy spec.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LlmSpec {
    /// `llm+model` or `llm-direct`.
    pub kind: String,
    /// The prompt: a template name or a path to a template file (which may hold `/`).
    pub prompt: String,
    /// The LLM's endpoint name.
    pub llm: String,
    /// The planner-limit suffix (`k8`, `exact`, `exact12`), `llm+model` only.
    pub limit: Option<String>,
}

impl LlmSpec {
    /// Reads `llm+model/<prompt>/<llm>[/<limit>]` or `llm-direct/<prompt>/<llm>`; `None` for
    /// other kinds. The prompt may be a path with slashes: the LLM is the last part (before an
    /// optional limit), the prompt everything between.
    pub fn parse(spec: &StrategySpec) -> Option<std::result::Result<Self, PlanError>> {
        if spec.kind != LLM_MODEL && spec.kind != LLM_DIRECT {
            return None;
        }
        let bad = |reason: String| PlanError::UnknownStrategy {
            spec: spec.raw.clone(),
            reason,
        };
        let mut args = spec.args.clone();
        let limit = if spec.kind == LLM_MODEL
            && args.len() >= 3
            && args.last().is_some_and(|a| parse_limit(a, 1).is_some())
        {
            args.pop()
        } else {
            None
        };
        if args.len() < 2 {
            return Some(Err(bad(format!("expected {}/<prompt>/<llm>", spec.kind))));
        }
        let llm = args.pop().unwrap_or_default();
        Some(Ok(Self {
            kind: spec.kind.clone(),
            prompt: args.join("/"),
            llm,
            limit,
        }))
    }
}

fn likelihood_error(source: &str, e: LlmError) -> PlanError {
    PlanError::Likelihood {
        source_name: source.to_string(),
        error: Box::new(e),
    }
}

/// (house name, house index, container count, target).
type MemoKey = (String, usize, usize, ObjectType);

/// A question to prefetch, and the source that asks it.
struct Job {
    source: Arc<LlmLikelihood>,
    question: Question,
    query: ProbabilityQuery,
}

/// A probability question answered, re-asks included.
#[derive(Clone, Debug, PartialEq)]
pub struct Resolved {
    /// The first question's cache key (what the ledger counts distinct prompts by).
    pub key: String,
    /// Tokens of every exchange.
    pub usage: TokenUsage,
    /// USD of every exchange.
    pub cost_usd: f64,
    /// The first answer's class.
    pub class: AnswerClass,
    /// True when the first answer was unusable and the question was asked again.
    pub reasked: bool,
    /// The probability, `None` when every answer was unusable.
    pub value: Option<f64>,
    /// Where the value came from.
    pub logprobs: LogprobUse,
}

/// `P_S` from an LLM: one question per (target, container type, room type) of a house, asked
/// with a probability prompt; answers read as DESIGN.md says (unreadable ones fall back to 0.01
/// and are counted).
pub struct LlmLikelihood {
    service: Arc<LlmService>,
    llm: Arc<Llm>,
    prompt: String,
    /// `<prompt>/<llm>`.
    name: String,
    /// The strategy the answers are counted under.
    strategy: String,
    /// Results per (house name, house index, container count, target): trials and replays on
    /// the same house reuse them without rendering or looking anything up again.
    memo: Mutex<HashMap<MemoKey, Vec<Probability>>>,
    /// The prompt's worked example, read from its template once.
    example: Option<WorkedExample>,
}

impl std::fmt::Debug for LlmLikelihood {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LlmLikelihood")
            .field("name", &self.name)
            .field("strategy", &self.strategy)
            .finish()
    }
}

impl LlmLikelihood {
    /// A source asking `llm` with `prompt` (a template name or path), counting under `strategy`.
    pub fn new(service: Arc<LlmService>, prompt: &str, llm: &str, strategy: &str) -> Result<Self> {
        let prompt = service.resolve_prompt(prompt)?;
        let llm = service.llm(llm)?;
        let example = service.prompts().example(&prompt);
        Ok(Self {
            name: format!("{prompt}/{}", llm.name()),
            service,
            llm,
            prompt,
            strategy: strategy.to_string(),
            memo: Mutex::new(HashMap::new()),
            example,
        })
    }

    /// The LLM asked.
    pub fn llm(&self) -> &Arc<Llm> {
        &self.llm
    }

    /// The prompt template's name.
    pub fn prompt(&self) -> &str {
        &self.prompt
    }

    /// The questions for `target` in `house`, each as the messages that would be sent.
    pub fn messages(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<(QueryPlan, Vec<Vec<ChatMessage>>)> {
        let (plan, questions) = self.questions(house, target)?;
        Ok((plan, questions.into_iter().map(|q| q.messages).collect()))
    }

    /// The questions for `target` in `house`.
    pub fn questions(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<(QueryPlan, Vec<Question>)> {
        let ctx = HouseContext::new(house);
        let plan = QueryPlan::with_context(house, &ctx, target);
        let prompts = self.service.prompts();
        let questions = plan
            .queries
            .iter()
            .map(|q| {
                let messages = prompts.probability_messages(&self.prompt, &ctx, q)?;
                Ok(Question::probability(
                    messages,
                    format!("house {} (#{}): {}", house.name, house.index, q.describe()),
                ))
            })
            .collect::<Result<Vec<_>>>()?;
        Ok((plan, questions))
    }

    /// The prompt's worked example, unless the question is about the example's own object (then
    /// the example's value may well be the answer).
    fn example_for(&self, query: &ProbabilityQuery) -> Option<WorkedExample> {
        let example = self.example.clone()?;
        let asked = format!(
            "{} {}",
            query.target.words().to_lowercase(),
            query.container.words().to_lowercase()
        );
        (!example.words.iter().any(|w| contains_phrase(&asked, w))).then_some(example)
    }

    /// Reads one answer: its class, the probability (from the text, or from the tokens'
    /// log-probabilities when the endpoint says so), and where it came from.
    fn read(
        &self,
        answer: &Answer,
        example: Option<&WorkedExample>,
    ) -> (AnswerClass, Option<f64>, LogprobUse) {
        let r = read_probability(&answer.text, example);
        let Some(p) = r.probability else {
            return (r.class, None, LogprobUse::NotWanted);
        };
        if self.llm.endpoint().config.probability_from == ProbabilityFrom::Text {
            return (r.class, Some(p), LogprobUse::NotWanted);
        }
        let expected = match (&answer.logprobs, r.number) {
            (Some(tokens), Some(number)) => expected_percentage(tokens, &answer.text, number).ok(),
            _ => None,
        };
        match expected {
            Some(e) => (
                r.class,
                Some((e / 100.0).clamp(FALLBACK_PROBABILITY, 1.0)),
                LogprobUse::Used,
            ),
            None => (r.class, Some(p), LogprobUse::Missing),
        }
    }

    /// Asks `question` (about `query`), and asks again with a format reminder while the answer
    /// is unusable, up to the endpoint's `max_reasks`. Every exchange goes through the cache.
    /// Nothing is counted as used here (see [`Self::record`]).
    pub async fn resolve(&self, question: &Question, query: &ProbabilityQuery) -> Result<Resolved> {
        let example = self.example_for(query);
        let first = self.llm.ask(question, &self.strategy).await?;
        let (class, mut value, mut logprobs) = self.read(&first, example.as_ref());
        let mut resolved = Resolved {
            key: first.key.clone(),
            usage: first.usage,
            cost_usd: first.cost_usd,
            class,
            reasked: false,
            value,
            logprobs,
        };
        let mut asked = question.clone();
        let mut answer = first;
        for _ in 0..self.llm.endpoint().config.max_reasks {
            if value.is_some() {
                break;
            }
            tracing::debug!(source = %self.name, answer = %answer.text, "unusable probability answer; asking again");
            resolved.reasked = true;
            asked = asked.reask(&answer.text, PROBABILITY_REMINDER);
            answer = self.llm.ask(&asked, &self.strategy).await?;
            resolved.usage.prompt_tokens += answer.usage.prompt_tokens;
            resolved.usage.completion_tokens += answer.usage.completion_tokens;
            resolved.cost_usd += answer.cost_usd;
            (_, value, logprobs) = self.read(&answer, example.as_ref());
        }
        resolved.value = value;
        resolved.logprobs = logprobs;
        Ok(resolved)
    }

    /// Counts a resolved question as used (once per distinct prompt) and returns its probability.
    fn record(&self, r: &Resolved) -> Probability {
        if r.value.is_none() {
            tracing::debug!(source = %self.name, "unreadable probability; using {FALLBACK_PROBABILITY}");
        }
        self.llm.ledger().record_answer(
            self.llm.name(),
            &self.strategy,
            &r.key,
            &r.usage,
            r.cost_usd,
            AnswerOutcome::Probability {
                class: r.class,
                reasked: r.reasked,
                value: r.value,
                logprobs: r.logprobs,
            },
        );
        Probability::clamped(
            r.value.unwrap_or(FALLBACK_PROBABILITY),
            FALLBACK_PROBABILITY,
            1.0,
        )
    }

    /// The probabilities, asking every question of the house concurrently.
    pub async fn likelihoods_async(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>> {
        let (plan, questions) = self.questions(house, target)?;
        let answers = join_all(
            questions
                .iter()
                .zip(&plan.queries)
                .map(|(q, query)| self.resolve(q, query)),
        )
        .await;
        let per_query = answers
            .into_iter()
            .map(|a| a.map(|r| self.record(&r)))
            .collect::<Result<Vec<_>>>()?;
        Ok(plan.of_container.iter().map(|&q| per_query[q]).collect())
    }
}

impl LikelihoodSource for LlmLikelihood {
    fn name(&self) -> &str {
        &self.name
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> std::result::Result<Vec<Probability>, PlanError> {
        let key = (
            house.name.clone(),
            house.index,
            house.containers.len(),
            target.clone(),
        );
        if let Some(p) = self
            .memo
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .get(&key)
        {
            return Ok(p.clone());
        }
        let p = self
            .service
            .block_on(self.likelihoods_async(house, target))
            .map_err(|e| likelihood_error(&self.name, e))?;
        self.memo
            .lock()
            .unwrap_or_else(|p| p.into_inner())
            .insert(key, p.clone());
        Ok(p)
    }
}

/// `llm-direct/<prompt>/<llm>`: asks the LLM where to search next at every decision.
pub struct LlmDirectStrategy {
    name: String,
    service: Arc<LlmService>,
    llm: Arc<Llm>,
    prompt: String,
}

impl std::fmt::Debug for LlmDirectStrategy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("LlmDirectStrategy")
            .field("name", &self.name)
            .finish()
    }
}

impl LlmDirectStrategy {
    /// The strategy `name` asking `llm` with `prompt`.
    pub fn new(service: Arc<LlmService>, name: &str, prompt: &str, llm: &str) -> Result<Self> {
        let prompt = service.resolve_prompt(prompt)?;
        let llm = service.llm(llm)?;
        Ok(Self {
            name: name.to_string(),
            service,
            llm,
            prompt,
        })
    }
}

impl Strategy for LlmDirectStrategy {
    fn name(&self) -> &str {
        &self.name
    }

    fn policy<'a>(
        &'a self,
        ctx: &TrialContext<'a>,
    ) -> std::result::Result<Box<dyn Policy + 'a>, PlanError> {
        Ok(Box::new(LlmDirectPolicy {
            strategy: self,
            house: HouseContext::new(ctx.house),
        }))
    }
}

/// The policy of one llm-direct trial.
pub struct LlmDirectPolicy<'a> {
    strategy: &'a LlmDirectStrategy,
    house: HouseContext,
}

impl LlmDirectPolicy<'_> {
    /// The messages asking where to search from `belief`, and the container of each option.
    pub fn messages(
        &self,
        belief: &Belief<'_>,
    ) -> Result<(Vec<ChatMessage>, Vec<String>, Vec<usize>)> {
        let unsearched: Vec<usize> = belief.unsearched().collect();
        let (ctx, order) = DirectContext::new(
            belief.house,
            &self.house,
            belief.distances,
            belief.target,
            belief.position(),
            &unsearched,
        )?;
        let messages = self
            .strategy
            .service
            .prompts()
            .direct_messages(&self.strategy.prompt, &ctx)?;
        Ok((
            messages,
            ctx.options.into_iter().map(|o| o.label).collect(),
            order,
        ))
    }
}

impl Policy for LlmDirectPolicy<'_> {
    fn choose(&mut self, belief: &Belief<'_>) -> std::result::Result<usize, PlanError> {
        let s = self.strategy;
        let fail = |e: LlmError| PlanError::Policy {
            policy: s.name.clone(),
            error: Box::new(e),
        };
        if belief.unsearched_count() == 1
            && let Some(last) = belief.unsearched().next()
        {
            // One container left: there is nothing to choose, so nothing is asked.
            return Ok(last);
        }
        self.ask(belief).map_err(fail)
    }
}

impl LlmDirectPolicy<'_> {
    fn ask(&self, belief: &Belief<'_>) -> Result<usize> {
        let s = self.strategy;
        let (messages, labels, order) = self.messages(belief)?;
        if order.is_empty() {
            return Err(LlmError::Context(format!(
                "{}: nothing left to search",
                belief.house.name
            )));
        }
        let mut question = Question {
            messages,
            expect: Expect::Location(labels.clone()),
            about: format!(
                "house {} (#{}): where to look for {} next",
                belief.house.name,
                belief.house.index,
                belief.target.words()
            ),
        };
        let mut answer = s.service.block_on(s.llm.ask(&question, &s.name))?;
        let first_key = answer.key.clone();
        let mut matched = match_location(&answer.text, &labels);
        for _ in 0..s.llm.endpoint().config.max_reasks {
            if matched.is_some() {
                break;
            }
            question = question.reask(&answer.text, LOCATION_REMINDER);
            answer = s.service.block_on(s.llm.ask(&question, &s.name))?;
            matched = match_location(&answer.text, &labels);
        }
        let (choice, kind) = match matched {
            Some((i, kind)) => (order[i], kind),
            None => {
                let c = nearest(belief, order.iter().copied()).unwrap_or(order[0]);
                tracing::debug!(strategy = %s.name, answer = %answer.text, "no location matches; taking the nearest");
                (c, MatchKind::Fallback)
            }
        };
        s.llm.ledger().record_answer(
            s.llm.name(),
            &s.name,
            &first_key,
            &answer.usage,
            answer.cost_usd,
            AnswerOutcome::Direct(kind),
        );
        Ok(choice)
    }
}

/// Registers `llm+model` and `llm-direct` in `registry`. `planner` and `exact_max` are the
/// planner settings for `llm+model` specs without a limit suffix and for `/exact`.
pub fn register_strategies(
    registry: &mut StrategyRegistry,
    service: Arc<LlmService>,
    planner: PlannerConfig,
    exact_max: usize,
) {
    let s = service.clone();
    registry.register(
        LLM_MODEL,
        "llm+model/<prompt>/<llm>[/k<N>|/exact]",
        move |spec| {
            let parsed = LlmSpec::parse(spec).unwrap_or_else(|| Err(not_llm(spec)))?;
            let source = LlmLikelihood::new(s.clone(), &parsed.prompt, &parsed.llm, &spec.raw)
                .map_err(|e| build_error(spec, e, false))?;
            let config = match &parsed.limit {
                None => planner,
                Some(l) => match parse_limit(l, exact_max) {
                    Some(limit) => PlannerConfig { limit, ..planner },
                    None => {
                        return Err(PlanError::UnknownStrategy {
                            spec: spec.raw.clone(),
                            reason: format!("bad limit `{l}`"),
                        });
                    }
                },
            };
            Ok(Arc::new(ModelStrategy::new(
                &spec.raw,
                Arc::new(source),
                config,
            )))
        },
    );
    registry.register(LLM_DIRECT, "llm-direct/p-direct/<llm>", move |spec| {
        let parsed = LlmSpec::parse(spec).unwrap_or_else(|| Err(not_llm(spec)))?;
        let strategy =
            LlmDirectStrategy::new(service.clone(), &spec.raw, &parsed.prompt, &parsed.llm)
                .map_err(|e| build_error(spec, e, true))?;
        Ok(Arc::new(strategy))
    });
}

/// Why an LLM strategy could not be built. Only a spec naming no known endpoint or prompt is an
/// unknown strategy; a cache or configuration failure is reported as what it is, as a failure of
/// the likelihood source or, for `llm-direct`, of the policy.
fn build_error(spec: &StrategySpec, e: LlmError, direct: bool) -> PlanError {
    match e {
        LlmError::Config(crate::error::ConfigError::UnknownEndpoint { .. })
        | LlmError::Prompt { .. } => PlanError::UnknownStrategy {
            spec: spec.raw.clone(),
            reason: e.to_string(),
        },
        other if direct => PlanError::Policy {
            policy: spec.raw.clone(),
            error: Box::new(other),
        },
        other => PlanError::Likelihood {
            source_name: spec.raw.clone(),
            error: Box::new(other),
        },
    }
}

fn not_llm(spec: &StrategySpec) -> PlanError {
    PlanError::UnknownStrategy {
        spec: spec.raw.clone(),
        reason: "not an LLM strategy".into(),
    }
}

/// What [`prefetch_probabilities`] did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct PrefetchSummary {
    /// Questions over all strategies and trials (a question shared by trials counted once per
    /// strategy and house).
    pub questions: usize,
    /// Distinct prompts among them, per LLM (what could have been sent).
    pub distinct: usize,
    /// Of those, already in the cache.
    pub cached: usize,
    /// Asked now and answered.
    pub asked: usize,
    /// Failures, one line each (the first per LLM stops that LLM's remaining questions, which are
    /// counted in `skipped`; offline misses do not).
    pub failures: Vec<String>,
    /// Questions not asked after an LLM failed.
    pub skipped: usize,
}

/// Reports prefetch progress: called with (questions finished, questions in all) as answers
/// arrive. The library prints nothing; the CLI draws a progress bar from this.
pub type PrefetchProgress<'a> = &'a (dyn Fn(usize, usize) + Send + Sync);

/// Asks every probability question the `llm+model` strategies among `specs` will ask on `trials`
/// (house, target), concurrently (each endpoint within its concurrency limit), re-asking unusable
/// answers as the trials would, so that the trials then find every answer in the cache. Other
/// specs are ignored. In offline mode nothing is sent; missing answers are listed in `failures`.
///
/// Answers are not counted as used here (the trials count what they use); requests sent are.
pub fn prefetch_probabilities(
    service: &Arc<LlmService>,
    specs: &[String],
    trials: &[(&House, &ObjectType)],
    progress: PrefetchProgress<'_>,
) -> Result<PrefetchSummary> {
    // Distinct requests (the cache key says everything that decides an answer, so endpoints that
    // send the same request share it), in the order the trials would ask them: house by house,
    // so that consecutive requests share the long prefix a house's context prompts have in
    // common, which servers with prefix caching (llama.cpp, vLLM, OpenAI) then skip.
    let mut work: Vec<Job> = Vec::new();
    let mut seen_keys: HashSet<String> = HashSet::new();
    let mut summary = PrefetchSummary::default();
    let mut seen_sources = HashSet::new();
    let mut sources = Vec::new();
    for raw in specs {
        let Ok(spec) = StrategySpec::parse(raw) else {
            continue;
        };
        if spec.kind != LLM_MODEL {
            continue;
        }
        let parsed = match LlmSpec::parse(&spec) {
            Some(Ok(p)) => p,
            _ => continue,
        };
        if !seen_sources.insert((parsed.prompt.clone(), parsed.llm.clone())) {
            continue;
        }
        sources.push(Arc::new(LlmLikelihood::new(
            service.clone(),
            &parsed.prompt,
            &parsed.llm,
            raw,
        )?));
    }
    for source in &sources {
        for (house, target) in trials {
            let (plan, questions) = source.questions(house, target)?;
            for (question, query) in questions.into_iter().zip(plan.queries) {
                summary.questions += 1;
                if seen_keys.insert(source.llm.key(&question)) {
                    work.push(Job {
                        source: source.clone(),
                        question,
                        query,
                    });
                }
            }
        }
    }
    summary.distinct = work.len();
    // One queue per server: endpoints naming the same server (or cache id) share a queue, so
    // their requests do not interleave and spoil each other's prefix cache.
    let mut per_server: Vec<(String, Vec<Job>)> = Vec::new();
    for job in work {
        if job.source.llm.is_cached(&job.question)? {
            summary.cached += 1;
        }
        let config = &job.source.llm.endpoint().config;
        let server = config
            .cache_id
            .clone()
            .unwrap_or_else(|| config.normalized_base_url());
        match per_server.iter_mut().find(|(s, _)| *s == server) {
            Some((_, jobs)) => jobs.push(job),
            None => per_server.push((server, vec![job])),
        }
    }
    let total = summary.distinct;
    let done = std::sync::atomic::AtomicUsize::new(0);
    let done = &done;
    progress(0, total);
    let results = service.block_on(join_all(per_server.into_iter().map(
        |(_, jobs)| async move {
            // Questions enter at the endpoint's concurrency, so that a failure can stop the rest: a
            // failed request has already been retried up to max_attempts, and the remaining ones would
            // most likely fail the same way, slowly.
            let width = jobs
                .first()
                .map_or(1, |j| j.source.llm.endpoint().config.concurrency.max(1));
            let stop = AtomicBool::new(false);
            let stop = &stop;
            stream::iter(jobs.iter())
                .map(|job| async move {
                    if stop.load(Ordering::Relaxed) {
                        return None;
                    }
                    let r = job.source.resolve(&job.question, &job.query).await;
                    if let Err(e) = &r
                        && !matches!(e, LlmError::NotCached { .. })
                    {
                        stop.store(true, Ordering::Relaxed);
                    }
                    progress(done.fetch_add(1, Ordering::Relaxed) + 1, total);
                    Some(r)
                })
                .buffer_unordered(width)
                .collect::<Vec<_>>()
                .await
        },
    )));
    for outcome in results.into_iter().flatten() {
        match outcome {
            None => summary.skipped += 1,
            Some(Ok(_)) => summary.asked += 1,
            Some(Err(e)) => summary.failures.push(e.to_string()),
        }
    }
    summary.asked = summary.asked.saturating_sub(summary.cached);
    if !summary.failures.is_empty() {
        tracing::warn!(
            failed = summary.failures.len(),
            skipped = summary.skipped,
            "prefetching LLM answers failed in part"
        );
    }
    Ok(summary)
}
