//! Fusion of the prior with another likelihood source (an LLM's), so that the other source can
//! only help: `logit P = a·logit P_prior + b·logit P_other + c + g·(d·logit P_other + e)`, with
//! the weights fitted by logistic regression on training houses ([`FusionWeights::fit`]) and `g`
//! the prior's evidence gap for each question (how little its training houses said about it). A
//! source that says nothing about where things are gets b ≈ d ≈ 0, and the fused source plans like
//! the prior; one that knows more gets weight where it helps, above all where the prior never
//! saw the target.
//!
//! Fits are stored in a fusion file ([`FusionFile`], JSON), one per source, each with the
//! fingerprint of the prior it was fitted with: weights fitted with another prior are refused,
//! since `a` and `c` only mean something for the prior they were fitted against.

use std::path::Path;
use std::sync::Arc;

use ferret_world::{House, ObjectType};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::error::PlanError;
use crate::likelihood::LikelihoodSource;
use crate::logistic::{logit, sigmoid};
use crate::prior::Prior;
use crate::probability::Probability;

/// Fused probabilities are kept in [FUSED_MIN, 1 − FUSED_MIN].
pub const FUSED_MIN: f64 = 1e-3;

/// The weights of `logit P = a·logit P_prior + b·logit P_other + c + g·(d·logit P_other + e)`,
/// where `g` in [0, 1] is the prior's evidence gap for the question
/// ([`Prior::evidence_gap`]: 1 where its training houses never showed the target with a
/// container of that type, near 0 where they often did). `d` and `e` let the other source carry
/// the weight where the prior has no evidence; a fit without such questions leaves them near 0.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FusionWeights {
    /// Weight of the prior's logit.
    pub a: f64,
    /// Weight of the other source's logit.
    pub b: f64,
    /// Intercept.
    pub c: f64,
    /// Extra weight of the other source's logit, times the evidence gap (0 in files written
    /// before fusions knew the prior's evidence).
    #[serde(default)]
    pub d: f64,
    /// Extra intercept, times the evidence gap.
    #[serde(default)]
    pub e: f64,
}

/// One (house, target, container) question of a fusion fit.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FusionSample {
    /// The prior's probability.
    pub prior: f64,
    /// The other source's probability.
    pub other: f64,
    /// The prior's evidence gap ([`Prior::evidence_gap`]).
    pub gap: f64,
    /// Whether the container holds the target.
    pub holds: bool,
}

impl FusionWeights {
    /// The prior alone: a = 1, everything else 0.
    pub const PRIOR: Self = Self {
        a: 1.0,
        b: 0.0,
        c: 0.0,
        d: 0.0,
        e: 0.0,
    };

    /// The fused probability of a container the prior gives `prior` (with evidence gap `gap`)
    /// and the other source `other`, in [[`FUSED_MIN`], 1 − [`FUSED_MIN`]].
    pub fn fuse(&self, prior: f64, other: f64, gap: f64) -> f64 {
        let o = logit(other);
        let g = gap.clamp(0.0, 1.0);
        sigmoid(self.a * logit(prior) + self.b * o + self.c + g * (self.d * o + self.e))
            .clamp(FUSED_MIN, 1.0 - FUSED_MIN)
    }

    /// Fits the weights to `samples` by maximum likelihood (Newton's method on the logistic
    /// log-likelihood with a tiny ridge penalty toward the prior alone on every weight but the
    /// intercept). `None` without both holders and non-holders, or when the fit does not
    /// settle.
    pub fn fit(samples: &[FusionSample]) -> Option<Self> {
        let rows: Vec<([f64; 5], bool)> = samples
            .iter()
            .map(|s| {
                let o = logit(s.other);
                let g = s.gap.clamp(0.0, 1.0);
                ([logit(s.prior), o, 1.0, g * o, g], s.holds)
            })
            .collect();
        let w = crate::logistic::fit(
            &rows,
            [1.0, 0.0, 0.0, 0.0, 0.0],
            [true, true, false, true, true],
        )?;
        Some(Self {
            a: w[0],
            b: w[1],
            c: w[2],
            d: w[3],
            e: w[4],
        })
    }
}

/// A fingerprint of a prior (SHA-256 of its JSON), which a fit records.
pub fn prior_fingerprint(prior: &Prior) -> String {
    let json = serde_json::to_vec(prior).unwrap_or_default();
    format!("{:x}", Sha256::digest(&json))
}

/// Scores of a source on the training pairs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrainingScore {
    /// Brier score.
    pub brier: f64,
    /// AUROC (`None` without both classes).
    pub auroc: Option<f64>,
}

/// What a fusion's weights `a` and `c` apply to: the prior's probability (`fused/...`), or the
/// learned likelihood over the prior file's word vectors (`fused-learned/...`, the prior where it
/// has evidence and its language head where it has none). Either way the evidence gap `g` is the
/// prior's.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum FusionBase {
    /// The prior (`model/prior`).
    #[default]
    Prior,
    /// The learned likelihood (`model/learned`).
    Learned,
}

impl FusionBase {
    /// True for [`FusionBase::Prior`] (files written before fusions had a base say nothing).
    pub fn is_prior(&self) -> bool {
        *self == Self::Prior
    }

    /// The strategy kind that plans over this base fused with another source: `fused` or
    /// `fused-learned`.
    pub const fn kind(self) -> &'static str {
        match self {
            Self::Prior => "fused",
            Self::Learned => "fused-learned",
        }
    }

    /// The base's built-in source (`model/<name>`): `prior` or `learned`.
    pub fn source_name(self) -> &'static str {
        match self {
            Self::Prior => "prior",
            Self::Learned => "learned",
        }
    }
}

/// One fitted fusion: the weights for a source, and how they were obtained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FusionFit {
    /// The source fused with the base, as `<prompt>/<llm>` (`p-yesno/qwen`).
    pub source: String,
    /// What the source is fused with (the prior unless the file says otherwise).
    #[serde(default, skip_serializing_if = "FusionBase::is_prior")]
    pub base: FusionBase,
    /// The fitted weights.
    pub weights: FusionWeights,
    /// [`prior_fingerprint`] of the prior it was fitted with.
    pub prior: String,
    /// What it was fitted on (houses, targets).
    pub trained_on: String,
    /// (house, target, container) pairs fitted.
    pub pairs: u64,
    /// Of them, containers holding the target.
    pub positives: u64,
    /// The base alone on those pairs (the prior, or the learned likelihood).
    pub prior_score: TrainingScore,
    /// The source alone.
    pub source_score: TrainingScore,
    /// The fused source (in-sample).
    pub fused_score: TrainingScore,
}

/// A fusion file: fits by source. `ferret calibrate --fit-fusion` writes it, `--fusion` reads it.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct FusionFile {
    /// Format version (1).
    pub ferret_fusion: u32,
    /// One fit per source.
    pub fits: Vec<FusionFit>,
}

impl FusionFile {
    /// The current format version.
    pub const VERSION: u32 = 1;

    /// A file holding `fits`.
    pub fn new(fits: Vec<FusionFit>) -> Self {
        Self {
            ferret_fusion: Self::VERSION,
            fits,
        }
    }

    /// The fit for `source` (`<prompt>/<llm>`) fused with `base`.
    pub fn fit(&self, base: FusionBase, source: &str) -> Option<&FusionFit> {
        self.fits
            .iter()
            .find(|f| f.base == base && f.source == source)
    }

    /// Reads a fusion file.
    pub fn load(path: &Path) -> Result<Self, PlanError> {
        let err = |message: String| PlanError::Fusion {
            path: path.display().to_string(),
            message,
        };
        let text = ferret_world::input::read_text(path, ferret_world::input::MAX_INPUT_BYTES)
            .map_err(|e| err(e.to_string()))?;
        let file: Self = serde_json::from_str(&text)
            .map_err(|e| err(format!("not a ferret fusion file: {e}")))?;
        if file.ferret_fusion != Self::VERSION {
            return Err(err(format!(
                "format version {} (this ferret reads {})",
                file.ferret_fusion,
                Self::VERSION
            )));
        }
        for f in &file.fits {
            let w = f.weights;
            if ![w.a, w.b, w.c, w.d, w.e].iter().all(|v| v.is_finite()) {
                return Err(err(format!("{}: weights are not finite numbers", f.source)));
            }
        }
        Ok(file)
    }

    /// The file as pretty JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).unwrap_or_default() + "\n"
    }
}

/// The fused likelihood source: a base (the prior, or the learned likelihood over it) and
/// another source combined by [`FusionWeights`], with the prior's evidence gaps.
pub struct Fused {
    name: String,
    base: Arc<dyn LikelihoodSource>,
    prior: Arc<Prior>,
    other: Arc<dyn LikelihoodSource>,
    weights: FusionWeights,
}

impl std::fmt::Debug for Fused {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Fused")
            .field("name", &self.name)
            .field("weights", &self.weights)
            .finish()
    }
}

impl Fused {
    /// `prior` and `other` fused with `weights`, named `name`.
    pub fn new(
        name: &str,
        prior: Arc<Prior>,
        other: Arc<dyn LikelihoodSource>,
        weights: FusionWeights,
    ) -> Self {
        Self::over(name, prior.clone(), prior, other, weights)
    }

    /// `base` and `other` fused with `weights`, named `name`; `prior` gives the evidence gaps.
    pub fn over(
        name: &str,
        base: Arc<dyn LikelihoodSource>,
        prior: Arc<Prior>,
        other: Arc<dyn LikelihoodSource>,
        weights: FusionWeights,
    ) -> Self {
        Self {
            name: name.to_string(),
            base,
            prior,
            other,
            weights,
        }
    }

    /// The other source.
    pub fn other(&self) -> &Arc<dyn LikelihoodSource> {
        &self.other
    }

    /// The weights.
    pub fn weights(&self) -> FusionWeights {
        self.weights
    }
}

impl LikelihoodSource for Fused {
    fn name(&self) -> &str {
        &self.name
    }

    fn check_names(&self, house: &House, targets: &[ObjectType]) -> Result<Vec<String>, String> {
        let mut notes = self.base.check_names(house, targets)?;
        notes.extend(self.other.check_names(house, targets)?);
        Ok(notes)
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        let prior = self.base.likelihoods(house, target)?;
        let gaps = self.prior.evidence_gaps(house, target);
        let other = self.other.likelihoods(house, target)?;
        for (source, got) in [(&self.base, prior.len()), (&self.other, other.len())] {
            if got != gaps.len() {
                return Err(PlanError::LikelihoodCount {
                    source_name: source.name().to_string(),
                    expected: gaps.len(),
                    got,
                });
            }
        }
        Ok(prior
            .iter()
            .zip(&other)
            .zip(&gaps)
            .map(|((p, o), &g)| {
                Probability::clamped(
                    self.weights.fuse(p.get(), o.get(), g),
                    FUSED_MIN,
                    1.0 - FUSED_MIN,
                )
            })
            .collect())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Samples drawn from a known model: the fit must come back near it. A quarter of the
    /// questions have no evidence in the prior (gap 1), the rest plenty (gap 0).
    fn synthetic(w: FusionWeights, n: usize, seed: u64) -> Vec<FusionSample> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|i| {
                let p: f64 = rng.random_range(0.01..0.99);
                let o: f64 = rng.random_range(0.01..0.99);
                let gap = if i % 4 == 0 { 1.0 } else { 0.0 };
                let holds = rng.random::<f64>() < w.fuse(p, o, gap);
                FusionSample {
                    prior: p,
                    other: o,
                    gap,
                    holds,
                }
            })
            .collect()
    }

    fn sample(prior: f64, other: f64, holds: bool) -> FusionSample {
        FusionSample {
            prior,
            other,
            gap: 0.0,
            holds,
        }
    }

    #[test]
    fn the_fit_recovers_the_weights_that_made_the_data() {
        let truth = FusionWeights {
            a: 0.9,
            b: 0.6,
            c: -1.2,
            d: 0.8,
            e: 0.5,
        };
        let w = FusionWeights::fit(&synthetic(truth, 40_000, 7)).unwrap();
        assert!((w.a - truth.a).abs() < 0.08, "{w:?}");
        assert!((w.b - truth.b).abs() < 0.08, "{w:?}");
        assert!((w.c - truth.c).abs() < 0.12, "{w:?}");
        assert!((w.d - truth.d).abs() < 0.15, "{w:?}");
        assert!((w.e - truth.e).abs() < 0.2, "{w:?}");
    }

    #[test]
    fn a_source_of_noise_gets_almost_no_weight() {
        let w = FusionWeights::fit(&synthetic(FusionWeights::PRIOR, 20_000, 3)).unwrap();
        assert!(w.b.abs() < 0.06 && w.d.abs() < 0.1, "{w:?}");
        assert!((w.a - 1.0).abs() < 0.08, "{w:?}");
    }

    #[test]
    fn one_class_only_has_no_fit() {
        assert_eq!(
            FusionWeights::fit(&[sample(0.2, 0.3, true), sample(0.5, 0.5, true)]),
            None
        );
        assert_eq!(FusionWeights::fit(&[]), None);
    }

    #[test]
    fn separable_data_still_gives_finite_weights() {
        let samples: Vec<FusionSample> = (1..50)
            .map(|i| {
                let p = f64::from(i) / 50.0;
                sample(p, 0.5, p > 0.5)
            })
            .collect();
        let w = FusionWeights::fit(&samples).unwrap();
        assert!([w.a, w.b, w.c].iter().all(|v| v.is_finite()), "{w:?}");
        assert!(w.a > 1.0, "the prior separates the classes: {w:?}");
    }

    #[test]
    fn the_prior_weights_give_the_prior_back() {
        for p in [0.01, 0.1, 0.5, 0.9] {
            for gap in [0.0, 1.0] {
                assert!((FusionWeights::PRIOR.fuse(p, 0.77, gap) - p).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn a_file_round_trips_and_bad_files_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let score = TrainingScore {
            brier: 0.05,
            auroc: Some(0.9),
        };
        let file = FusionFile::new(vec![FusionFit {
            source: "p-yesno/qwen".into(),
            base: FusionBase::Learned,
            weights: FusionWeights {
                a: 0.8,
                b: 0.4,
                c: 0.1,
                d: 0.3,
                e: -0.2,
            },
            prior: "abc".into(),
            trained_on: "houses".into(),
            pairs: 10,
            positives: 2,
            prior_score: score,
            source_score: score,
            fused_score: score,
        }]);
        let path = dir.path().join("fusion.json");
        std::fs::write(&path, file.to_json()).unwrap();
        assert_eq!(FusionFile::load(&path).unwrap(), file);
        assert!(file.fit(FusionBase::Learned, "p-yesno/qwen").is_some());
        assert!(file.fit(FusionBase::Prior, "p-yesno/qwen").is_none());
        // A file written before fusions had a base: every fit is the prior's.
        let json = file.to_json();
        assert!(json.contains("\"base\": \"learned\""), "{json}");
        std::fs::write(&path, json.replace("\"base\": \"learned\",", "")).unwrap();
        let read = FusionFile::load(&path).unwrap();
        assert_eq!(read.fits[0].base, FusionBase::Prior);
        assert!(
            !read.to_json().contains("base"),
            "the prior's base is not written"
        );
        // A file written before the evidence weights existed: d = e = 0, the fusion it was.
        let old = file
            .to_json()
            .replace(",\n        \"d\": 0.3,\n        \"e\": -0.2", "");
        assert!(!old.contains("\"d\""), "{old}");
        std::fs::write(&path, &old).unwrap();
        let read = FusionFile::load(&path).unwrap();
        assert_eq!((read.fits[0].weights.d, read.fits[0].weights.e), (0.0, 0.0));
        std::fs::write(&path, "{\"ferret_fusion\": 9, \"fits\": []}").unwrap();
        let e = FusionFile::load(&path).unwrap_err().to_string();
        assert!(e.contains("fusion.json") && e.contains("version 9"), "{e}");
        std::fs::write(&path, "[1, 2]").unwrap();
        let e = FusionFile::load(&path).unwrap_err().to_string();
        assert!(e.contains("not a ferret fusion file"), "{e}");
    }

    proptest! {
        /// Fused probabilities stay in their bounds and rise with either input when its weight
        /// is positive.
        #[test]
        fn fused_probabilities_are_bounded_and_monotone(
            a in 0.0f64..3.0, b in 0.0f64..3.0, c in -5.0f64..5.0,
            d in 0.0f64..3.0, e in -5.0f64..5.0, gap in 0.0f64..=1.0,
            p in 0.0f64..=1.0, o in 0.0f64..=1.0, dp in 0.0f64..0.5,
        ) {
            let w = FusionWeights { a, b, c, d, e };
            let f = w.fuse(p, o, gap);
            prop_assert!((FUSED_MIN..=1.0 - FUSED_MIN).contains(&f));
            prop_assert!(w.fuse((p + dp).min(1.0), o, gap) >= f - 1e-12);
            prop_assert!(w.fuse(p, (o + dp).min(1.0), gap) >= f - 1e-12);
        }
    }
}
