//! Calibration of likelihood sources: every (house, target, container) of the houses is a pair
//! (P_S, whether the container holds the target); each source gets a Brier score, log loss,
//! AUROC and reliability bins, and an LLM source can be fused with the prior (and, when the prior
//! has a learned part, with the learned likelihood) by a logistic fit on the same pairs.

use std::sync::Arc;

use ferret_plan::{
    Calibration, FusionBase, FusionFile, FusionFit, FusionSample, FusionWeights, HoldOut,
    LearnedKind, LearnedSource, LikelihoodSource, Prior, TrainingScore, draw_trial,
    prior_fingerprint,
};
use ferret_world::{House, ObjectType, Scene};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rayon::prelude::*;
use serde::Serialize;

use crate::error::{LabError, Result};
use crate::feedback::Feedback;
use crate::houses::LoadedHouses;
use crate::strategies::{LlmSettings, Strategies, prefetch};

/// The sources scored when none are named.
pub const DEFAULT_SOURCES: &str = "model/uniform,model/prior";

/// How many targets per house.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TargetCount {
    /// Every target type present.
    All,
    /// At most this many.
    N(usize),
}

impl std::str::FromStr for TargetCount {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        if s.eq_ignore_ascii_case("all") {
            return Ok(TargetCount::All);
        }
        match s.parse::<usize>() {
            Ok(0) | Err(_) => Err(format!("`{s}` is neither `all` nor a positive number")),
            Ok(n) => Ok(TargetCount::N(n)),
        }
    }
}

impl TargetCount {
    fn per_house(self, noun: &str) -> String {
        match self {
            TargetCount::All => "every target type present".to_string(),
            TargetCount::N(n) => format!("up to {n} {noun}"),
        }
    }
}

/// One row of `calibration.csv`: a source's name and its scores, flat, without the reliability
/// bins (they go to the diagram). Serialized by hand because serde's `flatten` goes through a
/// map, which the CSV writer refuses.
#[derive(Clone, Copy, Debug)]
pub struct CalibrationRow<'a> {
    /// The source's spec.
    pub source: &'a str,
    /// Its scores.
    pub calibration: &'a Calibration,
}

impl Serialize for CalibrationRow<'_> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeStruct;
        let c = self.calibration;
        let mut row = s.serialize_struct("CalibrationRow", 8)?;
        row.serialize_field("source", self.source)?;
        row.serialize_field("pairs", &c.pairs)?;
        row.serialize_field("positives", &c.positives)?;
        row.serialize_field("brier", &c.brier)?;
        row.serialize_field("log_loss", &c.log_loss)?;
        row.serialize_field("auroc", &c.auroc)?;
        row.serialize_field("mean_p_pos", &c.mean_p_pos)?;
        row.serialize_field("mean_p_neg", &c.mean_p_neg)?;
        row.end()
    }
}

/// The rows of `calibration.csv` for every scored source, in order.
pub fn calibration_rows(scored: &[(String, Calibration)]) -> Vec<CalibrationRow<'_>> {
    scored
        .iter()
        .map(|(source, calibration)| CalibrationRow {
            source,
            calibration,
        })
        .collect()
}

/// What a calibration scores.
#[derive(Clone, Debug, PartialEq)]
pub struct CalibrationSettings {
    /// Likelihood sources as strategy specs (any planner suffix is ignored).
    pub sources: Vec<String>,
    /// Targets per house.
    pub targets_per_house: TargetCount,
    /// Seed of the target choice (with [`TargetCount::N`]).
    pub seed: u64,
    /// Bins of the reliability diagram.
    pub bins: usize,
    /// Also fit the fusion of the prior with each LLM source (and control) among `sources`.
    pub fit_fusion: bool,
    /// Folds of target types the fusion fit also sees the prior without (each question asked
    /// again of a prior that never saw its target's fold), so that the fit learns how much the
    /// other source is worth where the prior has no evidence; 0 or 1 fits on the prior as it is.
    pub fit_unseen_folds: usize,
    /// With one held-out fold, only targets of its types are scored.
    pub holdout: Option<HoldOut>,
}

/// Folds of the fusion fit's unseen-type questions when none are given.
pub const FIT_UNSEEN_FOLDS: usize = 5;

/// The name a fitted source is stored under in a fusion file, for a source spec: `<prompt>/<llm>`
/// for `llm+model/<prompt>/<llm>`, the control's name for `model/noise` and `model/uniform`;
/// `None` for sources that are not fused.
pub fn fusion_name(spec: &str) -> Option<String> {
    let parsed = ferret_plan::StrategySpec::parse(spec).ok()?;
    if parsed.kind == "model" {
        let first = parsed.args.first()?;
        return ferret_plan::strategy::CONTROL_SOURCES
            .contains(&first.as_str())
            .then(|| first.clone());
    }
    if parsed.kind != ferret_llm::LLM_MODEL {
        return None;
    }
    let llm = ferret_llm::LlmSpec::parse(&parsed)?.ok()?;
    Some(format!("{}/{}", llm.prompt, llm.llm))
}

impl CalibrationSettings {
    /// The sources whose fusion with the prior is fitted: LLM sources and controls.
    fn fitted(&self) -> Vec<String> {
        if !self.fit_fusion {
            return Vec::new();
        }
        self.sources
            .iter()
            .filter(|s| fusion_name(s).is_some())
            .cloned()
            .collect()
    }

    /// Refuses unusable settings, naming the option, and returns the strategy specs the
    /// registry given to [`calibrate`] must build: the sources, and the prior when a fusion is
    /// fitted (even when it is not scored itself).
    pub fn specs_to_build(&self) -> Result<Vec<String>> {
        if self.sources.is_empty() {
            return Err(LabError::invalid("--sources names no source"));
        }
        if !(1..=100).contains(&self.bins) {
            return Err(LabError::invalid(format!(
                "--bins {}: must be between 1 and 100",
                self.bins
            )));
        }
        if self.fit_unseen_folds > ferret_plan::holdout::MAX_FOLDS {
            return Err(LabError::invalid(format!(
                "--fit-unseen-folds {}: at most {} folds",
                self.fit_unseen_folds,
                ferret_plan::holdout::MAX_FOLDS
            )));
        }
        let mut needed = self.sources.clone();
        if self.fit_fusion {
            if self.fitted().is_empty() {
                return Err(LabError::invalid(
                    "--fit-fusion: --sources names no llm+model/<prompt>/<llm> source (nor a control, model/noise or model/uniform) to fuse with the prior",
                ));
            }
            needed.push("model/prior".into());
        }
        Ok(needed)
    }
}

impl Default for CalibrationSettings {
    fn default() -> Self {
        Self {
            sources: DEFAULT_SOURCES.split(',').map(String::from).collect(),
            targets_per_house: TargetCount::All,
            seed: 0,
            bins: 10,
            fit_fusion: false,
            fit_unseen_folds: FIT_UNSEEN_FOLDS,
            holdout: None,
        }
    }
}

/// What a calibration found. Failures of single sources or trials are in `errors`; everything
/// else was scored.
pub struct Calibrated {
    /// Each scored source's calibration (with its reliability bins), in the order asked; its
    /// rows of `calibration.csv` are [`calibration_rows`].
    pub scored: Vec<(String, Calibration)>,
    /// The fitted fusions, when asked for.
    pub fusion: Option<FusionFile>,
    /// (house, target) pairs scored.
    pub trials: usize,
    /// `calibration.md`: the table of scores.
    pub markdown: String,
    /// What failed, one message each.
    pub errors: Vec<String>,
}

/// The targets scored in one house: with `N`, the eval's target first, then others in a seeded
/// order.
pub fn targets_for(scene: &Scene, count: TargetCount, seed: u64) -> Vec<ObjectType> {
    let all: Vec<ObjectType> = scene.truth.target_types().into_iter().collect();
    match count {
        TargetCount::All => all,
        TargetCount::N(n) => {
            let first = draw_trial(&scene.house, &scene.truth, seed, 0.0)
                .ok()
                .map(|t| t.task.first().clone());
            let mut rest: Vec<ObjectType> = all
                .into_iter()
                .filter(|t| Some(t) != first.as_ref())
                .collect();
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(
                seed ^ (scene.house.index as u64).wrapping_mul(0x2545_F491_4F6C_DD1D),
            );
            rest.shuffle(&mut rng);
            first.into_iter().chain(rest).take(n).collect()
        }
    }
}

/// Scores `settings.sources` on `loaded` with strategies from `setup` (a registry that builds
/// [`CalibrationSettings::specs_to_build`]): every question an LLM source asks goes through the
/// response cache first, each at most once; `llm` says what a failed endpoint means.
///
/// Errors (before anything is scored): no houses, unusable settings, no house holding a target,
/// a source that plans over no likelihood source, and the errors of building strategies and of
/// LLM prefetching.
pub fn calibrate(
    loaded: &LoadedHouses,
    setup: &Strategies,
    llm: &LlmSettings,
    settings: &CalibrationSettings,
    feedback: &dyn Feedback,
) -> Result<Calibrated> {
    if loaded.scenes.is_empty() {
        return Err(LabError::invalid(format!(
            "no houses to score in {}",
            loaded.source
        )));
    }
    settings.specs_to_build()?;
    let mut sources = likelihood_sources(setup, settings)?;
    let questions = Questions::new(loaded, settings, feedback)?;
    let pairs: Vec<(&House, &ObjectType)> =
        questions.trials.iter().map(|(h, t, _)| (*h, t)).collect();
    let dropped = prefetch(&setup.service, llm, &settings.sources, &pairs, feedback)?;
    sources.retain(|(spec, _)| !dropped.contains(spec));
    let mut errors = Vec::new();
    let (scored, per_source) = questions.score(&sources, &mut errors);
    let fusion = if settings.fit_fusion {
        Some(questions.fit_fusions(setup, &per_source, &mut errors)?)
    } else {
        None
    };
    let markdown = crate::report::calibration_markdown(
        &scored,
        &loaded.source,
        loaded.scenes.len(),
        questions.trials.len(),
        &settings.targets_per_house.per_house("target types"),
    );
    Ok(Calibrated {
        scored,
        fusion,
        trials: questions.trials.len(),
        markdown,
        errors,
    })
}

/// The likelihood source of every spec of `settings.sources`, in order.
fn likelihood_sources(
    setup: &Strategies,
    settings: &CalibrationSettings,
) -> Result<Vec<(String, Arc<dyn LikelihoodSource>)>> {
    settings
        .sources
        .iter()
        .map(|spec| {
            let strategy = setup.registry.build(spec)?;
            let source = strategy.likelihood_source().cloned().ok_or_else(|| {
                LabError::invalid(format!(
                    "{spec} plans over no likelihood source (use model/... or llm+model/...)"
                ))
            })?;
            Ok((spec.clone(), source))
        })
        .collect()
}

/// One (house, target) question of a calibration: every container of the house is a pair.
type Trial<'a> = (&'a House, ObjectType, &'a Scene);

/// Each source's probabilities per trial (`None` where it failed), by source.
type PerSource = Vec<(String, Vec<Option<Vec<f64>>>)>;

/// A fusion base, the unseen folds its second view holds out (when it has one), and its views
/// (`None` when the prior could not give them).
type BaseViews = (FusionBase, Option<usize>, Option<Vec<PriorView>>);

/// What every step of a calibration asks about: the houses' (house, target) trials, which
/// containers hold each target, and the settings they were drawn under.
struct Questions<'a> {
    loaded: &'a LoadedHouses,
    settings: &'a CalibrationSettings,
    trials: Vec<Trial<'a>>,
    /// Per trial, per container: whether it holds the target.
    holds: Vec<Vec<bool>>,
    feedback: &'a dyn Feedback,
}

impl<'a> Questions<'a> {
    /// The trials of every house (targets of the held-out fold only, with one), and their
    /// holders. Errors when no house holds a target.
    fn new(
        loaded: &'a LoadedHouses,
        settings: &'a CalibrationSettings,
        feedback: &'a dyn Feedback,
    ) -> Result<Self> {
        let holdout = settings.holdout;
        let trials: Vec<Trial<'a>> = loaded
            .scenes
            .iter()
            .flat_map(|s| {
                targets_for(s, settings.targets_per_house, settings.seed)
                    .into_iter()
                    .filter(move |t| holdout.is_none_or(|h| h.includes_target(t)))
                    .map(move |t| (&s.house, t, s))
            })
            .collect();
        if trials.is_empty() {
            return Err(LabError::invalid(format!(
                "no house in {} holds a target object",
                loaded.source
            )));
        }
        let holds = trials
            .iter()
            .map(|(house, target, scene)| {
                (0..house.containers.len())
                    .map(|c| scene.truth.holds(c, target))
                    .collect()
            })
            .collect();
        Ok(Self {
            loaded,
            settings,
            trials,
            holds,
            feedback,
        })
    }

    /// Every source's calibration (a source with no pair scored is an error instead), and its
    /// probabilities per trial, kept for the fusion fit.
    fn score(
        &self,
        sources: &[(String, Arc<dyn LikelihoodSource>)],
        errors: &mut Vec<String>,
    ) -> (Vec<(String, Calibration)>, PerSource) {
        let mut scored = Vec::new();
        let mut per_source = Vec::new();
        for (spec, source) in sources {
            let probabilities =
                source_probabilities(spec, source.as_ref(), &self.trials, errors, self.feedback);
            let all: Vec<(f64, bool)> = probabilities
                .iter()
                .zip(&self.holds)
                .filter_map(|(p, h)| p.as_ref().map(|p| p.iter().copied().zip(h.iter().copied())))
                .flatten()
                .collect();
            per_source.push((spec.clone(), probabilities));
            let Some(c) = Calibration::score(&all, self.settings.bins) else {
                errors.push(format!("{spec}: no pairs scored"));
                continue;
            };
            scored.push((spec.clone(), c));
        }
        (scored, per_source)
    }

    /// The fusion of every fitted source with each base (the prior, and the learned likelihood
    /// when the prior has one); a fit that fails is an error, the others are kept.
    fn fit_fusions(
        &self,
        setup: &Strategies,
        per_source: &PerSource,
        errors: &mut Vec<String>,
    ) -> Result<FusionFile> {
        let prior = setup
            .prior
            .clone()
            .ok_or_else(|| LabError::invalid("--fit-fusion needs the prior"))?;
        let fitted = self.settings.fitted();
        let views = self.fusion_views(&prior, errors);
        let mut fits = Vec::new();
        for (base, unseen_folds, views) in &views {
            // A base some view could not give is not fitted (the error says why).
            let Some(views) = views else { continue };
            for (spec, probabilities) in per_source.iter().filter(|(s, _)| fitted.contains(s)) {
                match fit_fusion(
                    spec,
                    *base,
                    &prior,
                    views,
                    probabilities,
                    &self.holds,
                    &self.trained_on(*unseen_folds),
                ) {
                    Ok(f) => fits.push(f),
                    Err(e) => errors.push(format!("--fit-fusion: {}: {spec}: {e}", base.kind())),
                }
            }
        }
        Ok(FusionFile::new(fits))
    }

    /// The views of every fusion base: the prior as it is and (for the evidence-aware weights)
    /// the prior that never saw each target's fold — the same questions, once with evidence and
    /// once without; likewise for the learned likelihood when the prior has a learned part.
    fn fusion_views(&self, prior: &Arc<Prior>, errors: &mut Vec<String>) -> Vec<BaseViews> {
        let (settings, trials, feedback) = (self.settings, &self.trials, self.feedback);
        let mut priors = vec![prior.clone()];
        if let Some(h) = HoldOut::every_fold(settings.fit_unseen_folds) {
            priors.push(Arc::new(prior.holding_out(h)));
        }
        let mut views = vec![(
            FusionBase::Prior,
            (priors.len() > 1).then_some(settings.fit_unseen_folds),
            prior_views(&priors, None, trials, errors, feedback),
        )];
        // With a learned part, the LLM sources are also fused with the learned likelihood
        // (`fused-learned/...`). Its heads answer for an unseen fold only in the folds they
        // were trained with, so its unseen view holds out those.
        if let Some(learned) = prior.learned() {
            let mut priors = vec![prior.clone()];
            if settings.fit_unseen_folds > 1
                && let Some(h) = HoldOut::every_fold(learned.settings.folds)
            {
                priors.push(Arc::new(prior.holding_out(h)));
            }
            views.push((
                FusionBase::Learned,
                (priors.len() > 1).then_some(learned.settings.folds),
                prior_views(&priors, Some(LearnedKind::Fused), trials, errors, feedback),
            ));
        }
        views
    }

    /// What a fit was trained on, as its file records it.
    fn trained_on(&self, unseen_folds: Option<usize>) -> String {
        let unseen = unseen_folds.map_or(String::new(), |k| {
            format!("; every question also asked of the prior without its target's fold of {k}")
        });
        format!(
            "{} houses from {}, {} ({} house–target pairs){unseen}",
            self.loaded.scenes.len(),
            self.loaded.source,
            self.settings
                .targets_per_house
                .per_house("target types per house"),
            self.trials.len()
        )
    }
}

/// The probabilities `source` gives on every trial; a failure is recorded in `errors` and
/// leaves that trial's entry `None`.
fn source_probabilities(
    spec: &str,
    source: &dyn LikelihoodSource,
    trials: &[(&House, ObjectType, &Scene)],
    errors: &mut Vec<String>,
    feedback: &dyn Feedback,
) -> Vec<Option<Vec<f64>>> {
    feedback.begin("calibrating", trials.len());
    let per_trial: Vec<std::result::Result<Vec<f64>, String>> = trials
        .par_iter()
        .map(|(house, target, _)| {
            let p = source
                .likelihoods(house, target)
                .map(|p| p.iter().map(|p| p.get()).collect())
                .map_err(|e| format!("{spec}: {}: {e}", house.name));
            feedback.tick();
            p
        })
        .collect();
    feedback.end();
    per_trial
        .into_iter()
        .map(|r| r.map_err(|e| errors.push(e)).ok())
        .collect()
}

/// What a view of the prior gives on every trial of a calibration: a fusion base's
/// probabilities, and the prior's evidence gaps.
struct PriorView {
    probabilities: Vec<Option<Vec<f64>>>,
    gaps: Vec<Vec<f64>>,
}

/// The views of a fusion base over each of `priors`: the prior itself, or (with `learned`) the
/// learned likelihood over it; `None`, with the reason in `errors`, when a prior cannot give it.
fn prior_views(
    priors: &[Arc<Prior>],
    learned: Option<LearnedKind>,
    trials: &[(&House, ObjectType, &Scene)],
    errors: &mut Vec<String>,
    feedback: &dyn Feedback,
) -> Option<Vec<PriorView>> {
    let mut views = Vec::new();
    for p in priors {
        let probabilities = match learned {
            None => source_probabilities("model/prior", p.as_ref(), trials, errors, feedback),
            Some(kind) => match LearnedSource::new(p.clone(), kind) {
                Ok(source) => source_probabilities(
                    &format!("model/{}", kind.name()),
                    &source,
                    trials,
                    errors,
                    feedback,
                ),
                Err(e) => {
                    errors.push(format!("--fit-fusion: fused-learned: {e}"));
                    return None;
                }
            },
        };
        views.push(PriorView {
            probabilities,
            gaps: trials
                .iter()
                .map(|(house, target, _)| p.evidence_gaps(house, target))
                .collect(),
        });
    }
    Some(views)
}

/// The fusion of `base` with the source `spec`, fitted on every trial both answered, under
/// every view of the prior.
fn fit_fusion(
    spec: &str,
    base: FusionBase,
    prior: &Prior,
    views: &[PriorView],
    other_p: &[Option<Vec<f64>>],
    holds: &[Vec<bool>],
    trained_on: &str,
) -> Result<FusionFit> {
    let mut samples: Vec<FusionSample> = Vec::new();
    // Scored on the prior as it is (the first view): the fit's in-sample scores.
    let mut first_view = 0;
    for (v, view) in views.iter().enumerate() {
        for (((p, o), g), h) in view
            .probabilities
            .iter()
            .zip(other_p)
            .zip(&view.gaps)
            .zip(holds)
        {
            let (Some(p), Some(o)) = (p, o) else { continue };
            for (((&prior, &other), &gap), &holds) in p.iter().zip(o).zip(g).zip(h) {
                samples.push(FusionSample {
                    prior,
                    other,
                    gap,
                    holds,
                });
            }
        }
        if v == 0 {
            first_view = samples.len();
        }
    }
    let weights = FusionWeights::fit(&samples).ok_or_else(|| {
        LabError::invalid("the fit needs containers that hold the target and ones that do not")
    })?;
    let as_is = &samples[..first_view];
    let score = |f: &dyn Fn(&FusionSample) -> f64| -> Result<TrainingScore> {
        let pairs: Vec<(f64, bool)> = as_is.iter().map(|s| (f(s), s.holds)).collect();
        let c = Calibration::score(&pairs, 10).ok_or_else(|| LabError::invalid("no pairs"))?;
        Ok(TrainingScore {
            brier: c.brier,
            auroc: c.auroc,
        })
    };
    let source =
        fusion_name(spec).ok_or_else(|| LabError::invalid("not an LLM source nor a control"))?;
    Ok(FusionFit {
        source,
        base,
        weights,
        prior: prior_fingerprint(prior),
        trained_on: trained_on.to_string(),
        pairs: as_is.len() as u64,
        positives: as_is.iter().filter(|s| s.holds).count() as u64,
        prior_score: score(&|s| s.prior)?,
        source_score: score(&|s| s.other)?,
        fused_score: score(&|s| weights.fuse(s.prior, s.other, s.gap))?,
    })
}
