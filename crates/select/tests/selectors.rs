//! UCB and replay selection, one trial at a time.

use std::collections::HashSet;

use ferret_select::{DEFAULT_C, Method, ReplaySelection, SelectError, Selector, Ucb};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

fn rng(seed: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed)
}

/// Feeds `selector` trials in which strategy `i` always costs `costs[i]` (replay exact).
fn run_constant(
    selector: &mut dyn Selector,
    costs: &[f64],
    trials: usize,
    seed: u64,
) -> Vec<usize> {
    let mut rng = rng(seed);
    (0..trials)
        .map(|_| {
            let i = selector.choose(&mut rng);
            selector.observe(i, costs[i], costs).unwrap();
            i
        })
        .collect()
}

#[test]
fn ucb_pulls_every_strategy_once_before_repeating() {
    // Strategy 0 is by far the cheapest, so only the untried-first rule makes UCB leave it.
    let costs = [1.0, 50.0, 60.0, 70.0, 80.0];
    for seed in 0..20 {
        let mut ucb = Ucb::new(costs.len(), DEFAULT_C).unwrap();
        let chosen = run_constant(&mut ucb, &costs, costs.len(), seed);
        let distinct: HashSet<usize> = chosen.iter().copied().collect();
        assert_eq!(distinct.len(), costs.len(), "seed {seed}: {chosen:?}");
        assert_eq!(ucb.pulls(), &[1, 1, 1, 1, 1]);
        // With every strategy tried once, the cheap one wins.
        assert_eq!(ucb.choose(&mut rng(seed)), 0);
    }
}

#[test]
fn ucb_score_is_paper_eq_2() {
    let mut ucb = Ucb::new(3, 5.0).unwrap();
    ucb.observe(0, 10.0, &[]).unwrap();
    ucb.observe(1, 20.0, &[]).unwrap();
    ucb.observe(0, 14.0, &[]).unwrap();
    // k = 3 trials; strategy 0: mean 12, n 2; strategy 1: mean 20, n 1; strategy 2 untried.
    let k: f64 = 3.0;
    assert_eq!(ucb.trials(), 3);
    assert!((ucb.score(0) - (12.0 - 5.0 * (k.ln() / 2.0).sqrt())).abs() < 1e-12);
    assert!((ucb.score(1) - (20.0 - 5.0 * k.ln().sqrt())).abs() < 1e-12);
    assert_eq!(ucb.score(2), f64::NEG_INFINITY);
    assert!(ucb.score(3).is_nan());
    assert_eq!(ucb.choose(&mut rng(0)), 2);
}

#[test]
fn ucb_single_strategy_after_one_trial_has_no_bonus() {
    // k = 1: ln 1 = 0, so the score is the plain mean.
    let mut ucb = Ucb::new(1, 5.0).unwrap();
    ucb.observe(0, 7.5, &[]).unwrap();
    assert_eq!(ucb.score(0), 7.5);
    assert_eq!(ucb.choose(&mut rng(1)), 0);
}

#[test]
fn ties_are_broken_by_the_seed() {
    let costs = [5.0; 6];
    let run = |seed| run_constant(&mut Ucb::new(6, DEFAULT_C).unwrap(), &costs, 30, seed);
    assert_eq!(run(3), run(3), "same seed, same choices");
    let firsts: HashSet<Vec<usize>> = (0..10).map(|seed| run(seed)[..6].to_vec()).collect();
    assert!(
        firsts.len() > 1,
        "different seeds must be able to choose differently"
    );

    let replay_run = |seed| {
        run_constant(
            &mut ReplaySelection::new(6, DEFAULT_C).unwrap(),
            &costs,
            30,
            seed,
        )
    };
    assert_eq!(replay_run(9), replay_run(9));
    let firsts: HashSet<usize> = (0..20).map(|seed| replay_run(seed)[0]).collect();
    assert!(
        firsts.len() > 1,
        "replay selection's first choice is a seeded tie"
    );
}

#[test]
fn replay_selection_score_is_paper_eq_5() {
    let mut sel = ReplaySelection::new(3, 5.0).unwrap();
    // Trial 1: deploy 0 (cost 10), replays 12 and 30. Entry 0 of the replay slice is ignored.
    sel.observe(0, 10.0, &[999.0, 12.0, 30.0]).unwrap();
    // Trial 2: deploy 1 (cost 8), replays 9 and 25.
    sel.observe(1, 8.0, &[9.0, 8.0, 25.0]).unwrap();
    let k: f64 = 2.0;
    let bonus = 5.0 * k.ln().sqrt(); // n = 1 for strategies 0 and 1
    assert_eq!(sel.replay_mean(0), Some((10.0 + 9.0) / 2.0));
    assert_eq!(sel.replay_mean(1), Some((12.0 + 8.0) / 2.0));
    assert_eq!(sel.replay_mean(2), Some((30.0 + 25.0) / 2.0));
    assert!((sel.score(0) - 9.5f64.max(10.0 - bonus)).abs() < 1e-12);
    assert!((sel.score(1) - 10.0f64.max(8.0 - bonus)).abs() < 1e-12);
    // Never deployed: the UCB term is −∞, so the score is the replay mean.
    assert_eq!(sel.score(2), 27.5);
    assert_eq!(sel.choose(&mut rng(0)), 0);
}

#[test]
fn replay_selection_trusts_replay_for_untried_strategies() {
    let mut sel = ReplaySelection::new(3, 5.0).unwrap();
    assert_eq!(sel.replay_mean(0), None);
    assert_eq!(sel.scores(), vec![f64::NEG_INFINITY; 3]);
    sel.observe(0, 10.0, &[10.0, 3.0, 20.0]).unwrap();
    // Strategy 1 was never deployed but replays cheaper than 0's real cost: it goes next.
    assert_eq!(sel.choose(&mut rng(0)), 1);

    let mut forced = ReplaySelection::new(3, 5.0).unwrap().untried_first(true);
    forced.observe(0, 10.0, &[10.0, 3.0, 20.0]).unwrap();
    forced.observe(1, 3.0, &[10.0, 3.0, 20.0]).unwrap();
    assert_eq!(
        forced.choose(&mut rng(0)),
        2,
        "untried_first deploys 2 despite its replay"
    );
}

#[test]
fn replay_selection_never_repeats_a_clearly_worse_strategy() {
    // After any first trial, every replay mean is exact: strategy 0 scores max(10, 10 − bonus)
    // = 10, every other at least its replay mean (12 or 100), so 0 is chosen from then on,
    // whichever strategy the (random) first trial deployed.
    let costs = [10.0, 12.0, 100.0, 100.0, 100.0];
    let mut firsts = HashSet::new();
    for seed in 0..50 {
        let mut sel = ReplaySelection::new(costs.len(), DEFAULT_C).unwrap();
        let chosen = run_constant(&mut sel, &costs, 100, seed);
        firsts.insert(chosen[0]);
        assert!(
            chosen[1..].iter().all(|&i| i == 0),
            "seed {seed}: {chosen:?}"
        );
    }
    assert!(
        firsts.len() > 2,
        "the first trial is a random tie: {firsts:?}"
    );
}

#[test]
fn observe_rejects_bad_input_and_records_nothing() {
    let mut sel = ReplaySelection::new(3, 5.0).unwrap();
    sel.observe(1, 4.0, &[5.0, 4.0, 6.0]).unwrap();
    let before = sel.clone();
    assert_eq!(
        sel.observe(3, 4.0, &[1.0, 2.0, 3.0]),
        Err(SelectError::StrategyOutOfRange {
            index: 3,
            strategies: 3
        })
    );
    assert!(matches!(
        sel.observe(0, f64::NAN, &[1.0, 2.0, 3.0]),
        Err(SelectError::NonFiniteObservation { strategy: 0, .. })
    ));
    assert!(matches!(
        sel.observe(0, 1.0, &[1.0, 2.0]),
        Err(SelectError::Shape {
            expected: 3,
            found: 2,
            ..
        })
    ));
    assert!(matches!(
        sel.observe(0, 1.0, &[1.0, f64::INFINITY, 3.0]),
        Err(SelectError::NonFiniteObservation { strategy: 1, .. })
    ));
    assert_eq!(sel, before);
    // The deployed strategy's own replay entry is not read.
    assert!(sel.observe(0, 1.0, &[f64::NAN, 2.0, 3.0]).is_ok());

    let mut ucb = Ucb::new(2, 5.0).unwrap();
    assert!(matches!(
        ucb.observe(0, f64::NEG_INFINITY, &[]),
        Err(SelectError::NonFiniteObservation { .. })
    ));
    assert_eq!(ucb.trials(), 0);
}

#[test]
fn constructors_reject_bad_parameters() {
    assert_eq!(Ucb::new(0, 5.0), Err(SelectError::NoStrategies));
    assert_eq!(ReplaySelection::new(0, 5.0), Err(SelectError::NoStrategies));
    for c in [-1.0, f64::NAN, f64::INFINITY] {
        assert!(matches!(
            Ucb::new(2, c),
            Err(SelectError::InvalidOption { name: "c", .. })
        ));
        assert!(matches!(
            ReplaySelection::new(2, c),
            Err(SelectError::InvalidOption { name: "c", .. })
        ));
    }
    assert!(Ucb::new(2, 0.0).is_ok(), "c = 0 is plain greedy");
}

#[test]
fn methods_have_stable_names_and_selectors() {
    for method in Method::ALL {
        assert_eq!(method.name().parse::<Method>(), Ok(method));
        let selector = method.selector(4, DEFAULT_C).unwrap();
        assert_eq!(selector.method(), method);
        assert_eq!(selector.n_strategies(), 4);
    }
    assert_eq!(Method::Ucb.to_string(), "ucb");
    assert_eq!(Method::ReplaySelection.to_string(), "replay");
    assert!("thompson".parse::<Method>().is_err());
}

#[test]
fn ucb_untried_score_zero_is_the_reference_rule() {
    // Strategy 0 costs 1 m; after one trial its bound is 1 − c·√(ln 1 / 1) = 1 > 0, so an
    // untried strategy (score 0) comes next.
    let mut ucb = Ucb::new(3, 5.0).unwrap().untried_score(0.0);
    assert_eq!(ucb.scores(), vec![0.0; 3]);
    ucb.observe(0, 1.0, &[]).unwrap();
    assert_eq!(ucb.score(0), 1.0);
    assert_eq!(ucb.score(1), 0.0);
    assert_ne!(ucb.choose(&mut rng(1)), 0);
    // After three trials of strategy 0 its bound 1 − 5·√(ln 3 / 3) is negative: it beats the
    // untried strategies, which the default (−∞) would have tried first.
    ucb.observe(0, 1.0, &[]).unwrap();
    ucb.observe(0, 1.0, &[]).unwrap();
    assert!(ucb.score(0) < 0.0);
    assert_eq!(ucb.choose(&mut rng(1)), 0);
    let mut default = Ucb::new(3, 5.0).unwrap();
    for _ in 0..3 {
        default.observe(0, 1.0, &[]).unwrap();
    }
    assert_ne!(default.choose(&mut rng(1)), 0);
    assert_eq!(
        Ucb::new(2, 5.0).unwrap().untried_score(f64::NAN).score(0),
        0.0
    );
}
