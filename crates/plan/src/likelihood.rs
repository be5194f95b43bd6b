//! Likelihood sources: anything that gives `P_S(target, container)`.

use ferret_world::{GroundTruth, House, ObjectType};
use sha2::{Digest, Sha256};

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

    /// Checks, before any trial, that every name of `house` and `targets` can be answered:
    /// notes on names read otherwise than spelt (a word taken as its base form or a WordNet
    /// hypernym, a word left out), or an error naming the first name that cannot be and what to
    /// give. Sources that answer any name (counts, an LLM) have nothing to check.
    fn check_names(&self, house: &House, targets: &[ObjectType]) -> Result<Vec<String>, String> {
        let _ = (house, targets);
        Ok(Vec::new())
    }
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

/// The seed of [`Noise`] when none is given.
pub const NOISE_SEED: u64 = 0x5eed;

/// A control that knows nothing: for each (target, container type, room type) question a fixed
/// pseudo-random probability in [0.01, 0.99], as an LLM that answered every distinct question
/// with noise would. Fused with the prior, it shows what a fusion fit alone gives.
#[derive(Clone, Copy, Debug)]
pub struct Noise {
    /// The seed of the answers.
    pub seed: u64,
}

impl Default for Noise {
    fn default() -> Self {
        Self { seed: NOISE_SEED }
    }
}

impl Noise {
    /// The probability it gives `target` in a `container` in a `room`.
    pub fn probability(&self, target: &ObjectType, container: &ObjectType, room: &str) -> f64 {
        let mut h = Sha256::new();
        h.update(self.seed.to_le_bytes());
        for part in [target.as_str(), container.as_str(), room] {
            h.update((part.len() as u64).to_le_bytes());
            h.update(part.as_bytes());
        }
        let digest = h.finalize();
        let mut first = [0u8; 8];
        first.copy_from_slice(&digest[..8]);
        let u = (u64::from_le_bytes(first) >> 11) as f64 / (1u64 << 53) as f64;
        0.01 + 0.98 * u
    }
}

impl LikelihoodSource for Noise {
    fn name(&self) -> &str {
        "noise"
    }

    fn likelihoods(
        &self,
        house: &House,
        target: &ObjectType,
    ) -> Result<Vec<Probability>, PlanError> {
        Ok(per_container(house, |container, room| {
            Probability::clamped(
                self.probability(target, container, room.unwrap_or("")),
                0.0,
                1.0,
            )
        }))
    }
}

/// The evidence gaps of one question ([`Prior::evidence`](crate::Prior::evidence)), each in (0, 1]: 1 where the training
/// houses showed nothing, near 0 where they showed much.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Evidence {
    /// Of the target type.
    pub target: f64,
    /// Of the container type.
    pub container: f64,
    /// Of the room type.
    pub room: f64,
    /// Of the target in containers of this type.
    pub pair: f64,
}

/// `estimate(container type, room type)` for every container of `house`, in order.
pub(crate) fn per_container(
    house: &House,
    estimate: impl Fn(&ObjectType, Option<&str>) -> Probability,
) -> Vec<Probability> {
    (0..house.containers.len())
        .map(|c| {
            let room = house.container_room(c).map(|r| r.room_type.as_str());
            estimate(&house.containers[c].object_type, room)
        })
        .collect()
}
