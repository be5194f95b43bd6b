//! Report rows and tables of a deployment experiment. The CLI writes them to files.

use std::fmt::Write as _;

use serde::{Deserialize, Serialize};

use crate::{ExperimentResult, Method, MethodSummary};

/// Picks one curve of a method summary.
type Curve = fn(&MethodSummary) -> &[f64];

/// `values[i]`, or NaN for a hand-built result whose curves are too short (never panic).
fn at(values: &[f64], i: usize) -> f64 {
    values.get(i).copied().unwrap_or(f64::NAN)
}

/// The trial counts of the paper's table.
pub const PAPER_KS: [usize; 3] = [20, 50, 100];

/// One row of `selection.csv`: one method at one `k`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct SelectionRow {
    /// `ucb` or `replay`.
    pub method: Method,
    /// Number of trials, from 1.
    pub k: usize,
    /// Mean cost of trials `1..=k`, averaged over deployments (metres).
    pub avg_cost: f64,
    /// Cumulative regret against the best single strategy over trials `1..=k`, averaged over
    /// deployments (metres).
    pub cum_regret: f64,
    /// Cumulative regret by the paper's definition, `Σ_{j ≤ k} (avg_cost_j − m*)` (see
    /// [`MethodSummary::paper_regret`]).
    pub paper_regret: f64,
    /// The best single strategy's mean cost over the same trials `1..=k` (reference curve).
    pub best_avg_cost: f64,
    /// Fraction of deployments that chose the best single strategy at trial `k`.
    pub best_fraction: f64,
}

/// One row of the choice-frequency table: how often `method` chose `strategy` at trial `k`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ChoiceRow {
    /// `ucb` or `replay`.
    pub method: Method,
    /// Trial number, from 1.
    pub k: usize,
    /// Strategy name.
    pub strategy: String,
    /// Fraction of deployments that chose it at trial `k`.
    pub fraction: f64,
}

/// Rows for `selection.csv`: every method (in the order of [`Method::ALL`]) at every `k`.
pub fn selection_rows(result: &ExperimentResult) -> Vec<SelectionRow> {
    let best = result.best_strategy;
    result
        .summaries
        .iter()
        .flat_map(|summary| {
            (0..result.trials()).map(move |t| SelectionRow {
                method: summary.method,
                k: t + 1,
                avg_cost: at(&summary.avg_cost, t),
                cum_regret: at(&summary.cum_regret, t),
                paper_regret: at(&summary.paper_regret, t),
                best_avg_cost: at(&result.best_avg_cost, t),
                best_fraction: summary
                    .choice_fraction
                    .get(t)
                    .map_or(f64::NAN, |row| at(row, best)),
            })
        })
        .collect()
}

/// Rows of how often each strategy is chosen at every `k`, for every method (long format, one
/// row per method, `k` and strategy).
pub fn choice_rows(result: &ExperimentResult) -> Vec<ChoiceRow> {
    let mut rows =
        Vec::with_capacity(result.summaries.len() * result.trials() * result.strategies.len());
    for summary in &result.summaries {
        for (t, fractions) in summary.choice_fraction.iter().enumerate() {
            for (name, &fraction) in result.strategies.iter().zip(fractions) {
                rows.push(ChoiceRow {
                    method: summary.method,
                    k: t + 1,
                    strategy: name.clone(),
                    fraction,
                });
            }
        }
    }
    rows
}

/// The paper's selection table (figure 4): average cost and cumulative regret of every method at
/// each `k` of `ks`, with the relative difference of each later method to the first (replay
/// selection to UCB).
///
/// Regret is given twice: per trial against the best single strategy on the same house
/// (`cum_regret`, the project's definition), and as the paper computes it (`paper_regret`).
///
/// `k`s outside `1..=trials` are dropped; if none is left, the last trial is used, so that a
/// short experiment still gets a table.
pub fn selection_table_markdown(result: &ExperimentResult, ks: &[usize]) -> String {
    let trials = result.trials();
    let mut ks: Vec<usize> = ks
        .iter()
        .copied()
        .filter(|&k| k >= 1 && k <= trials)
        .collect();
    if ks.is_empty() {
        ks.push(trials);
    }
    let mut out = String::new();
    out.push_str("| Metric | Selection |");
    for k in &ks {
        let _ = write!(out, " k = {k} |");
    }
    out.push_str("\n|---|---|");
    out.push_str(&"---:|".repeat(ks.len()));
    out.push('\n');
    let value = |curve: Curve, summary: &MethodSummary, k: usize| at(curve(summary), k - 1);
    let metrics: [(&str, Curve, usize); 3] = [
        ("Avg. cost (m)", |s| &s.avg_cost, 2),
        ("Cumul. regret (m)", |s| &s.cum_regret, 1),
        (
            "Cumul. regret, paper's definition (m)",
            |s| &s.paper_regret,
            1,
        ),
    ];
    for (name, curve, decimals) in metrics {
        for (row, summary) in result.summaries.iter().enumerate() {
            if row == 0 {
                let _ = write!(out, "| {name} | {} |", summary.method.label());
            } else {
                let _ = write!(out, "| | {} |", summary.method.label());
            }
            for &k in &ks {
                let _ = write!(out, " {:.*} |", decimals, value(curve, summary, k));
            }
            out.push('\n');
        }
        if let Some((baseline, others)) = result.summaries.split_first() {
            for other in others {
                let _ = write!(
                    out,
                    "| | {} vs. {} |",
                    other.method.short_label(),
                    baseline.method.short_label()
                );
                for &k in &ks {
                    let _ = write!(
                        out,
                        " {} |",
                        relative_difference(value(curve, other, k), value(curve, baseline, k))
                    );
                }
                out.push('\n');
            }
        }
    }
    let _ = write!(
        out,
        "\n{} deployments of {} {} each, c = {} m, seed {}. Best single strategy: \
         `{}` (mean cost {:.2} m).\n",
        result.options.deployments,
        trials,
        if result.options.with_replacement {
            "houses drawn with replacement"
        } else {
            "distinct houses"
        },
        result.options.c,
        result.options.seed,
        result
            .strategies
            .get(result.best_strategy)
            .map_or("?", String::as_str),
        at(&result.mean_costs, result.best_strategy),
    );
    if result.options.reference_draws {
        out.push_str(
            "Houses and tie-breaks drawn as the reference code draws them: numpy's legacy \
             generator, deployment d seeded with seed + d.\n",
        );
    }
    out
}

/// A table of the candidates: mean cost over all houses and the share of all trials (of all
/// deployments) in which each method chose them.
pub fn strategy_table_markdown(result: &ExperimentResult) -> String {
    let mut out = String::from("| Strategy | Mean cost (m) |");
    for s in &result.summaries {
        let _ = write!(out, " {}: share of trials |", s.method.label());
    }
    out.push_str("\n|---|---:|");
    out.push_str(&"---:|".repeat(result.summaries.len()));
    out.push('\n');
    let share = |summary: &MethodSummary, i: usize| {
        let fractions = &summary.choice_fraction;
        let total: f64 = fractions.iter().map(|row| at(row, i)).sum();
        100.0 * total / fractions.len().max(1) as f64
    };
    for (i, name) in result.strategies.iter().enumerate() {
        let marker = if i == result.best_strategy {
            " (best)"
        } else {
            ""
        };
        let _ = write!(
            out,
            "| `{name}`{marker} | {:.2} |",
            at(&result.mean_costs, i)
        );
        for s in &result.summaries {
            let _ = write!(out, " {:.1} % |", share(s, i));
        }
        out.push('\n');
    }
    out
}

/// `(value − reference) / reference` as a signed percentage; "n/a" when the reference is 0.
fn relative_difference(value: f64, reference: f64) -> String {
    if reference == 0.0 {
        "n/a".to_owned()
    } else {
        format!("{:+.1} %", 100.0 * (value - reference) / reference)
    }
}
