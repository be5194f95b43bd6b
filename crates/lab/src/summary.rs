//! Summaries of an evaluation: per-strategy statistics (the paper's table I), paired
//! comparisons trial by trial and the reference code's weighted means (rendered by
//! [`report`](crate::report)).

use std::collections::{BTreeMap, HashMap};

use serde::Serialize;

use crate::rows::{CELL_M, TrialRow};

/// Per-strategy statistics for `summary.csv`.
#[derive(Clone, Debug, Serialize)]
pub struct SummaryRow {
    /// Strategy spec.
    pub strategy: String,
    /// Trials run.
    pub trials: usize,
    /// Mean cost, metres.
    pub mean_m: f64,
    /// Median cost, metres.
    pub median_m: f64,
    /// Half-width of the 95 % confidence interval of the mean (normal approximation).
    pub ci95_m: f64,
    /// Improvement of the mean over optimistic+greedy, percent (positive = cheaper), on the
    /// paired trials only.
    pub improvement_pct: Option<f64>,
    /// Trials in the comparison with optimistic+greedy: the houses where every summarized
    /// strategy finished, so that a strategy is never credited for skipping hard houses.
    pub paired_trials: usize,
    /// Mean cost in 0.05 m cells (`--cells` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mean_cells: Option<f64>,
    /// Median cost in 0.05 m cells (`--cells` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub median_cells: Option<f64>,
    /// Half-width of the 95 % interval in 0.05 m cells (`--cells` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub ci95_cells: Option<f64>,
    /// Mean metres driven by the whole team (a run of teams only; the cost is then the
    /// makespan).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mean_total_travel_m: Option<f64>,
}

impl SummaryRow {
    /// Fills in the costs in 0.05 m cells.
    pub fn with_cells(self) -> Self {
        Self {
            mean_cells: Some(self.mean_m / CELL_M),
            median_cells: Some(self.median_m / CELL_M),
            ci95_cells: Some(self.ci95_m / CELL_M),
            ..self
        }
    }
}

/// Each strategy's mean cost as the reference code averages its table: 500 runs of 100 houses
/// drawn with replacement by numpy's legacy generator (`seed(s)`, shuffle, `choice`) from the
/// houses in file order, i.e. a mean weighted by how often each house is drawn. Houses a
/// strategy has no trial on are left out of its weights. `(strategy, metres)` in `order`.
pub fn reference_means(
    rows: &[TrialRow],
    order: &[String],
    houses: &[usize],
) -> Vec<(String, f64)> {
    reference_means_of(&CostTable::from_rows(rows), order, houses)
}

/// [`reference_means`] over a run's [`CostTable`].
pub fn reference_means_of(
    costs: &CostTable,
    order: &[String],
    houses: &[usize],
) -> Vec<(String, f64)> {
    let counts = ferret_select::numpy::reference_draw_counts(houses.len(), 500, 100);
    let weight: HashMap<usize, f64> = houses
        .iter()
        .zip(&counts)
        .map(|(&h, &c)| (h, c as f64))
        .collect();
    order
        .iter()
        .filter_map(|s| {
            let (sum, total) = costs
                .iter()
                .filter(|r| r.strategy == s)
                .filter_map(|r| weight.get(&r.house_index).map(|w| (w * r.cost_m, *w)))
                .fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
            (total > 0.0).then(|| (s.clone(), sum / total))
        })
        .collect()
}

/// A trial's identity across strategies: house index and target. Two strategies' rows with the
/// same key ran the same trial, so their costs pair.
pub type TrialKey<'a> = (usize, &'a str);

/// What the statistics of a run read of each trial row: its strategy, house, target and cost,
/// in the rows' order. A run too large to hold its rows keeps this instead: 24 bytes a row, the
/// strategy and target names stored once.
#[derive(Clone, Debug, Default)]
pub struct CostTable {
    names: Vec<String>,
    ids: HashMap<String, u32>,
    entries: Vec<CostEntry>,
}

#[derive(Clone, Copy, Debug)]
struct CostEntry {
    house_index: usize,
    cost_m: f64,
    /// A team's total travel, NaN for one robot.
    total_travel_m: f64,
    strategy: u32,
    target: u32,
}

/// One row of a [`CostTable`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CostRow<'a> {
    /// Strategy spec.
    pub strategy: &'a str,
    /// House index in its file.
    pub house_index: usize,
    /// Target object type.
    pub target: &'a str,
    /// Distance travelled, metres.
    pub cost_m: f64,
}

impl CostTable {
    /// The table of `rows`, in their order.
    pub fn from_rows(rows: &[TrialRow]) -> Self {
        let mut t = Self::default();
        for r in rows {
            t.push(r);
        }
        t
    }

    /// Appends a row.
    pub fn push(&mut self, row: &TrialRow) {
        let strategy = self.id(&row.strategy);
        let target = self.id(&row.target);
        self.entries.push(CostEntry {
            house_index: row.house_index,
            cost_m: row.cost_m,
            total_travel_m: row.total_travel_m.unwrap_or(f64::NAN),
            strategy,
            target,
        });
    }

    fn id(&mut self, name: &str) -> u32 {
        if let Some(&i) = self.ids.get(name) {
            return i;
        }
        // More distinct names than u32 holds cannot occur: each is a strategy or an object type.
        let i = u32::try_from(self.names.len()).unwrap_or(u32::MAX);
        self.names.push(name.to_string());
        self.ids.insert(name.to_string(), i);
        i
    }

    /// Rows held.
    pub fn len(&self) -> usize {
        self.entries.len()
    }

    /// True when it holds no row.
    pub fn is_empty(&self) -> bool {
        self.entries.is_empty()
    }

    /// The rows in order.
    pub fn iter(&self) -> impl Iterator<Item = CostRow<'_>> + '_ {
        let name = |i: u32| self.names.get(i as usize).map_or("", String::as_str);
        self.entries.iter().map(move |e| CostRow {
            strategy: name(e.strategy),
            house_index: e.house_index,
            target: name(e.target),
            cost_m: e.cost_m,
        })
    }

    /// The mean total travel of `strategy`'s teams, when every one of its rows is a team's.
    pub fn mean_total_travel(&self, strategy: &str) -> Option<f64> {
        let id = *self.ids.get(strategy)?;
        let v: Vec<f64> = self
            .entries
            .iter()
            .filter(|e| e.strategy == id)
            .map(|e| e.total_travel_m)
            .collect();
        (!v.is_empty() && v.iter().all(|x| !x.is_nan()))
            .then(|| v.iter().sum::<f64>() / v.len() as f64)
    }

    /// The costs of `strategy`'s trials, in row order.
    pub fn costs_of(&self, strategy: &str) -> Vec<f64> {
        self.iter()
            .filter(|r| r.strategy == strategy)
            .map(|r| r.cost_m)
            .collect()
    }
}

/// Each strategy's cost per trial.
fn costs_by_trial(costs: &CostTable) -> BTreeMap<&str, BTreeMap<TrialKey<'_>, f64>> {
    let mut by: BTreeMap<&str, BTreeMap<TrialKey<'_>, f64>> = BTreeMap::new();
    for r in costs.iter() {
        by.entry(r.strategy)
            .or_default()
            .insert((r.house_index, r.target), r.cost_m);
    }
    by
}

/// Mean, median, 95 % CI and improvement over optimistic+greedy, per strategy in `order`. The
/// improvement compares means over the paired trials only: the trials (house and target) that
/// every strategy of `order` that finished any trial finished.
pub fn summarize(rows: &[TrialRow], order: &[String]) -> Vec<SummaryRow> {
    summarize_costs(&CostTable::from_rows(rows), order)
}

/// [`summarize`] over a run's [`CostTable`].
pub fn summarize_costs(costs: &CostTable, order: &[String]) -> Vec<SummaryRow> {
    let mut by: BTreeMap<&str, Vec<f64>> = BTreeMap::new();
    let by_house = costs_by_trial(costs);
    for r in costs.iter() {
        by.entry(r.strategy).or_default().push(r.cost_m);
    }
    let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len().max(1) as f64;
    let compared: Vec<&BTreeMap<TrialKey<'_>, f64>> = order
        .iter()
        .filter_map(|s| by_house.get(s.as_str()))
        .collect();
    let paired: Vec<TrialKey<'_>> = compared
        .first()
        .map(|first| {
            first
                .keys()
                .copied()
                .filter(|h| compared.iter().all(|m| m.contains_key(h)))
                .collect()
        })
        .unwrap_or_default();
    let paired_mean = |s: &str| {
        let m = by_house.get(s)?;
        let v: Vec<f64> = paired.iter().filter_map(|h| m.get(h).copied()).collect();
        (!v.is_empty()).then(|| mean(&v))
    };
    let greedy = paired_mean("optimistic+greedy");
    order
        .iter()
        .filter_map(|s| by.get(s.as_str()).map(|v| (s, v)))
        .map(|(s, v)| {
            let m = mean(v);
            let mut sorted = v.clone();
            sorted.sort_by(f64::total_cmp);
            let n = sorted.len();
            let median = if n % 2 == 1 {
                sorted[n / 2]
            } else {
                (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0
            };
            let var = if n > 1 {
                v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1) as f64
            } else {
                0.0
            };
            SummaryRow {
                strategy: s.clone(),
                trials: n,
                mean_m: m,
                median_m: median,
                ci95_m: 1.96 * (var / n as f64).sqrt(),
                improvement_pct: greedy
                    .filter(|g| *g > 0.0)
                    .zip(paired_mean(s))
                    .map(|(g, m)| 100.0 * (g - m) / g),
                paired_trials: paired.len(),
                mean_cells: None,
                median_cells: None,
                ci95_cells: None,
                mean_total_travel_m: costs.mean_total_travel(s),
            }
        })
        .collect()
}

/// Bootstrap resamples of the paired confidence intervals: enough that the interval's ends move
/// by less than a hundredth of a metre between seeds on 150 trials.
pub const PAIRED_RESAMPLES: usize = 10_000;

/// One row of `paired.csv`: a strategy against a reference on the trials both finished.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct PairedRow {
    /// The strategy compared against.
    pub reference: String,
    /// Why it is the reference: `first` (the first strategy named), `best` (the lowest mean
    /// on the paired trials, the oracle excepted) or `named` (given with `--paired-against`).
    pub role: &'static str,
    /// The strategy.
    pub strategy: String,
    /// Trials (house and target) both finished.
    pub pairs: usize,
    /// Mean of cost(strategy) − cost(reference), metres; negative = the strategy is cheaper.
    pub mean_diff_m: f64,
    /// Lower end of the 95 % bootstrap interval of the mean difference, metres.
    pub ci95_low_m: f64,
    /// Upper end of that interval, metres.
    pub ci95_high_m: f64,
    /// Two-sided Wilcoxon signed-rank p-value; empty when every pair ties.
    pub wilcoxon_p: Option<f64>,
    /// Trials where the strategy is cheaper.
    pub wins: usize,
    /// Trials within a nanometre.
    pub ties: usize,
    /// Trials where the strategy costs more.
    pub losses: usize,
}

/// Every strategy of `order` against the first one, and against the best (lowest mean over the
/// trials every strategy finished; the oracle is a bound, never the best) when that is another
/// strategy, then against each of `named` that is neither. Pairs are the trials (house and
/// target) both strategies of a comparison finished. `seed` seeds the bootstrap, so the table is
/// reproducible.
pub fn paired_comparisons(
    rows: &[TrialRow],
    order: &[String],
    named: &[String],
    seed: u64,
) -> Vec<PairedRow> {
    paired_comparisons_of(&CostTable::from_rows(rows), order, named, seed)
}

/// [`paired_comparisons`] over a run's [`CostTable`].
pub fn paired_comparisons_of(
    costs: &CostTable,
    order: &[String],
    named: &[String],
    seed: u64,
) -> Vec<PairedRow> {
    let by = costs_by_trial(costs);
    let present: Vec<&str> = order
        .iter()
        .map(String::as_str)
        .filter(|s| by.contains_key(s))
        .collect();
    let Some(&first) = present.first() else {
        return Vec::new();
    };
    let common: Vec<TrialKey<'_>> = by[first]
        .keys()
        .copied()
        .filter(|k| present.iter().all(|s| by[s].contains_key(k)))
        .collect();
    let best = present
        .iter()
        .copied()
        .filter(|s| *s != "oracle" && !common.is_empty())
        .map(|s| (s, common.iter().map(|k| by[s][k]).sum::<f64>()))
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|(s, _)| s);
    let mut references = vec![(first, "first")];
    if let Some(b) = best.filter(|b| *b != first) {
        references.push((b, "best"));
    }
    for n in named {
        if let Some(&n) = present.iter().find(|s| **s == n.as_str())
            && !references.iter().any(|(r, _)| *r == n)
        {
            references.push((n, "named"));
        }
    }
    let mut out = Vec::new();
    for (reference, role) in references {
        for &s in present.iter().filter(|s| **s != reference) {
            let keys: Vec<&TrialKey<'_>> = by[s]
                .keys()
                .filter(|k| by[reference].contains_key(*k))
                .collect();
            let a: Vec<f64> = keys.iter().map(|k| by[s][*k]).collect();
            let b: Vec<f64> = keys.iter().map(|k| by[reference][*k]).collect();
            let Some(c) = crate::paired::compare_paired(&a, &b, PAIRED_RESAMPLES, seed) else {
                continue;
            };
            out.push(PairedRow {
                reference: reference.to_string(),
                role,
                strategy: s.to_string(),
                pairs: c.n,
                mean_diff_m: c.mean_diff,
                ci95_low_m: c.ci95.0,
                ci95_high_m: c.ci95.1,
                wilcoxon_p: c.wilcoxon.map(|w| w.p),
                wins: c.wins,
                ties: c.ties,
                losses: c.losses,
            });
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::report::{cells_markdown, paired_markdown, summary_markdown};
    use ferret_plan::TrialsPerHouse;

    fn trial(house_index: usize, strategy: &str, cost_m: f64) -> TrialRow {
        TrialRow {
            house: format!("h#{house_index}"),
            house_index,
            target: "Apple".into(),
            strategy: strategy.into(),
            cost_m,
            searches: 1,
            found: true,
            found_container: "1|0".into(),
            searched: "1|0".into(),
            goal_containers: 1,
            cost_cells: None,
            goal: None,
            destination: None,
            found_each: None,
            delivery_m: None,
            robots: None,
            total_travel_m: None,
            searched_by: None,
        }
    }

    #[test]
    fn reference_means_weight_houses_by_the_reference_draws() {
        // Houses 10, 11, 12 in file order; strategy b lacks house 12.
        let rows = vec![
            trial(10, "a", 1.0),
            trial(11, "a", 2.0),
            trial(12, "a", 4.0),
            trial(10, "b", 3.0),
            trial(11, "b", 3.0),
        ];
        let order = vec!["a".to_string(), "b".to_string(), "c".to_string()];
        let means = reference_means(&rows, &order, &[10, 11, 12]);
        let w = ferret_select::numpy::reference_draw_counts(3, 500, 100);
        let w: Vec<f64> = w.into_iter().map(|c| c as f64).collect();
        assert_eq!(means.len(), 2, "no rows, no mean for c");
        let a = (w[0] + 2.0 * w[1] + 4.0 * w[2]) / (w[0] + w[1] + w[2]);
        assert!((means[0].1 - a).abs() < 1e-12);
        // Unequal weights: the weighted mean is not the plain one.
        assert!((a - 7.0 / 3.0).abs() > 1e-6);
        assert!((means[1].1 - 3.0).abs() < 1e-12);
    }

    #[test]
    fn the_summary_table_shows_a_cheaper_strategy_as_a_lower_cost() {
        let order = vec!["optimistic+greedy".to_string(), "model/x".to_string()];
        let rows = vec![
            trial(0, "optimistic+greedy", 10.0),
            trial(0, "model/x", 4.0),
        ];
        let summary = summarize(&rows, &order);
        assert!((summary[1].improvement_pct.unwrap_or_default() - 60.0).abs() < 1e-9);
        let md = summary_markdown(&summary, "test", 1, (TrialsPerHouse::One, None), 1);
        assert!(
            md.contains("| model/x | 1 | 4.00 | ±0.00 | 4.00 | -60.0 % |"),
            "{md}"
        );
        assert!(
            md.contains("| optimistic+greedy | 1 | 10.00 | ±0.00 | 10.00 | +0.0 % |"),
            "{md}"
        );
    }

    #[test]
    fn strategies_with_failed_trials_are_compared_on_paired_trials_only() {
        let order = vec!["optimistic+greedy".to_string(), "model/x".to_string()];
        // Greedy finished all four houses; model/x failed on house 3, the most expensive one.
        let mut rows: Vec<TrialRow> = [10.0, 20.0, 30.0, 100.0]
            .iter()
            .enumerate()
            .map(|(h, &c)| trial(h, "optimistic+greedy", c))
            .collect();
        rows.extend(
            [9.0, 18.0, 27.0]
                .iter()
                .enumerate()
                .map(|(h, &c)| trial(h, "model/x", c)),
        );
        let summary = summarize(&rows, &order);
        assert_eq!(summary[0].trials, 4);
        assert_eq!(summary[1].trials, 3);
        assert!((summary[0].mean_m - 40.0).abs() < 1e-12);
        assert!((summary[1].mean_m - 18.0).abs() < 1e-12);
        // Over the three paired houses greedy averages 20 m, model/x 18 m: 10 % cheaper, not the
        // 55 % that comparing 18 m with greedy's 40 m over all four houses would claim.
        assert!((summary[1].improvement_pct.unwrap() - 10.0).abs() < 1e-9);
        assert!(summary[0].improvement_pct.unwrap().abs() < 1e-9);
        assert_eq!(summary[1].paired_trials, 3);
        let md = summary_markdown(&summary, "test houses", 4, (TrialsPerHouse::One, None), 4);
        // In cells: 18 m is 360 cells of 0.05 m.
        let cells = cells_markdown(&summary);
        assert!(cells.contains("| model/x | 3 | 360.0 | ±"), "{cells}");
        let with = summary[1].clone().with_cells();
        assert!((with.median_cells.unwrap() - 360.0).abs() < 1e-9);
        assert!((with.ci95_cells.unwrap() - with.ci95_m * 20.0).abs() < 1e-9);
        assert!(md.contains("model/x finished 3 of 4"), "{md}");
        assert!(md.contains("only the 3 paired trials"), "{md}");
        assert!(!md.contains("optimistic+greedy finished"), "{md}");
        // Complete runs carry no note.
        let complete = summarize(&rows[..4], &order[..1]);
        assert!(
            !summary_markdown(&complete, "test houses", 4, (TrialsPerHouse::One, None), 4)
                .contains("Failed trials")
        );
    }

    #[test]
    fn paired_comparisons_pair_by_house_and_target_against_first_and_best() {
        let order: Vec<String> = ["optimistic+greedy", "model/x", "model/y", "oracle"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let mut rows = Vec::new();
        // Two targets in each of three houses; model/x saves 2 m on every trial, model/y 1 m on
        // all but one (a tie), the oracle 5 m. model/x also has a trial no other strategy ran.
        for h in 0..3 {
            for (t, target) in ["Apple", "Book"].iter().enumerate() {
                let g = 10.0 + 3.0 * h as f64 + t as f64;
                let mut push = |s: &str, c: f64| {
                    let mut r = trial(h, s, c);
                    r.target = target.to_string();
                    rows.push(r);
                };
                push("optimistic+greedy", g);
                push("model/x", g - 2.0);
                push("model/y", if h == 0 && t == 0 { g } else { g - 1.0 });
                push("oracle", g - 5.0);
            }
        }
        let mut extra = trial(9, "model/x", 1.0);
        extra.target = "Cup".into();
        rows.push(extra);
        let paired = paired_comparisons(&rows, &order, &[], 0);
        // Against greedy: x, y, oracle; against the best (model/x): greedy, y, oracle.
        assert_eq!(paired.len(), 6);
        let x = &paired[0];
        assert_eq!(
            (x.role, x.strategy.as_str(), x.pairs),
            ("first", "model/x", 6)
        );
        assert!((x.mean_diff_m + 2.0).abs() < 1e-12);
        assert!((x.ci95_low_m + 2.0).abs() < 1e-12 && (x.ci95_high_m + 2.0).abs() < 1e-12);
        assert_eq!((x.wins, x.ties, x.losses), (6, 0, 0));
        // Six equal differences tie in rank: the normal approximation, z = (0 − 10.5 + 0.5)/√(22.75
        // − 210/48) = −2.33285 → p = 0.0196562 (Python: math.erfc(2.33285 / math.sqrt(2))).
        assert!(
            (x.wilcoxon_p.unwrap() - 0.019_656_157).abs() < 1e-8,
            "{:?}",
            x.wilcoxon_p
        );
        let y = &paired[1];
        assert_eq!((y.wins, y.ties, y.losses), (5, 1, 0));
        assert!((y.mean_diff_m + 5.0 / 6.0).abs() < 1e-12);
        assert_eq!(paired[3].role, "best");
        assert_eq!(paired[3].reference, "model/x");
        assert_eq!(paired[3].strategy, "optimistic+greedy");
        assert!((paired[3].mean_diff_m - 2.0).abs() < 1e-12);
        assert_eq!(paired[5].strategy, "oracle");
        let md = paired_markdown(&paired);
        assert!(
            md.contains("Against optimistic+greedy (the first strategy)"),
            "{md}"
        );
        assert!(
            md.contains("Against model/x (the lowest mean, oracle excepted)"),
            "{md}"
        );
        assert!(md.contains("| model/y | 6 | -0.83 | [-1.00, "), "{md}");
        assert!(
            md.contains("| optimistic+greedy | 6 | +2.00 | [+2.00, +2.00] | 0.020 | 0 / 0 / 6 |"),
            "{md}"
        );
        assert!(md.contains("| 5 / 1 / 0 |"), "{md}");
        // The same seed gives the same table.
        assert_eq!(
            paired_markdown(&paired_comparisons(&rows, &order, &[], 0)),
            md
        );
        // A named reference adds its own table; the first, the best and strategies that ran no
        // trial add nothing twice.
        let named: Vec<String> = ["model/y", "model/x", "optimistic+greedy", "model/z"]
            .iter()
            .map(|s| s.to_string())
            .collect();
        let with = paired_comparisons(&rows, &order, &named, 0);
        assert_eq!(with.len(), 9);
        assert_eq!(&with[..6], &paired[..]);
        let y: Vec<(&str, &str, &str)> = with[6..]
            .iter()
            .map(|r| (r.role, r.reference.as_str(), r.strategy.as_str()))
            .collect();
        assert_eq!(
            y,
            [
                ("named", "model/y", "optimistic+greedy"),
                ("named", "model/y", "model/x"),
                ("named", "model/y", "oracle")
            ]
        );
        assert!((with[7].mean_diff_m + 7.0 / 6.0).abs() < 1e-12);
        assert!(
            paired_markdown(&with).contains("Against model/y (named with --paired-against)"),
            "{}",
            paired_markdown(&with)
        );
    }
}
