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

use std::collections::{BTreeMap, BTreeSet};
use std::sync::Arc;

use ferret_world::{House, ObjectType, Scene};
use rand::{Rng, SeedableRng};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

pub use head::{Example, Head, HeadSettings};

use crate::error::PlanError;
use crate::holdout::HoldOut;
use crate::likelihood::{Evidence, LikelihoodSource, Prior};
use crate::logistic::{fit_counts, logit, sigmoid};
use crate::probability::Probability;

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

/// The names one question is about, as indices into a name table.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Question {
    target: usize,
    container: usize,
    room: usize,
}

/// Holders and containers asked, per question.
type Tally = BTreeMap<Question, (f64, f64)>;

/// The questions of one house, with how many containers held the target and how many there were.
fn house_questions(scene: &Scene, index: &BTreeMap<&str, usize>) -> Tally {
    let mut tally = Tally::new();
    let targets = scene.truth.target_types();
    for (c, container) in scene.house.containers.iter().enumerate() {
        let room = scene
            .house
            .container_room(c)
            .map(|r| r.room_type.as_str())
            .unwrap_or("");
        for t in &targets {
            // The table holds every name of these houses (`scene_names`); a name it lacked
            // would only drop that question.
            let (Some(&target), Some(&kind), Some(&in_room)) = (
                index.get(t.as_str()),
                index.get(container.object_type.as_str()),
                index.get(room),
            ) else {
                continue;
            };
            let q = Question {
                target,
                container: kind,
                room: in_room,
            };
            let e = tally.entry(q).or_insert((0.0, 0.0));
            e.0 += f64::from(u8::from(scene.truth.holds(c, t)));
            e.1 += 1.0;
        }
    }
    tally
}

/// The folds of the container types and of the room types of `scenes`: dealt round the folds in
/// name order.
fn kind_folds(
    scenes: &[&Scene],
    folds: usize,
) -> (BTreeMap<String, usize>, BTreeMap<String, usize>) {
    let (containers, rooms) = kinds_of_names(scenes);
    let deal = |kind: BTreeSet<String>| -> BTreeMap<String, usize> {
        kind.into_iter()
            .enumerate()
            .map(|(i, n)| (n, i % folds))
            .collect()
    };
    (deal(containers), deal(rooms))
}

/// The container type names and the room type names of `scenes` (no `""`).
fn kinds_of_names(scenes: &[&Scene]) -> (BTreeSet<String>, BTreeSet<String>) {
    let (mut containers, mut rooms) = (BTreeSet::new(), BTreeSet::new());
    for s in scenes {
        for (c, container) in s.house.containers.iter().enumerate() {
            containers.insert(container.object_type.as_str().to_string());
            if let Some(r) = s.house.container_room(c) {
                rooms.insert(r.room_type.as_str().to_string());
            }
        }
    }
    (containers, rooms)
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

fn learned_error(message: impl Into<String>) -> PlanError {
    PlanError::Learned {
        message: message.into(),
    }
}

/// Trains a learned source on `scenes` (the training houses `prior` was counted on), over
/// `vectors` (every name [`scene_names`] gives, but `""`), from `embedding`. Deterministic: the
/// same inputs and settings give the same model, whatever the number of threads.
pub fn train(
    scenes: &[&Scene],
    prior: &Prior,
    embedding: &str,
    vectors: BTreeMap<String, Vec<f32>>,
    settings: &LearnedSettings,
) -> Result<Learned, PlanError> {
    let folds = settings.folds;
    if folds < 2 {
        return Err(learned_error(format!(
            "{folds} folds: training holds types out in at least 2 folds"
        )));
    }
    if scenes.len() < 2 * folds {
        return Err(learned_error(format!(
            "{} training houses for {folds} folds: at least {} are needed",
            scenes.len(),
            2 * folds
        )));
    }
    let dim = vectors.values().next().map_or(0, Vec::len);
    if dim == 0 {
        return Err(learned_error("no word vectors given"));
    }
    if let Some((name, v)) = vectors.iter().find(|(_, v)| v.len() != dim) {
        return Err(learned_error(format!(
            "the vector of `{name}` has {} numbers, others {dim}",
            v.len()
        )));
    }
    let mut names: BTreeSet<String> = BTreeSet::new();
    for s in scenes {
        names.extend(scene_names(s));
    }
    let names: Vec<String> = names.into_iter().collect();
    let missing: Vec<&str> = names
        .iter()
        .filter(|n| !n.is_empty() && !vectors.contains_key(n.as_str()))
        .map(String::as_str)
        .collect();
    if !missing.is_empty() {
        return Err(learned_error(format!(
            "no vector for {} name(s) of the training houses: {}",
            missing.len(),
            missing.join(", ")
        )));
    }
    let index: BTreeMap<&str, usize> = names
        .iter()
        .enumerate()
        .map(|(i, n)| (n.as_str(), i))
        .collect();
    // Target types fall into folds by HoldOut's hash, so a run holding out target types finds
    // the heads that never saw them. Container and room types are dealt round the folds in name
    // order instead: ProcTHOR has four room types, and a hash put two of them in one fold,
    // whose heads then never saw a kitchen or a bedroom.
    let (container_fold, room_fold) = kind_folds(scenes, folds);
    let target_fold: Vec<usize> = names.iter().map(|n| fold_of(n, folds)).collect();
    let fold_in =
        |map: &BTreeMap<String, usize>, name: &str| map.get(name).copied().unwrap_or(usize::MAX);
    let c_fold: Vec<usize> = names.iter().map(|n| fold_in(&container_fold, n)).collect();
    let r_fold: Vec<usize> = names.iter().map(|n| fold_in(&room_fold, n)).collect();
    let language_vectors: Vec<Vec<f32>> = names
        .iter()
        .map(|n| vectors.get(n).cloned().unwrap_or_else(|| vec![0.0; dim]))
        .collect();
    let control_vectors: Vec<Vec<f32>> = names
        .iter()
        .map(|n| {
            if n.is_empty() {
                vec![0.0; dim]
            } else {
                random_vector(n, dim)
            }
        })
        .collect();

    let per_house: Vec<Tally> = scenes.iter().map(|s| house_questions(s, &index)).collect();
    let held_out = |q: &Question, k: usize| {
        target_fold[q.target] == k || c_fold[q.container] == k || r_fold[q.room] == k
    };
    // Per fold: the questions its heads learn from (other houses, no held-out type) and the
    // questions they answer blind (its own houses).
    let mut learn: Vec<Tally> = vec![Tally::new(); folds];
    let mut blind: Vec<Tally> = vec![Tally::new(); folds];
    for (i, tally) in per_house.iter().enumerate() {
        for k in 0..folds {
            let blind_house = i % folds == k;
            let into = if blind_house {
                &mut blind[k]
            } else {
                &mut learn[k]
            };
            for (q, &(pos, n)) in tally {
                if !blind_house && held_out(q, k) {
                    continue;
                }
                let e = into.entry(*q).or_insert((0.0, 0.0));
                e.0 += pos;
                e.1 += n;
            }
        }
    }

    if let Some(k) = (0..folds).find(|&k| learn[k].is_empty() || blind[k].is_empty()) {
        return Err(learned_error(format!(
            "fold {} of {folds} has no question to learn from or none to be scored on: too few training houses or types for {folds} folds",
            k + 1
        )));
    }
    let examples = |tally: &Tally, table: &[Vec<f32>]| -> Vec<Example> {
        tally
            .iter()
            .map(|(q, &(positives, total))| Example {
                x: head_input(&table[q.target], &table[q.container], &table[q.room]),
                positives,
                total,
            })
            .collect()
    };
    // Every head is its own job: two cores train two at a time, and the results come back in
    // job order whatever finished first.
    let jobs: Vec<(bool, usize, usize)> = [false, true]
        .into_iter()
        .flat_map(|control| {
            (0..folds).flat_map(move |k| (0..settings.seeds.max(1)).map(move |s| (control, k, s)))
        })
        .collect();
    let heads: Vec<Head> = jobs
        .par_iter()
        .map(|&(control, k, s)| {
            let table = if control {
                &control_vectors
            } else {
                &language_vectors
            };
            let seed = settings
                .seed
                .wrapping_add((k * settings.seeds.max(1) + s) as u64)
                .wrapping_add(if control { 1 << 32 } else { 0 });
            Head::train(&examples(&learn[k], table), &settings.head, seed)
        })
        .collect();
    let mut by_model: [Vec<Vec<Head>>; 2] = [vec![Vec::new(); folds], vec![Vec::new(); folds]];
    for (&(control, k, _), head) in jobs.iter().zip(heads) {
        by_model[usize::from(control)][k].push(head);
    }
    let [language_heads, control_heads] = by_model;

    // The prior of each fold: counted on the other houses, without the fold's container and
    // room types, forgetting its target types; calibrated as the full prior is.
    let fold_priors: Vec<Prior> = (0..folds)
        .map(|k| {
            let keep = |c: &ObjectType, room: &str| {
                fold_in(&container_fold, c.as_str()) != k && fold_in(&room_fold, room) != k
            };
            let counted = Prior::count_where(
                scenes
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| i % folds != k)
                    .map(|(_, s)| *s),
                prior.smoothing,
                &keep,
            )
            .without_types(&|t: &ObjectType| fold_of(t.as_str(), folds) == k);
            counted.with_calibration(prior.calibration.clone())
        })
        .collect();

    let fit_model = |heads: Vec<Vec<Head>>,
                     table: &[Vec<f32>],
                     compare: bool|
     -> Result<LearnedModel, PlanError> {
        // (prior logit, head logit, evidence, holders, asked, target unseen) per blind question,
        // and its fold and question.
        let mut rows = Vec::new();
        let mut asked = Vec::new();
        for (k, tally) in blind.iter().enumerate() {
            for (q, &(pos, n)) in tally {
                let x = head_input(&table[q.target], &table[q.container], &table[q.room]);
                let lh = mean_logit(&heads[k], &x);
                let target = ObjectType::new(names[q.target].as_str());
                let container = ObjectType::new(names[q.container].as_str());
                let room = names[q.room].as_str();
                let p = fold_priors[k].probability(&target, &container, Some(room));
                let e = fold_priors[k].evidence(&target, &container, room);
                rows.push((logit(p.get()), lh, e, pos, n, target_fold[q.target] == k));
                asked.push((k, *q));
            }
        }
        let head_rows: Vec<([f64; 2], f64, f64)> =
            rows.iter().map(|r| ([r.1, 1.0], r.3, r.4)).collect();
        let head_fit = fit_counts(&head_rows, [1.0, 0.0], [false, false]).ok_or_else(|| {
            learned_error("the head's scaling could not be fitted (one class only)")
        })?;
        let fusion_rows: Vec<([f64; FUSION_WEIGHTS], f64, f64)> = rows
            .iter()
            .map(|r| (fusion_features(r.0, r.1, &r.2), r.3, r.4))
            .collect();
        let mut start = [0.0; FUSION_WEIGHTS];
        start[0] = 1.0;
        let mut penalised = [true; FUSION_WEIGHTS];
        penalised[2] = false;
        let fusion = fit_counts(&fusion_rows, start, penalised)
            .ok_or_else(|| learned_error("the fusion could not be fitted (one class only)"))?;
        let scored = |only_unseen: bool| {
            let pick: Vec<_> = rows
                .iter()
                .zip(&fusion_rows)
                .filter(|(r, _)| !only_unseen || r.5)
                .collect();
            let score = |f: &dyn Fn(usize) -> f64| {
                weighted_auroc(
                    &pick
                        .iter()
                        .enumerate()
                        .map(|(i, (r, _))| (f(i), r.3, r.4))
                        .collect::<Vec<_>>(),
                )
            };
            HeldOutScore {
                questions: pick.iter().map(|(r, _)| r.4).sum(),
                positives: pick.iter().map(|(r, _)| r.3).sum(),
                prior_auroc: score(&|i| pick[i].0.0),
                head_auroc: score(&|i| pick[i].0.1),
                fused_auroc: score(&|i| pick[i].1.0.iter().zip(&fusion).map(|(x, w)| x * w).sum()),
            }
        };
        let counts_in_head = compare.then(|| {
            let joint: Vec<JointRow> = rows
                .iter()
                .zip(&fusion_rows)
                .zip(&asked)
                .map(|((r, f), &(k, q))| {
                    let mut x = head_input(&table[q.target], &table[q.container], &table[q.room]);
                    x.extend(
                        [r.0, r.2.target, r.2.container, r.2.room, r.2.pair].map(|v| v as f32),
                    );
                    JointRow {
                        fold: k,
                        features: f.0,
                        x,
                        positives: r.3,
                        total: r.4,
                        unseen: r.5,
                    }
                })
                .collect();
            let held = |i: usize, k: usize| held_out(&asked[i].1, k);
            compare_counts_in_head(&joint, folds, &held, settings)
        });
        Ok(LearnedModel {
            heads,
            head_fit,
            fusion: fusion.to_vec(),
            score: scored(false),
            unseen_score: scored(true),
            counts_in_head,
        })
    };
    let language = fit_model(
        language_heads,
        &language_vectors,
        settings.compare_counts_in_head,
    )?;
    let control = fit_model(control_heads, &control_vectors, false)?;
    Ok(Learned {
        ferret_learned: LEARNED_FORMAT,
        embedding: embedding.to_string(),
        dim,
        settings: settings.clone(),
        vectors: vectors.into_iter().filter(|(n, _)| !n.is_empty()).collect(),
        language,
        control,
    })
}

/// One cross-fitted question for [`compare_counts_in_head`].
struct JointRow {
    /// The fold whose heads and prior answered it blind.
    fold: usize,
    /// The fusion's inputs ([`fusion_features`]).
    features: [f64; FUSION_WEIGHTS],
    /// The joint head's inputs: [`head_input`], then the prior's logit and the four gaps.
    x: Vec<f32>,
    positives: f64,
    total: f64,
    /// Whether the target type was never seen by that fold.
    unseen: bool,
}

/// [`CountsInHead`] over cross-fitted rows: for each fold j, the fusion and a joint head are
/// fitted on the other folds' rows that hold none of fold j's types (`held(i, j)`), and score
/// fold j's rows.
fn compare_counts_in_head(
    rows: &[JointRow],
    folds: usize,
    held: &(dyn Fn(usize, usize) -> bool + Sync),
    settings: &LearnedSettings,
) -> CountsInHead {
    let scores: Vec<Vec<(usize, f64, f64)>> = (0..folds)
        .into_par_iter()
        .map(|j| {
            let train: Vec<usize> = (0..rows.len())
                .filter(|&i| rows[i].fold != j && !held(i, j))
                .collect();
            let fusion_rows: Vec<([f64; FUSION_WEIGHTS], f64, f64)> = train
                .iter()
                .map(|&i| (rows[i].features, rows[i].positives, rows[i].total))
                .collect();
            let mut start = [0.0; FUSION_WEIGHTS];
            start[0] = 1.0;
            let mut penalised = [true; FUSION_WEIGHTS];
            penalised[2] = false;
            let w = fit_counts(&fusion_rows, start, penalised).unwrap_or(start);
            let examples: Vec<Example> = train
                .iter()
                .map(|&i| Example {
                    x: rows[i].x.clone(),
                    positives: rows[i].positives,
                    total: rows[i].total,
                })
                .collect();
            let heads: Vec<Head> = (0..settings.seeds.max(1))
                .map(|s| {
                    let seed = settings
                        .seed
                        .wrapping_add((j * settings.seeds.max(1) + s) as u64)
                        .wrapping_add(2 << 32);
                    Head::train(&examples, &settings.head, seed)
                })
                .collect();
            (0..rows.len())
                .filter(|&i| rows[i].fold == j)
                .map(|i| {
                    let fused: f64 = rows[i].features.iter().zip(&w).map(|(x, w)| x * w).sum();
                    (i, fused, mean_logit(&heads, &rows[i].x))
                })
                .collect()
        })
        .collect();
    let scored: Vec<(usize, f64, f64)> = scores.into_iter().flatten().collect();
    let measure = |only_unseen: bool, pick: &dyn Fn(&(usize, f64, f64)) -> f64| {
        let chosen: Vec<(f64, f64, f64)> = scored
            .iter()
            .filter(|s| !only_unseen || rows[s.0].unseen)
            .map(|s| (pick(s), rows[s.0].positives, rows[s.0].total))
            .collect();
        (weighted_auroc(&chosen), grouped_log_loss(&chosen))
    };
    let (fusion_auroc, fusion_log_loss) = measure(false, &|s| s.1);
    let (head_auroc, head_log_loss) = measure(false, &|s| s.2);
    let (fusion_auroc_unseen, fusion_log_loss_unseen) = measure(true, &|s| s.1);
    let (head_auroc_unseen, head_log_loss_unseen) = measure(true, &|s| s.2);
    CountsInHead {
        fusion_auroc,
        head_auroc,
        fusion_log_loss,
        head_log_loss,
        fusion_auroc_unseen,
        head_auroc_unseen,
        fusion_log_loss_unseen,
        head_log_loss_unseen,
    }
}

/// Mean cross-entropy (nats per container) of logits over grouped rows (logit, positives,
/// total).
fn grouped_log_loss(rows: &[(f64, f64, f64)]) -> f64 {
    let (loss, n) = rows.iter().fold((0.0, 0.0), |(loss, n), &(z, pos, total)| {
        // −log σ(z) = softplus(−z) and −log(1 − σ(z)) = softplus(z), without overflow.
        (
            loss + pos * softplus(-z) + (total - pos) * softplus(z),
            n + total,
        )
    });
    if n > 0.0 { loss / n } else { 0.0 }
}

/// ln(1 + e^x), exact for large |x|.
fn softplus(x: f64) -> f64 {
    if x > 30.0 { x } else { x.exp().ln_1p() }
}

/// The mean of the heads' logits for `x`.
fn mean_logit(heads: &[Head], x: &[f32]) -> f64 {
    if heads.is_empty() {
        return 0.0;
    }
    heads.iter().map(|h| f64::from(h.logit(x))).sum::<f64>() / heads.len() as f64
}

/// AUROC of scores over grouped rows (score, positives, total): the chance that a random holder
/// scores above a random other container, ties counting half.
fn weighted_auroc(rows: &[(f64, f64, f64)]) -> f64 {
    let mut sorted: Vec<&(f64, f64, f64)> = rows.iter().collect();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let (mut neg_below, mut area) = (0.0, 0.0);
    let (pos_all, neg_all): (f64, f64) = rows
        .iter()
        .fold((0.0, 0.0), |(p, n), r| (p + r.1, n + r.2 - r.1));
    let mut i = 0;
    while i < sorted.len() {
        let mut j = i;
        let (mut pos, mut neg) = (0.0, 0.0);
        while j < sorted.len() && sorted[j].0 == sorted[i].0 {
            pos += sorted[j].1;
            neg += sorted[j].2 - sorted[j].1;
            j += 1;
        }
        area += pos * (neg_below + 0.5 * neg);
        neg_below += neg;
        i = j;
    }
    if pos_all > 0.0 && neg_all > 0.0 {
        area / (pos_all * neg_all)
    } else {
        0.5
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
                "the vector of `{name}` has {} numbers, the file says {}",
                v.len(),
                self.dim
            ));
        }
        for (what, model) in [("language", &self.language), ("control", &self.control)] {
            if model.heads.len() != self.settings.folds || model.heads.iter().any(Vec::is_empty) {
                return Err(format!(
                    "{what}: {} folds of heads for {} folds",
                    model.heads.len(),
                    self.settings.folds
                ));
            }
            if model
                .heads
                .iter()
                .flatten()
                .any(|h| !h.is_well_formed() || h.inputs() != head_inputs(self.dim))
            {
                return Err(format!(
                    "{what}: a head does not fit {}-number vectors",
                    self.dim
                ));
            }
            if model.fusion.len() != FUSION_WEIGHTS
                || !model
                    .fusion
                    .iter()
                    .chain(&model.head_fit)
                    .all(|w| w.is_finite())
            {
                return Err(format!(
                    "{what}: the fits are not {FUSION_WEIGHTS} + 2 finite numbers"
                ));
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

/// A likelihood source over a prior file's learned part ([`LearnedKind`]).
#[derive(Clone, Debug)]
pub struct LearnedSource {
    prior: Arc<Prior>,
    kind: LearnedKind,
    /// Answers by (target, container type, room type): a run asks the same few thousand
    /// questions again and again (every strategy's trials, every replay), and twenty heads per
    /// question made planning over the learned source four times as slow as over the prior.
    answers: Arc<std::sync::RwLock<Answers>>,
}

/// P(holds) by (target, container type, room type).
type Answers = std::collections::HashMap<(String, String, String), f64>;

/// Answers a [`LearnedSource`] keeps; past this it computes them again (the names a service
/// meets are few, but it runs for months).
const KEPT_ANSWERS: usize = 1 << 20;

impl LearnedSource {
    /// The source of `kind` over `prior`; an error when the prior has no learned part.
    pub fn new(prior: Arc<Prior>, kind: LearnedKind) -> Result<Self, String> {
        let Some(learned) = prior.learned() else {
            return Err(format!(
                "model/{} needs a prior trained with word vectors (`ferret prior train --embeddings DIR`); this prior has none",
                kind.name()
            ));
        };
        if let Some(h) = prior.holdout()
            && h.folds() != learned.settings.folds
        {
            return Err(format!(
                "--holdout-types with {} folds: the learned heads of this prior were trained with {} folds of held-out types, so only --holdout-types {} (or one fold of it) is answered by heads that never saw the held-out types",
                h.folds(),
                learned.settings.folds,
                learned.settings.folds
            ));
        }
        Ok(Self {
            prior,
            kind,
            answers: Arc::default(),
        })
    }

    /// P(holds) for one question.
    fn probability(
        &self,
        learned: &Learned,
        target: &ObjectType,
        container: &ObjectType,
        room: &str,
    ) -> Result<f64, String> {
        let control = self.kind.control();
        let model = if control {
            &learned.control
        } else {
            &learned.language
        };
        let embedder = self.prior.embedder();
        let x = head_input(
            &learned.vector(target.as_str(), control, "target type", embedder)?,
            &learned.vector(container.as_str(), control, "container type", embedder)?,
            &learned.vector(room, control, "room type", embedder)?,
        );
        // Under a hold-out, only the heads that never saw the target's fold may answer.
        let lh = match self.prior.holdout() {
            Some(h) => mean_logit(
                model
                    .heads
                    .get(h.prior_fold(target))
                    .map_or(&[][..], Vec::as_slice),
                &x,
            ),
            None => {
                model
                    .heads
                    .iter()
                    .map(|fold| mean_logit(fold, &x))
                    .sum::<f64>()
                    / model.heads.len().max(1) as f64
            }
        };
        if self.kind.head_only() {
            return Ok(sigmoid(model.head_fit[0] * lh + model.head_fit[1]));
        }
        let lp = logit(self.prior.probability(target, container, Some(room)).get());
        let e = self.prior.evidence(target, container, room);
        let fused: f64 = fusion_features(lp, lh, &e)
            .iter()
            .zip(&model.fusion)
            .map(|(x, w)| x * w)
            .sum();
        // The counts where they have evidence, the fusion where they have none: its weights
        // were fitted where the counts came from fewer houses and types than the prior's own,
        // so where the prior has seen the target, the furniture and the room, it is the prior
        // that knows best.
        let g = evidence_weight(&e);
        Ok(sigmoid((1.0 - g) * lp + g * fused))
    }
}

/// How much of a learned answer the fusion gives (the rest is the prior's): the largest of the
/// evidence gaps of the target, container and room types, so a question with any part the
/// counts never saw is the fusion's.
pub fn evidence_weight(e: &Evidence) -> f64 {
    e.target.max(e.container).max(e.room).clamp(0.0, 1.0)
}

impl LikelihoodSource for LearnedSource {
    fn name(&self) -> &str {
        self.kind.name()
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        let err = |message: String| PlanError::Likelihood {
            source_name: self.kind.name().to_string(),
            error: message.into(),
        };
        let learned = self
            .prior
            .learned()
            .ok_or_else(|| err("the prior has no learned part".into()))?;
        (0..house.containers.len())
            .map(|c| {
                let room = house
                    .container_room(c)
                    .map(|r| r.room_type.as_str())
                    .unwrap_or("");
                let container = &house.containers[c].object_type;
                let key = (
                    target.as_str().to_string(),
                    container.as_str().to_string(),
                    room.to_string(),
                );
                if let Some(&p) = self.answers.read().ok().as_ref().and_then(|a| a.get(&key)) {
                    return Ok(Probability::clamped(p, 0.0, 1.0));
                }
                let p = self
                    .probability(learned, target, container, room)
                    .map_err(err)?;
                if let Ok(mut answers) = self.answers.write()
                    && answers.len() < KEPT_ANSWERS
                {
                    answers.insert(key, p);
                }
                Ok(Probability::clamped(p, 0.0, 1.0))
            })
            .collect()
    }
}

#[cfg(test)]
mod tests;
