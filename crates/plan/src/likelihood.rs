//! Likelihood sources: anything that gives `P_S(target, container)`.

use std::collections::BTreeMap;
use std::path::Path;

use ferret_world::{GroundTruth, House, ObjectType, Scene};
use serde::{Deserialize, Serialize};

use crate::error::PlanError;
use crate::probability::Probability;

/// Gives, for a house and a target, the marginal probability that each container holds the target
/// (paper appendix D: not normalised across containers).
pub trait LikelihoodSource: Send + Sync {
    /// A short name for reports, e.g. `prior`.
    fn name(&self) -> &str;

    /// One probability per container of `house`, in [`House::containers`] order.
    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError>;
}

/// The same probability for every container: planning then trades distance only against how many
/// containers remain.
#[derive(Clone, Copy, Debug)]
pub struct Uniform {
    /// The probability given to every container.
    pub p: Probability,
}

impl Default for Uniform {
    fn default() -> Self {
        // 0.1 is roughly the chance that a given container in a ProcTHOR house holds a given
        // present object type (one goal container among ~10–20); any value in (0, 1) gives a
        // similar policy, but not the same one.
        Self {
            p: Probability::clamped(0.1, 0.0, 1.0),
        }
    }
}

impl LikelihoodSource for Uniform {
    fn name(&self) -> &str {
        "uniform"
    }

    fn likelihoods(
        &self,
        house: &House,
        _target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        Ok(vec![self.p; house.containers.len()])
    }
}

/// Ground truth as probabilities: 1 where the target is, 0 elsewhere. For bounds only; it is never
/// a selectable strategy.
#[derive(Clone, Debug)]
pub struct OracleLikelihood<'a> {
    truth: &'a GroundTruth,
}

impl<'a> OracleLikelihood<'a> {
    /// An oracle over one house's ground truth.
    pub fn new(truth: &'a GroundTruth) -> Self {
        Self { truth }
    }
}

impl LikelihoodSource for OracleLikelihood<'_> {
    fn name(&self) -> &str {
        "oracle"
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        Ok((0..house.containers.len())
            .map(|c| {
                if self.truth.holds(c, target) {
                    Probability::ONE
                } else {
                    Probability::ZERO
                }
            })
            .collect())
    }
}

/// How often containers of one kind held each object type in the training houses.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
struct Counts {
    /// Containers seen.
    containers: u32,
    /// For each object type, how many of those containers held at least one.
    holding: BTreeMap<ObjectType, u32>,
}

impl Counts {
    fn add(&mut self, held: &std::collections::BTreeSet<ObjectType>) {
        self.containers += 1;
        for t in held {
            *self.holding.entry(t.clone()).or_default() += 1;
        }
    }

    /// Additive smoothing toward `back_off` with weight `alpha` pseudo-containers.
    fn smoothed(&self, target: &ObjectType, alpha: f64, back_off: f64) -> f64 {
        let k = f64::from(self.holding.get(target).copied().unwrap_or(0));
        (k + alpha * back_off) / (f64::from(self.containers) + alpha)
    }
}

/// A prior learned from training houses: P(a container holds the target | container type, room
/// type), smoothed toward P(· | container type) and that toward the overall rate, so unseen
/// (container, room) pairs and unseen containers still get sensible values.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Prior {
    /// Pseudo-count weight of the back-off in each smoothing step.
    pub smoothing: f64,
    /// Number of training houses.
    pub houses: usize,
    /// Keyed by `ContainerType@RoomType`.
    by_pair: BTreeMap<String, Counts>,
    by_container: BTreeMap<ObjectType, Counts>,
    overall: Counts,
}

impl Prior {
    /// Learns a prior from scenes (training houses; ground truth is what training is for).
    pub fn train<'a>(scenes: impl IntoIterator<Item = &'a Scene>, smoothing: f64) -> Self {
        let mut prior = Prior {
            smoothing,
            ..Prior::default()
        };
        for scene in scenes {
            prior.houses += 1;
            for (c, container) in scene.house.containers.iter().enumerate() {
                let held: std::collections::BTreeSet<ObjectType> = scene
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
                prior
                    .by_pair
                    .entry(format!("{}@{}", container.object_type, room))
                    .or_default()
                    .add(&held);
                prior
                    .by_container
                    .entry(container.object_type.clone())
                    .or_default()
                    .add(&held);
                prior.overall.add(&held);
            }
        }
        prior
    }

    /// P(a container of `container` type in a room of `room` type holds `target`).
    pub fn probability(
        &self,
        target: &ObjectType,
        container: &ObjectType,
        room: Option<&str>,
    ) -> Probability {
        let a = self.smoothing.max(0.0);
        // Laplace-style base rate so an object never seen in training is unlikely but possible.
        let base = self
            .overall
            .smoothed(target, 1.0, 0.0)
            .max(1.0 / (f64::from(self.overall.containers) + 2.0));
        let by_type = self
            .by_container
            .get(container)
            .map_or(base, |c| c.smoothed(target, a, base));
        let by_pair = room
            .and_then(|r| self.by_pair.get(&format!("{container}@{r}")))
            .map_or(by_type, |c| c.smoothed(target, a, by_type));
        Probability::clamped(by_pair, 0.0, 1.0)
    }

    /// Number of training containers.
    pub fn container_count(&self) -> u32 {
        self.overall.containers
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

    /// Reads a prior written by [`save`](Self::save).
    pub fn load(path: &Path) -> Result<Self, PlanError> {
        let err = |message: String| PlanError::Prior {
            path: path.display().to_string(),
            message,
        };
        let text = ferret_world::input::read_text(path, ferret_world::input::MAX_INPUT_BYTES)
            .map_err(|e| err(e.to_string()))?;
        serde_json::from_str(&text).map_err(|e| err(format!("not a ferret prior: {e}")))
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
        Ok((0..house.containers.len())
            .map(|c| {
                let room = house.container_room(c).map(|r| r.room_type.as_str());
                self.probability(target, &house.containers[c].object_type, room)
            })
            .collect())
    }
}
