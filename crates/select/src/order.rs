//! The houses a deployment visits, in order, and the stream that picks one of a house's trials.
//! Batch deployments (`ferret deploy`) and the deployment experiment both take their houses from
//! a [`HouseOrder`].

use rand::seq::{SliceRandom, index};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::SelectError;

/// The houses (positions among `count` houses) of a deployment's trials, in order, and the
/// random stream that picks among a house's trials when it has several.
#[derive(Clone, Debug)]
pub struct HouseOrder {
    houses: Vec<usize>,
    picks: ChaCha8Rng,
}

impl HouseOrder {
    /// `trials` visits cycling through the houses in their order, as a robot in one home; picks
    /// come from `seed`.
    pub fn cycling(count: usize, trials: usize, seed: u64) -> Result<Self, SelectError> {
        check_count(count)?;
        Ok(Self {
            houses: (0..trials).map(|k| k % count).collect(),
            picks: ChaCha8Rng::seed_from_u64(seed),
        })
    }

    /// The first `trials` houses of a random permutation drawn from `rng`, which then picks
    /// (the order of `ferret deploy` and `ferret serve`).
    pub fn shuffled(count: usize, trials: usize, mut rng: ChaCha8Rng) -> Result<Self, SelectError> {
        check_distinct(count, trials)?;
        let mut houses: Vec<usize> = (0..count).collect();
        houses.shuffle(&mut rng);
        houses.truncate(trials);
        Ok(Self { houses, picks: rng })
    }

    /// `trials` distinct houses sampled from `rng` in random order, which then picks (the
    /// order of the deployment experiment).
    pub fn sampled(count: usize, trials: usize, mut rng: ChaCha8Rng) -> Result<Self, SelectError> {
        check_distinct(count, trials)?;
        let houses = index::sample(&mut rng, count, trials).into_vec();
        Ok(Self { houses, picks: rng })
    }

    /// `trials` houses drawn with replacement from `rng`, which then picks.
    pub fn with_replacement(
        count: usize,
        trials: usize,
        mut rng: ChaCha8Rng,
    ) -> Result<Self, SelectError> {
        check_count(count)?;
        let houses = (0..trials).map(|_| rng.random_range(0..count)).collect();
        Ok(Self { houses, picks: rng })
    }

    /// The same order, with picks from `picks` instead (so that picking never shifts the order
    /// of another deployment drawn from the same stream).
    pub fn picking_from(self, picks: ChaCha8Rng) -> Self {
        Self {
            houses: self.houses,
            picks,
        }
    }

    /// The house of each trial.
    pub fn houses(&self) -> &[usize] {
        &self.houses
    }

    /// One of `n > 0` trials of a house, uniformly; 0 when `n` is 0.
    pub fn pick(&mut self, n: usize) -> usize {
        if n == 0 {
            return 0;
        }
        self.picks.random_range(0..n)
    }
}

fn check_count(count: usize) -> Result<(), SelectError> {
    if count == 0 {
        return Err(SelectError::TooManyTrials {
            trials: 1,
            houses: 0,
        });
    }
    Ok(())
}

fn check_distinct(count: usize, trials: usize) -> Result<(), SelectError> {
    check_count(count)?;
    if trials > count {
        return Err(SelectError::TooManyTrials {
            trials,
            houses: count,
        });
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    proptest! {
        #[test]
        fn orders_visit_valid_houses_and_distinct_ones_when_asked(count in 1usize..40, trials in 0usize..60, seed: u64) {
            let rng = || ChaCha8Rng::seed_from_u64(seed);
            let all = [
                ("cycling", HouseOrder::cycling(count, trials, seed), false),
                ("shuffled", HouseOrder::shuffled(count, trials, rng()), true),
                ("sampled", HouseOrder::sampled(count, trials, rng()), true),
                ("replacement", HouseOrder::with_replacement(count, trials, rng()), false),
            ];
            for (name, order, distinct) in all {
                match order {
                    Err(_) => prop_assert!(distinct && trials > count, "{name}"),
                    Ok(order) => {
                        let h = order.houses();
                        prop_assert_eq!(h.len(), trials, "{}", name);
                        prop_assert!(h.iter().all(|&i| i < count), "{}", name);
                        if distinct {
                            let mut seen = h.to_vec();
                            seen.sort_unstable();
                            seen.dedup();
                            prop_assert_eq!(seen.len(), trials, "{} distinct", name);
                        }
                    }
                }
            }
        }

        #[test]
        fn picks_stay_below_their_bound(n in 1usize..20, seed: u64) {
            let mut order = HouseOrder::cycling(3, 3, seed).unwrap();
            for _ in 0..10 {
                prop_assert!(order.pick(n) < n);
            }
        }
    }

    #[test]
    fn no_houses_is_an_error_not_a_panic() {
        let rng = ChaCha8Rng::seed_from_u64(0);
        assert!(HouseOrder::cycling(0, 3, 0).is_err());
        assert!(HouseOrder::with_replacement(0, 3, rng.clone()).is_err());
        assert!(HouseOrder::sampled(0, 0, rng).is_err());
    }
}
