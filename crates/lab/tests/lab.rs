//! The experiment layer on small generated houses: evaluation, the deployment loop and its house
//! order, and the feedback long work reports.

use std::sync::Arc;
use std::sync::atomic::{AtomicUsize, Ordering};

use ferret_lab::{
    DeploySettings, Feedback, LlmSettings, PlanningSettings, Silent, Strategies, TrialDraw,
    build_maps, deploy, evaluate, house_order, summarize,
};
use ferret_plan::{
    DrawMode, Protocol, ReplayMode, SearchProblem, Strategy, TrialsPerHouse, replay_costs,
    run_trial,
};
use ferret_select::{DeploymentLoop, Method};
use ferret_world::{GridParams, TravelCost};
use proptest::prelude::*;

fn strategies(specs: &[&str]) -> Vec<Arc<dyn Strategy>> {
    let names: Vec<String> = specs.iter().map(|s| s.to_string()).collect();
    let setup = Strategies::builder(&PlanningSettings::default(), &LlmSettings::default())
        .for_specs(&names)
        .build()
        .unwrap();
    specs
        .iter()
        .map(|s| setup.registry.build(s).unwrap())
        .collect()
}

#[derive(Default)]
struct Count {
    begun: AtomicUsize,
    ticks: AtomicUsize,
    ended: AtomicUsize,
}

impl Feedback for Count {
    fn begin(&self, _: &str, _: usize) {
        self.begun.fetch_add(1, Ordering::SeqCst);
    }
    fn tick(&self) {
        self.ticks.fetch_add(1, Ordering::SeqCst);
    }
    fn end(&self) {
        self.ended.fetch_add(1, Ordering::SeqCst);
    }
}

#[test]
fn evaluate_runs_every_strategy_on_the_same_trials_and_ticks_once_per_house() {
    let scenes = ferret_world::generate::default_scenes(6, 11).unwrap();
    let maps = build_maps(&scenes, &GridParams::default(), &Silent);
    let specs = ["optimistic+greedy", "model/uniform", "oracle"];
    let s = strategies(&specs);
    let draw = TrialDraw {
        seed: 3,
        reveal_fraction: 0.0,
        per_house: TrialsPerHouse::One,
        protocol: &Protocol::FERRET,
        holdout: None,
        tasks: None,
        team: None,
    };
    let count = Count::default();
    let ev = evaluate(&scenes, &maps, &s, &draw, &count);
    assert!(ev.errors.is_empty(), "{:?}", ev.errors);
    assert_eq!(ev.rows.len(), 6 * 3);
    assert_eq!(ev.houses_run, 6);
    assert_eq!(count.ticks.load(Ordering::SeqCst), 6);
    assert_eq!(count.begun.load(Ordering::SeqCst), 1);
    assert_eq!(count.ended.load(Ordering::SeqCst), 1);
    // Same target per house for every strategy, and the oracle is never beaten.
    for chunk in ev.rows.chunks(3) {
        assert!(chunk.iter().all(|r| r.target == chunk[0].target));
        assert!(chunk[2].cost_m <= chunk[0].cost_m + 1e-9);
        assert!(chunk[2].cost_m <= chunk[1].cost_m + 1e-9);
    }
    let summary = summarize(&ev.rows, &specs.map(String::from));
    assert_eq!(summary.len(), 3);
    assert!(summary.iter().all(|r| r.trials == 6));
}

#[test]
fn a_deployment_step_learns_what_run_trial_and_replay_costs_say() {
    let scenes = ferret_world::generate::default_scenes(4, 5).unwrap();
    let candidates = strategies(&["optimistic+greedy", "model/uniform"]);
    let settings = (ReplayMode::Pessimistic, TravelCost::Plain);
    let mut d = DeploymentLoop::new(
        Method::ReplaySelection,
        candidates.clone(),
        5.0,
        9,
        settings,
    )
    .unwrap();
    let protocol = Protocol::FERRET;
    let draw = TrialDraw {
        seed: 0,
        reveal_fraction: 0.0,
        per_house: TrialsPerHouse::One,
        protocol: &protocol,
        holdout: None,
        tasks: None,
        team: None,
    };
    for scene in &scenes {
        let (_, distances) =
            ferret_world::distance::build(&scene.house, &GridParams::default()).unwrap();
        let trial = draw.trials(scene).unwrap().remove(0);
        let problem = SearchProblem::new(&scene.house, &distances, &trial);
        let before = d.live().stats().iter().map(|s| s.deployed).sum::<usize>();
        let step = d.step(&problem, &scene.truth).unwrap();
        let direct = run_trial(candidates[step.chosen].as_ref(), &problem, &scene.truth).unwrap();
        assert_eq!(step.cost, direct.cost);
        assert_eq!(Some(step.found), direct.found);
        let replays = replay_costs(
            settings,
            &candidates,
            &problem,
            &scene.truth,
            &step.found_each,
            (step.chosen, step.cost),
        )
        .unwrap();
        assert_eq!(step.replays, replays);
        assert_eq!(step.replays[step.chosen], step.cost);
        let after = d.live().stats().iter().map(|s| s.deployed).sum::<usize>();
        assert_eq!(after, before + 1, "the selector learned the trial");
    }
}

#[test]
fn a_batch_deployment_names_a_type_no_container_holds() {
    let scenes = ferret_world::generate::default_scenes(2, 1).unwrap();
    let candidates = strategies(&["optimistic+greedy", "model/uniform"]);
    let mut d = DeploymentLoop::new(
        Method::Ucb,
        candidates,
        5.0,
        0,
        (ReplayMode::Pessimistic, TravelCost::Plain),
    )
    .unwrap();
    let find = vec!["NoSuchThing".parse::<ferret_lab::TaskText>().unwrap()];
    let protocol = Protocol::FERRET;
    let grid = GridParams::default();
    let settings = DeploySettings {
        trials: 1,
        find: &find,
        tasks: None,
        per_house: TrialsPerHouse::One,
        seed: 0,
        protocol: &protocol,
        grid: &grid,
    };
    let err = deploy(&scenes, &mut d, &settings, &Silent, &mut |_| {})
        .err()
        .map(|e| e.to_string())
        .unwrap_or_default();
    assert!(err.contains("no container holds NoSuchThing"), "{err}");
    assert!(err.contains("trial 1"), "{err}");
}

proptest! {
    #[test]
    fn house_orders_visit_what_their_draw_says(count in 1usize..40, trials in 1usize..60, seed: u64, given: bool, replacement: bool) {
        let draw = if replacement { DrawMode::Replacement } else { DrawMode::Distinct };
        match house_order(count, trials, given, draw, seed) {
            Err(_) => prop_assert!(!given && !replacement && trials > count),
            Ok(order) => {
                let h = order.houses();
                prop_assert_eq!(h.len(), trials);
                prop_assert!(h.iter().all(|&i| i < count));
                if given {
                    prop_assert!(h.iter().enumerate().all(|(k, &i)| i == k % count));
                } else if !replacement {
                    let mut seen = h.to_vec();
                    seen.sort_unstable();
                    seen.dedup();
                    prop_assert_eq!(seen.len(), trials, "distinct houses");
                }
                let again = house_order(count, trials, given, draw, seed).unwrap();
                prop_assert_eq!(again.houses(), h, "the seed decides the order");
            }
        }
    }
}
