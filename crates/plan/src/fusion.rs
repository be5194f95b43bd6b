//! Fusion of the prior with another likelihood source (an LLM's), so that the other source can
//! only help: `logit P = a·logit P_prior + b·logit P_other + c`, with (a, b, c) fitted by
//! logistic regression on training houses ([`FusionWeights::fit`]). A source that says nothing
//! about where things are gets b ≈ 0, and the fused source plans like the prior; one that knows
//! more gets weight where it helps.
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
use crate::likelihood::{LikelihoodSource, Prior};
use crate::probability::Probability;

/// Probabilities are kept this far from 0 and 1 before their logit is taken (a source that says
/// 0.01 and one that says 1e-9 mean the same to a planner; the logit of the second would swamp
/// the fit).
const LOGIT_EPS: f64 = 1e-4;

/// Fused probabilities are kept in [FUSED_MIN, 1 − FUSED_MIN].
pub const FUSED_MIN: f64 = 1e-3;

/// The ridge penalty on a and b: enough to keep Newton's method finite on data the two inputs
/// separate perfectly (tiny test sets), far too small to matter on real training sets.
const RIDGE: f64 = 1e-3;

fn logit(p: f64) -> f64 {
    let p = p.clamp(LOGIT_EPS, 1.0 - LOGIT_EPS);
    (p / (1.0 - p)).ln()
}

fn sigmoid(z: f64) -> f64 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// The weights of `logit P = a·logit P_prior + b·logit P_other + c`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct FusionWeights {
    /// Weight of the prior's logit.
    pub a: f64,
    /// Weight of the other source's logit.
    pub b: f64,
    /// Intercept.
    pub c: f64,
}

impl FusionWeights {
    /// The prior alone: a = 1, b = c = 0.
    pub const PRIOR: Self = Self {
        a: 1.0,
        b: 0.0,
        c: 0.0,
    };

    /// The fused probability of a container the prior gives `prior` and the other source
    /// `other`, in [[`FUSED_MIN`], 1 − [`FUSED_MIN`]].
    pub fn fuse(&self, prior: f64, other: f64) -> f64 {
        sigmoid(self.a * logit(prior) + self.b * logit(other) + self.c)
            .clamp(FUSED_MIN, 1.0 - FUSED_MIN)
    }

    /// Fits the weights to `(P_prior, P_other, holds)` triples by maximum likelihood (Newton's
    /// method on the logistic log-likelihood with a tiny ridge penalty on a and b). `None`
    /// without both holders and non-holders, or when the fit does not settle.
    ///
    /// Written out rather than taken from a crate: three parameters need a 3×3 solve, and the
    /// crates that fit logistic regressions bring a linear-algebra stack for it.
    #[allow(clippy::needless_range_loop)] // gradient and Hessian by index, as written on paper
    pub fn fit(samples: &[(f64, f64, bool)]) -> Option<Self> {
        let positives = samples.iter().filter(|s| s.2).count();
        if positives == 0 || positives == samples.len() {
            return None;
        }
        let rows: Vec<([f64; 3], f64)> = samples
            .iter()
            .map(|&(p, o, y)| ([logit(p), logit(o), 1.0], f64::from(u8::from(y))))
            .collect();
        let mut w = [1.0, 0.0, 0.0];
        for _ in 0..100 {
            let mut grad = [-RIDGE * w[0], -RIDGE * w[1], 0.0];
            let mut hess = [[0.0; 3]; 3];
            hess[0][0] = RIDGE;
            hess[1][1] = RIDGE;
            for (x, y) in &rows {
                let p = sigmoid(x[0] * w[0] + x[1] * w[1] + x[2] * w[2]);
                let weight = p * (1.0 - p);
                for i in 0..3 {
                    grad[i] += (y - p) * x[i];
                    for j in 0..3 {
                        hess[i][j] += weight * x[i] * x[j];
                    }
                }
            }
            let step = solve3(hess, grad)?;
            for i in 0..3 {
                w[i] += step[i];
            }
            if !w.iter().all(|v| v.is_finite()) {
                return None;
            }
            if step.iter().map(|s| s.abs()).fold(0.0, f64::max) < 1e-10 {
                break;
            }
        }
        Some(Self {
            a: w[0],
            b: w[1],
            c: w[2],
        })
    }
}

/// Solves `m · x = v` by Gaussian elimination with partial pivoting; `None` when singular.
// Indices read as the textbook algorithm does; iterators over rows and columns would not.
#[allow(clippy::needless_range_loop)]
fn solve3(mut m: [[f64; 3]; 3], mut v: [f64; 3]) -> Option<[f64; 3]> {
    for col in 0..3 {
        let pivot = (col..3).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[pivot][col].abs() < 1e-12 {
            return None;
        }
        m.swap(col, pivot);
        v.swap(col, pivot);
        for row in col + 1..3 {
            let f = m[row][col] / m[col][col];
            for k in col..3 {
                m[row][k] -= f * m[col][k];
            }
            v[row] -= f * v[col];
        }
    }
    let mut x = [0.0; 3];
    for row in (0..3).rev() {
        let rest: f64 = (row + 1..3).map(|k| m[row][k] * x[k]).sum();
        x[row] = (v[row] - rest) / m[row][row];
    }
    Some(x)
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

/// One fitted fusion: the weights for a source, and how they were obtained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FusionFit {
    /// The source fused with the prior, as `<prompt>/<llm>` (`p-yesno/qwen`).
    pub source: String,
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
    /// The prior alone on those pairs.
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

    /// The fit for `source` (`<prompt>/<llm>`).
    pub fn fit(&self, source: &str) -> Option<&FusionFit> {
        self.fits.iter().find(|f| f.source == source)
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
            if ![w.a, w.b, w.c].iter().all(|v| v.is_finite()) {
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

/// The fused likelihood source: the prior and another source combined by [`FusionWeights`].
pub struct Fused {
    name: String,
    prior: Arc<dyn LikelihoodSource>,
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
        prior: Arc<dyn LikelihoodSource>,
        other: Arc<dyn LikelihoodSource>,
        weights: FusionWeights,
    ) -> Self {
        Self {
            name: name.to_string(),
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

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        let prior = self.prior.likelihoods(house, target)?;
        let other = self.other.likelihoods(house, target)?;
        if prior.len() != other.len() {
            return Err(PlanError::LikelihoodCount {
                source_name: self.other.name().to_string(),
                expected: prior.len(),
                got: other.len(),
            });
        }
        Ok(prior
            .iter()
            .zip(&other)
            .map(|(p, o)| {
                Probability::clamped(
                    self.weights.fuse(p.get(), o.get()),
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

    /// Samples drawn from a known model: the fit must come back near it.
    fn synthetic(w: FusionWeights, n: usize, seed: u64) -> Vec<(f64, f64, bool)> {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        (0..n)
            .map(|_| {
                let p: f64 = rng.random_range(0.01..0.99);
                let o: f64 = rng.random_range(0.01..0.99);
                let y = rng.random::<f64>() < sigmoid(w.a * logit(p) + w.b * logit(o) + w.c);
                (p, o, y)
            })
            .collect()
    }

    #[test]
    fn the_fit_recovers_the_weights_that_made_the_data() {
        let truth = FusionWeights {
            a: 0.9,
            b: 0.6,
            c: -1.2,
        };
        let w = FusionWeights::fit(&synthetic(truth, 20_000, 7)).unwrap();
        assert!((w.a - truth.a).abs() < 0.08, "{w:?}");
        assert!((w.b - truth.b).abs() < 0.08, "{w:?}");
        assert!((w.c - truth.c).abs() < 0.12, "{w:?}");
    }

    #[test]
    fn a_source_of_noise_gets_almost_no_weight() {
        let truth = FusionWeights {
            a: 1.0,
            b: 0.0,
            c: 0.0,
        };
        let w = FusionWeights::fit(&synthetic(truth, 20_000, 3)).unwrap();
        assert!(w.b.abs() < 0.06, "{w:?}");
        assert!((w.a - 1.0).abs() < 0.08, "{w:?}");
    }

    #[test]
    fn one_class_only_has_no_fit() {
        assert_eq!(
            FusionWeights::fit(&[(0.2, 0.3, true), (0.5, 0.5, true)]),
            None
        );
        assert_eq!(FusionWeights::fit(&[]), None);
    }

    #[test]
    fn separable_data_still_gives_finite_weights() {
        let samples: Vec<(f64, f64, bool)> = (1..50)
            .map(|i| {
                let p = f64::from(i) / 50.0;
                (p, 0.5, p > 0.5)
            })
            .collect();
        let w = FusionWeights::fit(&samples).unwrap();
        assert!([w.a, w.b, w.c].iter().all(|v| v.is_finite()), "{w:?}");
        assert!(w.a > 1.0, "the prior separates the classes: {w:?}");
    }

    #[test]
    fn the_prior_weights_give_the_prior_back() {
        for p in [0.01, 0.1, 0.5, 0.9] {
            assert!((FusionWeights::PRIOR.fuse(p, 0.77) - p).abs() < 1e-9);
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
            weights: FusionWeights {
                a: 0.8,
                b: 0.4,
                c: 0.1,
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
            p in 0.0f64..=1.0, o in 0.0f64..=1.0, dp in 0.0f64..0.5,
        ) {
            let w = FusionWeights { a, b, c };
            let f = w.fuse(p, o);
            prop_assert!((FUSED_MIN..=1.0 - FUSED_MIN).contains(&f));
            prop_assert!(w.fuse((p + dp).min(1.0), o) >= f - 1e-12);
            prop_assert!(w.fuse(p, (o + dp).min(1.0)) >= f - 1e-12);
        }
    }
}
