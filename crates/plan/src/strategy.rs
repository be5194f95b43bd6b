//! Strategies: named, fully specified policies, built from spec strings such as
//! `optimistic+greedy`, `model/prior`, `model/prior/exact` or `oracle`. Extension crates (the LLM
//! crate) register more spec kinds in a [`StrategyRegistry`].

use std::collections::BTreeMap;
use std::sync::Arc;

use ferret_world::GroundTruth;

use crate::belief::Belief;
use crate::error::PlanError;
use crate::learned::{LearnedKind, LearnedSource};
use crate::likelihood::{LikelihoodSource, Noise, Uniform};
use crate::policy::{
    CandidateLimit, CostModel, Greedy, Oracle, Planner, PlannerConfig, Policy, Sequential,
    oracle_route,
};
use crate::prior::{Prior, RawPrior};
use crate::probability::Probability;
use crate::problem::SearchProblem;

/// What a strategy needs to start a trial.
#[derive(Clone, Copy, Debug)]
pub struct TrialContext<'a> {
    /// The search problem.
    pub problem: SearchProblem<'a>,
    /// The ground truth, filled in only for strategies whose
    /// [`needs_ground_truth`](Strategy::needs_ground_truth) is true (the oracle).
    pub truth: Option<&'a GroundTruth>,
}

/// A named, fully specified policy (policy + likelihood source + prompt + LLM).
pub trait Strategy: Send + Sync {
    /// The spec string naming it, e.g. `model/prior`.
    fn name(&self) -> &str;

    /// True only for bounds such as the oracle, which may read the ground truth. Such strategies
    /// are never candidates for selection.
    fn needs_ground_truth(&self) -> bool {
        false
    }

    /// A fresh policy for one trial.
    fn policy<'a>(&'a self, ctx: &TrialContext<'a>) -> Result<Box<dyn Policy + 'a>, PlanError>;

    /// The likelihood source the strategy plans over, if it plans over one (what `ferret
    /// calibrate` scores).
    fn likelihood_source(&self) -> Option<&Arc<dyn LikelihoodSource>> {
        None
    }

    /// The planner settings, for a strategy that plans with the expected-cost planner (what
    /// `sequential/<spec>` runs target after target).
    fn planner_config(&self) -> Option<PlannerConfig> {
        None
    }

    /// How robots of a team running this strategy share the work (see [`run_team`]):
    /// coordinated unless the spec says otherwise (`independent/<spec>`, `split/<spec>`).
    ///
    /// [`run_team`]: crate::run_team
    fn teamwork(&self) -> Teamwork {
        Teamwork::Coordinated
    }
}

/// How the robots of a team share the work.
#[derive(
    Clone, Copy, Debug, Default, PartialEq, Eq, Hash, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "kebab-case")]
pub enum Teamwork {
    /// Each robot's next container is chosen knowing where the others are heading: as if
    /// those containers were searched in vain (this robot's plan matters only where they hold
    /// nothing), and never one of them. Sequential greedy assignment: robots choose in turn as
    /// they become free.
    #[default]
    Coordinated,
    /// Each robot runs the single-robot plan on what the team has seen, blind to where the
    /// others are heading: two may drive to the same container. The baseline to beat.
    Independent,
    /// The rooms are divided among the robots ([`split_rooms`](crate::split_rooms)); each plans its share, leaving
    /// the others' shares and claims alone, and once its share is done helps anywhere (as
    /// coordinated).
    SplitByRegion,
}

impl Teamwork {
    /// The spec prefix of the strategies that work this way (`independent/model/prior`);
    /// `None` for coordinated, the way a plain spec works.
    pub fn prefix(self) -> Option<&'static str> {
        match self {
            Teamwork::Coordinated => None,
            Teamwork::Independent => Some(INDEPENDENT),
            Teamwork::SplitByRegion => Some(SPLIT),
        }
    }
}

/// Spec kind of [`Teamwork::Independent`] strategies.
pub const INDEPENDENT: &str = "independent";
/// Spec kind of [`Teamwork::SplitByRegion`] strategies.
pub const SPLIT: &str = "split";

/// A parsed spec string: its kind (first `/`-separated part) and arguments.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StrategySpec {
    /// The spec as written.
    pub raw: String,
    /// The kind: `optimistic+greedy`, `model`, `oracle`, `llm+model`, `llm-direct`, ...
    pub kind: String,
    /// The remaining parts.
    pub args: Vec<String>,
}

impl StrategySpec {
    /// Splits a spec string at `/`.
    pub fn parse(spec: &str) -> Result<Self, PlanError> {
        let raw = spec.trim().to_string();
        let mut parts = raw.split('/').map(str::to_string);
        let kind = parts.next().unwrap_or_default();
        let args: Vec<String> = parts.collect();
        if kind.is_empty() || args.iter().any(String::is_empty) {
            return Err(PlanError::UnknownStrategy {
                spec: raw,
                reason: "empty part".into(),
            });
        }
        Ok(Self { raw, kind, args })
    }
}

/// Parses an optional planner-limit suffix: `exact`, `exact<N>` or `k<N>`.
pub fn parse_limit(arg: &str, default_exact_max: usize) -> Option<CandidateLimit> {
    if arg == "exact" {
        return Some(CandidateLimit::Exact {
            max: default_exact_max,
        });
    }
    if let Some(n) = arg.strip_prefix("exact") {
        return n
            .parse()
            .ok()
            .filter(|&m| m >= 1)
            .map(|max| CandidateLimit::Exact { max });
    }
    arg.strip_prefix('k')
        .and_then(|n| n.parse().ok())
        .filter(|&k| k >= 1)
        .map(|k| CandidateLimit::Paper { k })
}

type Builder = Box<dyn Fn(&StrategySpec) -> Result<Arc<dyn Strategy>, PlanError> + Send + Sync>;

/// Turns spec strings into strategies. Each kind is registered with a usage line for error
/// messages and `--help`.
#[derive(Default)]
pub struct StrategyRegistry {
    kinds: BTreeMap<String, (String, Builder)>,
}

impl StrategyRegistry {
    /// An empty registry.
    pub fn new() -> Self {
        Self::default()
    }

    /// Registers (or replaces) a kind.
    pub fn register(
        &mut self,
        kind: &str,
        usage: &str,
        build: impl Fn(&StrategySpec) -> Result<Arc<dyn Strategy>, PlanError> + Send + Sync + 'static,
    ) {
        self.kinds
            .insert(kind.to_string(), (usage.to_string(), Box::new(build)));
    }

    /// Usage lines of every registered kind, and of `sequential/<spec>`.
    pub fn usage(&self) -> Vec<String> {
        self.kinds
            .values()
            .map(|(u, _)| u.clone())
            .chain([format!("{SEQUENTIAL}/<model spec>")])
            .collect()
    }

    /// Builds the strategy a spec names. `sequential/<spec>` is the planner of `<spec>` run
    /// target after target (see [`Sequential`]), for any `<spec>` that plans over a likelihood
    /// source.
    pub fn build(&self, spec: &str) -> Result<Arc<dyn Strategy>, PlanError> {
        let parsed = StrategySpec::parse(spec)?;
        let teamwork = [Teamwork::Independent, Teamwork::SplitByRegion]
            .into_iter()
            .find(|t| t.prefix() == Some(parsed.kind.as_str()));
        if let Some(teamwork) = teamwork {
            let inner = self.build_wrapped(&parsed)?;
            return TeamStrategy::new(&parsed.raw, inner, teamwork).map(|s| Arc::new(s) as _);
        }
        if parsed.kind == SEQUENTIAL {
            let inner = self.build_wrapped(&parsed)?;
            return SequentialStrategy::new(&parsed.raw, inner).map(|s| Arc::new(s) as _);
        }
        match self.kinds.get(&parsed.kind) {
            Some((_, build)) => build(&parsed),
            None => Err(PlanError::UnknownStrategy {
                spec: parsed.raw,
                reason: format!("known forms: {}", self.usage().join(", ")),
            }),
        }
    }

    /// The strategy a wrapper spec (`sequential/<spec>`, `independent/<spec>`, ...) wraps; an
    /// unknown one is reported under the whole spec, as it was written.
    fn build_wrapped(&self, wrapper: &StrategySpec) -> Result<Arc<dyn Strategy>, PlanError> {
        self.build(&wrapper.args.join("/")).map_err(|e| match e {
            PlanError::UnknownStrategy { reason, .. } => PlanError::UnknownStrategy {
                spec: wrapper.raw.clone(),
                reason,
            },
            other => other,
        })
    }

    /// The registry of built-in strategies: `optimistic+greedy`, `model/<source>[/<limit>]` with
    /// sources `uniform` and (when a prior is given) `prior`, and `oracle`.
    pub fn builtin(prior: Option<Arc<Prior>>, planner: PlannerConfig, exact_max: usize) -> Self {
        let mut r = Self::new();
        r.register("optimistic+greedy", "optimistic+greedy", |spec| {
            no_args(spec)?;
            Ok(Arc::new(GreedyStrategy))
        });
        r.register("oracle", "oracle", |spec| {
            no_args(spec)?;
            Ok(Arc::new(OracleStrategy))
        });
        r.register(
            "model",
            "model/<prior|prior-raw|learned|learned-head|learned-random|learned-head-random|uniform|noise>[/k<N>|/exact][/authors]",
            move |spec| {
                let name = spec.args.first().map(String::as_str).unwrap_or("");
                let source = builtin_source(name, prior.as_ref()).map_err(|reason| {
                    PlanError::UnknownStrategy {
                        spec: spec.raw.clone(),
                        reason,
                    }
                })?;
                let config = planner_config_from(spec, 1, planner, exact_max)?;
                Ok(Arc::new(ModelStrategy::new(&spec.raw, source, config)))
            },
        );
        r
    }
}

/// The built-in sources that know nothing of where things are, which a fusion can take in an
/// LLM's place to show what the fit alone gives (`fused/noise`).
pub const CONTROL_SOURCES: [&str; 2] = ["noise", "uniform"];

/// The built-in likelihood source `name` names (`prior`, `prior-raw`, the learned sources of
/// [`LearnedKind`], `uniform`, `noise`): what
/// `model/<name>` plans over, and what `fused/<name>` fuses with the prior. The error says why
/// not.
pub fn builtin_source(
    name: &str,
    prior: Option<&Arc<Prior>>,
) -> Result<Arc<dyn LikelihoodSource>, String> {
    let prior = || {
        prior.cloned().ok_or_else(|| {
            "no prior loaded (train one with `ferret prior train` and pass --prior)".to_string()
        })
    };
    match name {
        "uniform" => Ok(Arc::new(Uniform::default())),
        "noise" => Ok(Arc::new(Noise::default())),
        "prior" => Ok(prior()?),
        "prior-raw" => Ok(Arc::new(RawPrior(prior()?))),
        _ => match LearnedKind::from_name(name) {
            Some(kind) => Ok(Arc::new(LearnedSource::new(prior()?, kind)?)),
            None => Err(
                "expected model/prior, model/prior-raw, model/learned, model/learned-head, model/learned-random, model/learned-head-random, model/uniform or model/noise"
                    .to_string(),
            ),
        },
    }
}

fn no_args(spec: &StrategySpec) -> Result<(), PlanError> {
    if spec.args.is_empty() {
        Ok(())
    } else {
        Err(PlanError::UnknownStrategy {
            spec: spec.raw.clone(),
            reason: format!("`{}` takes no arguments", spec.kind),
        })
    }
}

/// The planner settings of a spec whose optional limit suffix sits at `spec.args[at]`, followed
/// by an optional `authors` (the reference code's cost, [`CostModel::Authors`]).
pub fn planner_config_from(
    spec: &StrategySpec,
    at: usize,
    default: PlannerConfig,
    exact_max: usize,
) -> Result<PlannerConfig, PlanError> {
    let (args, default) = match spec.args.split_last() {
        Some((last, rest)) if last == "authors" && rest.len() >= at => (
            rest,
            PlannerConfig {
                cost: CostModel::Authors,
                ..default
            },
        ),
        _ => (spec.args.as_slice(), default),
    };
    match args.get(at) {
        None => Ok(default),
        Some(arg) if args.len() == at + 1 => match parse_limit(arg, exact_max) {
            Some(limit) => Ok(PlannerConfig { limit, ..default }),
            None => Err(PlanError::UnknownStrategy {
                spec: spec.raw.clone(),
                reason: format!("`{arg}` is not a planner limit (k<N>, exact or exact<N>)"),
            }),
        },
        Some(_) => Err(PlanError::UnknownStrategy {
            spec: spec.raw.clone(),
            reason: "too many parts".into(),
        }),
    }
}

/// `optimistic+greedy`.
#[derive(Debug)]
pub struct GreedyStrategy;

impl Strategy for GreedyStrategy {
    fn name(&self) -> &str {
        "optimistic+greedy"
    }

    fn policy<'a>(&'a self, _ctx: &TrialContext<'a>) -> Result<Box<dyn Policy + 'a>, PlanError> {
        Ok(Box::new(Greedy))
    }
}

/// `oracle`: the nearest container holding the target.
#[derive(Debug)]
pub struct OracleStrategy;

impl Strategy for OracleStrategy {
    fn name(&self) -> &str {
        "oracle"
    }

    fn needs_ground_truth(&self) -> bool {
        true
    }

    fn policy<'a>(&'a self, ctx: &TrialContext<'a>) -> Result<Box<dyn Policy + 'a>, PlanError> {
        let truth = ctx.truth.ok_or_else(|| PlanError::Policy {
            policy: "oracle".into(),
            error: "the oracle was not given the ground truth".into(),
        })?;
        let task = ctx.problem.task();
        if task.is_single() {
            return Ok(Box::new(Oracle::new(truth.goal_containers(task.first()))));
        }
        let holds: Vec<u8> = (0..ctx.problem.house.containers.len())
            .map(|c| {
                task.targets()
                    .iter()
                    .enumerate()
                    .filter(|(_, t)| truth.holds(c, t))
                    .fold(0u8, |m, (i, _)| m | (1 << i))
            })
            .collect();
        let legs = ctx.problem.destination_legs().map_err(task_error)?;
        let belief = Belief::new(ctx.problem.house, ctx.problem.distances, task);
        // The route from the start; containers searched beforehand hold no target.
        let route = oracle_route(&belief, &holds, task.goal(), legs.as_deref());
        Ok(Box::new(Oracle::along(route)))
    }
}

/// A task the map cannot serve, as a policy's failure.
pub(crate) fn task_error(e: crate::task::TaskError) -> PlanError {
    PlanError::Task(e)
}

/// The spec kind of [`SequentialStrategy`].
pub const SEQUENTIAL: &str = "sequential";

/// The spec a strategy plans with: `<spec>` of `sequential/<spec>` (at any depth), else the
/// spec itself. What it needs (a prior, an LLM's answers) is what that spec needs.
pub fn planned_spec(spec: &str) -> &str {
    let mut s = spec.trim();
    while let Some(inner) = [SEQUENTIAL, INDEPENDENT, SPLIT]
        .iter()
        .find_map(|kind| s.strip_prefix(kind).and_then(|rest| rest.strip_prefix('/')))
    {
        s = inner;
    }
    s
}

/// `independent/<spec>` and `split/<spec>`: `<spec>` itself, its robots working as the
/// [`Teamwork`] says when several run one trial. One robot runs exactly `<spec>`.
pub struct TeamStrategy {
    name: String,
    inner: Arc<dyn Strategy>,
    teamwork: Teamwork,
}

impl TeamStrategy {
    /// `inner`, named `name`, its robots working as `teamwork` says.
    ///
    /// # Errors
    /// [`PlanError::UnknownStrategy`] for a teamwork wrapped around another
    /// (`independent/split/...`).
    pub fn new(
        name: &str,
        inner: Arc<dyn Strategy>,
        teamwork: Teamwork,
    ) -> Result<Self, PlanError> {
        if inner.teamwork() != Teamwork::Coordinated {
            return Err(PlanError::UnknownStrategy {
                spec: name.to_string(),
                reason: format!(
                    "`{}` already says how robots share the work; give one of independent/ and split/",
                    inner.name()
                ),
            });
        }
        Ok(Self {
            name: name.to_string(),
            inner,
            teamwork,
        })
    }
}

impl Strategy for TeamStrategy {
    fn name(&self) -> &str {
        &self.name
    }

    fn needs_ground_truth(&self) -> bool {
        self.inner.needs_ground_truth()
    }

    fn policy<'a>(&'a self, ctx: &TrialContext<'a>) -> Result<Box<dyn Policy + 'a>, PlanError> {
        self.inner.policy(ctx)
    }

    fn likelihood_source(&self) -> Option<&Arc<dyn LikelihoodSource>> {
        self.inner.likelihood_source()
    }

    fn planner_config(&self) -> Option<PlannerConfig> {
        self.inner.planner_config()
    }

    fn teamwork(&self) -> Teamwork {
        self.teamwork
    }
}

/// `sequential/<spec>`: the single-target planner of `<spec>` looking for a task's targets one
/// after another, then driving to the destination. On one target it is `<spec>` itself.
pub struct SequentialStrategy {
    name: String,
    inner: Arc<dyn Strategy>,
}

impl SequentialStrategy {
    /// `inner` run target after target, named `name`.
    ///
    /// # Errors
    /// [`PlanError::UnknownStrategy`] when `inner` does not plan over a likelihood source.
    pub fn new(name: &str, inner: Arc<dyn Strategy>) -> Result<Self, PlanError> {
        if inner.likelihood_source().is_none() || inner.planner_config().is_none() {
            return Err(PlanError::UnknownStrategy {
                spec: name.to_string(),
                reason: format!(
                    "`{}` does not plan over a likelihood source; sequential/ takes a model strategy such as sequential/model/prior",
                    inner.name()
                ),
            });
        }
        Ok(Self {
            name: name.to_string(),
            inner,
        })
    }
}

impl Strategy for SequentialStrategy {
    fn name(&self) -> &str {
        &self.name
    }

    fn likelihood_source(&self) -> Option<&Arc<dyn LikelihoodSource>> {
        self.inner.likelihood_source()
    }

    fn planner_config(&self) -> Option<PlannerConfig> {
        self.inner.planner_config()
    }

    fn policy<'a>(&'a self, ctx: &TrialContext<'a>) -> Result<Box<dyn Policy + 'a>, PlanError> {
        // One target, no destination: nothing to do one after another.
        if ctx.problem.task().is_single() {
            return self.inner.policy(ctx);
        }
        let (Some(source), Some(config)) = (self.likelihood_source(), self.planner_config()) else {
            return Err(PlanError::Policy {
                policy: self.name.clone(),
                error: "no likelihood source".into(),
            });
        };
        let p = task_likelihoods(source.as_ref(), &ctx.problem)?;
        Ok(Box::new(
            Sequential::new(p, config).with_memo(ctx.problem.plan_memo().cloned()),
        ))
    }
}

/// One row of likelihoods per target of the problem's task, each checked to have one entry per
/// container.
pub fn task_likelihoods(
    source: &dyn LikelihoodSource,
    problem: &SearchProblem<'_>,
) -> Result<Vec<Vec<Probability>>, PlanError> {
    let house = problem.house;
    problem
        .task()
        .targets()
        .iter()
        .map(|t| {
            let p = source.likelihoods(house, t)?;
            if p.len() == house.containers.len() {
                Ok(p)
            } else {
                Err(PlanError::LikelihoodCount {
                    source_name: source.name().to_string(),
                    expected: house.containers.len(),
                    got: p.len(),
                })
            }
        })
        .collect()
}

/// The model-based planner over a likelihood source: `model/prior`, `llm+model/<prompt>/<llm>`.
pub struct ModelStrategy {
    name: String,
    source: Arc<dyn LikelihoodSource>,
    config: PlannerConfig,
}

impl ModelStrategy {
    /// A planner strategy named `name` over `source`.
    pub fn new(name: &str, source: Arc<dyn LikelihoodSource>, config: PlannerConfig) -> Self {
        Self {
            name: name.to_string(),
            source,
            config,
        }
    }

    /// The likelihood source.
    pub fn source(&self) -> &Arc<dyn LikelihoodSource> {
        &self.source
    }
}

impl Strategy for ModelStrategy {
    fn name(&self) -> &str {
        &self.name
    }

    fn likelihood_source(&self) -> Option<&Arc<dyn LikelihoodSource>> {
        Some(&self.source)
    }

    fn planner_config(&self) -> Option<PlannerConfig> {
        Some(self.config)
    }

    fn policy<'a>(&'a self, ctx: &TrialContext<'a>) -> Result<Box<dyn Policy + 'a>, PlanError> {
        let task = ctx.problem.task();
        let p = task_likelihoods(self.source.as_ref(), &ctx.problem)?;
        let memo = ctx.problem.plan_memo().cloned();
        if task.is_single() {
            let p = p.into_iter().next().unwrap_or_default();
            return Ok(Box::new(Planner::new(p, self.config).with_memo(memo)));
        }
        let legs = ctx
            .problem
            .destination_legs()
            .map_err(task_error)?
            .map(std::borrow::Cow::into_owned);
        let rows = (0..p.len()).collect();
        Ok(Box::new(
            Planner::for_targets(p, rows, task.goal(), legs, self.config).with_memo(memo),
        ))
    }
}
