//! Property tests of policies, the simulator and offline replay on small synthetic houses.

use std::sync::Arc;

use ferret_plan::{
    CandidateLimit, PlanMemo, PlannerConfig, SearchProblem, StrategyRegistry, TrialSpec,
    replay_cost, run_trial,
};
use ferret_world::{GroundTruth, House, ObjectType, Scene, SmallObject};
use proptest::prelude::{
    Just, ProptestConfig, any, prop, prop_assert, prop_assert_eq, prop_assume, prop_oneof, proptest,
};
use proptest::strategy::Strategy as _;

mod support;
use support::{HouseParts, arb_house, house, house_at, registry, tasks_of};

const SPECS: [&str; 6] = [
    "optimistic+greedy",
    "model/uniform",
    "model/prior",
    "model/prior/k3",
    "model/prior/exact",
    "oracle",
];

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    #[test]
    fn every_policy_finds_the_target_and_none_beats_the_oracle((pts, kinds, contents) in arb_house()) {
        let (house, truth, distances) = house(&pts, &kinds, &contents);
        let scene = Scene { house: house.clone(), truth: truth.clone() };
        let reg = registry(std::slice::from_ref(&scene));
        for target in truth.target_types() {
            let trial = TrialSpec::single(target.clone());
            let oracle = run_trial(reg.build("oracle").unwrap().as_ref(), &SearchProblem::new(&house, &distances, &trial), &truth).unwrap();
            for spec in SPECS {
                let s = reg.build(spec).unwrap();
                // run_trial itself rejects a policy choosing a searched container, so Ok means it never did.
                let out = run_trial(s.as_ref(), &SearchProblem::new(&house, &distances, &trial), &truth).unwrap();
                let found = out.found.expect("target exists, so every policy must find it");
                prop_assert!(truth.holds(found, &target));
                prop_assert_eq!(*out.searched.last().unwrap(), found);
                let mut seen = out.searched.clone();
                seen.sort_unstable();
                seen.dedup();
                prop_assert_eq!(seen.len(), out.searched.len(), "{} searched a container twice", spec);
                prop_assert!(out.cost + 1e-9 >= oracle.cost, "{} ({}) beat the oracle ({})", spec, out.cost, oracle.cost);
            }
        }
    }

    #[test]
    fn replay_of_the_deployed_strategy_is_its_own_cost_and_others_are_pessimistic(
        (pts, kinds, contents) in arb_house()
    ) {
        let (house, truth, distances) = house(&pts, &kinds, &contents);
        let scene = Scene { house: house.clone(), truth: truth.clone() };
        let reg = registry(std::slice::from_ref(&scene));
        for target in truth.target_types() {
            let trial = TrialSpec::single(target.clone());
            let single_goal = truth.goal_containers(&target).len() == 1;
            for deployed in SPECS.iter().filter(|s| **s != "oracle") {
                let d = reg.build(deployed).unwrap();
                let real = run_trial(d.as_ref(), &SearchProblem::new(&house, &distances, &trial), &truth).unwrap();
                let found = real.found.unwrap();
                let own = replay_cost(d.as_ref(), &SearchProblem::new(&house, &distances, &trial), &[Some(found)]).unwrap();
                prop_assert!((own - real.cost).abs() < 1e-9, "{}: replay {} != real {}", deployed, own, real.cost);
                for other in SPECS.iter().filter(|s| **s != "oracle") {
                    let o = reg.build(other).unwrap();
                    let true_cost = run_trial(o.as_ref(), &SearchProblem::new(&house, &distances, &trial), &truth).unwrap().cost;
                    let replay = replay_cost(o.as_ref(), &SearchProblem::new(&house, &distances, &trial), &[Some(found)]).unwrap();
                    prop_assert!(replay + 1e-9 >= true_cost, "{} replay {} < true {}", other, replay, true_cost);
                    if single_goal {
                        prop_assert!((replay - true_cost).abs() < 1e-9);
                    }
                }
            }
        }
    }
}

#[test]
fn model_strategy_prefers_the_likely_container() {
    // Fridge 6 m away always holds eggs in training; the bed 2 m away never does.
    let (house, truth, distances) = house(&[(2.0, 0.0), (-6.0, 0.0)], &[1, 0], &[vec![], vec![0]]);
    let training: Vec<Scene> = (0..20)
        .map(|_| Scene {
            house: house.clone(),
            truth: truth.clone(),
        })
        .collect();
    let reg = registry(&training);
    let trial = TrialSpec::single(ObjectType::new("Egg"));
    let model = run_trial(
        reg.build("model/prior").unwrap().as_ref(),
        &SearchProblem::new(&house, &distances, &trial),
        &truth,
    )
    .unwrap();
    let greedy = run_trial(
        reg.build("optimistic+greedy").unwrap().as_ref(),
        &SearchProblem::new(&house, &distances, &trial),
        &truth,
    )
    .unwrap();
    assert_eq!(model.searched, vec![1]);
    assert!((model.cost - 6.0).abs() < 1e-12);
    assert_eq!(greedy.searched, vec![0, 1]);
    assert!((greedy.cost - 10.0).abs() < 1e-12);
}

#[test]
fn unknown_and_malformed_specs_are_clear_errors() {
    let reg = StrategyRegistry::builtin(None, PlannerConfig::default(), 12);
    let msg = |s: &str| {
        reg.build(s)
            .err()
            .map(|e| e.to_string())
            .unwrap_or_default()
    };
    assert!(msg("model/prior").contains("no prior loaded"));
    assert!(msg("model/uniform/k0").contains("not a planner limit"));
    assert!(msg("teleport").contains("known forms"));
    assert!(msg("oracle/extra").contains("takes no arguments"));
    assert!(reg.build("model/uniform/exact").is_ok());
    let _ = CandidateLimit::PAPER;
}

#[test]
fn trials_per_house_draws_distinct_targets_and_one_is_draw_trial() {
    use ferret_plan::{TrialsPerHouse, draw_trial, draw_trials};
    // Three object types spread over four containers.
    let (house, truth, _) = house(
        &[(1.0, 0.0), (2.0, 0.0), (3.0, 0.0), (4.0, 0.0)],
        &[0, 1, 2, 3],
        &[vec![0], vec![1, 2], vec![], vec![0]],
    );
    for seed in 0..20 {
        let one = draw_trials(&house, &truth, seed, 0.0, TrialsPerHouse::One).unwrap();
        assert_eq!(one, vec![draw_trial(&house, &truth, seed, 0.0).unwrap()]);
        let two = draw_trials(&house, &truth, seed, 0.5, TrialsPerHouse::Count(2)).unwrap();
        assert_eq!(two.len(), 2);
        assert_ne!(two[0].task.first(), two[1].task.first());
        for t in &two {
            // Half of the containers without the target start out searched, never a goal.
            let goals = truth.goal_containers(t.task.first());
            assert_eq!(
                t.revealed.len(),
                ((4 - goals.len()) as f64 * 0.5).round() as usize
            );
            assert!(t.revealed.iter().all(|c| !goals.contains(c)));
        }
        // More than the house has, or `all`: every type once, in name order for `all`.
        let many = draw_trials(&house, &truth, seed, 0.0, TrialsPerHouse::Count(9)).unwrap();
        assert_eq!(many.len(), 3);
        let all = draw_trials(&house, &truth, seed, 0.0, TrialsPerHouse::All).unwrap();
        let names: Vec<&str> = all.iter().map(|t| t.task.first().as_str()).collect();
        assert_eq!(names, ["Book", "Egg", "RemoteControl"]);
    }
    assert_eq!("all".parse(), Ok(TrialsPerHouse::All));
    assert_eq!("1".parse(), Ok(TrialsPerHouse::One));
    assert_eq!("5".parse(), Ok(TrialsPerHouse::Count(5)));
    assert!("0".parse::<TrialsPerHouse>().is_err());
    assert!("some".parse::<TrialsPerHouse>().is_err());
    assert_eq!(TrialsPerHouse::Count(5).to_string(), "5");
}

#[test]
fn authors_cost_specs_parse_and_plan_with_the_extra_term() {
    use ferret_plan::{CostModel, strategy::planner_config_from};
    let reg = StrategyRegistry::builtin(None, PlannerConfig::default(), 12);
    for ok in [
        "model/uniform/authors",
        "model/uniform/k3/authors",
        "model/uniform/exact/authors",
    ] {
        assert!(reg.build(ok).is_ok(), "{ok}");
    }
    let err = reg
        .build("model/uniform/authors/k3")
        .err()
        .map(|e| e.to_string());
    assert!(err.unwrap_or_default().contains("too many parts"));
    let spec = ferret_plan::StrategySpec::parse("model/uniform/k3/authors").unwrap();
    let config = planner_config_from(&spec, 1, PlannerConfig::default(), 12).unwrap();
    assert_eq!(config.cost, CostModel::Authors);
    assert_eq!(config.limit, CandidateLimit::Paper { k: 3 });
    let plain = ferret_plan::StrategySpec::parse("model/uniform/k3").unwrap();
    let config = planner_config_from(&plain, 1, PlannerConfig::default(), 12).unwrap();
    assert_eq!(config.cost, CostModel::Paper);

    // Uniform likelihood p on a line: a likely container 4 m away and another 5 m the other way.
    // Eq. 3 from the start: 4 + (1−p)·9 vs 5 + (1−p)·9 → the nearer first either way; the
    // authors' term adds p·4 vs p·5, the same order. Both find the target at 5 m after 4 + 9 m.
    let (house, truth, distances) = house(&[(4.0, 0.0), (-5.0, 0.0)], &[0, 1], &[vec![], vec![0]]);
    let trial = TrialSpec::single(ObjectType::new("Egg"));
    for s in ["model/uniform", "model/uniform/authors"] {
        let strategy = reg.build(s).unwrap();
        let out = run_trial(
            strategy.as_ref(),
            &SearchProblem::new(&house, &distances, &trial),
            &truth,
        )
        .unwrap();
        assert_eq!(out.searched, vec![0, 1], "{s}");
        assert!((out.cost - 13.0).abs() < 1e-9, "{s}: {}", out.cost);
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// The counterfactual replay (the reference code's) stops at any goal container, so it never
    /// costs more than the pessimistic one, equals the true run of the replayed strategy, and the
    /// two agree when only one container holds the target.
    #[test]
    fn counterfactual_replay_is_at_most_pessimistic_on_every_trial(
        (pts, kinds, contents) in arb_house(),
        seed in 0u64..50,
    ) {
        use ferret_plan::{InitialBelief, Protocol, ReplayMode, SearchProblem, TrialsPerHouse, draw_trials_with, replay_cost_with};
        let (house, truth, distances) = house(&pts, &kinds, &contents);
        prop_assume!(!truth.target_types().is_empty());
        let scene = Scene { house: house.clone(), truth: truth.clone() };
        let reg = registry(std::slice::from_ref(&scene));
        for belief in [InitialBelief::Empty, InitialBelief::Paper] {
            let protocol = Protocol { initial_belief: belief, ..Protocol::FERRET };
            let trials = draw_trials_with(&house, &truth, seed, 0.0, TrialsPerHouse::All, &protocol).unwrap();
            for trial in &trials {
                let single_goal = truth.goal_containers(trial.task.first()).len() == 1;
                for deployed in SPECS.iter().filter(|s| **s != "oracle") {
                    let d = reg.build(deployed).unwrap();
                    let found = run_trial(d.as_ref(), &SearchProblem::new(&house, &distances, trial), &truth).unwrap().found.unwrap();
                    for other in SPECS.iter().filter(|s| **s != "oracle") {
                        let o = reg.build(other).unwrap();
                        let pess = replay_cost_with(ReplayMode::Pessimistic, o.as_ref(), &SearchProblem::new(&house, &distances, trial), &truth, &[Some(found)]).unwrap();
                        let cf = replay_cost_with(ReplayMode::Counterfactual, o.as_ref(), &SearchProblem::new(&house, &distances, trial), &truth, &[Some(found)]).unwrap();
                        let real = run_trial(o.as_ref(), &SearchProblem::new(&house, &distances, trial), &truth).unwrap().cost;
                        prop_assert!(cf <= pess + 1e-9, "{}: counterfactual {} > pessimistic {}", other, cf, pess);
                        prop_assert!((cf - real).abs() < 1e-9);
                        if single_goal {
                            prop_assert!((cf - pess).abs() < 1e-9);
                        }
                    }
                }
            }
        }
    }

    /// The paper's initial belief marks no goal container searched, keeps at least half of all
    /// the containers (and at least two) unsearched, so at most ⌈n/2⌉ start out searched, and
    /// changes nothing else of the draw.
    #[test]
    fn paper_belief_never_marks_a_goal_searched(
        (pts, kinds, contents) in arb_house(),
        seed in 0u64..50,
    ) {
        use ferret_plan::{InitialBelief, Protocol, TrialsPerHouse, draw_trials, draw_trials_with};
        let (house, truth, _) = house(&pts, &kinds, &contents);
        prop_assume!(!truth.target_types().is_empty());
        let paper = Protocol { initial_belief: InitialBelief::Paper, ..Protocol::FERRET };
        for per_house in [TrialsPerHouse::One, TrialsPerHouse::All] {
            let plain = draw_trials(&house, &truth, seed, 0.0, per_house).unwrap();
            prop_assert_eq!(&draw_trials_with(&house, &truth, seed, 0.0, per_house, &Protocol::FERRET).unwrap(), &plain);
            let with = draw_trials_with(&house, &truth, seed, 0.0, per_house, &paper).unwrap();
            prop_assert_eq!(with.len(), plain.len());
            for (a, b) in plain.iter().zip(&with) {
                prop_assert_eq!(&a.task.first(), &b.task.first());
                prop_assert!(a.revealed.is_empty());
                let goals = truth.goal_containers(b.task.first());
                prop_assert!(b.revealed.iter().all(|c| !goals.contains(c)));
                let n = house.containers.len();
                let kept = n - b.revealed.len();
                prop_assert!(kept >= (n / 2).max(n.min(2)), "kept {} of {}", kept, n);
                prop_assert!(b.revealed.len() <= n.div_ceil(2), "revealed {} of {}", b.revealed.len(), n);
            }
        }
    }
}

#[test]
fn paper_targets_leave_out_types_that_are_also_furniture() {
    use ferret_plan::{Protocol, TargetSet, TrialsPerHouse, draw_trials_with};
    // Containers are Fridge, Bed; contents Egg, Book and a "Bed" (a child that is furniture too).
    let (house, mut truth, _) = house(&[(1.0, 0.0), (2.0, 0.0)], &[0, 1], &[vec![0], vec![1]]);
    truth = GroundTruth::new(vec![
        truth.contents(0).to_vec(),
        vec![
            truth.contents(1)[0].clone(),
            SmallObject {
                id: "small|bed".into(),
                object_type: ObjectType::new("Bed"),
            },
        ],
    ]);
    let all = |targets| {
        let p = Protocol {
            targets,
            ..Protocol::FERRET
        };
        draw_trials_with(&house, &truth, 0, 0.0, TrialsPerHouse::All, &p)
            .unwrap()
            .into_iter()
            .map(|t| t.task.first().to_string())
            .collect::<Vec<_>>()
    };
    assert_eq!(all(TargetSet::Pickupable), ["Bed", "Book", "Egg"]);
    assert_eq!(all(TargetSet::Paper), ["Book", "Egg"]);
}

#[test]
fn python_draws_give_the_reference_trials() {
    use ferret_plan::{InitialBelief, Protocol, TrialRng, TrialsPerHouse, draw_trials_with};
    // Ten containers; seven distinct object types, listed in house order T0 … T6, with T6 (the
    // type a fresh `random.seed(1000)` samples among seven) in container 2 only.
    let (mut house, _, _) = house(&[(1.0, 0.0); 10], &[0; 10], &[]);
    house.index = 1000;
    let obj = |t: &str| SmallObject {
        id: format!("small|{t}"),
        object_type: ObjectType::new(t),
    };
    let mut contents = vec![vec![]; 10];
    contents[0] = vec![obj("T0"), obj("T1")];
    contents[1] = vec![obj("T2"), obj("T0")];
    contents[2] = vec![obj("T3"), obj("T4"), obj("T5"), obj("T6")];
    // Put the types out of name order so that house order is what is tested.
    contents[0][0].object_type = ObjectType::new("Z0");
    contents[1][1].object_type = ObjectType::new("Z0");
    contents[2][3].object_type = ObjectType::new("A6");
    let truth = GroundTruth::new(contents);
    let p = Protocol {
        rng: TrialRng::Python,
        initial_belief: InitialBelief::Paper,
        ..Protocol::FERRET
    };
    let trials = draw_trials_with(&house, &truth, 0, 0.0, TrialsPerHouse::One, &p).unwrap();
    assert_eq!(trials[0].task.first().as_str(), "A6");
    // Drawn unsearched: 1 6 5 0 3 9 7 8; containers 2 and 4 pre-searched, but 2 holds the
    // target and stays unsearched.
    assert_eq!(trials[0].revealed, vec![4]);
    // Another trial seed draws another trial; the ferret generator draws yet another way.
    let other = draw_trials_with(&house, &truth, 1, 0.0, TrialsPerHouse::One, &p).unwrap();
    let ferret = Protocol {
        rng: TrialRng::Ferret,
        ..p
    };
    let f = draw_trials_with(&house, &truth, 0, 0.0, TrialsPerHouse::One, &ferret).unwrap();
    assert!(other != trials || f != trials);
    // Without the paper belief the python target is the same and nothing is searched.
    let empty = Protocol {
        initial_belief: InitialBelief::Empty,
        ..p
    };
    let t = draw_trials_with(&house, &truth, 0, 0.0, TrialsPerHouse::One, &empty).unwrap();
    assert_eq!((t[0].task.first().as_str(), t[0].revealed.len()), ("A6", 0));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// A replay memo shared by every trial of a house answers exactly what replaying again
    /// answers, whatever the order the trials end in and whichever candidate each deploys: same
    /// target and found container but other containers revealed, other targets, other found
    /// containers are all told apart; a repeat is answered from the memo; counterfactual
    /// replays are never kept.
    #[test]
    fn a_replay_memo_answers_exactly_what_replaying_again_answers(
        (pts, kinds, contents) in arb_house(),
        reveal in prop::collection::vec(0usize..9, 0..3),
    ) {
        use ferret_plan::{ReplayMemo, ReplayMode, TravelCost, replay_costs};
        let (house, truth, distances) = house(&pts, &kinds, &contents);
        let scene = Scene { house: house.clone(), truth: truth.clone() };
        let reg = registry(std::slice::from_ref(&scene));
        let candidates: Vec<_> = SPECS.iter().map(|s| reg.build(s).unwrap()).collect();
        let n = house.containers.len();
        let mut revealed: Vec<usize> = reveal.into_iter().filter(|&c| c < n).collect();
        revealed.sort_unstable();
        revealed.dedup();
        let mut trials = Vec::new();
        for target in truth.target_types() {
            for revealed in [vec![], revealed.clone()] {
                let goals = truth.goal_containers(&target);
                if goals.iter().all(|g| revealed.contains(g)) {
                    continue;
                }
                trials.push(TrialSpec { task: ferret_plan::Task::single(target.clone()), revealed });
            }
        }
        prop_assume!(!trials.is_empty());
        let memo = ReplayMemo::new(10_000);
        let settings = (ReplayMode::Pessimistic, TravelCost::Plain);
        let mut asked = std::collections::HashSet::new();
        let mut repeats = 0;
        // Every trial twice, the second time in reverse order, each time another candidate
        // deployed.
        for (k, trial) in trials.iter().chain(trials.iter().rev()).enumerate() {
            let deployed = (k % candidates.len(), 1.0);
            let plain = SearchProblem::new(&house, &distances, trial);
            let found = truth
                .goal_containers(trial.task.first())
                .into_iter()
                .find(|g| !trial.revealed.contains(g))
                .unwrap();
            let fresh = replay_costs(settings, &candidates, &plain, &truth, &[Some(found)], deployed).unwrap();
            let kept = replay_costs(settings, &candidates, &plain.with_replay_memo(&memo), &truth, &[Some(found)], deployed).unwrap();
            prop_assert_eq!(
                fresh.iter().map(|c| c.to_bits()).collect::<Vec<_>>(),
                kept.iter().map(|c| c.to_bits()).collect::<Vec<_>>()
            );
            let key = (trial.task.first().clone(), trial.revealed.clone(), found);
            if !asked.insert(key) {
                repeats += candidates.len() - 1;
            }
        }
        // The first ending of each kind replays the deployed candidate too, so every repeat,
        // whichever candidate it deploys, finds all it needs.
        prop_assert_eq!(memo.hits(), repeats as u64);
        prop_assert_eq!(memo.len(), asked.len() * candidates.len());
        let before = memo.len();
        let trial = &trials[0];
        let found = truth.goal_containers(trial.task.first())[0];
        let problem = SearchProblem::new(&house, &distances, trial).with_replay_memo(&memo);
        replay_costs((ReplayMode::Counterfactual, TravelCost::Plain), &candidates, &problem, &truth, &[Some(found)], (0, 1.0)).unwrap();
        prop_assert_eq!(memo.len(), before);
    }
}

/// A full memo keeps what it has and still answers every replay.
#[test]
fn a_full_replay_memo_keeps_no_more_and_still_answers() {
    use ferret_plan::{ReplayMemo, ReplayMode, TravelCost, replay_costs};
    let (house, truth, distances) = house(
        &[(1.0, 0.0), (0.0, 4.0), (-3.0, 0.0)],
        &[0, 1, 2],
        &[vec![0], vec![1], vec![2]],
    );
    let scene = Scene {
        house: house.clone(),
        truth: truth.clone(),
    };
    let reg = registry(std::slice::from_ref(&scene));
    let candidates: Vec<_> = SPECS[..3].iter().map(|s| reg.build(s).unwrap()).collect();
    let memo = ReplayMemo::new(1);
    let settings = (ReplayMode::Pessimistic, TravelCost::Plain);
    for (target, found) in [("Egg", 0), ("Book", 1), ("Book", 1)] {
        let trial = TrialSpec::single(ObjectType::new(target));
        let plain = SearchProblem::new(&house, &distances, &trial);
        let fresh = replay_costs(
            settings,
            &candidates,
            &plain,
            &truth,
            &[Some(found)],
            (0, 1.0),
        )
        .unwrap();
        let kept = replay_costs(
            settings,
            &candidates,
            &plain.with_replay_memo(&memo),
            &truth,
            &[Some(found)],
            (0, 1.0),
        )
        .unwrap();
        assert_eq!(fresh, kept);
        assert_eq!(memo.len(), 1);
    }
    // Only the first replay of the first trial was kept, so nothing repeated was found.
    assert_eq!(memo.hits(), 0);
}

/// A greedy strategy that counts its trials and takes its time starting each, so that
/// replays of it overlap.
struct SlowCounted(std::sync::atomic::AtomicUsize);

impl ferret_plan::Strategy for SlowCounted {
    fn name(&self) -> &str {
        "slow-counted"
    }

    fn policy<'a>(
        &'a self,
        _ctx: &ferret_plan::TrialContext<'a>,
    ) -> Result<Box<dyn ferret_plan::Policy + 'a>, ferret_plan::PlanError> {
        self.0.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        std::thread::sleep(std::time::Duration::from_millis(30));
        Ok(Box::new(ferret_plan::Greedy))
    }
}

/// Eight ends of the same trial at once replay each other candidate once between them: the
/// rest wait for that replay and answer with its cost.
#[test]
fn ends_of_one_trial_at_once_replay_it_once() {
    use ferret_plan::{ReplayMemo, ReplayMode, TravelCost, replay_costs};
    let (house, truth, distances) = house(
        &[(1.0, 0.0), (0.0, 4.0), (-3.0, 0.0)],
        &[0, 1, 2],
        &[vec![], vec![], vec![0]],
    );
    let slow = Arc::new(SlowCounted(std::sync::atomic::AtomicUsize::new(0)));
    let candidates: Vec<Arc<dyn ferret_plan::Strategy>> = vec![
        Arc::new(ferret_plan::strategy::GreedyStrategy),
        slow.clone(),
    ];
    let memo = ReplayMemo::new(100);
    let trial = TrialSpec::single(ObjectType::new("Egg"));
    let problem = SearchProblem::new(&house, &distances, &trial).with_replay_memo(&memo);
    let settings = (ReplayMode::Pessimistic, TravelCost::Plain);
    let costs: Vec<Vec<f64>> = std::thread::scope(|scope| {
        let ends: Vec<_> = (0..8)
            .map(|_| {
                scope.spawn(|| {
                    replay_costs(
                        settings,
                        &candidates,
                        &problem,
                        &truth,
                        &[Some(2)],
                        (0, 1.0),
                    )
                    .unwrap()
                })
            })
            .collect();
        ends.into_iter().map(|e| e.join().unwrap()).collect()
    });
    assert_eq!(slow.0.load(std::sync::atomic::Ordering::SeqCst), 1);
    assert_eq!(memo.hits(), 7);
    let alone = replay_costs(
        settings,
        &candidates,
        &SearchProblem::new(&house, &distances, &trial),
        &truth,
        &[Some(2)],
        (0, 1.0),
    )
    .unwrap();
    assert!(costs.iter().all(|c| *c == alone), "{costs:?} vs {alone:?}");
}

/// A strategy that cannot plan (an LLM endpoint down).
struct Down;

impl ferret_plan::Strategy for Down {
    fn name(&self) -> &str {
        "down"
    }

    fn policy<'a>(
        &'a self,
        _ctx: &ferret_plan::TrialContext<'a>,
    ) -> Result<Box<dyn ferret_plan::Policy + 'a>, ferret_plan::PlanError> {
        Err(ferret_plan::PlanError::Policy {
            policy: "down".into(),
            error: "the endpoint is down".into(),
        })
    }
}

/// The deployed candidate is replayed for later ends only on the side: when it cannot be
/// replayed, the end still gets the replays it needs, and nothing is kept for it.
#[test]
fn a_deployed_candidate_that_cannot_be_replayed_fails_no_end() {
    use ferret_plan::{ReplayMemo, ReplayMode, TravelCost, replay_costs};
    let (house, truth, distances) = house(
        &[(1.0, 0.0), (0.0, 4.0), (-3.0, 0.0)],
        &[0, 1, 2],
        &[vec![], vec![], vec![0]],
    );
    let candidates: Vec<Arc<dyn ferret_plan::Strategy>> = vec![
        Arc::new(Down),
        Arc::new(ferret_plan::strategy::GreedyStrategy),
    ];
    let memo = ReplayMemo::new(100);
    let trial = TrialSpec::single(ObjectType::new("Egg"));
    let problem = SearchProblem::new(&house, &distances, &trial);
    let settings = (ReplayMode::Pessimistic, TravelCost::Plain);
    let kept = replay_costs(
        settings,
        &candidates,
        &problem.with_replay_memo(&memo),
        &truth,
        &[Some(2)],
        (0, 7.0),
    )
    .unwrap();
    let alone = replay_costs(
        settings,
        &candidates,
        &problem,
        &truth,
        &[Some(2)],
        (0, 7.0),
    )
    .unwrap();
    assert_eq!(kept, alone);
    assert_eq!(memo.len(), 1);
    // Deployed elsewhere, the candidate that cannot be replayed fails the end, as without a memo.
    assert!(
        replay_costs(
            settings,
            &candidates,
            &problem.with_replay_memo(&memo),
            &truth,
            &[Some(2)],
            (1, 7.0)
        )
        .is_err()
    );
}

/// Every trial of every target from each of `starts` in one house, with `spec` planning and one
/// plan memo shared by them all, each beside the same trial without a memo; returns the memo's
/// hits.
fn trials_with_and_without_a_memo(
    spec: &str,
    (pts, kinds, contents): &HouseParts,
    starts: &[(f64, f64)],
) -> Result<u64, proptest::test_runner::TestCaseError> {
    let memo = Arc::new(PlanMemo::new(64));
    for &start in starts {
        let (house, truth, distances) = house_at(start, pts, kinds, contents);
        let scene = Scene {
            house: house.clone(),
            truth: truth.clone(),
        };
        let strategy = registry(std::slice::from_ref(&scene)).build(spec).unwrap();
        for target in truth.target_types() {
            let trial = TrialSpec::single(target);
            let problem = SearchProblem::new(&house, &distances, &trial);
            let alone = run_trial(strategy.as_ref(), &problem, &truth);
            let shared = run_trial(strategy.as_ref(), &problem.with_plan_memo(&memo), &truth);
            prop_assert_eq!(alone.ok(), shared.ok(), "{} from {:?}", spec, start);
        }
    }
    Ok(memo.hits())
}

fn arb_larger_house() -> impl proptest::strategy::Strategy<Value = HouseParts> {
    (7usize..=13).prop_flat_map(|n| {
        (
            prop::collection::vec((-15.0f64..15.0, -15.0f64..15.0), n),
            prop::collection::vec(0usize..4, n),
            prop::collection::vec(prop::collection::vec(0usize..3, 0..3), n),
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(32))]

    /// A plan memo shared by a house's trials (from several starts, for every target) changes
    /// no decision of any model strategy: each trial searches the same containers in the same
    /// order at the same cost as without it.
    #[test]
    fn a_plan_memo_changes_no_decision(
        parts in arb_larger_house(),
        starts in prop::collection::vec((-15.0f64..15.0, -15.0f64..15.0), 1..4),
    ) {
        for spec in ["model/uniform/exact5", "model/prior/exact4", "model/uniform", "model/prior/k3"] {
            trials_with_and_without_a_memo(spec, &parts, &starts)?;
        }
    }
}

/// The memo is used: in a house of twelve containers on a ring, trials from several starts meet
/// candidate sets solved before (so the property above compares decisions taken from it).
#[test]
fn a_plan_memo_is_used_by_trials_of_one_house() {
    let pts: Vec<(f64, f64)> = (0..12)
        .map(|i| {
            let a = f64::from(i) * std::f64::consts::TAU / 12.0;
            (10.0 * a.cos(), 10.0 * a.sin())
        })
        .collect();
    let kinds: Vec<usize> = (0..12).map(|i| i % 4).collect();
    let contents: Vec<Vec<usize>> = (0..12).map(|i| vec![i % 3]).collect();
    let starts = [(0.0, 0.0), (1.0, 0.5), (-2.0, 1.0), (0.5, -3.0)];
    let hits =
        trials_with_and_without_a_memo("model/uniform/exact5", &(pts, kinds, contents), &starts)
            .unwrap();
    assert!(hits > 0, "no decision came from the memo");
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Every strategy does every task: its goal holds, each target is found where it is, no
    /// container is searched twice, the cost is the legs walked plus the last one to the
    /// destination, and no strategy beats the oracle's cheapest route.
    #[test]
    fn every_strategy_does_every_task_and_none_beats_the_oracle(
        (pts, kinds, contents) in arb_house(),
        pick in 0usize..5,
    ) {
        use ferret_world::Place;
        let (house, truth, distances) = house(&pts, &kinds, &contents);
        let scene = Scene { house: house.clone(), truth: truth.clone() };
        let reg = registry(std::slice::from_ref(&scene));
        for task in tasks_of(&truth, house.containers.len(), pick) {
            let trial = TrialSpec::of(task.clone());
            let problem = SearchProblem::new(&house, &distances, &trial);
            let legs = problem.destination_legs().unwrap();
            let oracle = run_trial(reg.build("oracle").unwrap().as_ref(), &problem, &truth).unwrap();
            for spec in SPECS.iter().copied().chain(["sequential/model/prior", "sequential/model/uniform/exact"]) {
                let out = run_trial(reg.build(spec).unwrap().as_ref(), &problem, &truth).unwrap();
                prop_assert!(out.found.is_some(), "{} did not do {}", spec, task);
                prop_assert!(task.holds(out.found_each.iter().map(Option::is_some)));
                for (t, f) in task.targets().iter().zip(&out.found_each) {
                    if let Some(c) = f {
                        prop_assert!(truth.holds(*c, t) && out.searched.contains(c));
                        // Found where it was first seen.
                        let first = out.searched.iter().find(|&&x| truth.holds(x, t));
                        prop_assert_eq!(first, Some(c));
                    }
                }
                let mut seen = out.searched.clone();
                seen.sort_unstable();
                seen.dedup();
                prop_assert_eq!(seen.len(), out.searched.len(), "{} searched a container twice", spec);
                let last = out.searched.last().map_or(Place::Start, |&c| Place::Container(c));
                let delivery = legs.as_ref().map_or(0.0, |l| l.from(last));
                prop_assert_eq!(out.delivery, delivery);
                let walked: f64 = out.places().windows(2).map(|w| distances.between(w[0], w[1])).sum();
                let walked = if out.delivered_to.is_some() { walked } else { walked + delivery };
                prop_assert!((out.cost - walked).abs() < 1e-9, "{}: cost {} walked {}", spec, out.cost, walked);
                prop_assert!(out.cost + 1e-9 >= oracle.cost, "{} ({}) beat the oracle ({}) on {}", spec, out.cost, oracle.cost, task);
                // Replayed where it was deployed, a strategy costs what it cost; others replayed
                // in the hindsight world cost at least what they cost in the true one.
                if spec != "oracle" {
                    let s = reg.build(spec).unwrap();
                    let own = replay_cost(s.as_ref(), &problem, &out.found_each).unwrap();
                    prop_assert!((own - out.cost).abs() < 1e-9, "{}: replay {} real {}", spec, own, out.cost);
                    let greedy = reg.build("optimistic+greedy").unwrap();
                    let replay = replay_cost(greedy.as_ref(), &problem, &out.found_each).unwrap();
                    let real = run_trial(greedy.as_ref(), &problem, &truth).unwrap().cost;
                    prop_assert!(replay + 1e-9 >= real, "greedy replay {} < real {}", replay, real);
                }
            }
        }
    }

    /// In the world its likelihoods describe (each target in each container independently),
    /// the exact task planner's expected cost is the least: below one search after another and
    /// below the nearest container first, summed over every world. Every likelihood is
    /// positive, so that every unsearched container stays a candidate: a container no wanted
    /// target can be in is left out of the plan, as eq. 3 leaves what lies beyond the
    /// candidates uncounted.
    #[test]
    fn the_task_planner_is_best_in_its_own_world(
        (pts, kinds, _) in arb_small_house(),
        ps in prop::collection::vec(prop_oneof![6 => 0.01f64..=1.0, 1 => Just(1.0)], 8),
        any_goal in any::<bool>(),
        destination in 0usize..3,
    ) {
        use ferret_plan::{Destination, Goal, ModelStrategy, SequentialStrategy, Task, Strategy};
        let n = pts.len();
        let (house, _, distances) = house(&pts, &kinds, &vec![vec![]; n]);
        let targets = [ObjectType::new("Egg"), ObjectType::new("Book")];
        let source: Arc<dyn ferret_plan::LikelihoodSource> = Arc::new(Table {
            targets: targets.to_vec(),
            p: ps.clone(),
            n,
        });
        let config = PlannerConfig { limit: CandidateLimit::Exact { max: 8 }, ..PlannerConfig::default() };
        let planner: Arc<dyn Strategy> = Arc::new(ModelStrategy::new("model/table/exact", source.clone(), config));
        let sequential = SequentialStrategy::new("sequential/model/table/exact", planner.clone()).unwrap();
        let greedy = StrategyRegistry::builtin(None, config, 8).build("optimistic+greedy").unwrap();
        let goal = if any_goal { Goal::Any } else { Goal::All };
        let destination = match destination {
            0 => None,
            1 => Some(Destination::Start),
            _ => Some(Destination::Container { index: n - 1 }),
        };
        let task = Task::new(targets.to_vec(), goal, destination).unwrap();
        let trial = TrialSpec::of(task);
        let problem = SearchProblem::new(&house, &distances, &trial);
        let expected = |s: &dyn Strategy| -> f64 {
            let mut total = 0.0;
            for world in 0..(1usize << (2 * n)) {
                let holds = |t: usize, c: usize| world & (1 << (t * n + c)) != 0;
                let weight: f64 = (0..2)
                    .flat_map(|t| (0..n).map(move |c| (t, c)))
                    .map(|(t, c)| if holds(t, c) { ps[t * n + c] } else { 1.0 - ps[t * n + c] })
                    .product();
                if weight == 0.0 {
                    continue;
                }
                let truth = GroundTruth::new(
                    (0..n)
                        .map(|c| {
                            (0..2)
                                .filter(|&t| holds(t, c))
                                .map(|t| SmallObject { id: format!("{t}|{c}"), object_type: targets[t].clone() })
                                .collect()
                        })
                        .collect(),
                );
                total += weight * run_trial(s, &problem, &truth).unwrap().cost;
            }
            total
        };
        let best = expected(planner.as_ref());
        for (name, other) in [("sequential", expected(&sequential)), ("greedy", expected(greedy.as_ref()))] {
            prop_assert!(best <= other + 1e-9 * other.max(1.0), "planner {} > {} {}", best, name, other);
        }
    }
}

/// Houses of 2 to 4 containers: every world of 2 targets can be enumerated.
fn arb_small_house() -> impl proptest::strategy::Strategy<Value = HouseParts> {
    (2usize..=4).prop_flat_map(|n| {
        (
            prop::collection::vec((-15.0f64..15.0, -15.0f64..15.0), n),
            prop::collection::vec(0usize..4, n),
            Just(vec![vec![]; n]),
        )
    })
}

/// Likelihoods from a table: `p[t·n + c]` for target `t` of `targets` in container `c`.
struct Table {
    targets: Vec<ObjectType>,
    p: Vec<f64>,
    n: usize,
}

impl ferret_plan::LikelihoodSource for Table {
    fn name(&self) -> &str {
        "table"
    }

    fn likelihoods(
        &self,
        _house: &House,
        target: &ObjectType,
    ) -> Result<Vec<ferret_plan::Probability>, ferret_plan::PlanError> {
        let t = self.targets.iter().position(|x| x == target).unwrap_or(0);
        Ok((0..self.n)
            .map(|c| ferret_plan::Probability::clamped(self.p[t * self.n + c], 0.0, 1.0))
            .collect())
    }
}
