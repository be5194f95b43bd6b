//! A live deployment rebuilt from its stored trials behaves exactly as the one that ran.

use ferret_select::{DeploymentEvent, FinishedTrial, LiveDeployment, Method, TrialEnd};
use proptest::prelude::*;

/// Runs `trials` trials with the given per-trial costs (`costs[k][i]` = cost of strategy i in
/// trial k) and returns the deployment.
fn run(method: Method, costs: &[Vec<f64>], seed: u64) -> LiveDeployment {
    let n = costs[0].len();
    let mut d = LiveDeployment::new(method, n, 5.0, seed).unwrap();
    for row in costs {
        let i = d.choose();
        assert_eq!(d.choose(), i, "asking twice gives the same choice");
        d.finish(row[i], row).unwrap();
    }
    d
}

fn method() -> impl Strategy<Value = Method> {
    prop_oneof![Just(Method::Ucb), Just(Method::ReplaySelection)]
}

proptest! {
    #[test]
    fn a_restored_deployment_continues_exactly_like_the_original(
        method in method(),
        seed in 0u64..1000,
        // Integer costs make exact ties common, so the tie-breaking stream matters.
        costs in prop::collection::vec(prop::collection::vec(0u8..6, 3), 1..15),
        more in prop::collection::vec(prop::collection::vec(0u8..6, 3), 1..6),
    ) {
        let costs: Vec<Vec<f64>> = costs.iter().map(|r| r.iter().map(|&c| f64::from(c)).collect()).collect();
        let more: Vec<Vec<f64>> = more.iter().map(|r| r.iter().map(|&c| f64::from(c)).collect()).collect();
        let mut original = run(method, &costs, seed);
        let mut restored = LiveDeployment::restore(method, 3, 5.0, seed, &original.history(), None).unwrap();
        prop_assert_eq!(restored.stats(), original.stats());
        prop_assert_eq!(restored.peek(), original.peek());
        for row in &more {
            let (a, b) = (original.choose(), restored.choose());
            prop_assert_eq!(a, b);
            original.finish(row[a], row).unwrap();
            restored.finish(row[b], row).unwrap();
        }
        prop_assert!(original.finished().eq(restored.finished()));
    }

    #[test]
    fn peek_never_changes_what_is_chosen(
        method in method(),
        seed in 0u64..1000,
        costs in prop::collection::vec(prop::collection::vec(0u8..4, 4), 0..10),
    ) {
        let mut d = LiveDeployment::new(method, 4, 5.0, seed).unwrap();
        for row in &costs {
            let row: Vec<f64> = row.iter().map(|&c| f64::from(c)).collect();
            let peeked = d.peek();
            prop_assert_eq!(d.peek(), peeked);
            let i = d.choose();
            prop_assert_eq!(i, peeked);
            d.finish(row[i], &row).unwrap();
        }
    }
}

/// Drives a deployment whose trials overlap: `script[j]` says, at step j, either start a trial
/// (`None`) or end the open trial at position `Some(p)` (mod the open ones), with costs from
/// `costs`. Returns the deployment, its event log and the choices made at each start.
fn overlapping(
    method: Method,
    seed: u64,
    script: &[Option<usize>],
    costs: &[Vec<f64>],
) -> (LiveDeployment, Vec<DeploymentEvent>) {
    let mut d = LiveDeployment::new(method, 3, 5.0, seed).unwrap();
    let (mut open, mut events) = (Vec::new(), Vec::new());
    for (j, step) in script.iter().enumerate() {
        match step {
            Some(p) if !open.is_empty() => {
                let chosen: usize = open.remove(p % open.len());
                let row = &costs[j % costs.len()];
                let end = if row[0] > 4.0 {
                    TrialEnd::Abandoned { chosen }
                } else {
                    let mut replays = row.clone();
                    replays[chosen] = row[chosen];
                    TrialEnd::Finished(FinishedTrial {
                        chosen,
                        cost: row[chosen],
                        replays,
                    })
                };
                d.end_overlapping(&end).unwrap();
                events.push(DeploymentEvent::Ended(end));
            }
            _ => {
                let chosen = d.choose_overlapping();
                open.push(chosen);
                events.push(DeploymentEvent::Started { chosen });
            }
        }
    }
    (d, events)
}

proptest! {
    #[test]
    fn overlapping_trials_replay_exactly_from_their_events(
        method in method(),
        seed in 0u64..1000,
        script in prop::collection::vec(prop::option::of(0usize..4), 1..40),
        costs in prop::collection::vec(prop::collection::vec(0u8..6, 3), 1..8),
    ) {
        let costs: Vec<Vec<f64>> = costs.iter().map(|r| r.iter().map(|&c| f64::from(c)).collect()).collect();
        let (mut original, events) = overlapping(method, seed, &script, &costs);
        let mut replayed = LiveDeployment::replay_events(method, 3, 5.0, seed, &events).unwrap();
        prop_assert_eq!(replayed.stats(), original.stats());
        prop_assert_eq!(replayed.peek(), original.peek());
        prop_assert!(original.finished().eq(replayed.finished()));
        // And both go on choosing alike.
        for _ in 0..3 {
            prop_assert_eq!(original.choose_overlapping(), replayed.choose_overlapping());
        }
    }

    #[test]
    fn a_history_replayed_in_pieces_is_the_history_replayed_at_once(
        method in method(),
        seed in 0u64..1000,
        script in prop::collection::vec(prop::option::of(0usize..4), 1..40),
        costs in prop::collection::vec(prop::collection::vec(0u8..6, 3), 1..8),
        cuts in prop::collection::vec(0usize..40, 0..4),
    ) {
        let costs: Vec<Vec<f64>> = costs.iter().map(|r| r.iter().map(|&c| f64::from(c)).collect()).collect();
        let (original, events) = overlapping(method, seed, &script, &costs);
        let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c % (events.len() + 1)).collect();
        cuts.push(events.len());
        cuts.sort_unstable();
        let mut pieces = LiveDeployment::new(method, 3, 5.0, seed).unwrap();
        let mut from = 0;
        for cut in cuts {
            pieces.extend_events(&events[from..cut]).unwrap();
            from = cut;
            // What a service answers between pieces without committing to it: the choice the
            // next start makes.
            let mut probe = LiveDeployment::replay_events(method, 3, 5.0, seed, &events[..cut]).unwrap();
            prop_assert_eq!(pieces.peek(), probe.choose_overlapping());
        }
        prop_assert_eq!(pieces.stats(), original.stats());
        prop_assert!(original.finished().eq(pieces.finished()));
    }

    #[test]
    fn sequential_events_are_the_sequential_deployment(
        method in method(),
        seed in 0u64..1000,
        costs in prop::collection::vec(prop::collection::vec(0u8..6, 3), 1..15),
    ) {
        let costs: Vec<Vec<f64>> = costs.iter().map(|r| r.iter().map(|&c| f64::from(c)).collect()).collect();
        let original = run(method, &costs, seed);
        let events: Vec<DeploymentEvent> = original
            .history()
            .into_iter()
            .flat_map(|end| {
                let chosen = match &end {
                    TrialEnd::Finished(t) => t.chosen,
                    TrialEnd::Abandoned { chosen } => *chosen,
                };
                [DeploymentEvent::Started { chosen }, DeploymentEvent::Ended(end)]
            })
            .collect();
        let replayed = LiveDeployment::replay_events(method, 3, 5.0, seed, &events).unwrap();
        prop_assert_eq!(replayed.stats(), original.stats());
        prop_assert_eq!(replayed.peek(), original.peek());
    }
}

#[test]
fn overlapping_events_that_contradict_the_selector_are_refused() {
    let costs = vec![vec![1.0, 9.0, 9.0]];
    let script = [None, None, Some(0), None, Some(0), Some(0), None];
    let (_, mut events) = overlapping(Method::ReplaySelection, 1, &script, &costs);
    // An end before any start.
    let early = [events[2].clone()];
    let e = LiveDeployment::replay_events(Method::ReplaySelection, 3, 5.0, 1, &early).unwrap_err();
    assert!(e.to_string().contains("before any open trial"), "{e}");
    // A start whose stored choice is not the selector's.
    let last = events.len() - 1;
    let DeploymentEvent::Started { chosen } = &mut events[last] else {
        panic!("the script ends with a start")
    };
    *chosen = (*chosen + 1) % 3;
    let e = LiveDeployment::replay_events(Method::ReplaySelection, 3, 5.0, 1, &events).unwrap_err();
    assert!(e.to_string().contains("trial 4"), "{e}");
}

#[test]
fn a_stored_choice_the_selector_would_not_make_is_refused() {
    let costs = vec![vec![1.0, 9.0, 9.0]; 6];
    let d = run(Method::ReplaySelection, &costs, 3);
    let mut tampered: Vec<TrialEnd> = d.history();
    let last = tampered.len() - 1;
    let TrialEnd::Finished(t) = &mut tampered[last] else {
        panic!("every trial finished")
    };
    t.chosen = (t.chosen + 1) % 3;
    let e =
        LiveDeployment::restore(Method::ReplaySelection, 3, 5.0, 3, &tampered, None).unwrap_err();
    assert!(e.to_string().contains("trial 6"), "{e}");
    // The open trial's choice is checked too.
    let next = d.peek();
    assert!(
        LiveDeployment::restore(Method::ReplaySelection, 3, 5.0, 3, &d.history(), Some(next))
            .is_ok()
    );
    assert!(
        LiveDeployment::restore(
            Method::ReplaySelection,
            3,
            5.0,
            3,
            &d.history(),
            Some((next + 1) % 3)
        )
        .is_err()
    );
}

#[test]
fn finishing_without_a_choice_is_an_error_and_stats_follow_the_trials() {
    let mut d = LiveDeployment::new(Method::ReplaySelection, 2, 5.0, 0).unwrap();
    assert!(d.finish(1.0, &[1.0, 2.0]).is_err());
    let i = d.choose();
    d.finish(4.0, &[4.0, 8.0]).unwrap();
    let s = d.stats();
    assert_eq!(s[i].deployed, 1);
    assert_eq!(s[i].mean_cost, Some(4.0));
    assert_eq!(s[1 - i].deployed, 0);
    assert_eq!(s[1 - i].mean_cost, None);
    // Replay means: the deployed strategy's real cost, the other's replay.
    assert_eq!(s[0].replay_mean, Some(4.0));
    assert_eq!(s[1].replay_mean, Some(if i == 1 { 4.0 } else { 8.0 }));
    let names = vec!["a".to_string(), "b".to_string()];
    assert!(d.why(&names).contains("replay mean"), "{}", d.why(&names));
}

#[test]
fn abandoned_trials_keep_their_draw_and_teach_nothing() {
    // All ties: every choice draws from the stream, so a lost draw would show.
    let mut d = LiveDeployment::new(Method::ReplaySelection, 3, 5.0, 11).unwrap();
    let mut chosen = Vec::new();
    for k in 0..8 {
        let i = d.choose();
        chosen.push(i);
        if k % 3 == 1 {
            d.abandon().unwrap();
        } else {
            d.finish(2.0, &[2.0, 2.0, 2.0]).unwrap();
        }
    }
    assert_eq!(d.finished().count(), 5);
    assert_eq!(d.history().len(), 8);
    let r =
        LiveDeployment::restore(Method::ReplaySelection, 3, 5.0, 11, &d.history(), None).unwrap();
    assert_eq!(r.peek(), d.peek());
    assert_eq!(r.stats(), d.stats());
    assert!(d.abandon().is_err(), "nothing in progress");
}
