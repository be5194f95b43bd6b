//! Paired comparisons of two strategies on the same trials: the mean paired difference with a
//! bootstrap confidence interval, the Wilcoxon signed-rank test, and wins, ties and losses.
//!
//! Two strategies run on the same house and target are compared trial by trial: the spread
//! between houses (some houses are simply large) cancels out, so a difference that an unpaired
//! confidence interval hides can be a tested claim. The normal CDF comes from `statrs`; the
//! signed-rank test and the percentile bootstrap are written here because no maintained crate
//! offers them without a linear-algebra stack, and both are short.

use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use statrs::function::erf::erfc;

/// Differences of at most this many metres count as ties (costs are sums of float distances).
pub const TIE_TOLERANCE: f64 = 1e-9;

/// Largest number of non-zero differences for which the signed-rank p-value is exact (when no
/// two absolute differences tie); above it, or with ties, the normal approximation is used. The
/// same threshold as SciPy's `wilcoxon(method="auto")`.
pub const EXACT_WILCOXON_MAX: usize = 50;

/// The Wilcoxon signed-rank test of differences `d` against a zero median.
#[derive(Clone, Debug, PartialEq)]
pub struct Wilcoxon {
    /// Non-zero differences ranked (zeros are dropped, Wilcoxon's original convention).
    pub n: usize,
    /// Sum of the ranks of the positive differences.
    pub w_plus: f64,
    /// Sum of the ranks of the negative differences.
    pub w_minus: f64,
    /// Two-sided p-value.
    pub p: f64,
    /// Whether `p` comes from the exact null distribution (else the normal approximation).
    pub exact: bool,
}

/// Two-sided Wilcoxon signed-rank test. Zero differences (|d| ≤ [`TIE_TOLERANCE`]) are dropped;
/// tied absolute differences get their average rank. The p-value is exact for at most
/// [`EXACT_WILCOXON_MAX`] differences without ties, else it uses the normal approximation with
/// the tie correction of the variance and a continuity correction of ½. `None` when no
/// difference is non-zero or a value is not finite.
pub fn wilcoxon(d: &[f64]) -> Option<Wilcoxon> {
    if d.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let mut nz: Vec<f64> = d
        .iter()
        .copied()
        .filter(|x| x.abs() > TIE_TOLERANCE)
        .collect();
    let n = nz.len();
    if n == 0 {
        return None;
    }
    nz.sort_by(|a, b| a.abs().total_cmp(&b.abs()));
    // Average ranks over runs of equal absolute values; the tie term Σ(t³ − t) corrects the
    // variance of the normal approximation.
    let mut ranks = vec![0.0; n];
    let mut tie_term = 0.0;
    let mut i = 0;
    while i < n {
        let mut j = i + 1;
        while j < n && (nz[j].abs() - nz[i].abs()).abs() <= TIE_TOLERANCE {
            j += 1;
        }
        let avg = (i + j + 1) as f64 / 2.0; // ranks i+1..=j
        for r in &mut ranks[i..j] {
            *r = avg;
        }
        let t = (j - i) as f64;
        tie_term += t * t * t - t;
        i = j;
    }
    let w_plus: f64 = nz
        .iter()
        .zip(&ranks)
        .filter(|(x, _)| **x > 0.0)
        .map(|(_, r)| r)
        .sum();
    let total = (n * (n + 1)) as f64 / 2.0;
    let w_minus = total - w_plus;
    let w = w_plus.min(w_minus);
    let exact = n <= EXACT_WILCOXON_MAX && tie_term == 0.0;
    let p = if exact {
        exact_lower_tail(n, w.round() as usize)
            .map(|tail| (2.0 * tail).min(1.0))
            .unwrap_or(1.0)
    } else {
        let nf = n as f64;
        let mean = nf * (nf + 1.0) / 4.0;
        let var = nf * (nf + 1.0) * (2.0 * nf + 1.0) / 24.0 - tie_term / 48.0;
        if var <= 0.0 {
            1.0
        } else {
            // w ≤ mean, so the continuity correction moves it half a rank towards the mean.
            let z = ((w - mean + 0.5).min(0.0)) / var.sqrt();
            (2.0 * normal_cdf(z)).min(1.0)
        }
    };
    Some(Wilcoxon {
        n,
        w_plus,
        w_minus,
        p,
        exact,
    })
}

/// P(W ≤ w) under the null for n untied ranks: every subset of 1..=n is equally likely to be
/// the positive one, so count subsets by their rank sum (a knapsack count).
fn exact_lower_tail(n: usize, w: usize) -> Option<f64> {
    let max = n * (n + 1) / 2;
    let mut counts = vec![0.0f64; max + 1];
    counts[0] = 1.0;
    for k in 1..=n {
        for s in (k..=max).rev() {
            counts[s] += counts[s - k];
        }
    }
    let all = 2f64.powi(i32::try_from(n).ok()?);
    Some(counts.iter().take(w + 1).sum::<f64>() / all)
}

/// The standard normal CDF, Φ(z) = erfc(−z/√2)/2.
pub fn normal_cdf(z: f64) -> f64 {
    0.5 * erfc(-z / std::f64::consts::SQRT_2)
}

/// The percentile bootstrap interval of the mean of `d` at `level` (e.g. 0.95): `resamples`
/// resamples with replacement drawn from a ChaCha8 generator seeded with `seed`, percentiles by
/// linear interpolation. `None` for empty data, no resamples or non-finite values.
pub fn bootstrap_mean_ci(d: &[f64], resamples: usize, seed: u64, level: f64) -> Option<(f64, f64)> {
    if d.is_empty() || resamples == 0 || d.iter().any(|x| !x.is_finite()) {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let n = d.len();
    let mut means: Vec<f64> = (0..resamples)
        .map(|_| (0..n).map(|_| d[rng.random_range(0..n)]).sum::<f64>() / n as f64)
        .collect();
    means.sort_by(f64::total_cmp);
    let q = |p: f64| {
        let pos = p * (means.len() - 1) as f64;
        let lo = pos.floor() as usize;
        let hi = pos.ceil() as usize;
        means[lo] + (means[hi] - means[lo]) * (pos - lo as f64)
    };
    let alpha = (1.0 - level.clamp(0.0, 1.0)) / 2.0;
    Some((q(alpha), q(1.0 - alpha)))
}

/// One strategy against a reference on their paired trials.
#[derive(Clone, Debug, PartialEq)]
pub struct PairedComparison {
    /// Paired trials.
    pub n: usize,
    /// Mean of `cost(strategy) − cost(reference)`; negative = the strategy is cheaper.
    pub mean_diff: f64,
    /// 95 % percentile-bootstrap interval of `mean_diff`.
    pub ci95: (f64, f64),
    /// The signed-rank test; `None` when every pair ties.
    pub wilcoxon: Option<Wilcoxon>,
    /// Pairs where the strategy is cheaper.
    pub wins: usize,
    /// Pairs within [`TIE_TOLERANCE`].
    pub ties: usize,
    /// Pairs where the strategy costs more.
    pub losses: usize,
}

/// Compares `strategy` with `reference`, pair by pair (`strategy[i]` and `reference[i]` are the
/// same trial). `None` when the slices differ in length, are empty, or hold non-finite values.
pub fn compare_paired(
    strategy: &[f64],
    reference: &[f64],
    resamples: usize,
    seed: u64,
) -> Option<PairedComparison> {
    if strategy.len() != reference.len() || strategy.is_empty() {
        return None;
    }
    let d: Vec<f64> = strategy.iter().zip(reference).map(|(s, r)| s - r).collect();
    let ci95 = bootstrap_mean_ci(&d, resamples, seed, 0.95)?;
    Some(PairedComparison {
        n: d.len(),
        mean_diff: d.iter().sum::<f64>() / d.len() as f64,
        ci95,
        wilcoxon: wilcoxon(&d),
        wins: d.iter().filter(|x| **x < -TIE_TOLERANCE).count(),
        ties: d.iter().filter(|x| x.abs() <= TIE_TOLERANCE).count(),
        losses: d.iter().filter(|x| **x > TIE_TOLERANCE).count(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Darwin's Zea mays data (cross- minus self-fertilised height, eighths of an inch), the
    /// example of SciPy's `wilcoxon` documentation: W = min(W+, W−) = 24, exact two-sided
    /// p = 0.041259765625 (= 2 · 676 / 32768).
    const DARWIN: [f64; 15] = [
        6.0, 8.0, 14.0, 16.0, 23.0, 24.0, 28.0, 29.0, 41.0, -48.0, 49.0, 56.0, 60.0, -67.0, 75.0,
    ];

    #[test]
    fn darwin_exact_p_matches_scipy() {
        let w = wilcoxon(&DARWIN).unwrap();
        assert_eq!(w.n, 15);
        assert_eq!(w.w_minus, 24.0);
        assert_eq!(w.w_plus, 96.0);
        assert!(w.exact);
        assert!((w.p - 0.041259765625).abs() < 1e-12, "{}", w.p);
    }

    #[test]
    fn ties_use_the_normal_approximation_computed_by_hand() {
        // |d| = 1,1,2,3,3,3,4,5 (one zero dropped): ranks 1.5,1.5,3,5,5,5,7,8; negatives are the
        // second 1 and one 3 → W− = 1.5 + 5 = 6.5, W+ = 29.5. n = 8, mean 18, tie term
        // (8−2) + (27−3) = 30 → var = 8·9·17/24 − 30/48 = 51 − 0.625 = 50.375.
        // z = (6.5 − 18 + 0.5)/√50.375 = −1.549834; p = 2Φ(z) = 0.121181 (Python:
        // math.erfc(1.5498339 / math.sqrt(2)) = 0.1211814).
        let d = [1.0, -1.0, 2.0, 3.0, -3.0, 3.0, 4.0, 5.0, 0.0];
        let w = wilcoxon(&d).unwrap();
        assert_eq!(w.n, 8);
        assert!(!w.exact);
        assert_eq!(w.w_minus, 6.5);
        let z: f64 = (6.5 - 18.0 + 0.5) / 50.375f64.sqrt();
        assert!((z + 1.549_833_898).abs() < 1e-8, "{z}");
        assert!((w.p - 0.121_181_388_585).abs() < 1e-9, "{}", w.p);
    }

    #[test]
    fn large_samples_use_the_normal_approximation() {
        // 60 untied differences, all positive but the smallest: W− = 1, n = 60,
        // mean 915, var = 60·61·121/24 = 18452.5; z = (1 − 915 + 0.5)/135.84 = −6.725 → p ≈ 1.8e-11.
        let d: Vec<f64> = (1..=60)
            .map(|i| if i == 1 { -1.0 } else { i as f64 })
            .collect();
        let w = wilcoxon(&d).unwrap();
        assert!(!w.exact);
        assert_eq!(w.w_minus, 1.0);
        let z: f64 = (1.0 - 915.0 + 0.5) / 18452.5f64.sqrt();
        assert!((w.p - 2.0 * normal_cdf(z)).abs() < 1e-20);
        assert!(w.p < 1e-10 && w.p > 1e-12, "{}", w.p);
    }

    #[test]
    fn normal_cdf_known_values() {
        assert!((normal_cdf(0.0) - 0.5).abs() < 1e-15);
        let q = normal_cdf(1.959_963_984_540_054);
        assert!((q - 0.975).abs() < 1e-10, "{q}");
        assert!((normal_cdf(-1.0) - 0.158_655_253_931_457).abs() < 1e-10);
    }

    #[test]
    fn all_ties_have_no_test_and_count_as_ties() {
        let c = compare_paired(&[1.0, 2.0, 3.0], &[1.0, 2.0, 3.0], 100, 0).unwrap();
        assert_eq!((c.wins, c.ties, c.losses), (0, 3, 0));
        assert_eq!(c.mean_diff, 0.0);
        assert_eq!(c.ci95, (0.0, 0.0));
        assert!(c.wilcoxon.is_none());
    }

    #[test]
    fn comparison_counts_and_means() {
        let c = compare_paired(&[9.0, 18.0, 30.0, 5.0], &[10.0, 20.0, 30.0, 4.0], 2000, 7).unwrap();
        assert_eq!((c.wins, c.ties, c.losses), (2, 1, 1));
        assert!((c.mean_diff - (-0.5)).abs() < 1e-12);
        // The bootstrap interval of a mean lies within the data's range and holds the mean.
        assert!(c.ci95.0 >= -2.0 && c.ci95.1 <= 1.0, "{:?}", c.ci95);
        assert!(c.ci95.0 <= c.mean_diff && c.mean_diff <= c.ci95.1);
        assert!(compare_paired(&[1.0], &[1.0, 2.0], 10, 0).is_none());
        assert!(compare_paired(&[], &[], 10, 0).is_none());
    }

    #[test]
    fn bootstrap_of_a_constant_is_the_constant() {
        assert_eq!(
            bootstrap_mean_ci(&[2.5; 10], 500, 3, 0.95),
            Some((2.5, 2.5))
        );
        assert_eq!(bootstrap_mean_ci(&[], 500, 3, 0.95), None);
    }

    proptest! {
        #[test]
        fn swapping_negates_the_difference_and_keeps_p(
            pairs in prop::collection::vec((0.0f64..50.0, 0.0f64..50.0), 1..80),
            seed in 0u64..1000,
        ) {
            let a: Vec<f64> = pairs.iter().map(|p| p.0).collect();
            let b: Vec<f64> = pairs.iter().map(|p| p.1).collect();
            let ab = compare_paired(&a, &b, 300, seed).unwrap();
            let ba = compare_paired(&b, &a, 300, seed).unwrap();
            prop_assert!((ab.mean_diff + ba.mean_diff).abs() < 1e-9);
            prop_assert!((ab.ci95.0 + ba.ci95.1).abs() < 1e-9);
            prop_assert!((ab.ci95.1 + ba.ci95.0).abs() < 1e-9);
            prop_assert_eq!((ab.wins, ab.ties, ab.losses), (ba.losses, ba.ties, ba.wins));
            match (&ab.wilcoxon, &ba.wilcoxon) {
                (Some(x), Some(y)) => {
                    prop_assert!((x.p - y.p).abs() < 1e-12);
                    prop_assert_eq!(x.w_plus, y.w_minus);
                    prop_assert!(x.p > 0.0 && x.p <= 1.0);
                }
                (None, None) => {}
                _ => prop_assert!(false, "one direction has a test and the other not"),
            }
        }

        #[test]
        fn exact_and_normal_p_agree_roughly(n in 20usize..=50, flips in prop::collection::vec(any::<bool>(), 50)) {
            // Untied differences ±1..±n: the exact p and the normal approximation differ little
            // at these sizes.
            let d: Vec<f64> = (1..=n).map(|i| if flips[i - 1] { -(i as f64) } else { i as f64 }).collect();
            let w = wilcoxon(&d).unwrap();
            prop_assert!(w.exact);
            let nf = n as f64;
            let mean = nf * (nf + 1.0) / 4.0;
            let var = nf * (nf + 1.0) * (2.0 * nf + 1.0) / 24.0;
            let z = ((w.w_plus.min(w.w_minus) - mean + 0.5).min(0.0)) / var.sqrt();
            let approx = (2.0 * normal_cdf(z)).min(1.0);
            prop_assert!((w.p - approx).abs() < 0.01, "exact {} approx {}", w.p, approx);
        }
    }
}
