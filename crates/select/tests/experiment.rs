//! Cost tables and the deployment experiment.

use std::collections::HashSet;

use ferret_select::{
    CostTable, ExperimentOptions, ExperimentResult, MAX_EXPERIMENT_TRIALS, Method, SelectError,
    run_experiment,
};
use proptest::prelude::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn names(prefix: &str, n: usize) -> Vec<String> {
    (0..n).map(|i| format!("{prefix}-{i}")).collect()
}

fn gaussian(rng: &mut impl Rng, mean: f64, sd: f64) -> f64 {
    // Box–Muller; 1 − u keeps the logarithm finite.
    let u: f64 = rng.random();
    let v: f64 = rng.random();
    mean + sd * (-2.0 * (1.0 - u).ln()).sqrt() * (std::f64::consts::TAU * v).cos()
}

/// A bandit with known means: one Gaussian cost per (house, strategy), replay exact.
fn gaussian_table(means: &[f64], sd: f64, houses: usize, seed: u64) -> CostTable {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let cost = (0..houses)
        .map(|_| {
            means
                .iter()
                .map(|&m| gaussian(&mut rng, m, sd).max(0.0))
                .collect()
        })
        .collect();
    CostTable::with_exact_replay(names("arm", means.len()), names("house", houses), cost).unwrap()
}

/// A small table with pessimistic replays (replay ≥ real cost).
fn small_table() -> CostTable {
    let cost = vec![
        vec![10.0, 20.0, 30.0],
        vec![12.0, 8.0, 40.0],
        vec![15.0, 25.0, 5.0],
        vec![9.0, 30.0, 35.0],
    ];
    let replay = cost
        .iter()
        .map(|row: &Vec<f64>| {
            (0..3)
                .map(|j| {
                    row.iter()
                        .enumerate()
                        .map(|(i, &c)| if i == j { c } else { c + 1.0 + i as f64 })
                        .collect()
                })
                .collect()
        })
        .collect();
    CostTable::new(names("s", 3), names("h", 4), cost, replay).unwrap()
}

fn opts(deployments: usize, trials: usize, seed: u64) -> ExperimentOptions {
    ExperimentOptions {
        deployments,
        trials_per_deployment: trials,
        c: 5.0,
        seed,
        ..ExperimentOptions::default()
    }
}

#[test]
fn both_methods_converge_to_the_best_arm_of_a_gaussian_bandit() {
    // Noise (sd 5 m) of the order of c = 5 m and of the gaps between arms.
    let means = [40.0, 44.0, 48.0, 55.0, 70.0];
    let table = gaussian_table(&means, 5.0, 400, 11);
    assert_eq!(table.best_strategy(), 0);
    let result = run_experiment(&table, &opts(300, 100, 5)).unwrap();
    let at_100 = |m: Method| result.summary(m).unwrap().choice_fraction[99][0];
    let ucb = at_100(Method::Ucb);
    let replay = at_100(Method::ReplaySelection);
    assert!(
        ucb >= 0.85,
        "UCB chose the best arm in {ucb} of deployments at k = 100"
    );
    assert!(
        replay >= 0.95,
        "replay chose the best arm in {replay} at k = 100"
    );
    let regret = |m: Method| result.summary(m).unwrap().cum_regret[99];
    assert!(
        regret(Method::ReplaySelection) <= 0.5 * regret(Method::Ucb),
        "replay regret {} > UCB regret {}",
        regret(Method::ReplaySelection),
        regret(Method::Ucb)
    );
    assert!(
        result.summary(Method::ReplaySelection).unwrap().avg_cost[99]
            <= result.summary(Method::Ucb).unwrap().avg_cost[99],
        "replay avg cost {} > UCB {}",
        result.summary(Method::ReplaySelection).unwrap().avg_cost[99],
        result.summary(Method::Ucb).unwrap().avg_cost[99]
    );
    // UCB's first five trials try all five arms, so it cannot be converged yet.
    for k in 0..5 {
        let fractions = &result.summary(Method::Ucb).unwrap().choice_fraction[k];
        assert!(fractions[0] < 0.5, "UCB at k = {}: {fractions:?}", k + 1);
    }
}

#[test]
fn replay_regret_is_no_higher_than_ucb_across_bandits() {
    for (seed, means) in [
        (1, [30.0, 31.0, 35.0, 40.0, 60.0]),
        (2, [50.0, 50.5, 51.0, 52.0, 53.0]),
        (3, [20.0, 60.0, 60.0, 60.0, 60.0]),
    ] {
        let table = gaussian_table(&means, 8.0, 200, seed);
        let result = run_experiment(&table, &opts(200, 100, seed)).unwrap();
        for k in [20, 50, 100] {
            assert!(
                result.summary(Method::ReplaySelection).unwrap().cum_regret[k - 1]
                    <= result.summary(Method::Ucb).unwrap().cum_regret[k - 1],
                "means {means:?}, k = {k}: replay {} > UCB {}",
                result.summary(Method::ReplaySelection).unwrap().cum_regret[k - 1],
                result.summary(Method::Ucb).unwrap().cum_regret[k - 1]
            );
        }
    }
}

#[test]
fn replay_untried_first_option_reaches_the_selector() {
    // Strategy 2 replays terribly; after the (random) first trial, only the option makes replay
    // selection deploy it.
    let table = CostTable::with_exact_replay(
        names("s", 3),
        names("h", 20),
        (0..20).map(|_| vec![10.0, 11.0, 90.0]).collect(),
    )
    .unwrap();
    let mut o = opts(30, 10, 4);
    let paper = run_experiment(&table, &o).unwrap();
    assert!(
        paper
            .deployments
            .iter()
            .all(|d| !d.run(Method::ReplaySelection).unwrap().chosen[1..].contains(&2))
    );
    o.replay_untried_first = true;
    let forced = run_experiment(&table, &o).unwrap();
    for dep in &forced.deployments {
        let first: HashSet<usize> = dep.run(Method::ReplaySelection).unwrap().chosen[..3]
            .iter()
            .copied()
            .collect();
        assert_eq!(
            first.len(),
            3,
            "{:?}",
            dep.run(Method::ReplaySelection).unwrap().chosen
        );
        assert!(
            dep.run(Method::ReplaySelection).unwrap().chosen[3..]
                .iter()
                .all(|&i| i == 0)
        );
    }
}

#[test]
fn experiment_is_deterministic_for_a_seed() {
    let table = gaussian_table(&[10.0, 12.0, 15.0], 4.0, 50, 3);
    let a = run_experiment(&table, &opts(40, 30, 99)).unwrap();
    let b = run_experiment(&table, &opts(40, 30, 99)).unwrap();
    assert_eq!(a, b);
    let c = run_experiment(&table, &opts(40, 30, 100)).unwrap();
    assert_ne!(
        a.deployments, c.deployments,
        "another seed draws other deployments"
    );
}

#[test]
fn experiment_does_not_depend_on_thread_count() {
    let table = gaussian_table(&[10.0, 12.0, 15.0, 11.0], 4.0, 60, 4);
    let run = |threads| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap()
            .install(|| run_experiment(&table, &opts(64, 40, 8)).unwrap())
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn deployments_draw_distinct_houses_shared_by_both_methods() {
    let table = small_table();
    let result = run_experiment(&table, &opts(50, 4, 1)).unwrap();
    let mut orders = HashSet::new();
    for dep in &result.deployments {
        let distinct: HashSet<usize> = dep.houses.iter().copied().collect();
        assert_eq!(distinct.len(), 4, "{:?}", dep.houses);
        orders.insert(dep.houses.clone());
        for method in Method::ALL {
            let run = dep.run(method).unwrap();
            for ((&h, &i), &c) in dep.houses.iter().zip(&run.chosen).zip(&run.costs) {
                assert_eq!(c, table.costs(h).unwrap()[i]);
            }
        }
    }
    assert!(
        orders.len() > 10,
        "house orders must vary: {}",
        orders.len()
    );
}

#[test]
fn best_single_strategy_has_the_lowest_mean_cost() {
    let table = small_table();
    // Means: s-0 11.5, s-1 20.75, s-2 27.5.
    assert_eq!(table.mean_costs(), vec![11.5, 20.75, 27.5]);
    assert_eq!(table.best_strategy(), 0);
    let result = run_experiment(&table, &opts(5, 2, 0)).unwrap();
    assert_eq!(result.best_strategy, 0);
    assert_eq!(result.strategies, names("s", 3));
}

#[test]
fn cost_table_rejects_bad_input() {
    let ok_cost = || vec![vec![1.0, 2.0]];
    let exact = |s: Vec<String>, h: Vec<String>, c| CostTable::with_exact_replay(s, h, c);
    assert_eq!(
        exact(vec![], names("h", 1), vec![vec![]]),
        Err(SelectError::NoStrategies)
    );
    assert_eq!(
        exact(names("s", 2), vec![], vec![]),
        Err(SelectError::NoHouses)
    );
    assert_eq!(
        exact(vec!["a".into(), "oracle".into()], names("h", 1), ok_cost()),
        Err(SelectError::OracleCandidate)
    );
    assert_eq!(
        exact(vec!["a".into(), "a".into()], names("h", 1), ok_cost()),
        Err(SelectError::DuplicateStrategy("a".into()))
    );
    assert_eq!(
        exact(
            names("s", 2),
            vec!["x".into(), "x".into()],
            vec![vec![1.0, 2.0]; 2]
        ),
        Err(SelectError::DuplicateHouse("x".into()))
    );
    assert!(matches!(
        exact(names("s", 2), names("h", 1), vec![vec![1.0]]),
        Err(SelectError::Shape {
            expected: 2,
            found: 1,
            ..
        })
    ));
    assert!(matches!(
        exact(names("s", 2), names("h", 2), ok_cost()),
        Err(SelectError::Shape {
            expected: 2,
            found: 1,
            ..
        })
    ));
    assert!(matches!(
        exact(names("s", 2), names("h", 1), vec![vec![1.0, f64::NAN]]),
        Err(SelectError::NonFiniteCost {
            house: 0,
            strategy: 1,
            ..
        })
    ));

    let new = |replay| CostTable::new(names("s", 2), names("h", 1), ok_cost(), replay);
    assert!(new(vec![vec![vec![1.0, 3.0], vec![4.0, 2.0]]]).is_ok());
    assert!(matches!(
        new(vec![vec![vec![1.0, 3.0], vec![4.0, f64::NAN]]]),
        Err(SelectError::NonFiniteReplay {
            house: 0,
            deployed: 1,
            strategy: 1,
            ..
        })
    ));
    assert!(matches!(
        new(vec![vec![vec![1.0, 3.0], vec![4.0, 2.5]]]),
        Err(SelectError::ReplayOfDeployed {
            house: 0,
            strategy: 1,
            ..
        })
    ));
    // Summation-order noise on the diagonal is accepted.
    assert!(new(vec![vec![vec![1.0 + 1e-12, 3.0], vec![4.0, 2.0]]]).is_ok());
    assert!(matches!(
        new(vec![vec![vec![1.0, 3.0]]]),
        Err(SelectError::Shape {
            expected: 2,
            found: 1,
            ..
        })
    ));
    assert!(matches!(
        new(vec![]),
        Err(SelectError::Shape {
            expected: 1,
            found: 0,
            ..
        })
    ));
}

#[test]
fn experiment_rejects_bad_options() {
    let table = small_table();
    assert_eq!(
        run_experiment(&table, &opts(10, 5, 0)),
        Err(SelectError::TooManyTrials {
            trials: 5,
            houses: 4
        })
    );
    assert!(matches!(
        run_experiment(&table, &opts(0, 2, 0)),
        Err(SelectError::InvalidOption {
            name: "deployments",
            ..
        })
    ));
    assert!(matches!(
        run_experiment(&table, &opts(3, 0, 0)),
        Err(SelectError::InvalidOption {
            name: "trials-per-deployment",
            ..
        })
    ));
    let mut bad_c = opts(3, 2, 0);
    bad_c.c = f64::NAN;
    assert!(matches!(
        run_experiment(&table, &bad_c),
        Err(SelectError::InvalidOption { name: "c", .. })
    ));
    // All houses in one deployment is fine.
    assert!(run_experiment(&table, &opts(3, 4, 0)).is_ok());
}

#[test]
fn experiments_too_large_for_memory_are_refused_before_running() {
    let table = small_table();
    // 100 M deployments used to be allocated, and the process killed for memory.
    for (deployments, trials) in [
        (100_000_000, 2),
        (MAX_EXPERIMENT_TRIALS / 2 + 1, 2),
        (usize::MAX, 4),
    ] {
        match run_experiment(&table, &opts(deployments, trials, 0)) {
            Err(SelectError::InvalidOption {
                name: "deployments",
                reason,
            }) => assert!(
                reason.contains(&MAX_EXPERIMENT_TRIALS.to_string()),
                "{reason}"
            ),
            other => panic!("{deployments} × {trials}: expected a limit error, got {other:?}"),
        }
    }
    let result = run_experiment(&table, &opts(MAX_EXPERIMENT_TRIALS / 1000, 1, 0)).unwrap();
    assert_eq!(result.deployments.len(), MAX_EXPERIMENT_TRIALS / 1000);
}

#[test]
fn default_options_are_the_papers() {
    let d = ExperimentOptions::default();
    assert_eq!(
        (d.deployments, d.trials_per_deployment, d.c),
        (500, 100, 5.0)
    );
}

/// Checks the summary curves against the raw deployments.
fn check_invariants(table: &CostTable, result: &ExperimentResult) {
    let d = result.deployments.len() as f64;
    let best = result.best_strategy;
    let means = table.mean_costs();
    assert!(means.iter().all(|&m| means[best] <= m));
    let s = table.n_strategies();
    for method in Method::ALL {
        let summary = result.summary(method).unwrap();
        for t in 0..result.trials() {
            let k = (t + 1) as f64;
            let mut avg = 0.0;
            let mut regret = 0.0;
            for dep in &result.deployments {
                let run = dep.run(method).unwrap();
                assert_eq!(
                    run.costs[t],
                    table.costs(dep.houses[t]).unwrap()[run.chosen[t]]
                );
                avg += run.costs[..=t].iter().sum::<f64>() / k;
                regret += (0..=t)
                    .map(|u| run.costs[u] - table.costs(dep.houses[u]).unwrap()[best])
                    .sum::<f64>();
            }
            let tol = 1e-9 * (1.0 + avg.abs() + regret.abs());
            assert!((summary.avg_cost[t] - avg / d).abs() <= tol);
            assert!((summary.cum_regret[t] - regret / d).abs() <= tol);
            // Regret is k times the gap to the best strategy's average on the same houses.
            let gap = k * (summary.avg_cost[t] - result.best_avg_cost[t]);
            assert!((summary.cum_regret[t] - gap).abs() <= 1e-9 * (1.0 + k * avg.abs() / d));
            let paper: f64 = summary.avg_cost[..=t].iter().map(|a| a - means[best]).sum();
            assert!((summary.paper_regret[t] - paper).abs() <= 1e-9 * (1.0 + paper.abs()));
            let total: f64 = summary.choice_fraction[t].iter().sum();
            assert!((total - 1.0).abs() < 1e-12);
        }
        let untried_first = if method == Method::Ucb {
            !result.options.ucb_untried_zero
        } else {
            result.options.replay_untried_first
        };
        if untried_first && result.trials() >= s {
            for dep in &result.deployments {
                let first: HashSet<usize> = dep.run(method).unwrap().chosen[..s]
                    .iter()
                    .copied()
                    .collect();
                assert_eq!(first.len(), s);
            }
        }
    }
}

fn arb_table() -> impl Strategy<Value = CostTable> {
    (1usize..5, 1usize..9).prop_flat_map(|(s, h)| {
        (
            prop::collection::vec(prop::collection::vec(0.0f64..100.0, s), h),
            prop::collection::vec(prop::collection::vec(0.0f64..30.0, s * s), h),
        )
            .prop_map(move |(cost, extra)| {
                // Pessimistic replay: real cost plus a non-negative extra, exact when deployed.
                let replay = cost
                    .iter()
                    .zip(&extra)
                    .map(|(row, extra)| {
                        (0..s)
                            .map(|j| {
                                (0..s)
                                    .map(|i| {
                                        if i == j {
                                            row[i]
                                        } else {
                                            row[i] + extra[j * s + i]
                                        }
                                    })
                                    .collect()
                            })
                            .collect()
                    })
                    .collect();
                CostTable::new(names("s", s), names("h", h), cost, replay).unwrap()
            })
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn summaries_are_consistent_with_deployments(
        table in arb_table(),
        deployments in 1usize..6,
        trials_frac in 0.0f64..1.0,
        c in 0.0f64..20.0,
        seed in any::<u64>(),
        replay_untried_first in any::<bool>(),
        ucb_untried_zero in any::<bool>(),
    ) {
        let trials = 1 + ((table.n_houses() - 1) as f64 * trials_frac) as usize;
        let opts = ExperimentOptions {
            deployments,
            trials_per_deployment: trials,
            c,
            seed,
            replay_untried_first,
            with_replacement: false,
            ucb_untried_zero,
            reference_draws: false,
        };
        let result = run_experiment(&table, &opts).unwrap();
        check_invariants(&table, &result);
    }
}

#[test]
fn grouped_tables_draw_one_trial_per_house_per_deployment() {
    // 12 rows: 4 houses with 3 trials (targets) each.
    let table = gaussian_table(&[10.0, 12.0], 3.0, 12, 4);
    let groups: Vec<usize> = (0..12).map(|r| r / 3).collect();
    let grouped = table.clone().grouped(groups.clone()).unwrap();
    assert_eq!(grouped.n_groups(), 4);
    assert_eq!(grouped.groups()[1], vec![3, 4, 5]);
    let opts = ExperimentOptions {
        deployments: 200,
        trials_per_deployment: 4,
        seed: 9,
        ..ExperimentOptions::default()
    };
    let result = run_experiment(&grouped, &opts).unwrap();
    let mut used = HashSet::new();
    for d in &result.deployments {
        let houses: HashSet<usize> = d.houses.iter().map(|&r| groups[r]).collect();
        assert_eq!(
            houses.len(),
            4,
            "a house twice in one deployment: {:?}",
            d.houses
        );
        used.extend(d.houses.iter().copied());
    }
    assert_eq!(used.len(), 12, "every trial is drawn in some deployment");
    // Five houses cannot be drawn from four.
    let too_many = ExperimentOptions {
        trials_per_deployment: 5,
        ..opts
    };
    assert!(matches!(
        run_experiment(&grouped, &too_many),
        Err(SelectError::TooManyTrials { houses: 4, .. })
    ));
    // One trial per house: grouping changes nothing.
    let singletons = table.clone().grouped((0..12).collect()).unwrap();
    let opts = ExperimentOptions {
        trials_per_deployment: 6,
        ..opts
    };
    let a = run_experiment(&table, &opts).unwrap();
    let b = run_experiment(&singletons, &opts).unwrap();
    assert_eq!(
        a.summary(Method::Ucb).unwrap().avg_cost,
        b.summary(Method::Ucb).unwrap().avg_cost
    );
    assert_eq!(
        a.summary(Method::ReplaySelection).unwrap().avg_cost,
        b.summary(Method::ReplaySelection).unwrap().avg_cost
    );
    assert!(table.grouped(vec![0; 3]).is_err());
}

#[test]
fn with_replacement_draws_repeat_houses_and_may_outnumber_them() {
    let table = gaussian_table(&[10.0, 12.0], 3.0, 5, 8);
    let opts = ExperimentOptions {
        deployments: 50,
        trials_per_deployment: 8,
        seed: 3,
        with_replacement: true,
        ..ExperimentOptions::default()
    };
    let result = run_experiment(&table, &opts).unwrap();
    for d in &result.deployments {
        assert_eq!(d.houses.len(), 8);
        let distinct: HashSet<usize> = d.houses.iter().copied().collect();
        assert!(distinct.len() < 8, "8 draws from 5 houses repeat one");
    }
    // Without replacement, 8 trials cannot be drawn from 5 houses.
    let distinct = ExperimentOptions {
        with_replacement: false,
        ..opts
    };
    assert!(matches!(
        run_experiment(&table, &distinct),
        Err(SelectError::TooManyTrials { .. })
    ));
    // Same seed, 4 trials: draws differ from the distinct ones in some deployment (repeats).
    let four = ExperimentOptions {
        trials_per_deployment: 4,
        ..opts
    };
    let result = run_experiment(&table, &four).unwrap();
    assert!(
        result
            .deployments
            .iter()
            .any(|d| { d.houses.iter().collect::<HashSet<_>>().len() < d.houses.len() })
    );
}

#[test]
fn reference_draws_follow_the_reference_script() {
    // 150 houses, two strategies; house m costs m for strategy 0 and 100 for strategy 1.
    let cost: Vec<Vec<f64>> = (0..150).map(|m| vec![m as f64, 100.0]).collect();
    let table = CostTable::with_exact_replay(names("s", 2), names("h", 150), cost).unwrap();
    let o = ExperimentOptions {
        reference_draws: true,
        ucb_untried_zero: true,
        ..opts(500, 100, 0)
    };
    let result = run_experiment(&table, &o).unwrap();
    // Run 0's and run 1's first maps are the reference's (its seeds 1000 + m).
    assert_eq!(
        result.deployments[0].houses[..10],
        [20, 16, 139, 20, 125, 30, 63, 42, 7, 58]
    );
    assert_eq!(
        result.deployments[1].houses[..10],
        [38, 94, 87, 113, 126, 37, 87, 99, 71, 134]
    );
    // The best strategy's curve ends at the reference's weighted table mean.
    let counts = ferret_select::numpy::reference_draw_counts(150, 500, 100);
    let weighted: f64 = counts
        .iter()
        .enumerate()
        .map(|(m, &w)| m as f64 * w as f64)
        .sum::<f64>()
        / 50_000.0;
    assert_eq!(result.best_strategy, 0);
    let last = *result.best_avg_cost.last().unwrap();
    assert!((last - weighted).abs() < 1e-9, "{last} vs {weighted}");
    // The first pick is a tie of two untried strategies: it draws from the stream, so the
    // methods' maps part from the tie-free sequence after the first trial.
    for dep in &result.deployments {
        for m in Method::ALL {
            let h = dep.houses_of(m);
            assert_eq!(h.len(), 100);
            assert_eq!(h[0], dep.houses[0]);
        }
    }
    assert!(
        result
            .deployments
            .iter()
            .any(|d| d.houses_of(Method::Ucb) != d.houses.as_slice())
    );
    // Without reference draws every method sees the deployment's houses.
    let plain = run_experiment(&table, &opts(5, 100, 0)).unwrap();
    for d in &plain.deployments {
        assert!(
            d.run(Method::Ucb).unwrap().houses.is_none()
                && d.houses_of(Method::Ucb) == d.houses.as_slice()
        );
    }
}
