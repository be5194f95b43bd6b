//! How good a likelihood source is: its probabilities against the ground truth.
//!
//! Every (house, target, container) gives a pair (`P_S(target, container)`, whether the container
//! holds the target). Over many pairs: the Brier score and log loss (lower is better), AUROC (the
//! chance that a holder gets a higher probability than a non-holder; 0.5 is no better than a
//! coin, and what any constant source gets), the mean probability of holders and of non-holders,
//! and a reliability table (mean probability against the observed rate, per probability bin).

use serde::Serialize;

/// Probabilities are kept this far from 0 and 1 in the log loss, so that one confident mistake
/// costs a lot but not infinitely much.
const LOG_LOSS_EPS: f64 = 1e-6;

/// One bin of the reliability table.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ReliabilityBin {
    /// Lower edge of the bin's probability range.
    pub lo: f64,
    /// Upper edge (the last bin includes it).
    pub hi: f64,
    /// Pairs in the bin.
    pub count: u64,
    /// Their mean probability.
    pub mean_p: f64,
    /// The share of them that hold the target.
    pub observed: f64,
}

/// A likelihood source's scores over a set of pairs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Calibration {
    /// Pairs scored.
    pub pairs: u64,
    /// Of those, containers that hold the target.
    pub positives: u64,
    /// Mean squared error of the probability against 0/1.
    pub brier: f64,
    /// Mean negative log-likelihood (natural log).
    pub log_loss: f64,
    /// Area under the ROC curve (ties count half); `None` without both holders and non-holders.
    pub auroc: Option<f64>,
    /// Mean probability given to holders.
    pub mean_p_pos: Option<f64>,
    /// Mean probability given to non-holders.
    pub mean_p_neg: Option<f64>,
    /// The reliability table, empty bins left out.
    pub bins: Vec<ReliabilityBin>,
}

impl Calibration {
    /// Scores `pairs` of (probability, holds), with a reliability table of `bins` equal-width
    /// bins over [0, 1]. `None` without pairs. Probabilities outside [0, 1] are clamped.
    pub fn score(pairs: &[(f64, bool)], bins: usize) -> Option<Self> {
        if pairs.is_empty() {
            return None;
        }
        let n = pairs.len() as f64;
        let clamped: Vec<(f64, bool)> = pairs
            .iter()
            .map(|&(p, y)| (if p.is_nan() { 0.0 } else { p.clamp(0.0, 1.0) }, y))
            .collect();
        let y = |b: bool| if b { 1.0 } else { 0.0 };
        let brier = clamped
            .iter()
            .map(|&(p, t)| (p - y(t)).powi(2))
            .sum::<f64>()
            / n;
        let log_loss = clamped
            .iter()
            .map(|&(p, t)| {
                let p = p.clamp(LOG_LOSS_EPS, 1.0 - LOG_LOSS_EPS);
                if t { -p.ln() } else { -(1.0 - p).ln() }
            })
            .sum::<f64>()
            / n;
        let pos: Vec<f64> = clamped.iter().filter(|x| x.1).map(|x| x.0).collect();
        let neg: Vec<f64> = clamped.iter().filter(|x| !x.1).map(|x| x.0).collect();
        let mean = |v: &[f64]| (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64);
        let bins = bins.max(1);
        let mut table: Vec<(u64, f64, f64)> = vec![(0, 0.0, 0.0); bins];
        for &(p, t) in &clamped {
            let i = ((p * bins as f64) as usize).min(bins - 1);
            table[i].0 += 1;
            table[i].1 += p;
            table[i].2 += y(t);
        }
        Some(Self {
            pairs: pairs.len() as u64,
            positives: pos.len() as u64,
            brier,
            log_loss,
            auroc: auroc(&clamped),
            mean_p_pos: mean(&pos),
            mean_p_neg: mean(&neg),
            bins: table
                .into_iter()
                .enumerate()
                .filter(|(_, b)| b.0 > 0)
                .map(|(i, (count, sum_p, sum_y))| ReliabilityBin {
                    lo: i as f64 / bins as f64,
                    hi: (i + 1) as f64 / bins as f64,
                    count,
                    mean_p: sum_p / count as f64,
                    observed: sum_y / count as f64,
                })
                .collect(),
        })
    }
}

/// The Mann–Whitney form of the AUROC: sort by probability, give tied probabilities their mean
/// rank, and compare the positives' rank sum with its minimum. O(n log n).
fn auroc(pairs: &[(f64, bool)]) -> Option<f64> {
    let n_pos = pairs.iter().filter(|p| p.1).count();
    let n_neg = pairs.len() - n_pos;
    if n_pos == 0 || n_neg == 0 {
        return None;
    }
    let mut sorted: Vec<(f64, bool)> = pairs.to_vec();
    sorted.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut rank_sum = 0.0;
    let mut i = 0;
    while i < sorted.len() {
        let mut j = i;
        while j < sorted.len() && sorted[j].0 == sorted[i].0 {
            j += 1;
        }
        // Ranks i+1 ..= j share their mean.
        let mean_rank = (i + 1 + j) as f64 / 2.0;
        rank_sum += mean_rank * sorted[i..j].iter().filter(|p| p.1).count() as f64;
        i = j;
    }
    let u = rank_sum - (n_pos * (n_pos + 1)) as f64 / 2.0;
    Some(u / (n_pos as f64 * n_neg as f64))
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn known_values() {
        let c = Calibration::score(&[(0.9, true), (0.2, false), (0.6, false), (0.4, true)], 10)
            .unwrap();
        assert_eq!((c.pairs, c.positives), (4, 2));
        // Brier: (0.01 + 0.04 + 0.36 + 0.36) / 4.
        assert!((c.brier - 0.1925).abs() < 1e-12);
        let ll = -(0.9f64.ln() + 0.8f64.ln() + 0.4f64.ln() + 0.4f64.ln()) / 4.0;
        assert!((c.log_loss - ll).abs() < 1e-12);
        // Holder/non-holder pairs ordered right: (0.9>0.2), (0.9>0.6), (0.4>0.2); wrong: (0.4<0.6).
        assert_eq!(c.auroc, Some(0.75));
        assert!((c.mean_p_pos.unwrap() - 0.65).abs() < 1e-12);
        assert!((c.mean_p_neg.unwrap() - 0.4).abs() < 1e-12);
        assert_eq!(c.bins.len(), 4);
        assert_eq!(c.bins[0].lo, 0.2);
        assert_eq!((c.bins[3].count, c.bins[3].observed), (1, 1.0));
    }

    #[test]
    fn constant_sources_score_one_half_and_edges_are_safe() {
        let pairs: Vec<(f64, bool)> = (0..50).map(|i| (0.1, i % 7 == 0)).collect();
        assert_eq!(Calibration::score(&pairs, 10).unwrap().auroc, Some(0.5));
        let all_pos = Calibration::score(&[(1.0, true), (0.0, true)], 10).unwrap();
        assert_eq!(all_pos.auroc, None);
        assert_eq!(all_pos.mean_p_neg, None);
        assert!(all_pos.log_loss.is_finite());
        assert_eq!(all_pos.bins.last().unwrap().hi, 1.0);
        assert_eq!(Calibration::score(&[], 10), None);
    }

    proptest! {
        #[test]
        fn scores_stay_in_range(pairs in prop::collection::vec((0.0f64..=1.0, any::<bool>()), 1..200), bins in 1usize..20) {
            let c = Calibration::score(&pairs, bins).unwrap();
            prop_assert!((0.0..=1.0).contains(&c.brier));
            prop_assert!(c.log_loss >= 0.0);
            if let Some(a) = c.auroc { prop_assert!((0.0..=1.0).contains(&a)); }
            prop_assert_eq!(c.bins.iter().map(|b| b.count).sum::<u64>(), pairs.len() as u64);
        }

        #[test]
        fn auroc_of_the_flipped_source_is_one_minus(pairs in prop::collection::vec((0.0f64..=1.0, any::<bool>()), 2..100)) {
            let flipped: Vec<(f64, bool)> = pairs.iter().map(|&(p, y)| (1.0 - p, y)).collect();
            if let (Some(a), Some(b)) = (auroc(&pairs), auroc(&flipped)) {
                prop_assert!((a + b - 1.0).abs() < 1e-9);
            }
        }

        #[test]
        fn a_separating_source_has_auroc_one(pos in prop::collection::vec(0.6f64..=1.0, 1..30), neg in prop::collection::vec(0.0f64..0.5, 1..30)) {
            let pairs: Vec<(f64, bool)> = pos.iter().map(|&p| (p, true)).chain(neg.iter().map(|&p| (p, false))).collect();
            prop_assert_eq!(auroc(&pairs), Some(1.0));
        }
    }
}
