//! Property tests of teams of robots on small synthetic houses: one robot is the single-robot
//! simulator bit for bit, coordinated robots never open a container twice, nobody beats the
//! team oracle, and independent robots at one start are one robot twice over.

use ferret_plan::{
    PlanError, SearchProblem, Task, TeamOutcome, Teamwork, TrialSpec, run_team, run_trial,
    split_rooms,
};
use ferret_world::{
    Container, Distances, Footprint, GroundTruth, House, ObjectType, Place, Point, Polygon, Pose,
    Room, RoomType, Scene,
};
use proptest::prelude::{ProptestConfig, any, prop, prop_assert, prop_assert_eq, proptest};

mod support;
use support::{arb_house, house, house_at, registry, tasks_of};

const SPECS: [&str; 9] = [
    "optimistic+greedy",
    "model/uniform",
    "model/prior",
    "model/prior/k3",
    "oracle",
    "sequential/model/prior",
    "independent/model/prior",
    "split/model/prior",
    "split/oracle",
];

/// The single target of every type the house holds, then the tasks of [`tasks_of`].
fn every_task(truth: &GroundTruth, n: usize, pick: usize) -> Vec<Task> {
    truth
        .target_types()
        .into_iter()
        .map(Task::single)
        .chain(tasks_of(truth, n, pick))
        .collect()
}

/// The length of the way from `start` through `searched` on `distances`.
fn walked(distances: &Distances, searched: &[usize]) -> f64 {
    let places: Vec<Place> = std::iter::once(Place::Start)
        .chain(searched.iter().map(|&c| Place::Container(c)))
        .collect();
    places
        .windows(2)
        .map(|w| distances.between(w[0], w[1]))
        .sum()
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    /// A team of one is the single-robot simulator: the same searches, found containers and
    /// cost, bit for bit, for every strategy and task (a destination included).
    #[test]
    fn one_robot_is_the_single_robot_simulator(
        (pts, kinds, contents) in arb_house(),
        pick in 0usize..5,
    ) {
        let (house, truth, distances) = house(&pts, &kinds, &contents);
        let scene = Scene { house: house.clone(), truth: truth.clone() };
        let reg = registry(std::slice::from_ref(&scene));
        for task in every_task(&truth, house.containers.len(), pick) {
            let trial = TrialSpec::of(task.clone());
            let problem = SearchProblem::new(&house, &distances, &trial);
            for spec in SPECS {
                let s = reg.build(spec).unwrap();
                let one = run_trial(s.as_ref(), &problem, &truth).unwrap();
                let team = run_team(s.as_ref(), &[problem], &truth).unwrap();
                prop_assert_eq!(team.trial.cost.to_bits(), one.cost.to_bits(), "{} on {}", spec, task);
                prop_assert_eq!(&team.trial, &one, "{} on {}", spec, task);
                prop_assert_eq!(team.total_travel.to_bits(), one.cost.to_bits());
                prop_assert_eq!(&team.robots[0].searched, &one.searched);
            }
        }
    }

    /// Teams of 2 to 4 robots from their own starts: the goal holds; no container is opened
    /// twice; coordinated and split robots never head for a container another reaches at the
    /// same moment; no strategy's makespan beats the team oracle's; and each robot drove at
    /// least its searches' way and no farther than the makespan.
    #[test]
    fn teams_do_the_task_never_search_twice_and_none_beats_the_team_oracle(
        (pts, kinds, contents) in arb_house(),
        starts in prop::collection::vec((-15.0f64..15.0, -15.0f64..15.0), 1..4),
        together in any::<bool>(),
        pick in 0usize..5,
    ) {
        let (house, truth, distances) = house(&pts, &kinds, &contents);
        let scene = Scene { house: house.clone(), truth: truth.clone() };
        let reg = registry(std::slice::from_ref(&scene));
        // The first robot at the house's start, the others there too or where drawn.
        let others: Vec<Distances> = starts
            .iter()
            .map(|&s| if together { distances.clone() } else { house_at(s, &pts, &kinds, &contents).2 })
            .collect();
        let team: Vec<&Distances> = std::iter::once(&distances).chain(&others).collect();
        for task in every_task(&truth, house.containers.len(), pick) {
            let trial = TrialSpec::of(task.clone());
            let problems: Vec<SearchProblem<'_>> = team
                .iter()
                .map(|d| SearchProblem::new(&house, d, &trial))
                .collect();
            let oracle = run_team(reg.build("oracle").unwrap().as_ref(), &problems, &truth).unwrap();
            prop_assert!(oracle.trial.found.is_some());
            for spec in SPECS {
                let s = reg.build(spec).unwrap();
                let out: TeamOutcome = run_team(s.as_ref(), &problems, &truth).unwrap();
                prop_assert!(out.trial.found.is_some(), "{} did not do {}", spec, task);
                prop_assert!(task.holds(out.trial.found_each.iter().map(Option::is_some)));
                prop_assert!(
                    out.trial.cost + 1e-9 >= oracle.trial.cost,
                    "{} ({}) beat the team oracle ({}) on {}", spec, out.trial.cost, oracle.trial.cost, task
                );
                let mut seen = out.trial.searched.clone();
                seen.sort_unstable();
                seen.dedup();
                prop_assert_eq!(seen.len(), out.trial.searched.len());
                prop_assert_eq!(out.searched_by.len(), out.trial.searched.len());
                let total: f64 = out.robots.iter().map(|r| r.travelled).sum();
                prop_assert!((total - out.total_travel).abs() < 1e-9);
                for (r, run) in out.robots.iter().enumerate() {
                    prop_assert!(run.travelled <= out.trial.cost + 1e-9, "{}: robot {} drove {} > makespan {}", spec, r, run.travelled, out.trial.cost);
                    let mine: Vec<usize> = out.trial.searched.iter().zip(&out.searched_by)
                        .filter(|(_, by)| **by == r).map(|(c, _)| *c).collect();
                    prop_assert_eq!(&mine, &run.searched);
                    prop_assert!(run.travelled + 1e-9 >= walked(team[r], &run.searched));
                }
                // Coordinated robots leave a container to the one that gets there first: two
                // heading for one container never arrive together (independent ones, at one
                // start, do).
                if s.teamwork() != Teamwork::Independent {
                    for (a, ra) in out.robots.iter().enumerate() {
                        for rb in &out.robots[a + 1..] {
                            if let (Some((ca, ta)), Some((cb, tb))) = (ra.heading, rb.heading) {
                                prop_assert!(ca != cb || ta != tb, "{}: two robots reach {} together", spec, ca);
                            }
                        }
                    }
                }
            }
        }
    }

    /// Independent robots at one start are blind to each other: they drive in lockstep, so
    /// the team takes as long as one robot and drives twice as far (but for the way to the
    /// destination, which only the robot carrying the finds drives).
    #[test]
    fn independent_robots_at_one_start_are_one_robot_twice(
        (pts, kinds, contents) in arb_house(),
    ) {
        let (house, truth, distances) = house(&pts, &kinds, &contents);
        let scene = Scene { house: house.clone(), truth: truth.clone() };
        let reg = registry(std::slice::from_ref(&scene));
        for task in every_task(&truth, house.containers.len(), 0) {
            let trial = TrialSpec::of(task);
            let problem = SearchProblem::new(&house, &distances, &trial);
            let s = reg.build("independent/model/prior").unwrap();
            let one = run_trial(s.as_ref(), &problem, &truth).unwrap();
            let two = run_team(s.as_ref(), &[problem, problem], &truth).unwrap();
            prop_assert!((two.trial.cost - one.cost).abs() < 1e-9);
            prop_assert_eq!(&two.trial.searched, &one.searched);
            // Both search; only the first, which opened everything, carries what it found.
            let searching = one.cost - one.delivery;
            prop_assert!(
                (two.total_travel - (2.0 * searching + one.delivery)).abs() < 1e-6,
                "{} vs 2 × {} + {}", two.total_travel, searching, one.delivery
            );
        }
    }
}

/// A house of four square rooms around the origin, two containers in each.
fn four_rooms() -> House {
    let corners = [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)];
    let rooms = corners
        .iter()
        .enumerate()
        .map(|(i, &(sx, sz))| Room {
            id: format!("room|{i}"),
            room_type: RoomType::new("LivingRoom"),
            floor: Polygon::new(vec![
                Point::new(0.0, 0.0),
                Point::new(10.0 * sx, 0.0),
                Point::new(10.0 * sx, 10.0 * sz),
                Point::new(0.0, 10.0 * sz),
            ]),
        })
        .collect();
    let containers = corners
        .iter()
        .enumerate()
        .flat_map(|(room, &(sx, sz))| {
            [(3.0, 5.0), (6.0, 7.0)].map(move |(a, b)| (room, Point::new(a * sx, b * sz)))
        })
        .enumerate()
        .map(|(i, (room, p))| Container {
            id: format!("c|{i}"),
            object_type: ObjectType::new("Desk"),
            room: Some(room),
            position: p,
            footprint: Footprint {
                center: p,
                size_x: 0.5,
                size_z: 0.5,
                yaw_deg: 0.0,
            },
            access: None,
        })
        .collect();
    House {
        name: "four-rooms#0".into(),
        index: 0,
        rooms,
        walls: vec![],
        doors: vec![],
        containers,
        obstacles: vec![],
        start: Pose {
            position: Point::new(0.0, 0.0),
            yaw_deg: 0.0,
        },
        map: None,
    }
}

#[test]
fn rooms_are_split_whole_among_robots_nearest_first() {
    let house = four_rooms();
    let room_of = |c: usize| house.containers[c].room;
    // Every container has an owner; a room is never divided.
    for n in 1..=4 {
        let owner = split_rooms(&house, &vec![Point::new(0.0, 0.0); n]);
        assert_eq!(owner.len(), 8);
        for c in 0..8 {
            for d in 0..8 {
                if room_of(c) == room_of(d) {
                    assert_eq!(owner[c], owner[d], "{n} robots: room divided");
                }
            }
        }
        let mut used: Vec<usize> = owner.clone();
        used.sort_unstable();
        used.dedup();
        assert_eq!(used.len(), n, "{n} robots: {owner:?}");
    }
    // Two robots: two neighbouring rooms each, four containers each.
    let owner = split_rooms(&house, &[Point::new(0.0, 0.0); 2]);
    assert_eq!(owner.iter().filter(|&&o| o == 0).count(), 4);
    // Robots in the corners get their own corner's room.
    let corners = [
        Point::new(8.0, 8.0),
        Point::new(-8.0, -8.0),
        Point::new(-8.0, 8.0),
        Point::new(8.0, -8.0),
    ];
    let owner = split_rooms(&house, &corners);
    for (c, container) in house.containers.iter().enumerate() {
        let p = container.position;
        let nearest = (0..4)
            .min_by(|&a, &b| corners[a].distance(p).total_cmp(&corners[b].distance(p)))
            .unwrap();
        assert_eq!(owner[c], nearest, "container {c} at {p:?}");
    }
}

#[test]
fn bad_teams_are_refused_with_the_reason() {
    let (house, truth, distances) = house(&[(1.0, 0.0), (4.0, 0.0)], &[0, 1], &[vec![0], vec![1]]);
    let scene = Scene {
        house: house.clone(),
        truth: truth.clone(),
    };
    let reg = registry(std::slice::from_ref(&scene));
    let s = reg.build("model/prior").unwrap();
    let trial = TrialSpec::single(ObjectType::new("Egg"));
    let other = TrialSpec::single(ObjectType::new("Book"));
    let p = SearchProblem::new(&house, &distances, &trial);
    let q = SearchProblem::new(&house, &distances, &other);
    let err = |r: Result<TeamOutcome, PlanError>| match r {
        Err(e @ PlanError::Team { .. }) => e.to_string(),
        other => panic!("expected a team error, got {other:?}"),
    };
    assert!(err(run_team(s.as_ref(), &[], &truth)).contains("at least one robot"));
    assert!(err(run_team(s.as_ref(), &[p; 5], &truth)).contains("5 robots: a team has 1 to 4"));
    assert!(err(run_team(s.as_ref(), &[p, q], &truth)).contains("same house and trial"));
}

#[test]
fn teamwork_is_part_of_the_spec() {
    let (house, truth, _) = house(&[(1.0, 0.0)], &[0], &[vec![0]]);
    let reg = registry(&[Scene { house, truth }]);
    assert_eq!(
        reg.build("model/prior").unwrap().teamwork(),
        Teamwork::Coordinated
    );
    assert_eq!(
        reg.build("independent/model/prior").unwrap().teamwork(),
        Teamwork::Independent
    );
    let split = reg.build("split/sequential/model/prior").unwrap();
    assert_eq!(split.teamwork(), Teamwork::SplitByRegion);
    assert!(split.likelihood_source().is_some());
    assert_eq!(
        ferret_plan::planned_spec("split/sequential/model/prior"),
        "model/prior"
    );
    let e = reg
        .build("independent/split/model/prior")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("one of independent/ and split/"), "{e}");
    let e = reg
        .build("independent/model/nothing")
        .err()
        .unwrap()
        .to_string();
    assert!(e.contains("independent/model/nothing"), "{e}");
}
