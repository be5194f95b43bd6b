//! The prior: likelihoods counted on training houses, calibrated, with its learned part and
//! hold-outs, as a prior file stores them.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::sync::Arc;

use ferret_world::{House, ObjectType, Scene};
use serde::{Deserialize, Serialize};

use crate::error::PlanError;
use crate::holdout::HoldOut;
use crate::likelihood::{Evidence, LikelihoodSource, Uniform, per_container};
use crate::probability::Probability;

/// How often containers of one kind held each object type in the training houses.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Counts {
    /// Containers seen.
    containers: u32,
    /// For each object type, how many of those containers held at least one.
    holding: BTreeMap<ObjectType, u32>,
    /// For each object type, how many of those containers stood in a house where the type was
    /// present: the denominator of P(holds | the target is in the house).
    #[serde(default)]
    present: BTreeMap<ObjectType, u32>,
    /// The sums over every type that [`any_type`](Self::any_type) reads.
    #[serde(skip)]
    totals: Totals,
}

/// Adds one to `t`'s count, cloning the type only when it is new (`entry` would clone it every
/// time, and training counts every type of every house for every container in it).
fn bump(counts: &mut BTreeMap<ObjectType, u32>, t: &ObjectType) {
    match counts.get_mut(t) {
        Some(n) => *n += 1,
        None => {
            counts.insert(t.clone(), 1);
        }
    }
}

/// The sums of [`Counts::holding`] and [`Counts::present`], computed on first use and forgotten
/// whenever the counts change. Every question asks them of three counts, and summing a hundred
/// types each time was most of training a prior (its cross-fitting asks hundreds of thousands of
/// questions), paid again by every process that trains the default prior.
#[derive(Clone, Debug, Default)]
struct Totals(std::sync::OnceLock<(f64, f64)>);

impl PartialEq for Totals {
    /// A cache of what the counts say: never what makes two counts differ.
    fn eq(&self, _: &Self) -> bool {
        true
    }
}

impl Counts {
    fn add(&mut self, held: &BTreeSet<ObjectType>, in_house: &BTreeSet<ObjectType>) {
        self.totals = Totals::default();
        self.containers += 1;
        for t in held {
            bump(&mut self.holding, t);
        }
        for t in in_house {
            bump(&mut self.present, t);
        }
    }

    /// Additive smoothing toward `back_off` with weight `alpha` pseudo-containers, over every
    /// container seen (whether or not the target was in its house).
    fn smoothed(&self, target: &ObjectType, alpha: f64, back_off: f64) -> f64 {
        let k = f64::from(self.holding.get(target).copied().unwrap_or(0));
        (k + alpha * back_off) / (f64::from(self.containers) + alpha)
    }

    /// Containers of this kind that stood in a house holding `target`.
    fn present(&self, target: &ObjectType) -> u32 {
        self.present.get(target).copied().unwrap_or(0)
    }

    /// P(holds `target` | `target` is in the house), smoothed toward `back_off`.
    fn conditioned(&self, target: &ObjectType, alpha: f64, back_off: f64) -> f64 {
        let k = f64::from(self.holding.get(target).copied().unwrap_or(0));
        let n = f64::from(self.present(target));
        if n + alpha <= 0.0 {
            return back_off;
        }
        (k + alpha * back_off) / (n + alpha)
    }

    /// The same for an object type of any kind: how much a container of this kind holds of
    /// whatever is in its house (a counter holds more than a toilet), smoothed toward
    /// `back_off`. What the prior says about a type it never saw.
    fn any_type(&self, alpha: f64, back_off: f64) -> f64 {
        let &(k, n) = self.totals.0.get_or_init(|| {
            (
                self.holding.values().map(|&v| f64::from(v)).sum(),
                self.present.values().map(|&v| f64::from(v)).sum(),
            )
        });
        if n + alpha <= 0.0 {
            return back_off;
        }
        (k + alpha * back_off) / (n + alpha)
    }

    fn forget(&mut self, hidden: &dyn Fn(&ObjectType) -> bool) {
        self.totals = Totals::default();
        self.holding.retain(|t, _| !hidden(t));
        self.present.retain(|t, _| !hidden(t));
    }
}

/// The Platt scaling of the prior's estimates: `logit P = a·logit P_counts + c`, fitted by
/// cross-fitting on the training houses (each fold's houses scored by a prior counted on the
/// others), so that its probabilities mean what they say on houses it never saw.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PriorCalibration {
    /// Slope on the logit of the counted estimate.
    pub a: f64,
    /// Intercept.
    pub c: f64,
    /// Folds of the cross-fitting.
    pub folds: usize,
    /// (house, target, container) questions fitted.
    pub pairs: u64,
    /// Of them, containers holding the target.
    pub positives: u64,
}

impl PriorCalibration {
    /// The calibrated probability of a counted estimate `p`.
    pub fn apply(&self, p: f64) -> f64 {
        crate::logistic::sigmoid(self.a * crate::logistic::logit(p) + self.c)
    }
}

/// Folds of the calibration's cross-fitting when a prior is trained.
pub const CALIBRATION_FOLDS: usize = 5;

/// The format of prior files this version writes: 2 adds the presence counts and the calibration.
pub const PRIOR_FORMAT: u32 = 2;

/// A prior learned from training houses. Its probability is
/// P(a container holds the target | container type, room type, the target is in the house),
/// counted over the training houses that held the target, smoothed toward P(· | container type)
/// and that toward the target's overall rate (unseen pairs and containers still get sensible
/// values), then Platt-scaled ([`PriorCalibration`]). A target type no training house held gets
/// the rate of objects of any type in containers of that kind.
///
/// Every trial has its target in the house, so counting over all training houses (what
/// [`raw_probability`](Self::raw_probability) does, the estimate of earlier versions) understates
/// every probability by how often the type is absent, and a planner trading probability against
/// distance then walks too far for too little.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Prior {
    /// The file format ([`PRIOR_FORMAT`]; 0 for files of versions before it was recorded).
    #[serde(default)]
    pub ferret_prior: u32,
    /// Pseudo-count weight of the back-off in each smoothing step.
    pub smoothing: f64,
    /// Number of training houses.
    pub houses: usize,
    /// Keyed by `ContainerType@RoomType`.
    by_pair: BTreeMap<String, Counts>,
    by_container: BTreeMap<ObjectType, Counts>,
    overall: Counts,
    /// The Platt scaling, when it could be fitted (enough training houses with both classes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub calibration: Option<PriorCalibration>,
    /// The learned likelihood (`model/learned`), when the prior was trained with word vectors.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    learned: Option<Arc<crate::learned::Learned>>,
    /// Where the learned part finds vectors of names the file lacks.
    #[serde(skip)]
    embedder: Option<crate::learned::Embedder>,
    /// Held-out target types: priors that never saw them, asked in their stead.
    #[serde(skip)]
    hidden: Option<Arc<Hidden>>,
}

/// The priors of a [`HoldOut`]: one per fold, each the prior holding it without that fold's
/// types, made when a question first needs it (a run holding out fold 1 of 1 000 needs one of
/// them, and each is a copy of the prior).
#[derive(Debug)]
struct Hidden {
    holdout: HoldOut,
    priors: Vec<std::sync::OnceLock<Prior>>,
}

impl PartialEq for Hidden {
    /// The fold priors follow from the prior holding them: equal hold-outs are equal whatever
    /// was asked so far.
    fn eq(&self, other: &Self) -> bool {
        self.holdout == other.holdout
    }
}

impl Prior {
    /// Learns a prior from scenes (training houses; ground truth is what training is for) and
    /// fits its calibration by [`CALIBRATION_FOLDS`]-fold cross-fitting.
    pub fn train<'a>(scenes: impl IntoIterator<Item = &'a Scene>, smoothing: f64) -> Self {
        Self::train_with(scenes, smoothing, CALIBRATION_FOLDS)
    }

    /// [`train`](Self::train) with `folds` folds of cross-fitting for the calibration; 0 or 1
    /// leaves the prior uncalibrated (the counted estimate), as does a set of houses too small
    /// to fit on (fewer than two per fold, or no fold with both holders and others).
    pub fn train_with<'a>(
        scenes: impl IntoIterator<Item = &'a Scene>,
        smoothing: f64,
        folds: usize,
    ) -> Self {
        let scenes: Vec<&Scene> = scenes.into_iter().collect();
        let mut prior = Self::count(scenes.iter().copied(), smoothing);
        if folds >= 2 && scenes.len() >= 2 * folds {
            prior.calibration = Self::cross_fit(&scenes, smoothing, folds);
        }
        prior
    }

    /// The counts alone, without a calibration.
    pub fn count<'a>(scenes: impl IntoIterator<Item = &'a Scene>, smoothing: f64) -> Self {
        Self::count_where(scenes, smoothing, &|_, _| true)
    }

    /// The counts of the containers `keep` accepts (by container type and room type), as if
    /// the others had not stood in the training houses: the prior of a world without some
    /// kinds of furniture or rooms, which is what a learned source is cross-fitted against.
    pub fn count_where<'a>(
        scenes: impl IntoIterator<Item = &'a Scene>,
        smoothing: f64,
        keep: &dyn Fn(&ObjectType, &str) -> bool,
    ) -> Self {
        let mut prior = Prior {
            ferret_prior: PRIOR_FORMAT,
            smoothing,
            ..Prior::default()
        };
        for scene in scenes {
            prior.houses += 1;
            let in_house = scene.truth.target_types();
            for (c, container) in scene.house.containers.iter().enumerate() {
                let held: BTreeSet<ObjectType> = scene
                    .truth
                    .contents(c)
                    .iter()
                    .map(|o| o.object_type.clone())
                    .collect();
                let room = scene
                    .house
                    .container_room(c)
                    .map(|r| r.room_type.as_str())
                    .unwrap_or("");
                if !keep(&container.object_type, room) {
                    continue;
                }
                prior
                    .by_pair
                    .entry(format!("{}@{}", container.object_type, room))
                    .or_default()
                    .add(&held, &in_house);
                prior
                    .by_container
                    .entry(container.object_type.clone())
                    .or_default()
                    .add(&held, &in_house);
                prior.overall.add(&held, &in_house);
            }
        }
        prior
    }

    /// Fits the Platt scaling: each fold's houses (every target present, every container) are
    /// scored by a prior counted on the other folds.
    fn cross_fit(scenes: &[&Scene], smoothing: f64, folds: usize) -> Option<PriorCalibration> {
        // Questions grouped by their counted probability (positives, total): tens of millions of
        // questions over a large training set share a few hundred thousand values, and a row
        // per question would hold them all in memory.
        let mut groups: BTreeMap<u64, (f64, f64)> = BTreeMap::new();
        for f in 0..folds {
            let counted = Self::count(
                scenes
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| i % folds != f)
                    .map(|(_, s)| *s),
                smoothing,
            );
            for scene in scenes.iter().skip(f).step_by(folds) {
                // Each container's counts, looked up once for all the house's targets.
                let kinds: Vec<(Option<&Counts>, Option<&Counts>)> =
                    (0..scene.house.containers.len())
                        .map(|c| counted.kind_counts(&scene.house, c))
                        .collect();
                for target in scene.truth.target_types() {
                    for (c, &(by_container, pair)) in kinds.iter().enumerate() {
                        let p = counted.counted_from(&target, by_container, pair);
                        let group = groups
                            .entry(crate::logistic::logit(p).to_bits())
                            .or_default();
                        group.1 += 1.0;
                        if scene.truth.holds(c, &target) {
                            group.0 += 1.0;
                        }
                    }
                }
            }
        }
        let rows: Vec<([f64; 2], f64, f64)> = groups
            .iter()
            .map(|(x, &(positives, total))| ([f64::from_bits(*x), 1.0], positives, total))
            .collect();
        let w = crate::logistic::fit_counts(&rows, [1.0, 0.0], [true, false])?;
        let (positives, pairs) = groups
            .values()
            .fold((0.0, 0.0), |(p, n), g| (p + g.0, n + g.1));
        Some(PriorCalibration {
            a: w[0],
            c: w[1],
            folds,
            pairs: pairs as u64,
            positives: positives as u64,
        })
    }

    /// The learned part, if the prior was trained with word vectors.
    pub fn learned(&self) -> Option<&crate::learned::Learned> {
        self.learned.as_deref()
    }

    /// The prior with `learned` as its learned part.
    pub fn with_learned(&self, learned: crate::learned::Learned) -> Prior {
        Prior {
            learned: Some(Arc::new(learned)),
            ..self.clone()
        }
    }

    /// The prior whose learned part also has `vectors` (names of houses its training houses
    /// never had, embedded with the same embeddings); names it has keep their vectors. Unchanged
    /// without a learned part.
    pub fn with_vectors(&self, vectors: BTreeMap<String, Vec<f32>>) -> Prior {
        let Some(learned) = &self.learned else {
            return self.clone();
        };
        let mut learned = (**learned).clone();
        for (name, v) in vectors {
            learned.vectors.entry(name).or_insert(v);
        }
        Prior {
            learned: Some(Arc::new(learned)),
            ..self.clone()
        }
    }

    /// The prior whose learned part looks up names its file lacks in `embedder`.
    pub fn with_embedder(&self, embedder: crate::learned::Embedder) -> Prior {
        Prior {
            embedder: Some(embedder),
            ..self.clone()
        }
    }

    /// Where the learned part looks up names its file lacks, if anywhere.
    pub fn embedder(&self) -> Option<&crate::learned::Embedder> {
        self.embedder.as_ref()
    }

    /// The same counts with another calibration.
    pub fn with_calibration(self, calibration: Option<PriorCalibration>) -> Prior {
        Prior {
            calibration,
            ..self
        }
    }

    /// The prior that asks about each target one that never saw the target types `holdout`
    /// holds out for it (its calibration is kept: two numbers fitted over all types, which
    /// carry no one type's counts).
    pub fn holding_out(&self, holdout: HoldOut) -> Prior {
        let priors = (0..holdout.folds())
            .map(|_| std::sync::OnceLock::new())
            .collect();
        Prior {
            hidden: Some(Arc::new(Hidden { holdout, priors })),
            ..self.without_hidden()
        }
    }

    /// The hold-out this prior applies, if any.
    pub fn holdout(&self) -> Option<HoldOut> {
        self.hidden.as_ref().map(|h| h.holdout)
    }

    /// The prior as if no training house had held an object of a type `hidden` accepts:
    /// exactly what training without those objects gives.
    pub fn without_types(&self, hidden: &dyn Fn(&ObjectType) -> bool) -> Prior {
        let mut p = self.without_hidden();
        for counts in p
            .by_pair
            .values_mut()
            .chain(p.by_container.values_mut())
            .chain(std::iter::once(&mut p.overall))
        {
            counts.forget(hidden);
        }
        p
    }

    fn without_hidden(&self) -> Prior {
        Prior {
            hidden: None,
            ..self.clone()
        }
    }

    /// The prior whose counts answer questions about `target`.
    fn counts_for(&self, target: &ObjectType) -> &Prior {
        match &self.hidden {
            Some(h) => {
                let k = h.holdout.prior_fold(target);
                let folds = h.holdout.folds();
                h.priors.get(k).map_or(self, |cell| {
                    cell.get_or_init(|| {
                        self.without_types(&|t: &ObjectType| HoldOut::fold_of(t, folds) == k)
                    })
                })
            }
            None => self,
        }
    }

    /// Whether the training houses ever held an object of type `t` (after any hold-out).
    pub fn has_seen(&self, t: &ObjectType) -> bool {
        self.counts_for(t).overall.present(t) > 0
    }

    /// P(a container of `container` type in a room of `room` type holds `target` | the target
    /// is in the house), calibrated: what `model/prior` plans with.
    pub fn probability(
        &self,
        target: &ObjectType,
        container: &ObjectType,
        room: Option<&str>,
    ) -> Probability {
        let p = self
            .counts_for(target)
            .counted_probability(target, container, room);
        let p = match &self.calibration {
            Some(c) => c.apply(p),
            None => p,
        };
        Probability::clamped(p, 0.0, 1.0)
    }

    /// The counted estimate of [`probability`](Self::probability), before calibration.
    fn counted_probability(
        &self,
        target: &ObjectType,
        container: &ObjectType,
        room: Option<&str>,
    ) -> f64 {
        let pair = room.and_then(|r| self.by_pair.get(&format!("{container}@{r}")));
        self.counted_from(target, self.by_container.get(container), pair)
    }

    /// The counts of container `c`'s kind in `house`: of its type, and of its type in its room.
    fn kind_counts(&self, house: &House, c: usize) -> (Option<&Counts>, Option<&Counts>) {
        let Some(container) = house.containers.get(c) else {
            return (None, None);
        };
        let room = house.container_room(c).map(|r| r.room_type.as_str());
        (
            self.by_container.get(&container.object_type),
            room.and_then(|r| self.by_pair.get(&format!("{}@{r}", container.object_type))),
        )
    }

    /// [`counted_probability`](Self::counted_probability) from the counts of the container's
    /// type (`by_type`) and of its type in its room (`pair`).
    fn counted_from(
        &self,
        target: &ObjectType,
        by_type: Option<&Counts>,
        pair: Option<&Counts>,
    ) -> f64 {
        let a = self.smoothing.max(0.0);
        // The fallback of a prior that has seen nothing at all: the uniform source's value.
        let any = self.overall.any_type(0.0, Uniform::default().p.get());
        let ratio = |x: f64, y: f64| if y > 0.0 { x / y } else { 1.0 };
        let any_c = by_type.map_or(any, |c| c.any_type(a, any));
        let any_p = pair.map_or(any_c, |c| c.any_type(a, any_c));
        // Back-offs multiply relative rates: the target's rate over all containers scaled by how
        // much this kind of container holds, and that by how much more it holds in this room.
        let rate = self.overall.conditioned(target, a, any);
        let by_type = {
            let back_off = (any_c * ratio(rate, any)).clamp(0.0, 1.0);
            by_type.map_or(back_off, |c| c.conditioned(target, a, back_off))
        };
        let back_off = (by_type * ratio(any_p, any_c)).clamp(0.0, 1.0);
        pair.map_or(back_off, |c| c.conditioned(target, a, back_off))
            .clamp(0.0, 1.0)
    }

    /// The estimate of earlier versions, kept for the paper's comparison (`model/prior-raw`):
    /// P(holds | container type, room type) counted over every training house, whether or not
    /// it held the target, and not calibrated.
    pub fn raw_probability(
        &self,
        target: &ObjectType,
        container: &ObjectType,
        room: Option<&str>,
    ) -> Probability {
        let prior = self.counts_for(target);
        let a = prior.smoothing.max(0.0);
        // Laplace-style base rate so an object never seen in training is unlikely but possible.
        let base = prior
            .overall
            .smoothed(target, 1.0, 0.0)
            .max(1.0 / (f64::from(prior.overall.containers) + 2.0));
        let by_type = prior
            .by_container
            .get(container)
            .map_or(base, |c| c.smoothed(target, a, base));
        let by_pair = room
            .and_then(|r| prior.by_pair.get(&format!("{container}@{r}")))
            .map_or(by_type, |c| c.smoothed(target, a, by_type));
        Probability::clamped(by_pair, 0.0, 1.0)
    }

    /// How little evidence the training houses give about `target` in a container of type
    /// `container`: `s / (n + s)` with `n` the training containers of that type that stood in a
    /// house holding the target and `s` the smoothing weight (at least 1). 1 for a target or a
    /// container type never seen together, near 0 for a pair seen often. A fusion lets the other
    /// source carry the weight where this is high.
    pub fn evidence_gap(&self, target: &ObjectType, container: &ObjectType) -> f64 {
        let n = self
            .counts_for(target)
            .by_container
            .get(container)
            .map_or(0, |c| c.present(target));
        let s = self.smoothing.max(1.0);
        s / (f64::from(n) + s)
    }

    /// How little the training houses (after any hold-out) say about each part of a question,
    /// each as `s / (n + s)` like [`evidence_gap`](Self::evidence_gap): of the target type
    /// (containers that stood in a house holding it), of the container type (containers of it
    /// seen), of the room type (containers seen in such rooms) and of the pair (containers of
    /// the type in a house holding the target). One gap cannot tell a pairing never seen from
    /// furniture never seen; these can.
    pub fn evidence(&self, target: &ObjectType, container: &ObjectType, room: &str) -> Evidence {
        let counts = self.counts_for(target);
        let s = self.smoothing.max(1.0);
        let gap = |n: u32| s / (f64::from(n) + s);
        let by_type = counts.by_container.get(container);
        let suffix = format!("@{room}");
        let in_room: u32 = counts
            .by_pair
            .iter()
            .filter(|(k, _)| k.ends_with(&suffix))
            .map(|(_, c)| c.containers)
            .sum();
        Evidence {
            target: gap(counts.overall.present(target)),
            container: gap(by_type.map_or(0, |c| c.containers)),
            room: gap(in_room),
            pair: gap(by_type.map_or(0, |c| c.present(target))),
        }
    }

    /// [`evidence_gap`](Self::evidence_gap) of every container of `house`.
    pub fn evidence_gaps(&self, house: &House, target: &ObjectType) -> Vec<f64> {
        house
            .containers
            .iter()
            .map(|c| self.evidence_gap(target, &c.object_type))
            .collect()
    }

    /// Number of training containers.
    pub fn container_count(&self) -> u32 {
        self.overall.containers
    }

    /// The object types the training houses held (before any hold-out).
    pub fn seen_types(&self) -> impl Iterator<Item = &ObjectType> {
        self.overall.present.keys()
    }

    /// Writes the prior as JSON.
    pub fn save(&self, path: &Path) -> Result<(), PlanError> {
        let err = |message: String| PlanError::Prior {
            path: path.display().to_string(),
            message,
        };
        let json = serde_json::to_string_pretty(self).map_err(|e| err(e.to_string()))?;
        std::fs::write(path, json).map_err(|e| err(e.to_string()))
    }

    /// Reads a prior written by [`save`](Self::save). A file of a format before
    /// [`PRIOR_FORMAT`] is refused: it lacks the presence counts the estimate needs.
    pub fn load(path: &Path) -> Result<Self, PlanError> {
        let err = |message: String| PlanError::Prior {
            path: path.display().to_string(),
            message,
        };
        let text = ferret_world::input::read_text(path, ferret_world::input::MAX_INPUT_BYTES)
            .map_err(|e| err(e.to_string()))?;
        let prior: Prior =
            serde_json::from_str(&text).map_err(|e| err(format!("not a ferret prior: {e}")))?;
        if prior.ferret_prior != PRIOR_FORMAT {
            return Err(err(format!(
                "format {} (this ferret reads {PRIOR_FORMAT}; a file without presence counts was written by an older ferret): train it again with `ferret prior train`",
                prior.ferret_prior
            )));
        }
        if let Some(c) = &prior.calibration
            && !(c.a.is_finite() && c.c.is_finite())
        {
            return Err(err("calibration weights are not finite numbers".into()));
        }
        if let Some(learned) = &prior.learned {
            learned
                .check()
                .map_err(|m| err(format!("learned part: {m}")))?;
        }
        Ok(prior)
    }
}

impl LikelihoodSource for Prior {
    fn name(&self) -> &str {
        "prior"
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        Ok(per_container(house, |container, room| {
            self.probability(target, container, room)
        }))
    }
}

/// The prior's estimate of earlier versions ([`Prior::raw_probability`]), as a source:
/// `model/prior-raw`.
#[derive(Clone, Debug)]
pub struct RawPrior(pub Arc<Prior>);

impl LikelihoodSource for RawPrior {
    fn name(&self) -> &str {
        "prior-raw"
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        Ok(per_container(house, |container, room| {
            self.0.raw_probability(target, container, room)
        }))
    }
}

#[cfg(test)]
mod hold_out_tests {
    use super::*;

    /// A hold-out of a thousand folds builds only the fold priors its questions need: before,
    /// it copied the prior a thousand times up front (and `1/100000` ran out of memory).
    #[test]
    fn a_hold_out_builds_only_the_folds_it_is_asked_about() {
        let scenes = ferret_world::generate::default_scenes(6, 3).unwrap();
        let prior = Prior::count(&scenes, 2.0);
        let held = prior.holding_out(HoldOut::every_fold(crate::holdout::MAX_FOLDS).unwrap());
        let built = |p: &Prior| {
            p.hidden
                .as_ref()
                .map_or(0, |h| h.priors.iter().filter(|c| c.get().is_some()).count())
        };
        assert_eq!(built(&held), 0);
        let house = &scenes[0].house;
        let targets = scenes[0].truth.target_types();
        for t in &targets {
            held.likelihoods(house, t).unwrap();
        }
        let folds: std::collections::BTreeSet<usize> = targets
            .iter()
            .map(|t| HoldOut::fold_of(t, crate::holdout::MAX_FOLDS))
            .collect();
        assert_eq!(built(&held), folds.len());
        // Asking again builds nothing more; a clone shares what was built.
        let again = held.clone();
        again
            .likelihoods(house, targets.iter().next().unwrap())
            .unwrap();
        assert_eq!(built(&again), folds.len());
    }
}
