//! The learned likelihood: language that generalizes to names no training house had.
//!
//! Counts only know the names they counted. This source sees the target, the container type and
//! the room type through vectors of their names (word embeddings, given by the caller; this crate
//! loads no embedding file) and asks a small [`Head`] trained on the training houses' questions
//! "does this container hold the target, given the target is in the house". Training holds
//! types out in folds so that the head must generalize: fold `k`'s head never saw fold `k`'s
//! target, container and room types (by [`HoldOut::fold_of`]) nor fold `k`'s houses, and its
//! answers on those houses, beside a prior counted without them, are what the head's Platt
//! scaling and the fusion with the counts are fitted on. The fusion weighs the head by how little
//! the counts saw of the target, of the container type and of the room type separately
//! ([`Evidence`]), so the counts speak where they have evidence and language where they have
//! none.
//!
//! Every model is trained twice: over the names' vectors, and over one fixed random vector per
//! name (identity without meaning), the control that every learned row is reported beside.

pub mod head;
mod source;
mod train;

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use ferret_world::{House, ObjectType, Scene};
use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

pub use head::{Example, Head, HeadSettings};
pub use source::{LearnedSource, evidence_weight};
pub use train::train;

use crate::error::PlanError;
use crate::holdout::HoldOut;
use crate::likelihood::Evidence;

/// The format of the learned part of a prior file this version writes.
pub const LEARNED_FORMAT: u32 = 1;

/// Folds of types (and houses) held out while training, by default: the same 5 as
/// `--holdout-types 5`, so that a run holding out target types plans each trial with the head
/// that never saw its target's type.
pub const LEARNED_FOLDS: usize = 5;

/// Number of fusion weights ([`fusion_features`]).
pub const FUSION_WEIGHTS: usize = 15;

/// How a learned source is trained.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LearnedSettings {
    /// Folds of held-out types and houses.
    pub folds: usize,
    /// Heads per fold, each from its own seed; their logits are averaged.
    pub seeds: usize,
    /// The seed of the first head (the others follow from it).
    pub seed: u64,
    /// The heads' shape and training.
    pub head: HeadSettings,
    /// Also measure counts built into the head against the fusion ([`CountsInHead`]): more
    /// heads to train, nothing of it used for answers.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub compare_counts_in_head: bool,
}

impl Default for LearnedSettings {
    fn default() -> Self {
        Self {
            folds: LEARNED_FOLDS,
            seeds: 4,
            seed: 0,
            head: HeadSettings::default(),
            compare_counts_in_head: false,
        }
    }
}

/// Two ways of joining counts and language, compared on the same cross-fitted questions: the
/// fusion ([`fusion_features`]: the counted prior's logit, the head's logit and the evidence
/// gaps, 15 weights) and one head whose inputs are the names' vectors together with the
/// counted prior's logit and the four evidence gaps. Each is fitted on the held-out answers of
/// all folds but one and scored on that one (the head never seeing that fold's types), so both
/// are scored where they were not fitted.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CountsInHead {
    /// AUROC of the fusion, every question.
    pub fusion_auroc: f64,
    /// AUROC of counts built into the head, every question.
    pub head_auroc: f64,
    /// Log loss (nats per container) of the fusion, every question.
    pub fusion_log_loss: f64,
    /// Log loss of counts built into the head, every question.
    pub head_log_loss: f64,
    /// AUROC of the fusion where the target type was never seen.
    pub fusion_auroc_unseen: f64,
    /// AUROC of counts built into the head where the target type was never seen.
    pub head_auroc_unseen: f64,
    /// Log loss of the fusion where the target type was never seen.
    pub fusion_log_loss_unseen: f64,
    /// Log loss of counts built into the head where the target type was never seen.
    pub head_log_loss_unseen: f64,
}

/// How well a model's answers ranked the holders on the questions its heads never saw
/// (cross-fitted), beside the counted prior of the same folds.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct HeldOutScore {
    /// Questions ((house, target, container) triples).
    pub questions: f64,
    /// Of them, containers holding the target.
    pub positives: f64,
    /// AUROC of the counted prior.
    pub prior_auroc: f64,
    /// AUROC of the head alone.
    pub head_auroc: f64,
    /// AUROC of the fusion of both.
    pub fused_auroc: f64,
}

/// One set of heads with the fits over their cross-fitted answers.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LearnedModel {
    /// Heads by fold, then by seed.
    pub heads: Vec<Vec<Head>>,
    /// Platt scaling of the head alone: `logit P = a·z + c`.
    pub head_fit: [f64; 2],
    /// The fusion's weights over [`fusion_features`].
    pub fusion: Vec<f64>,
    /// Scores on every held-out question.
    pub score: HeldOutScore,
    /// Scores on the questions whose target type the heads and the prior never saw.
    pub unseen_score: HeldOutScore,
    /// Counts built into the head against the fusion, when training was asked to measure it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub counts_in_head: Option<CountsInHead>,
}

/// The learned part of a prior file: vectors of every name it embedded and two models, one over
/// those vectors and the random-vector control.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Learned {
    /// [`LEARNED_FORMAT`].
    pub ferret_learned: u32,
    /// Which embeddings gave the vectors (e.g. `glove-6b-50d`).
    pub embedding: String,
    /// Vector length.
    pub dim: usize,
    /// How it was trained.
    pub settings: LearnedSettings,
    /// The vector of every name embedded (types of targets, containers and rooms).
    pub vectors: BTreeMap<String, Vec<f32>>,
    /// Heads over the names' vectors.
    pub language: LearnedModel,
    /// Heads over one random vector per name: the control.
    pub control: LearnedModel,
}

/// Vectors of names a prior file does not hold, looked up when first asked (a house with
/// furniture or rooms its training houses never had). Implemented above this crate, which loads
/// no embedding file; errors say what to give.
pub trait NameVectors: Send + Sync {
    /// The vector of `name`, of the learned part's length, from the embeddings it was trained
    /// with.
    fn vector(&self, name: &str) -> Result<Vec<f32>, String>;

    /// What was said of `name` when its vector was made: one line per word read otherwise than
    /// spelt (its base form, a WordNet hypernym, left out). Empty for a name not asked yet.
    fn notes(&self, name: &str) -> Vec<String> {
        let _ = name;
        Vec::new()
    }
}

/// A [`NameVectors`] kept beside a prior: compared as equal always (it only fills in what the
/// file lacks, the same vectors whoever asks).
#[derive(Clone)]
pub struct Embedder(pub Arc<dyn NameVectors>);

impl std::fmt::Debug for Embedder {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("Embedder")
    }
}

impl PartialEq for Embedder {
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

/// Which answer of a learned prior a source gives.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LearnedKind {
    /// Counts and language fused by evidence: `learned`.
    Fused,
    /// The head alone, Platt-scaled: `learned-head`.
    Head,
    /// The fusion over the random-vector control: `learned-random`.
    FusedControl,
    /// The control's head alone: `learned-head-random`.
    HeadControl,
}

impl LearnedKind {
    /// Every kind, in the order of reports.
    pub const ALL: [LearnedKind; 4] = [
        LearnedKind::Fused,
        LearnedKind::Head,
        LearnedKind::FusedControl,
        LearnedKind::HeadControl,
    ];

    /// The source name (`model/<name>`).
    pub fn name(self) -> &'static str {
        match self {
            LearnedKind::Fused => "learned",
            LearnedKind::Head => "learned-head",
            LearnedKind::FusedControl => "learned-random",
            LearnedKind::HeadControl => "learned-head-random",
        }
    }

    /// The kind a source name names.
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|k| k.name() == name)
    }

    fn control(self) -> bool {
        matches!(self, LearnedKind::FusedControl | LearnedKind::HeadControl)
    }

    fn head_only(self) -> bool {
        matches!(self, LearnedKind::Head | LearnedKind::HeadControl)
    }
}

/// The fold of a name among `folds` ([`HoldOut::fold_of`], for any kind of name).
fn fold_of(name: &str, folds: usize) -> usize {
    HoldOut::fold_of(&ObjectType::new(name), folds)
}

/// One fixed pseudo-random unit vector per name: the control's "embedding", which tells names
/// apart and says nothing of what they mean.
pub fn random_vector(name: &str, dim: usize) -> Vec<f32> {
    let digest = Sha256::digest(format!("ferret random vector\u{0}{name}").as_bytes());
    let mut seed = [0u8; 32];
    seed.copy_from_slice(&digest);
    let mut rng = rand_chacha::ChaCha8Rng::from_seed(seed);
    let v: Vec<f32> = (0..dim).map(|_| rng.random_range(-1.0f32..1.0)).collect();
    normalized(v)
}

fn normalized(mut v: Vec<f32>) -> Vec<f32> {
    let norm = v.iter().map(|x| x * x).sum::<f32>().sqrt();
    if norm > 0.0 {
        v.iter_mut().for_each(|x| *x /= norm);
    }
    v
}

/// Inputs of the head for vectors of `dim` numbers ([`head_input`]).
pub fn head_inputs(dim: usize) -> usize {
    5 * dim + 3
}

/// The head's input for one question: the three vectors, the target's products with the
/// container's and the room's (which let a small head see "this object goes with that
/// furniture" without having to find the product itself), and the three cosines. The cosines
/// are what carries over to names far from every training name: a head that has only seen
/// eighty names learns their coordinates, but "similar names go together" holds for any.
pub fn head_input(target: &[f32], container: &[f32], room: &[f32]) -> Vec<f32> {
    let mut x = Vec::with_capacity(head_inputs(target.len()));
    x.extend_from_slice(target);
    x.extend_from_slice(container);
    x.extend_from_slice(room);
    x.extend(target.iter().zip(container).map(|(a, b)| a * b));
    x.extend(target.iter().zip(room).map(|(a, b)| a * b));
    let dot = |a: &[f32], b: &[f32]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f32>();
    // The vectors are unit length (or zero), so their dot products are their cosines.
    x.push(COSINE_SCALE * dot(target, container));
    x.push(COSINE_SCALE * dot(target, room));
    x.push(COSINE_SCALE * dot(container, room));
    x
}

/// The cosines enter the head scaled up, so that three inputs are not lost among hundreds at
/// the start of training.
const COSINE_SCALE: f32 = 4.0;

/// The fusion's inputs: the prior's logit `lp`, the head's logit `lh`, an intercept, and for each
/// evidence gap (target, container, room, pair) the gap alone and times each logit.
pub fn fusion_features(lp: f64, lh: f64, e: &Evidence) -> [f64; FUSION_WEIGHTS] {
    [
        lp,
        lh,
        1.0,
        e.target,
        e.target * lh,
        e.target * lp,
        e.container,
        e.container * lh,
        e.container * lp,
        e.room,
        e.room * lh,
        e.room * lp,
        e.pair,
        e.pair * lh,
        e.pair * lp,
    ]
}

/// Every name a scene's questions use: target types present, container types, room types (`""`
/// for a container in no room).
pub fn scene_names(scene: &Scene) -> BTreeSet<String> {
    let mut names: BTreeSet<String> = scene
        .truth
        .target_types()
        .into_iter()
        .map(|t| t.as_str().to_string())
        .collect();
    names.extend(house_names(&scene.house));
    names
}

/// The container and room type names of a house.
pub fn house_names(house: &House) -> BTreeSet<String> {
    let mut names = BTreeSet::new();
    for (c, container) in house.containers.iter().enumerate() {
        names.insert(container.object_type.as_str().to_string());
        names.insert(
            house
                .container_room(c)
                .map(|r| r.room_type.as_str().to_string())
                .unwrap_or_default(),
        );
    }
    names
}

/// The mean of the heads' logits for `x`.
fn mean_logit(heads: &[Head], x: &[f32]) -> f64 {
    if heads.is_empty() {
        return 0.0;
    }
    heads.iter().map(|h| f64::from(h.logit(x))).sum::<f64>() / heads.len() as f64
}

/// Largest weight a file's fits may hold. Fits over logits give weights of order one (a trained
/// file's are within ±2); a weight of a thousand already makes every answer 0 or 1, so one past
/// it is a damaged or hand-edited file, not a fit.
const MAX_FIT_WEIGHT: f64 = 1_000.0;

fn learned_error(message: impl Into<String>) -> PlanError {
    PlanError::Learned {
        message: message.into(),
    }
}

impl Learned {
    /// Checks what a file read back must hold: the format, heads of one input width for the
    /// vectors' length, one head list per fold, finite fits.
    pub fn check(&self) -> Result<(), String> {
        if self.ferret_learned != LEARNED_FORMAT {
            return Err(format!(
                "learned format {} (this ferret reads {LEARNED_FORMAT}): train it again",
                self.ferret_learned
            ));
        }
        if let Some((name, v)) = self.vectors.iter().find(|(_, v)| v.len() != self.dim) {
            return Err(format!(
                "vectors.{name}: {} numbers, the file says {}",
                v.len(),
                self.dim
            ));
        }
        for (what, model) in [("language", &self.language), ("control", &self.control)] {
            if model.heads.len() != self.settings.folds || model.heads.iter().any(Vec::is_empty) {
                return Err(format!(
                    "{what}.heads: {} folds of heads for {} folds",
                    model.heads.len(),
                    self.settings.folds
                ));
            }
            for (f, fold) in model.heads.iter().enumerate() {
                for (i, h) in fold.iter().enumerate() {
                    if !h.is_well_formed() {
                        return Err(format!(
                            "{what}.heads[{f}][{i}]: its layers do not chain, or a weight is not a finite number"
                        ));
                    }
                    if h.inputs() != head_inputs(self.dim) {
                        return Err(format!(
                            "{what}.heads[{f}][{i}]: {} inputs, where {}-number vectors make {}",
                            h.inputs(),
                            self.dim,
                            head_inputs(self.dim)
                        ));
                    }
                }
            }
            if model.fusion.len() != FUSION_WEIGHTS {
                return Err(format!(
                    "{what}.fusion: {} weights, not {FUSION_WEIGHTS}",
                    model.fusion.len()
                ));
            }
            for (field, weights) in [("fusion", &model.fusion[..]), ("head_fit", &model.head_fit)] {
                if let Some((i, w)) = weights
                    .iter()
                    .enumerate()
                    .find(|(_, w)| !(w.is_finite() && w.abs() <= MAX_FIT_WEIGHT))
                {
                    return Err(format!(
                        "{what}.{field}[{i}]: {w} is not a weight a fit gives (a finite number within ±{MAX_FIT_WEIGHT})"
                    ));
                }
            }
        }
        Ok(())
    }

    /// The names among `names` that have no vector (`""`, no room, never needs one).
    pub fn missing_vectors<'a>(&self, names: impl IntoIterator<Item = &'a str>) -> Vec<String> {
        let mut missing: BTreeSet<String> = BTreeSet::new();
        for n in names {
            if !n.is_empty() && !self.vectors.contains_key(n) {
                missing.insert(n.to_string());
            }
        }
        missing.into_iter().collect()
    }

    fn vector(
        &self,
        name: &str,
        control: bool,
        kind: &str,
        embedder: Option<&Embedder>,
    ) -> Result<Vec<f32>, String> {
        if name.is_empty() {
            return Ok(vec![0.0; self.dim]);
        }
        if control {
            return Ok(random_vector(name, self.dim));
        }
        if let Some(v) = self.vectors.get(name) {
            return Ok(v.clone());
        }
        if let Some(e) = embedder {
            let v =
                e.0.vector(name)
                    .map_err(|m| format!("the {kind} `{name}`: {m}"))?;
            if v.len() != self.dim {
                return Err(format!(
                    "the {kind} `{name}`: a vector of {} numbers where the prior's have {}",
                    v.len(),
                    self.dim
                ));
            }
            return Ok(v);
        }
        Err(format!(
            "no word vector for the {kind} `{name}`, which the training houses never had: give the embeddings it was trained with ({}) as --embeddings DIR or FERRET_EMBEDDINGS (scripts/embeddings.sh install prints the folder)",
            self.embedding
        ))
    }
}

#[cfg(test)]
mod tests;
