//! Report rows and Markdown tables.

use ferret_select::{
    CostTable, ExperimentOptions, ExperimentResult, Method, MethodSummary, PAPER_KS, choice_rows,
    run_experiment, selection_rows, selection_table_markdown, strategy_table_markdown,
};

/// A result with the paper's figure-4 numbers at k = 20, 50, 100 and zeros elsewhere.
fn paper_like_result() -> ExperimentResult {
    let curve = |at: [f64; 3]| {
        let mut v = vec![0.0; 100];
        v[19] = at[0];
        v[49] = at[1];
        v[99] = at[2];
        v
    };
    let fractions = |i: usize| {
        (0..100)
            .map(|_| {
                let mut row = vec![0.0; 3];
                row[i] = 1.0;
                row
            })
            .collect()
    };
    ExperimentResult {
        options: ExperimentOptions {
            deployments: 500,
            trials_per_deployment: 100,
            c: 5.0,
            seed: 0,
            replay_untried_first: false,
            with_replacement: false,
            ucb_untried_zero: false,
            reference_draws: false,
        },
        strategies: vec!["a".into(), "b".into(), "c".into()],
        mean_costs: vec![230.0, 240.0, 250.0],
        best_strategy: 0,
        best_avg_cost: vec![230.0; 100],
        summaries: vec![
            MethodSummary {
                method: Method::Ucb,
                avg_cost: curve([258.72, 254.63, 247.25]),
                cum_regret: curve([862.6, 1952.0, 3166.0]),
                paper_regret: curve([884.7, 2102.8, 3800.2]),
                choice_fraction: fractions(1),
            },
            MethodSummary {
                method: Method::ReplaySelection,
                avg_cost: curve([248.12, 240.40, 231.29]),
                cum_regret: curve([650.6, 1240.6, 1570.0]),
                paper_regret: curve([751.0, 1579.8, 2516.5]),
                choice_fraction: fractions(0),
            },
        ],
        deployments: vec![],
    }
}

#[test]
fn selection_table_has_the_papers_layout_and_differences() {
    let md = selection_table_markdown(&paper_like_result(), &PAPER_KS);
    let expected = "\
| Metric | Selection | k = 20 | k = 50 | k = 100 |
|---|---|---:|---:|---:|
| Avg. cost (m) | UCB selection | 258.72 | 254.63 | 247.25 |
| | Replay selection | 248.12 | 240.40 | 231.29 |
| | Replay vs. UCB | -4.1 % | -5.6 % | -6.5 % |
| Cumul. regret (m) | UCB selection | 862.6 | 1952.0 | 3166.0 |
| | Replay selection | 650.6 | 1240.6 | 1570.0 |
| | Replay vs. UCB | -24.6 % | -36.4 % | -50.4 % |
| Cumul. regret, paper's definition (m) | UCB selection | 884.7 | 2102.8 | 3800.2 |
| | Replay selection | 751.0 | 1579.8 | 2516.5 |
| | Replay vs. UCB | -15.1 % | -24.9 % | -33.8 % |
";
    assert!(md.starts_with(expected), "{md}");
    assert!(md.contains("Best single strategy: `a` (mean cost 230.00 m)"));
    assert!(
        md.contains("500 deployments of 100 distinct houses each"),
        "{md}"
    );
    let mut drawn = paper_like_result();
    drawn.options.with_replacement = true;
    let md = selection_table_markdown(&drawn, &PAPER_KS);
    assert!(
        md.contains("100 houses drawn with replacement each"),
        "{md}"
    );
    drawn.options.reference_draws = true;
    let md = selection_table_markdown(&drawn, &PAPER_KS);
    assert!(md.contains("numpy's legacy generator"), "{md}");
}

#[test]
fn selection_table_drops_ks_beyond_the_run() {
    let mut result = paper_like_result();
    result.options.trials_per_deployment = 60;
    let md = selection_table_markdown(&result, &PAPER_KS);
    assert!(md.starts_with("| Metric | Selection | k = 20 | k = 50 |\n"));
    let md = selection_table_markdown(&result, &[0, 200]);
    assert!(md.starts_with("| Metric | Selection | k = 60 |\n"), "{md}");
}

#[test]
fn strategy_table_reports_shares_of_trials() {
    let md = strategy_table_markdown(&paper_like_result());
    assert!(
        md.contains("| `a` (best) | 230.00 | 0.0 % | 100.0 % |"),
        "{md}"
    );
    assert!(md.contains("| `b` | 240.00 | 100.0 % | 0.0 % |"), "{md}");
    assert!(md.contains("| `c` | 250.00 | 0.0 % | 0.0 % |"), "{md}");
}

#[test]
fn selection_rows_cover_every_method_and_k() {
    let table = CostTable::with_exact_replay(
        vec!["x".into(), "y".into()],
        (0..6).map(|h| format!("h{h}")).collect(),
        (0..6).map(|h| vec![h as f64, 10.0]).collect(),
    )
    .unwrap();
    let opts = ExperimentOptions {
        deployments: 7,
        trials_per_deployment: 5,
        c: 5.0,
        seed: 2,
        ..ExperimentOptions::default()
    };
    let result = run_experiment(&table, &opts).unwrap();
    let rows = selection_rows(&result);
    assert_eq!(rows.len(), 10);
    for (n, row) in rows.iter().enumerate() {
        let method = if n < 5 {
            Method::Ucb
        } else {
            Method::ReplaySelection
        };
        let t = n % 5;
        assert_eq!((row.method, row.k), (method, t + 1));
        let summary = result.summary(method).unwrap();
        assert_eq!(row.avg_cost, summary.avg_cost[t]);
        assert_eq!(row.cum_regret, summary.cum_regret[t]);
        assert_eq!(row.paper_regret, summary.paper_regret[t]);
        assert_eq!(row.best_avg_cost, result.best_avg_cost[t]);
        assert_eq!(row.best_fraction, summary.choice_fraction[t][0]);
    }

    let choices = choice_rows(&result);
    assert_eq!(choices.len(), 2 * 5 * 2);
    assert_eq!(choices[0].strategy, "x");
    assert_eq!(choices[1].strategy, "y");
    assert_eq!((choices[3].method, choices[3].k), (Method::Ucb, 2));
    for pair in choices.chunks(2) {
        assert!((pair[0].fraction + pair[1].fraction - 1.0).abs() < 1e-12);
    }
}

#[test]
fn tables_show_the_methods_a_result_holds() {
    // Tables and rows come from the result's summaries, not from a fixed pair of methods.
    let mut result = paper_like_result();
    result
        .summaries
        .retain(|s| s.method == Method::ReplaySelection);
    let md = selection_table_markdown(&result, &PAPER_KS);
    assert!(
        md.contains("| Avg. cost (m) | Replay selection | 248.12 |"),
        "{md}"
    );
    assert!(!md.contains("UCB"), "{md}");
    assert!(!md.contains(" vs. "), "{md}");
    let strategies = strategy_table_markdown(&result);
    assert!(
        strategies.starts_with(
            "| Strategy | Mean cost (m) | Replay selection: share of trials |\n|---|---:|---:|\n"
        ),
        "{strategies}"
    );
    assert!(
        strategies.contains("| `a` (best) | 230.00 | 100.0 % |"),
        "{strategies}"
    );
    assert!(
        selection_rows(&result)
            .iter()
            .all(|r| r.method == Method::ReplaySelection)
    );
    assert_eq!(choice_rows(&result).len(), 100 * 3);
    assert!(result.summary(Method::Ucb).is_none());
}
