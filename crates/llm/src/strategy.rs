//! LLMs in the plan crate's terms: a likelihood source ([`LlmLikelihood`], behind the strategy
//! `llm+model/<prompt>/<llm>[/k<N>|/exact]`), a policy ([`LlmDirectPolicy`], behind
//! `llm-direct/<prompt>/<llm>`), their registration in a [`StrategyRegistry`], and
//! [`prefetch_probabilities`], which asks every probability question of a set of trials
//! concurrently before the trials run so that they find every answer in the cache.
//!
//! The plan crate's traits are synchronous (trials run on rayon threads); these types reach the
//! async client through the [`LlmService`]'s runtime with `block_on`.

use std::collections::{BTreeMap, HashMap, HashSet};
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

use crate::answer::{FALLBACK_PROBABILITY, MatchKind, match_location, parse_probability};
use crate::context::{DirectContext, HouseContext, QueryPlan};
use crate::error::{LlmError, Result};
use crate::ledger::AnswerOutcome;
use crate::message::ChatMessage;
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

/// A question to prefetch: who asks, what, on behalf of which strategy.
struct Job {
    llm: Arc<Llm>,
    messages: Vec<ChatMessage>,
    strategy: String,
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
        Ok(Self {
            name: format!("{prompt}/{}", llm.name()),
            service,
            llm,
            prompt,
            strategy: strategy.to_string(),
            memo: Mutex::new(HashMap::new()),
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
        let plan = QueryPlan::new(house, target);
        let ctx = HouseContext::new(house);
        let prompts = self.service.prompts();
        let messages = plan
            .queries
            .iter()
            .map(|q| prompts.probability_messages(&self.prompt, &ctx, q))
            .collect::<Result<Vec<_>>>()?;
        Ok((plan, messages))
    }

    /// Reads one answer, counting it.
    fn read(&self, answer: &Answer) -> Probability {
        let parsed = parse_probability(&answer.text);
        if parsed.is_none() {
            tracing::debug!(source = %self.name, answer = %answer.text, "unreadable probability; using {FALLBACK_PROBABILITY}");
        }
        self.llm.ledger().record_answer(
            self.llm.name(),
            &self.strategy,
            &answer.key,
            &answer.usage,
            answer.cost_usd,
            AnswerOutcome::Probability {
                parsed: parsed.is_some(),
            },
        );
        Probability::clamped(
            parsed.unwrap_or(FALLBACK_PROBABILITY),
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
        let (plan, messages) = self.messages(house, target)?;
        let answers = join_all(messages.iter().map(|m| self.llm.ask(m, &self.strategy))).await;
        let per_query = answers
            .into_iter()
            .map(|a| a.map(|a| self.read(&a)))
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
        let answer = s.service.block_on(s.llm.ask(&messages, &s.name))?;
        let (choice, kind) = match match_location(&answer.text, &labels) {
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
            &answer.key,
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

/// Asks every probability question the `llm+model` strategies among `specs` will ask on `trials`
/// (house, target), concurrently (each endpoint within its concurrency limit), so that the trials
/// then find every answer in the cache. Other specs are ignored. In offline mode nothing is sent;
/// missing answers are listed in `failures`.
///
/// Answers are not counted as used here (the trials count what they use); requests sent are.
pub fn prefetch_probabilities(
    service: &Arc<LlmService>,
    specs: &[String],
    trials: &[(&House, &ObjectType)],
) -> Result<PrefetchSummary> {
    // (LLM name, cache key) → (LLM, messages, strategy), first asker wins.
    let mut work: BTreeMap<(String, String), Job> = BTreeMap::new();
    let mut summary = PrefetchSummary::default();
    let mut seen_sources = HashSet::new();
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
        let source = LlmLikelihood::new(service.clone(), &parsed.prompt, &parsed.llm, raw)?;
        for (house, target) in trials {
            let (_, messages) = source.messages(house, target)?;
            for m in messages {
                summary.questions += 1;
                let key = source.llm.key(&m);
                work.entry((source.llm.name().to_string(), key))
                    .or_insert_with(|| Job {
                        llm: source.llm.clone(),
                        messages: m,
                        strategy: raw.clone(),
                    });
            }
        }
    }
    summary.distinct = work.len();
    let mut per_llm: BTreeMap<String, Vec<Job>> = BTreeMap::new();
    for ((llm, key), job) in work {
        let hit = match service.cache()? {
            Some(c) => c.get(&key)?.is_some(),
            None => false,
        };
        if hit {
            summary.cached += 1;
        } else {
            per_llm.entry(llm).or_default().push(job);
        }
    }
    let results = service.block_on(join_all(per_llm.into_values().map(|jobs| async move {
        // Questions enter at the endpoint's concurrency, so that a failure can stop the rest: a
        // failed request has already been retried up to max_attempts, and the remaining ones would
        // most likely fail the same way, slowly.
        let width = jobs
            .first()
            .map_or(1, |j| j.llm.endpoint().config.concurrency.max(1));
        let stop = AtomicBool::new(false);
        let stop = &stop;
        stream::iter(jobs.iter())
            .map(
                |Job {
                     llm,
                     messages: m,
                     strategy,
                 }| async move {
                    if stop.load(Ordering::Relaxed) {
                        return None;
                    }
                    let r = llm.ask(m, strategy).await;
                    if let Err(e) = &r
                        && !matches!(e, LlmError::NotCached { .. })
                    {
                        stop.store(true, Ordering::Relaxed);
                    }
                    Some(r)
                },
            )
            .buffer_unordered(width)
            .collect::<Vec<_>>()
            .await
    })));
    for outcome in results.into_iter().flatten() {
        match outcome {
            None => summary.skipped += 1,
            Some(Ok(_)) => summary.asked += 1,
            Some(Err(e)) => summary.failures.push(e.to_string()),
        }
    }
    if !summary.failures.is_empty() {
        tracing::warn!(
            failed = summary.failures.len(),
            skipped = summary.skipped,
            "prefetching LLM answers failed in part"
        );
    }
    Ok(summary)
}
