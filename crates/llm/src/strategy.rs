//! LLMs in the plan crate's terms: the planner over an LLM's likelihoods
//! (`llm+model/<prompt>/<llm>[/k<N>|/exact]`, see [`LlmLikelihood`]), the same fused with the
//! prior (`fused/<prompt>/<llm>`, see [`ferret_plan::Fused`]; `fused/noise` is its control) or
//! with the learned likelihood (`fused-learned/<prompt>/<llm>`), a policy ([`LlmDirectPolicy`],
//! behind `llm-direct/<prompt>/<llm>`), their registration in a [`StrategyRegistry`], and
//! [`prefetch_probabilities`], which asks every probability question of a set of trials
//! concurrently before the trials run so that they find every answer in the cache.
//!
//! The plan crate's traits are synchronous (trials run on rayon threads); these types reach the
//! async client through the [`LlmService`]'s runtime with `block_on`.

use std::collections::HashSet;
use std::sync::Arc;

use ferret_plan::policy::nearest;
use ferret_plan::strategy::{CONTROL_SOURCES, builtin_source, parse_limit, planner_config_from};
use ferret_plan::{
    Belief, Fused, FusionBase, FusionFile, LikelihoodSource, ModelStrategy, PlanError,
    PlannerConfig, Policy, Prior, Strategy, StrategyRegistry, StrategySpec, TrialContext,
    prior_fingerprint,
};
use ferret_world::{House, ObjectType};
use futures::future::join_all;
use futures::stream::{self, StreamExt};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::answer::{MatchKind, match_location};
use crate::context::{DirectContext, HouseContext};
use crate::error::{LlmError, Result};
use crate::ledger::{AnswerOutcome, Spent};
use crate::likelihood::{Asked, LlmLikelihood};
use crate::message::ChatMessage;
use crate::question::{Expect, LOCATION_REMINDER, Question};
use crate::service::{Llm, LlmService};

/// The strategy kind of the LLM-informed planner.
pub const LLM_MODEL: &str = "llm+model";
/// The strategy kind of the LLM-direct baseline.
pub const LLM_DIRECT: &str = "llm-direct";
/// The strategy kind of the planner over the prior fused with an LLM's likelihoods.
pub const FUSED: &str = FusionBase::Prior.kind();
/// The strategy kind of the planner over the learned likelihood (`model/learned`) fused with an
/// LLM's likelihoods.
pub const FUSED_LEARNED: &str = FusionBase::Learned.kind();

/// True for the kinds that plan over an LLM's likelihoods (`llm+model`, `fused`,
/// `fused-learned`): the ones whose probability questions are asked before trials run.
pub fn asks_probabilities(kind: &str) -> bool {
    kind == LLM_MODEL || fusion_base(kind).is_some()
}

/// What a fused kind fuses the LLM's likelihoods with: the prior (`fused`), the learned
/// likelihood (`fused-learned`); `None` for kinds that are not fused.
pub fn fusion_base(kind: &str) -> Option<FusionBase> {
    [FusionBase::Prior, FusionBase::Learned]
        .into_iter()
        .find(|b| b.kind() == kind)
}

/// A parsed LLM strategy spec.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LlmSpec {
    /// `llm+model`, `fused` or `llm-direct`.
    pub kind: String,
    /// The prompt: a template name or a path to a template file (which may hold `/`).
    pub prompt: String,
    /// The LLM's endpoint name.
    pub llm: String,
    /// The planner-limit suffix (`k8`, `exact`, `exact12`), `llm+model` and `fused` only.
    pub limit: Option<String>,
}

impl LlmSpec {
    /// Reads `llm+model/<prompt>/<llm>[/<limit>]`, `fused/<prompt>/<llm>[/<limit>]` or
    /// `llm-direct/<prompt>/<llm>`; `None` for other kinds. The prompt may be a path with
    /// slashes: the LLM is the last part (before an optional limit), the prompt everything
    /// between.
    pub fn parse(spec: &StrategySpec) -> Option<std::result::Result<Self, PlanError>> {
        if (!asks_probabilities(&spec.kind) && spec.kind != LLM_DIRECT)
            || control_source(spec).is_some()
        {
            return None;
        }
        let bad = |reason: String| PlanError::UnknownStrategy {
            spec: spec.raw.clone(),
            reason,
        };
        let mut args = spec.args.clone();
        let limit = if asks_probabilities(&spec.kind)
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
            house: HouseContext::new(ctx.problem.house),
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
            belief.sought(),
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
                belief.sought().words()
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
        s.llm.ledger().record_answers(
            s.llm.name(),
            &s.name,
            &first_key,
            Spent {
                usage: &answer.usage,
                cost_usd: answer.cost_usd,
                seconds: answer.latency.as_secs_f64(),
            },
            &[AnswerOutcome::Direct(kind)],
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
            let config = limit_config(spec, &parsed, planner, exact_max)?;
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

/// The planner settings of a spec with an optional limit suffix.
fn limit_config(
    spec: &StrategySpec,
    parsed: &LlmSpec,
    planner: PlannerConfig,
    exact_max: usize,
) -> std::result::Result<PlannerConfig, PlanError> {
    match &parsed.limit {
        None => Ok(planner),
        Some(l) => match parse_limit(l, exact_max) {
            Some(limit) => Ok(PlannerConfig { limit, ..planner }),
            None => Err(PlanError::UnknownStrategy {
                spec: spec.raw.clone(),
                reason: format!("bad limit `{l}`"),
            }),
        },
    }
}

/// Registers `fused/<prompt>/<llm>[/<limit>]`: the planner over `prior` fused with the LLM's
/// likelihoods by the weights `fusion` holds for `<prompt>/<llm>` (see [`ferret_plan::fusion`]),
/// and `fused/<control>[/<limit>]`, the same with a control that knows nothing
/// ([`CONTROL_SOURCES`]: `noise`, `uniform`) in the LLM's place, fitted the same way. Registers
/// `fused-learned/...` alike, fused with the learned likelihood (`model/learned`) instead of the
/// prior, by the fits whose base is the learned one. Without a fusion file, or without a fit for
/// the source, or with a fit made against another prior, building the strategy fails and says
/// which.
pub fn register_fused(
    registry: &mut StrategyRegistry,
    service: Arc<LlmService>,
    prior: Option<Arc<Prior>>,
    fusion: Option<(String, Arc<FusionFile>)>,
    planner: PlannerConfig,
    exact_max: usize,
) {
    let fingerprint = prior.as_deref().map(prior_fingerprint);
    for base in [FusionBase::Prior, FusionBase::Learned] {
        let (service, prior, fusion, fingerprint) = (
            service.clone(),
            prior.clone(),
            fusion.clone(),
            fingerprint.clone(),
        );
        let kind = base.kind();
        registry.register(
            kind,
            &format!(
                "{kind}/<prompt>/<llm>[/k<N>|/exact], {kind}/<noise|uniform>[/k<N>|/exact]"
            ),
            move |spec| {
                let bad = |reason: String| PlanError::UnknownStrategy {
                    spec: spec.raw.clone(),
                    reason,
                };
                let (source, config): (Arc<dyn LikelihoodSource>, PlannerConfig) =
                    match control_source(spec) {
                        Some(name) => (
                            builtin_source(name, None).map_err(bad)?,
                            planner_config_from(spec, 1, planner, exact_max)?,
                        ),
                        None => {
                            let parsed =
                                LlmSpec::parse(spec).unwrap_or_else(|| Err(not_llm(spec)))?;
                            let source = LlmLikelihood::new(
                                service.clone(),
                                &parsed.prompt,
                                &parsed.llm,
                                &spec.raw,
                            )
                            .map_err(|e| build_error(spec, e, false))?;
                            (
                                Arc::new(source),
                                limit_config(spec, &parsed, planner, exact_max)?,
                            )
                        }
                    };
                let (Some(prior), Some(fingerprint)) = (&prior, &fingerprint) else {
                    return Err(bad("fused sources need the prior (pass --prior)".into()));
                };
                let Some((path, file)) = &fusion else {
                    return Err(bad(
                        "no fusion weights: fit them with `ferret calibrate --fit-fusion FILE` on training houses and pass --fusion FILE".into(),
                    ));
                };
                let name = source.name().to_string();
                let fit = file.fit(base, &name).ok_or_else(|| {
                    let have: Vec<String> = file
                        .fits
                        .iter()
                        .map(|f| format!("{}/{}", f.base.kind(), f.source))
                        .collect();
                    let hint = match base {
                        FusionBase::Prior => "",
                        FusionBase::Learned => {
                            "; `calibrate --fit-fusion` fits the learned base when the prior has a learned part (`ferret prior train --embeddings DIR`)"
                        }
                    };
                    bad(format!(
                        "{path} holds no fit for {kind}/{name} (it has: {}){hint}",
                        have.join(", ")
                    ))
                })?;
                if fit.prior != *fingerprint {
                    return Err(bad(format!(
                        "{path}: the fit for {kind}/{name} was made with another prior; fit it again with this one"
                    )));
                }
                let base_source = builtin_source(base.source_name(), Some(prior)).map_err(bad)?;
                let fused = Fused::over(
                    &format!("{kind}/{name}"),
                    base_source,
                    prior.clone(),
                    source,
                    fit.weights,
                );
                Ok(Arc::new(ModelStrategy::new(
                    &spec.raw,
                    Arc::new(fused),
                    config,
                )))
            },
        );
    }
}

/// The control a `fused/...` spec fuses with the prior instead of an LLM (`fused/noise`), if it
/// names one.
pub fn control_source(spec: &StrategySpec) -> Option<&'static str> {
    fusion_base(&spec.kind)?;
    let first = spec.args.first()?;
    CONTROL_SOURCES.iter().copied().find(|c| c == first)
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

/// A question to prefetch, and the source that asks it.
struct Job {
    source: Arc<LlmLikelihood>,
    question: Question,
    asked: Asked,
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

/// The questions a run has prefetched so far, for a run that prefetches a batch of houses at a
/// time: a question met in an earlier batch (P-YESNO's, one per target, container type and room
/// type, recur in every house) is neither counted as distinct again nor looked up again. Keeps
/// 32 bytes per distinct question (a digest of its cache key).
#[derive(Debug, Default)]
pub struct Prefetched {
    keys: HashSet<[u8; 32]>,
}

impl Prefetched {
    /// Distinct questions met so far.
    pub fn len(&self) -> usize {
        self.keys.len()
    }

    /// True before any question.
    pub fn is_empty(&self) -> bool {
        self.keys.is_empty()
    }

    /// Records `key`; false when it was met before.
    fn insert(&mut self, key: &str) -> bool {
        use sha2::{Digest, Sha256};
        self.keys.insert(Sha256::digest(key.as_bytes()).into())
    }
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
    prefetch_probabilities_after(service, specs, trials, &mut Prefetched::default(), progress)
}

/// [`prefetch_probabilities`] for one batch of a run's trials: questions in `before` (met in
/// earlier batches) are skipped, and this batch's are added to it, so that the batches'
/// summaries add up to one run's.
pub fn prefetch_probabilities_after(
    service: &Arc<LlmService>,
    specs: &[String],
    trials: &[(&House, &ObjectType)],
    before: &mut Prefetched,
    progress: PrefetchProgress<'_>,
) -> Result<PrefetchSummary> {
    // Distinct requests (the cache key says everything that decides an answer, so endpoints that
    // send the same request share it), in the order the trials would ask them: house by house,
    // so that consecutive requests share the long prefix a house's context prompts have in
    // common, which servers with prefix caching (llama.cpp, vLLM, OpenAI) then skip.
    let mut work: Vec<Job> = Vec::new();
    let mut summary = PrefetchSummary::default();
    let mut seen_sources = HashSet::new();
    let mut sources = Vec::new();
    for raw in specs {
        let Ok(spec) = StrategySpec::parse(raw) else {
            continue;
        };
        if !asks_probabilities(&spec.kind) {
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
        let mut i = 0;
        while i < trials.len() {
            // The trials of one house together; within them, listing questions in the same
            // order of places one after another, so consecutive requests share the listing.
            let same_house = |t: &(&House, &ObjectType)| {
                t.0.name == trials[i].0.name && t.0.index == trials[i].0.index
            };
            let end = i + trials[i..].iter().take_while(|t| same_house(t)).count();
            let mut jobs: Vec<Job> = Vec::new();
            for (house, target) in &trials[i..end] {
                for (question, asked) in source.questions(house, target)?.questions {
                    summary.questions += 1;
                    if before.insert(&source.llm().key(&question)) {
                        jobs.push(Job {
                            source: source.clone(),
                            question,
                            asked,
                        });
                    }
                }
            }
            jobs.sort_by_key(|j| j.asked.places().and_then(|p| p.first().copied()));
            work.extend(jobs);
            i = end;
        }
    }
    summary.distinct = work.len();
    // One queue per server: endpoints naming the same server (or cache id) share a queue, so
    // their requests do not interleave and spoil each other's prefix cache.
    let mut per_server: Vec<(String, Vec<Job>)> = Vec::new();
    for job in work {
        if job.source.llm().is_cached(&job.question)? {
            summary.cached += 1;
        }
        let config = &job.source.llm().endpoint().config;
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
                .map_or(1, |j| j.source.llm().endpoint().config.concurrency.max(1));
            let stop = AtomicBool::new(false);
            let stop = &stop;
            stream::iter(jobs.iter())
                .map(|job| async move {
                    if stop.load(Ordering::Relaxed) {
                        return None;
                    }
                    let r = job.source.resolve(&job.question, &job.asked).await;
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
