//! numpy's legacy `RandomState`, as far as the paper's reference code draws from it to average
//! its table and to order its deployments: `seed(int)`, `shuffle` of a 1-d array and `choice`
//! of one element with replacement.
//!
//! The generator is MT19937 from the `rand_mt` crate (`Mt::new` is the reference
//! `init_genrand`, which numpy's legacy seeding with an integer uses); numpy's bounded integers
//! on top of it (a bit mask and rejection on 32-bit outputs) are a few lines that no maintained
//! crate offers, so they are written here, following numpy's `random_interval` and
//! `buffered_bounded_masked_uint32`, which the legacy `shuffle` and `randint` (under `choice`)
//! use.

use rand_mt::Mt;

/// numpy's `RandomState` seeded with an integer.
#[derive(Clone)]
pub struct LegacyRandomState {
    mt: Mt,
}

impl std::fmt::Debug for LegacyRandomState {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("LegacyRandomState")
    }
}

impl LegacyRandomState {
    /// `np.random.seed(seed)`.
    pub fn new(seed: u32) -> Self {
        Self { mt: Mt::new(seed) }
    }

    /// A uniform integer in `0..=max`: the smallest all-ones mask covering `max`, 32-bit outputs
    /// masked until one is not above `max`. Draws nothing for `max = 0`.
    pub fn interval(&mut self, max: u32) -> u32 {
        if max == 0 {
            return 0;
        }
        let mask = u32::MAX >> max.leading_zeros();
        loop {
            let v = self.mt.next_u32() & mask;
            if v <= max {
                return v;
            }
        }
    }

    /// `shuffle(a)` of a 1-d array: from the last position down to 1, swap with a position
    /// drawn in `0..=i`.
    pub fn shuffle<T>(&mut self, a: &mut [T]) {
        for i in (1..a.len()).rev() {
            let j = self.interval(i as u32) as usize;
            a.swap(i, j);
        }
    }

    /// The position `choice(a)` picks in an array of `len ≥ 1` elements (`randint(0, len)`);
    /// 0 without drawing for a single element.
    pub fn choice(&mut self, len: usize) -> usize {
        self.interval(len.saturating_sub(1) as u32) as usize
    }
}

/// How often the reference's averaging picks each of `n` items: for every run `s` in
/// `0..runs`, `seed(s)`, shuffle the items, then `draws` choices with replacement. The paper's
/// table reports each strategy's `Σ counts[m]·cost[m] / (runs·draws)` over its maps, in the
/// order the maps are listed; with `runs = 500`, `draws = 100` and 150 maps the counts range
/// from 295 to 381.
pub fn reference_draw_counts(n: usize, runs: u32, draws: usize) -> Vec<usize> {
    let mut counts = vec![0; n];
    if n == 0 {
        return counts;
    }
    for s in 0..runs {
        let mut rng = LegacyRandomState::new(s);
        let mut items: Vec<usize> = (0..n).collect();
        rng.shuffle(&mut items);
        for _ in 0..draws {
            counts[items[rng.choice(n)]] += 1;
        }
    }
    counts
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The first ten maps of runs 0 and 1 over the reference's seeds 1000…1149.
    #[test]
    fn first_draws_match_the_reference() {
        let first = |s: u32| {
            let mut rng = LegacyRandomState::new(s);
            let mut seeds: Vec<u32> = (1000..1150).collect();
            rng.shuffle(&mut seeds);
            (0..10)
                .map(|_| seeds[rng.choice(seeds.len())])
                .collect::<Vec<_>>()
        };
        assert_eq!(
            first(0),
            [1020, 1016, 1139, 1020, 1125, 1030, 1063, 1042, 1007, 1058]
        );
        assert_eq!(
            first(1),
            [1038, 1094, 1087, 1113, 1126, 1037, 1087, 1099, 1071, 1134]
        );
    }

    #[test]
    fn table_counts_match_the_reference() {
        #[rustfmt::skip]
        const COUNTS: [usize; 150] = [
            320, 348, 327, 343, 365, 315, 320, 354, 336, 329, 336, 323, 325, 339, 332, 334, 335, 332, 337, 325, 370, 327, 328, 308, 304,
            326, 369, 335, 312, 331, 331, 336, 323, 339, 312, 332, 300, 334, 345, 324, 354, 302, 307, 321, 303, 345, 341, 352, 356, 368,
            342, 331, 336, 331, 329, 336, 348, 334, 315, 325, 342, 321, 350, 350, 327, 328, 308, 307, 318, 347, 339, 335, 334, 363, 338,
            325, 308, 353, 302, 295, 381, 334, 323, 328, 354, 349, 324, 335, 321, 320, 310, 349, 355, 326, 332, 325, 319, 333, 362, 309,
            350, 352, 347, 340, 339, 310, 358, 349, 308, 337, 332, 355, 339, 348, 335, 345, 338, 336, 332, 310, 330, 359, 322, 336, 326,
            353, 350, 327, 344, 332, 304, 349, 334, 351, 296, 335, 335, 353, 301, 326, 344, 308, 369, 336, 316, 375, 300, 338, 323, 352,
        ];
        let counts = reference_draw_counts(150, 500, 100);
        assert_eq!(counts, COUNTS);
        assert_eq!(counts.iter().sum::<usize>(), 50_000);
    }

    #[test]
    fn interval_stays_in_range_and_single_choices_draw_nothing() {
        let mut a = LegacyRandomState::new(3);
        for max in [1u32, 2, 5, 149, 1 << 20] {
            for _ in 0..50 {
                assert!(a.interval(max) <= max);
            }
        }
        let (mut b, mut c) = (LegacyRandomState::new(9), LegacyRandomState::new(9));
        assert_eq!(b.choice(1), 0);
        assert_eq!(b.interval(1000), c.interval(1000));
        assert_eq!(reference_draw_counts(0, 5, 5), Vec::<usize>::new());
    }
}
