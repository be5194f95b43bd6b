//! CPython's `random` module, as far as the paper's reference code draws from it: seeding with
//! an integer, `getrandbits`, `randbelow` (under `randrange`) and `sample`.
//!
//! Reproducing these draws bit for bit lets `--rng python` give houses at the reference's line
//! indices the reference's very targets and initial beliefs. The generator itself is MT19937
//! from the `rand_mt` crate (its `new_with_key` is the reference `init_by_array`); what CPython
//! builds on top of it is a few lines of integer arithmetic that no maintained crate offers, so
//! it is written here, following CPython 3.10/3.11 (`Modules/_randommodule.c`,
//! `Lib/random.py`), whose algorithms these releases share.

use rand_mt::Mt;

/// CPython's `random.Random`, seeded with a non-negative integer.
#[derive(Clone)]
pub struct PyRandom {
    mt: Mt,
}

impl std::fmt::Debug for PyRandom {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("PyRandom")
    }
}

impl PyRandom {
    /// `random.seed(seed)`: MT19937 `init_by_array` on the 32-bit words of `seed`, least
    /// significant first (one word `0` for seed 0).
    pub fn new(seed: u64) -> Self {
        let (lo, hi) = (seed as u32, (seed >> 32) as u32);
        let mt = if hi == 0 {
            Mt::new_with_key([lo])
        } else {
            Mt::new_with_key([lo, hi])
        };
        Self { mt }
    }

    /// `getrandbits(k)` for `1 ≤ k ≤ 64`: whole 32-bit outputs, least significant word first,
    /// the last one cut to its top bits. `k` outside that range is clamped into it.
    pub fn getrandbits(&mut self, k: u32) -> u64 {
        let k = k.clamp(1, 64);
        if k <= 32 {
            return u64::from(self.mt.next_u32() >> (32 - k));
        }
        let low = u64::from(self.mt.next_u32());
        let high = u64::from(self.mt.next_u32() >> (64 - k));
        low | (high << 32)
    }

    /// `_randbelow(n)`: `getrandbits` of the bit length of `n` (not of `n − 1`), drawn again
    /// until below `n`. 0 for `n = 0`, without drawing.
    pub fn randbelow(&mut self, n: u64) -> u64 {
        if n == 0 {
            return 0;
        }
        let k = u64::BITS - n.leading_zeros();
        loop {
            let r = self.getrandbits(k);
            if r < n {
                return r;
            }
        }
    }

    /// `randint(a, b)` for `a ≤ b`: `a + randbelow(b − a + 1)`.
    pub fn randint(&mut self, a: u64, b: u64) -> u64 {
        a + self.randbelow(b.saturating_sub(a) + 1)
    }

    /// `sample(range(n), k)`: `k ≤ n` distinct positions in draw order, by CPython's two
    /// methods — a shrinking pool for small populations, rejection with a seen set otherwise —
    /// which draw differently, so the same choice of method is made. `k` above `n` is cut to `n`.
    pub fn sample(&mut self, n: usize, k: usize) -> Vec<usize> {
        let k = k.min(n);
        let mut setsize = 21usize;
        if k > 5 {
            // CPython: 4 ** _ceil(_log(k * 3, 4)), in floating point.
            let e = ((k * 3) as f64).ln() / 4f64.ln();
            setsize += 4usize.saturating_pow(e.ceil() as u32);
        }
        let mut out = Vec::with_capacity(k);
        if n <= setsize {
            let mut pool: Vec<usize> = (0..n).collect();
            for i in 0..k {
                let j = self.randbelow((n - i) as u64) as usize;
                out.push(pool[j]);
                pool[j] = pool[n - i - 1];
            }
        } else {
            let mut seen = std::collections::HashSet::with_capacity(k);
            for _ in 0..k {
                let mut j = self.randbelow(n as u64) as usize;
                while !seen.insert(j) {
                    j = self.randbelow(n as u64) as usize;
                }
                out.push(j);
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn raw_outputs_match_cpython() {
        let mut r = PyRandom::new(1000);
        let v: Vec<u64> = (0..3).map(|_| r.getrandbits(32)).collect();
        assert_eq!(v, [3338721356, 1842444242, 2876878853]);
        let mut r = PyRandom::new(0);
        let v: Vec<u64> = (0..3).map(|_| r.getrandbits(32)).collect();
        assert_eq!(v, [3626764237, 1654615998, 3255389356]);
    }

    #[test]
    fn wide_getrandbits_puts_the_first_word_low() {
        let mut a = PyRandom::new(1000);
        let mut b = PyRandom::new(1000);
        let wide = a.getrandbits(40);
        let (lo, hi) = (b.getrandbits(32), b.getrandbits(32) >> 24);
        assert_eq!(wide, lo | (hi << 32));
    }

    /// `randint(⌊n/2⌋, n − 1)` then `sample(range(n), m)` after a fresh seed: the reference's
    /// unsearched containers.
    fn unsearched(seed: u64, n: usize) -> (usize, Vec<usize>) {
        let mut r = PyRandom::new(seed);
        let m = (r.randint((n / 2) as u64, (n - 1) as u64) as usize).max(n.min(2));
        (m, r.sample(n, m))
    }

    fn complement(n: usize, drawn: &[usize]) -> Vec<usize> {
        (0..n).filter(|i| !drawn.contains(i)).collect()
    }

    /// Seed, container count, kept count, the drawn positions, the rest.
    type UnsearchedCase = (u64, usize, usize, &'static [usize], &'static [usize]);

    #[test]
    fn unsearched_draws_match_the_reference() {
        let cases: [UnsearchedCase; 6] = [
            (1000, 5, 3, &[0, 3, 1], &[2, 4]),
            (1000, 10, 8, &[1, 6, 5, 0, 3, 9, 7, 8], &[2, 4]),
            (
                1000,
                22,
                17,
                &[21, 3, 12, 11, 2, 14, 5, 8, 6, 17, 20, 10, 18, 15, 7, 1, 16],
                &[0, 4, 9, 13, 19],
            ),
            (1001, 10, 5, &[3, 1, 6, 7, 8], &[0, 2, 4, 5, 9]),
            (
                1001,
                22,
                11,
                &[6, 2, 17, 12, 5, 13, 11, 9, 10, 18, 21],
                &[0, 1, 3, 4, 7, 8, 14, 15, 16, 19, 20],
            ),
            (1021, 10, 9, &[8, 2, 3, 9, 4, 7, 5, 6, 1], &[0]),
        ];
        for (seed, n, m, drawn, pre) in cases {
            let (got_m, got) = unsearched(seed, n);
            assert_eq!((got_m, got.as_slice()), (m, drawn), "seed {seed}, n {n}");
            assert_eq!(complement(n, &got), pre, "seed {seed}, n {n}");
        }
        let (m, got) = unsearched(1021, 40);
        assert_eq!((m, complement(40, &got)), (36, vec![2, 4, 9, 12]));
        let (m, got) = unsearched(1000, 40);
        assert_eq!(
            (m, complement(40, &got)),
            (33, vec![2, 9, 12, 16, 18, 19, 34])
        );
        assert_eq!(unsearched(1001, 40).0, 21);
    }

    #[test]
    fn target_indices_match_the_reference() {
        let cases = [
            (1000, [(7, 6), (15, 12), (30, 24)]),
            (1001, [(7, 6), (15, 12), (30, 25)]),
            (1021, [(7, 4), (15, 8), (30, 16)]),
        ];
        for (seed, by_types) in cases {
            for (types, index) in by_types {
                // `sample(list, 1)`: the pool method up to 21 types, the seen set above.
                assert_eq!(
                    PyRandom::new(seed).sample(types, 1),
                    [index],
                    "seed {seed}, {types} types"
                );
                assert_eq!(PyRandom::new(seed).randbelow(types as u64), index as u64);
            }
        }
    }

    #[test]
    fn sample_is_distinct_and_bounded_with_both_methods() {
        let mut r = PyRandom::new(7);
        for (n, k) in [(10, 10), (200, 150), (1000, 3), (4, 9)] {
            let s = r.sample(n, k);
            assert_eq!(s.len(), k.min(n));
            let set: std::collections::HashSet<_> = s.iter().collect();
            assert_eq!(set.len(), s.len());
            assert!(s.iter().all(|&i| i < n));
        }
        assert_eq!(r.randbelow(0), 0);
    }
}
