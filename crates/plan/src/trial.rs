//! Trials: drawing a target for a house, and the simulator that runs a strategy until the target
//! is found.

use ferret_world::{Distances, GroundTruth, House, ObjectType, Place, Point};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::belief::Belief;
use crate::error::PlanError;
use crate::policy::Policy;
use crate::protocol::{InitialBelief, Protocol, TargetSet};
use crate::strategy::{Strategy, TrialContext};

/// One house, one target, one start pose (the house's), and containers revealed beforehand.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialSpec {
    /// The object type to find.
    pub target: ObjectType,
    /// Containers known to be searched before the trial starts (usually none).
    pub revealed: Vec<usize>,
}

/// A deterministic RNG for house `index` under `seed`, independent of thread scheduling.
fn house_rng(seed: u64, index: usize, stream: u64) -> ChaCha8Rng {
    let mut rng =
        ChaCha8Rng::seed_from_u64(seed ^ (index as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15));
    rng.set_stream(stream);
    rng
}

/// Draws a trial for a house: the target uniformly among the small-object types present in its
/// containers; with `reveal_fraction > 0`, that fraction of the containers that do not hold the
/// target start out searched (some variants of the experiment do this).
pub fn draw_trial(
    house: &House,
    truth: &GroundTruth,
    seed: u64,
    reveal_fraction: f64,
) -> Result<TrialSpec, PlanError> {
    let types: Vec<ObjectType> = truth.target_types().into_iter().collect();
    if types.is_empty() {
        return Err(PlanError::NoTarget {
            house: house.name.clone(),
        });
    }
    let mut rng = house_rng(seed, house.index, 1);
    let target = types[rng.random_range(0..types.len())].clone();
    let revealed = reveal(house, truth, &target, reveal_fraction, &mut rng);
    Ok(TrialSpec { target, revealed })
}

/// The containers that start out searched: `reveal_fraction` of those not holding `target`.
fn reveal(
    house: &House,
    truth: &GroundTruth,
    target: &ObjectType,
    reveal_fraction: f64,
    rng: &mut ChaCha8Rng,
) -> Vec<usize> {
    let mut revealed = Vec::new();
    if reveal_fraction > 0.0 {
        let empty: Vec<usize> = (0..house.containers.len())
            .filter(|&c| !truth.holds(c, target))
            .collect();
        let k = ((empty.len() as f64) * reveal_fraction.clamp(0.0, 1.0)).round() as usize;
        let mut pool = empty;
        for _ in 0..k.min(pool.len()) {
            let i = rng.random_range(0..pool.len());
            revealed.push(pool.swap_remove(i));
        }
        revealed.sort_unstable();
    }
    revealed
}

/// How many trials (distinct targets) to run per house.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TrialsPerHouse {
    /// One target drawn per house: [`draw_trial`], the paper's protocol and ferret's default.
    #[default]
    One,
    /// Up to this many distinct targets per house (every target type when the house has fewer).
    Count(usize),
    /// Every target type present in the house, once each.
    All,
}

impl std::str::FromStr for TrialsPerHouse {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        match s.trim() {
            "all" => Ok(Self::All),
            n => match n.parse::<usize>() {
                Ok(0) => Err("must be at least 1, or `all`".into()),
                Ok(1) => Ok(Self::One),
                Ok(n) => Ok(Self::Count(n)),
                Err(_) => Err(format!("`{s}`: expected a number ≥ 1 or `all`")),
            },
        }
    }
}

impl std::fmt::Display for TrialsPerHouse {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::One => write!(f, "1"),
            Self::Count(n) => write!(f, "{n}"),
            Self::All => write!(f, "all"),
        }
    }
}

/// Draws the trials of a house, each with a distinct target. [`TrialsPerHouse::One`] is exactly
/// [`draw_trial`]. Otherwise the target types are shuffled by a generator of the house and
/// `seed` (a stream of its own, so the single-trial draw is untouched) and the first `n` kept —
/// the first of them is not necessarily [`draw_trial`]'s target; `All` keeps every type in name
/// order. Each trial's revealed containers are drawn as in [`draw_trial`].
pub fn draw_trials(
    house: &House,
    truth: &GroundTruth,
    seed: u64,
    reveal_fraction: f64,
    per_house: TrialsPerHouse,
) -> Result<Vec<TrialSpec>, PlanError> {
    draw_trials_with(
        house,
        truth,
        seed,
        reveal_fraction,
        per_house,
        &Protocol::FERRET,
    )
}

/// [`draw_trials`] under a protocol's target set and initial belief. Under ferret's protocol it
/// is exactly [`draw_trials`]. The paper's target set leaves out types that are also top-level
/// objects of the house (containers or other furniture); the paper's initial belief marks
/// searched, besides any `reveal_fraction`, all but a random number — between half and all but
/// one — of the containers that do not hold the target (drawn from a stream of its own).
pub fn draw_trials_with(
    house: &House,
    truth: &GroundTruth,
    seed: u64,
    reveal_fraction: f64,
    per_house: TrialsPerHouse,
    protocol: &Protocol,
) -> Result<Vec<TrialSpec>, PlanError> {
    let mut trials = match protocol.targets {
        TargetSet::Pickupable => draw_targets(
            house,
            truth.target_types().into_iter().collect(),
            truth,
            seed,
            reveal_fraction,
            per_house,
        )?,
        TargetSet::Paper => {
            let furniture: std::collections::BTreeSet<&ObjectType> = house
                .containers
                .iter()
                .map(|c| &c.object_type)
                .chain(house.obstacles.iter().map(|o| &o.object_type))
                .collect();
            let types = truth
                .target_types()
                .into_iter()
                .filter(|t| !furniture.contains(t))
                .collect();
            draw_targets(house, types, truth, seed, reveal_fraction, per_house)?
        }
    };
    if protocol.initial_belief == InitialBelief::Paper {
        let mut rng = house_rng(seed, house.index, 4);
        for t in &mut trials {
            let mut others: Vec<usize> = (0..house.containers.len())
                .filter(|&c| !truth.holds(c, &t.target))
                .collect();
            let m = others.len();
            if m == 0 {
                continue;
            }
            // Keep between half and all but one of the others unsearched.
            let keep = rng.random_range((m / 2).min(m - 1)..=m - 1);
            for _ in 0..keep {
                let i = rng.random_range(0..others.len());
                others.swap_remove(i);
            }
            t.revealed.extend(others);
            t.revealed.sort_unstable();
            t.revealed.dedup();
        }
    }
    Ok(trials)
}

/// The trials of a house among target `types` (in name order).
fn draw_targets(
    house: &House,
    mut types: Vec<ObjectType>,
    truth: &GroundTruth,
    seed: u64,
    reveal_fraction: f64,
    per_house: TrialsPerHouse,
) -> Result<Vec<TrialSpec>, PlanError> {
    if types.is_empty() {
        return Err(PlanError::NoTarget {
            house: house.name.clone(),
        });
    }
    let n = match per_house {
        TrialsPerHouse::One => {
            // The same stream and draws as `draw_trial`.
            let mut rng = house_rng(seed, house.index, 1);
            let target = types[rng.random_range(0..types.len())].clone();
            let revealed = reveal(house, truth, &target, reveal_fraction, &mut rng);
            return Ok(vec![TrialSpec { target, revealed }]);
        }
        TrialsPerHouse::Count(n) => n,
        TrialsPerHouse::All => types.len(),
    };
    let mut rng = house_rng(seed, house.index, 2);
    if per_house != TrialsPerHouse::All {
        rand::seq::SliceRandom::shuffle(types.as_mut_slice(), &mut rng);
        types.truncate(n);
    }
    Ok(types
        .into_iter()
        .map(|target| {
            let revealed = reveal(house, truth, &target, reveal_fraction, &mut rng);
            TrialSpec { target, revealed }
        })
        .collect())
}

/// What happened in a trial.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TrialOutcome {
    /// The strategy's name.
    pub strategy: String,
    /// The target.
    pub target: ObjectType,
    /// Distance travelled until the target was found (or everything was searched), metres.
    pub cost: f64,
    /// Containers searched, in order.
    pub searched: Vec<usize>,
    /// The container where the target was found; `None` when it is in no container.
    pub found: Option<usize>,
}

impl TrialOutcome {
    /// The places visited, from the start.
    pub fn places(&self) -> Vec<Place> {
        std::iter::once(Place::Start)
            .chain(self.searched.iter().map(|&c| Place::Container(c)))
            .collect()
    }

    /// The trajectory on the floor (the cells walked), when the distances came from a grid.
    pub fn trajectory(&self, distances: &Distances) -> Option<Vec<Point>> {
        let places = self.places();
        let mut points = Vec::new();
        for leg in places.windows(2) {
            let path = distances.path(leg[0], leg[1])?;
            points.extend(path);
        }
        Some(points)
    }
}

/// One trial in progress, one search at a time: what a robot loop drives (ask for the next
/// container, go there, report what was seen). The simulator [`run_trial`] is this loop with the
/// ground truth answering, so a robot and a simulation cannot plan differently.
pub struct Search<'a> {
    strategy: &'a dyn Strategy,
    policy: Box<dyn Policy + 'a>,
    belief: Belief<'a>,
}

impl<'a> Search<'a> {
    /// Starts `strategy` on a trial for `target` from the house's start. `revealed` are
    /// containers known before the trial, with what they hold. `truth` is read only by
    /// strategies that declare [`needs_ground_truth`](Strategy::needs_ground_truth) (the oracle);
    /// such a strategy fails without it.
    pub fn start(
        strategy: &'a dyn Strategy,
        house: &'a House,
        distances: &'a Distances,
        target: &'a ObjectType,
        truth: Option<&'a GroundTruth>,
        revealed: impl IntoIterator<Item = (usize, Vec<ObjectType>)>,
    ) -> Result<Self, PlanError> {
        let ctx = TrialContext {
            house,
            distances,
            target,
            truth: if strategy.needs_ground_truth() {
                Some(truth.ok_or_else(|| PlanError::BadChoice {
                    policy: strategy.name().into(),
                    container: 0,
                    why: "unusable: the strategy needs the ground truth and none is known",
                })?)
            } else {
                None
            },
        };
        let policy = strategy.policy(&ctx)?;
        let mut belief = Belief::new(house, distances, target);
        for (c, contents) in revealed {
            belief.reveal(c, contents);
        }
        Ok(Self {
            strategy,
            policy,
            belief,
        })
    }

    /// The container to search next, or `None` when every container has been searched.
    ///
    /// # Errors
    /// The policy's own failures, and a choice of a container that does not exist or was
    /// already searched.
    pub fn next_container(&mut self) -> Result<Option<usize>, PlanError> {
        if self.belief.unsearched_count() == 0 {
            return Ok(None);
        }
        let c = self.policy.choose(&self.belief)?;
        self.check(c)?;
        Ok(Some(c))
    }

    /// Records that container `c` was searched and held `seen`; returns the distance of the leg
    /// on the map, metres. The robot may search another container than the one proposed.
    ///
    /// # Errors
    /// [`PlanError::BadChoice`] for a container that does not exist or was already searched.
    pub fn record(&mut self, c: usize, seen: Vec<ObjectType>) -> Result<f64, PlanError> {
        self.check(c)?;
        Ok(self.belief.search(c, seen))
    }

    /// What is known so far.
    pub fn belief(&self) -> &Belief<'a> {
        &self.belief
    }

    fn check(&self, c: usize) -> Result<(), PlanError> {
        let why = if c >= self.belief.house.containers.len() {
            "not in the house"
        } else if self.belief.is_searched(c) {
            "already searched"
        } else {
            return Ok(());
        };
        Err(PlanError::BadChoice {
            policy: self.strategy.name().into(),
            container: c,
            why,
        })
    }
}

/// Runs `strategy` on one trial: replans after every search until a container holding the target
/// is searched or none is left.
pub fn run_trial(
    strategy: &dyn Strategy,
    house: &House,
    truth: &GroundTruth,
    distances: &Distances,
    trial: &TrialSpec,
) -> Result<TrialOutcome, PlanError> {
    let revealed = trial.revealed.iter().map(|&c| (c, contents_of(truth, c)));
    let mut search = Search::start(
        strategy,
        house,
        distances,
        &trial.target,
        Some(truth),
        revealed,
    )?;
    let mut found = None;
    while let Some(c) = search.next_container()? {
        search.record(c, contents_of(truth, c))?;
        if truth.holds(c, &trial.target) {
            found = Some(c);
            break;
        }
    }
    Ok(TrialOutcome {
        strategy: strategy.name().to_string(),
        target: trial.target.clone(),
        cost: search.belief().travelled(),
        searched: search.belief().searched_in_order().to_vec(),
        found,
    })
}

fn contents_of(truth: &GroundTruth, c: usize) -> Vec<ObjectType> {
    truth
        .contents(c)
        .iter()
        .map(|o| o.object_type.clone())
        .collect()
}
