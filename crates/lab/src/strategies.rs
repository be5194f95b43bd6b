//! Strategy setup without a command line: planner and prior settings, LLM settings, the one
//! builder of the strategies ([`Strategies::builder`]: built-in kinds plus the LLM crate's, over
//! the prior the specs need), prefetching LLM answers, and what the LLM service reports after a
//! run.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use ferret_llm::{
    FailurePolicy, LlmConfig, LlmOptions, LlmService, PrefetchSummary, Prefetched, TokenReport,
    prefetch_probabilities, prefetch_probabilities_after, register_fused, register_strategies,
};
use ferret_plan::{
    CandidateLimit, FusionFile, HoldOut, PlannerConfig, Prior, StrategyRegistry, planned_spec,
};
use ferret_world::{House, ObjectType};
use serde::{Deserialize, Serialize};

use crate::error::{LabError, Result};
use crate::feedback::Feedback;

/// The strategies evaluated when none are named.
pub const DEFAULT_STRATEGIES: &str =
    "optimistic+greedy,model/uniform,model/prior,model/prior/exact,oracle";

/// Houses and seed of the prior used when none is given: generated houses with a seed other than
/// the evaluation houses', so that an evaluation never trains on its own test houses.
pub const DEFAULT_PRIOR_HOUSES: (usize, u64) = (500, 1_000_003);

/// Smoothing weight of the default prior (pseudo-containers toward the back-off estimate).
pub const DEFAULT_SMOOTHING: f64 = 2.0;

/// A prior trained on `count` generated houses of `seed`.
pub fn default_prior(count: usize, seed: u64) -> Result<Prior> {
    let scenes = ferret_world::generate::default_scenes(count, seed)?;
    Ok(Prior::train(&scenes, DEFAULT_SMOOTHING))
}

/// True when one of `specs` plans over the prior (`model/prior...`, `model/prior-raw...`,
/// `fused/...`), so that a face can supply a prior it already holds instead of loading or
/// training one per call.
pub fn needs_prior(specs: &[String]) -> bool {
    specs.iter().map(|s| planned_spec(s)).any(|s| {
        s.starts_with("model/prior") || s.starts_with("model/learned") || s.starts_with("fused")
    })
}

/// The specs the strategies of `specs` plan with (`<spec>` of `sequential/<spec>`): what their
/// LLM questions are asked for.
fn planned_specs(specs: &[String]) -> Vec<String> {
    specs.iter().map(|s| planned_spec(s).to_string()).collect()
}

/// Refuses a list option naming the same value twice (`--strategies a,b,a`): its results would
/// be counted twice or overwrite each other. `option` is the option as the caller names it.
pub fn check_distinct(option: &str, values: &[String]) -> Result<()> {
    let mut seen = std::collections::HashSet::new();
    match values.iter().find(|v| !seen.insert(v.as_str())) {
        Some(v) => Err(LabError::invalid(format!("{option}: `{v}` is given twice"))),
        None => Ok(()),
    }
}

/// Planner and prior settings shared by evaluations, selections and deployments. Field names
/// are those of `run.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanningSettings {
    /// A prior file; `None` trains the default one (see [`DEFAULT_PRIOR_HOUSES`]).
    pub prior: Option<PathBuf>,
    /// Containers the planner considers per decision (the paper's K = 8).
    pub max_containers: usize,
    /// Largest exact problem of `/exact` strategies.
    pub exact_max: usize,
    /// Search cost R per container, metres.
    pub search_cost: f64,
    /// Target types the prior must not have seen (`--holdout-types`): the prior asked about a
    /// target is one without the types of its fold.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub holdout: Option<HoldOut>,
    /// Word embeddings for names a learned prior's file lacks (`--embeddings`; without it,
    /// `FERRET_EMBEDDINGS`), opened only when such a name is asked. Not recorded in run.json:
    /// the vectors of a name are the embeddings' (whose id the prior file checks), wherever the
    /// folder is; a later step (`select`) finds it again through `FERRET_EMBEDDINGS`.
    #[serde(skip)]
    pub embeddings: Option<PathBuf>,
}

impl Default for PlanningSettings {
    fn default() -> Self {
        Self {
            prior: None,
            max_containers: 8,
            exact_max: 16,
            search_cost: 0.0,
            holdout: None,
            embeddings: None,
        }
    }
}

impl PlanningSettings {
    /// Refuses unusable planner settings, naming the option.
    pub fn validate(&self) -> Result<()> {
        if !(self.search_cost.is_finite() && self.search_cost >= 0.0) {
            return Err(LabError::invalid(format!(
                "--search-cost {}: must be a finite number ≥ 0 m",
                self.search_cost
            )));
        }
        if self.max_containers == 0 {
            return Err(LabError::invalid(
                "--max-containers 0: the planner needs at least one container",
            ));
        }
        let max = ferret_plan::planner::MAX_EXACT;
        if !(1..=max).contains(&self.exact_max) {
            return Err(LabError::invalid(format!(
                "--exact-max {}: must be between 1 and {max}",
                self.exact_max
            )));
        }
        Ok(())
    }

    /// The prior these settings name, or the default one.
    pub fn prior(&self) -> Result<Prior> {
        match &self.prior {
            Some(p) => Ok(Prior::load(p)?),
            None => default_prior(DEFAULT_PRIOR_HOUSES.0, DEFAULT_PRIOR_HOUSES.1),
        }
    }

    /// The planner settings of model strategies without a limit suffix.
    pub fn planner_config(&self) -> PlannerConfig {
        PlannerConfig {
            search_cost: self.search_cost,
            limit: CandidateLimit::Paper {
                k: self.max_containers.max(1),
            },
            cost: ferret_plan::CostModel::Paper,
        }
    }
}

/// Where LLM endpoints and cached answers live, and what a failed endpoint means.
#[derive(Clone, Debug, PartialEq)]
pub struct LlmSettings {
    /// Endpoint configuration (TOML); `ferret.toml` in the working directory when `None`.
    pub config: Option<PathBuf>,
    /// The response cache (SQLite).
    pub llm_cache: PathBuf,
    /// Answer from the cache only.
    pub offline: bool,
    /// Go on without the strategies of a failed endpoint instead of stopping.
    pub keep_going: bool,
    /// Largest share of unreadable answers an LLM strategy may have.
    pub max_fallback_share: Option<f64>,
    /// Fusion weights from a calibration, for `fused/<prompt>/<llm>`.
    pub fusion: Option<PathBuf>,
}

impl Default for LlmSettings {
    fn default() -> Self {
        Self {
            config: None,
            llm_cache: PathBuf::from(ferret_llm::DEFAULT_CACHE_PATH),
            offline: false,
            keep_going: false,
            max_fallback_share: None,
            fusion: None,
        }
    }
}

/// Strategies and the LLM service behind the LLM ones.
pub struct Strategies {
    /// Every kind: built-in and LLM.
    pub registry: StrategyRegistry,
    /// The LLM service (endpoints, cache, accounting).
    pub service: Arc<LlmService>,
    /// The prior, when a strategy plans over it.
    pub prior: Option<Arc<Prior>>,
}

/// Which prior a [`StrategiesBuilder`] plans over.
enum PriorChoice<'a> {
    /// The prior these specs need, if any: loaded from the settings' file or the default one
    /// trained.
    ForSpecs(&'a [String]),
    /// A prior the caller already holds, or none.
    Held(Option<Arc<Prior>>),
}

/// Builds [`Strategies`], the one way every face sets up its strategies: built-in kinds plus
/// the LLM kinds under planning and LLM settings, over the prior the specs to build need
/// ([`for_specs`](Self::for_specs)) or one the caller holds ([`prior`](Self::prior)), with what
/// a failed LLM endpoint means for later questions ([`on_failure`](Self::on_failure); batch
/// runs stop asking it, a server pauses and asks again).
///
/// The LLM service opens its cache only when an LLM is first asked, so runs without LLM
/// strategies touch no cache file.
pub struct StrategiesBuilder<'a> {
    planning: &'a PlanningSettings,
    llm: &'a LlmSettings,
    prior: PriorChoice<'a>,
    on_failure: FailurePolicy,
}

impl Strategies {
    /// A builder under these settings: no prior (so `model/prior...` and `fused/...` specs are
    /// unbuildable, as for [`StrategyRegistry::builtin`]) until [`for_specs`] or [`prior`] says
    /// which, and a failed LLM stops being asked for the run.
    ///
    /// [`for_specs`]: StrategiesBuilder::for_specs
    /// [`prior`]: StrategiesBuilder::prior
    pub fn builder<'a>(
        planning: &'a PlanningSettings,
        llm: &'a LlmSettings,
    ) -> StrategiesBuilder<'a> {
        StrategiesBuilder {
            planning,
            llm,
            prior: PriorChoice::Held(None),
            on_failure: FailurePolicy::StopForRun,
        }
    }
}

impl<'a> StrategiesBuilder<'a> {
    /// Plans over the prior `specs` need, when one of them plans over a prior ([`needs_prior`]):
    /// the settings' prior file, or the default prior trained ([`PlanningSettings::prior`]).
    pub fn for_specs(self, specs: &'a [String]) -> Self {
        Self {
            prior: PriorChoice::ForSpecs(specs),
            ..self
        }
    }

    /// Plans over a prior the caller already holds (the settings' prior file is not read): a
    /// face that keeps a prior in memory (a Python `Prior` object) builds the very registry
    /// `ferret eval` builds from the same prior's file.
    pub fn prior(self, prior: Option<Arc<Prior>>) -> Self {
        Self {
            prior: PriorChoice::Held(prior),
            ..self
        }
    }

    /// What a failed LLM endpoint means for later questions.
    pub fn on_failure(self, on_failure: FailurePolicy) -> Self {
        Self { on_failure, ..self }
    }

    /// The registry and the LLM service.
    ///
    /// Errors: a prior file, fusion file or endpoint configuration that cannot be read, and an
    /// LLM service that cannot start.
    pub fn build(self) -> Result<Strategies> {
        let Self {
            planning,
            llm,
            prior,
            on_failure,
        } = self;
        let prior = match prior {
            PriorChoice::ForSpecs(specs) if needs_prior(specs) => Some(Arc::new(planning.prior()?)),
            PriorChoice::ForSpecs(_) => None,
            PriorChoice::Held(p) => p,
        };
        // The hold-out applies to whichever prior was chosen, once.
        let prior = match (prior, planning.holdout) {
            (Some(p), Some(h)) if p.holdout() != Some(h) => Some(Arc::new(p.holding_out(h))),
            (p, _) => p,
        }
        .map(|p| crate::language::with_embeddings(p, planning.embeddings.as_deref()));
        let mut registry =
            StrategyRegistry::builtin(prior.clone(), planning.planner_config(), planning.exact_max);
        let fusion = match &llm.fusion {
            Some(path) => Some((
                path.display().to_string(),
                Arc::new(FusionFile::load(path)?),
            )),
            None => None,
        };
        let config = LlmConfig::load_default(llm.config.as_deref())?;
        let service = Arc::new(LlmService::new(
            config,
            LlmOptions {
                cache_path: Some(llm.llm_cache.clone()),
                offline: llm.offline,
                on_failure,
            },
        )?);
        register_strategies(
            &mut registry,
            service.clone(),
            planning.planner_config(),
            planning.exact_max,
        );
        register_fused(
            &mut registry,
            service.clone(),
            prior.clone(),
            fusion,
            planning.planner_config(),
            planning.exact_max,
        );
        Ok(Strategies {
            registry,
            service,
            prior,
        })
    }
}

/// True when one of `specs` asks an LLM for probabilities, i.e. when [`prefetch`] has questions
/// to ask (`fused/noise` is fused like an LLM source but asks nothing).
pub fn asks_llm(specs: &[String]) -> bool {
    specs.iter().any(|s| {
        ferret_plan::StrategySpec::parse(planned_spec(s)).is_ok_and(|spec| {
            ferret_llm::asks_probabilities(&spec.kind)
                && ferret_llm::control_source(&spec).is_none()
        })
    })
}

/// Asks every probability question of the `llm+model` strategies concurrently before trials
/// run, so trials answer from the cache. When an endpoint fails (after its retries), the run
/// stops with the endpoint's error, or, with `keep_going`, goes on without the strategies of
/// `specs` that use a failed LLM: those are returned, for the caller to drop. An offline miss is
/// not an endpoint failure: the trials that need it fail and are reported.
pub fn prefetch(
    service: &Arc<LlmService>,
    llm: &LlmSettings,
    specs: &[String],
    trials: &[(&House, &ObjectType)],
    feedback: &dyn Feedback,
) -> Result<Vec<String>> {
    if !asks_llm(specs) {
        return Ok(Vec::new());
    }
    feedback.begin("LLM questions", 0);
    let planned = planned_specs(specs);
    let summary = prefetch_probabilities(service, &planned, trials, &|done, total| {
        feedback.set_len(total);
        feedback.set_done(done);
    });
    feedback.end();
    prefetch_outcome(service, llm, specs, &summary?, feedback)
}

/// The questions of some trials asked as [`prefetch`] asks them, without progress or remarks:
/// for a caller that asks a batch of houses at a time, passing every batch the same `before`
/// (questions of earlier batches are skipped), and sums the summaries ([`add_summary`]) for one
/// [`prefetch_outcome`].
pub fn prefetch_quiet(
    service: &Arc<LlmService>,
    specs: &[String],
    trials: &[(&House, &ObjectType)],
    before: &mut Prefetched,
) -> Result<PrefetchSummary> {
    if !asks_llm(specs) {
        return Ok(PrefetchSummary::default());
    }
    Ok(prefetch_probabilities_after(
        service,
        &planned_specs(specs),
        trials,
        before,
        &|_, _| {},
    )?)
}

/// Adds the counts and failures of `more` to `sum`: the run's counts when the batches shared
/// one [`Prefetched`].
pub fn add_summary(sum: &mut PrefetchSummary, more: PrefetchSummary) {
    sum.questions += more.questions;
    sum.distinct += more.distinct;
    sum.cached += more.cached;
    sum.asked += more.asked;
    sum.skipped += more.skipped;
    sum.failures.extend(more.failures);
}

/// What prefetching came to: remarks on what was asked, then the run's error when an LLM failed
/// without `keep_going`, or the strategies to drop with it (see [`prefetch`]).
pub fn prefetch_outcome(
    service: &Arc<LlmService>,
    llm: &LlmSettings,
    specs: &[String],
    summary: &PrefetchSummary,
    feedback: &dyn Feedback,
) -> Result<Vec<String>> {
    feedback.note(&format!(
        "LLM questions: {} distinct ({} cached, {} asked now, {} skipped after a failure)",
        summary.distinct, summary.cached, summary.asked, summary.skipped
    ));
    let down = service.failed_llms();
    if down.is_empty() {
        for f in &summary.failures {
            feedback.note(&format!("LLM failure: {f}"));
        }
        return Ok(Vec::new());
    }
    let reasons: Vec<String> = down.iter().map(|(_, why)| why.clone()).collect();
    if !llm.keep_going {
        return Err(LabError::LlmStopped(format!(
            "{}\nanswers received so far are kept in the response cache; rerun to resume, or pass --keep-going to run the other strategies",
            reasons.join("\n")
        )));
    }
    let dropped: Vec<String> = specs
        .iter()
        .filter(|s| {
            ferret_plan::StrategySpec::parse(planned_spec(s))
                .ok()
                .and_then(|spec| ferret_llm::LlmSpec::parse(&spec))
                .and_then(|p| p.ok())
                .is_some_and(|p| down.iter().any(|(name, _)| *name == p.llm))
        })
        .cloned()
        .collect();
    for r in &reasons {
        feedback.note(&format!("error: {r}"));
    }
    feedback.note(&format!(
        "--keep-going: going on without {} (their LLM failed)",
        dropped.join(", ")
    ));
    Ok(dropped)
}

/// Warnings for LLM strategies whose answers mostly fell back or collapsed into one value, by
/// strategy.
pub fn answer_warnings(service: &LlmService) -> Vec<(String, String)> {
    service
        .report()
        .rows
        .iter()
        .filter_map(|r| r.warning().map(|w| (r.strategy.clone(), w)))
        .collect()
}

/// Fails when `max_fallback_share` is set and an LLM strategy's fallback share exceeds it.
pub fn check_fallback_gate(service: &LlmService, llm: &LlmSettings) -> Result<()> {
    let Some(max) = llm.max_fallback_share else {
        return Ok(());
    };
    let over: Vec<String> = service
        .report()
        .rows
        .iter()
        .filter_map(|r| {
            let share = r.answers.fallback_share()?;
            (share > max).then(|| {
                format!(
                    "{}: {:.1} % of {} answers fell back",
                    r.strategy,
                    100.0 * share,
                    r.answers.answers()
                )
            })
        })
        .collect();
    if over.is_empty() {
        Ok(())
    } else {
        Err(LabError::invalid(format!(
            "fallback share above --max-fallback-share {max}:\n  {}",
            over.join("\n  ")
        )))
    }
}

/// What an LLM service used in a run, as written beside the run's other files.
pub struct TokenFiles {
    /// The token report (the paper's table V).
    pub report: TokenReport,
    /// Warnings by strategy (see [`answer_warnings`]).
    pub warnings: Vec<(String, String)>,
}

/// Writes `tokens.csv` into `dir` and appends the token report, the answer classes and warnings
/// to `dir/summary.md` when it exists; `None` when no LLM was used.
pub fn write_token_files(service: &LlmService, dir: &Path) -> Result<Option<TokenFiles>> {
    let report = service.report();
    if report.rows.is_empty() {
        return Ok(None);
    }
    let warnings = answer_warnings(service);
    // Also in the run's summary, beside the cost table, with the answer classes and a mark on
    // every row whose answers say little.
    let summary = dir.join("summary.md");
    if summary.exists() {
        let md = ferret_world::input::read_text(&summary, ferret_world::input::MAX_INPUT_BYTES)
            .map_err(|e| LabError::io(format!("reading {}", summary.display()), e))?;
        let md = crate::report::with_llm_sections(&md, &report, &warnings);
        crate::files::write_bytes(&summary, md)?;
    }
    std::fs::create_dir_all(dir)
        .map_err(|e| LabError::io(format!("creating {}", dir.display()), e))?;
    let tokens = dir.join("tokens.csv");
    crate::files::write_atomic(&tokens, |w| report.write_csv(w)).map_err(|source| {
        LabError::Csv {
            context: format!("writing {}", tokens.display()),
            source,
        }
    })?;
    Ok(Some(TokenFiles { report, warnings }))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn specs(s: &[&str]) -> Vec<String> {
        s.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn a_value_given_twice_is_named_with_its_option() {
        let err = check_distinct("--strategies", &specs(&["a", "b", "a"])).unwrap_err();
        assert_eq!(err.to_string(), "--strategies: `a` is given twice");
        assert!(check_distinct("--strategies", &specs(&["a", "b"])).is_ok());
    }

    #[test]
    fn only_prior_and_fused_specs_need_the_prior() {
        assert!(needs_prior(&specs(&["oracle", "model/prior/exact"])));
        assert!(needs_prior(&specs(&["fused/p-yesno/gpt"])));
        assert!(needs_prior(&specs(&["sequential/model/prior"])));
        assert!(needs_prior(&specs(&["sequential/sequential/fused/noise"])));
        assert!(!needs_prior(&specs(&["sequential/model/uniform"])));
        assert!(asks_llm(&specs(&["sequential/llm+model/p-yesno/gpt"])));
        assert!(!needs_prior(&specs(&[
            "optimistic+greedy",
            "model/uniform",
            "oracle"
        ])));
        assert!(!needs_prior(&[]));
    }

    #[test]
    fn a_registry_over_a_held_prior_builds_prior_strategies() {
        let dir = tempfile::tempdir().unwrap();
        let llm = LlmSettings {
            llm_cache: dir.path().join("cache.sqlite"),
            ..LlmSettings::default()
        };
        let planning = PlanningSettings::default();
        let prior = Arc::new(default_prior(5, 7).unwrap());
        let over = Strategies::builder(&planning, &llm)
            .prior(Some(prior.clone()))
            .build()
            .unwrap();
        assert!(over.registry.build("model/prior").is_ok());
        assert!(Arc::ptr_eq(over.prior.as_ref().unwrap(), &prior));
        let none = Strategies::builder(&planning, &llm).build().unwrap();
        assert!(none.registry.build("model/prior").is_err());
        assert!(none.registry.build("model/uniform").is_ok());
        // Nothing was asked, so no cache file was made.
        assert!(!dir.path().join("cache.sqlite").exists());
    }
}
