//! Decision latency of the exact planner (targets: ≤ 50 µs at n = 8, ≤ 100 ms at n = 16), of
//! the task table (targets: ≤ 2 ms for 3 targets over 8 candidates, ≤ 200 ms over 12), and the
//! cost of a whole trial of `model/…/exact`, where a trial needs a new table only when its
//! candidate set changes; and a robot's decision in a team of 3 at K = 8 (target ≤ 5 ms): the
//! belief seen with the two containers the others are heading to left out, planned afresh.

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use ferret_plan::{
    Belief, CandidateLimit, Planner, PlannerConfig, Policy, Probability, Task, TaskProblem,
    TourProblem, solve_exact, solve_task,
};
use ferret_world::{
    Container, Distances, Footprint, House, ObjectType, Point, Polygon, Pose, Room, RoomType,
};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("exact_planner_decision");
    for n in [4usize, 8, 12, 16, 20] {
        if n >= 16 {
            group.sample_size(10);
        }
        let p = TourProblem::random(n, n as u64);
        group.bench_with_input(BenchmarkId::from_parameter(n), &p, |b, p| {
            b.iter(|| solve_exact(p))
        });
    }
    group.finish();
}

fn bench_task(c: &mut Criterion) {
    let mut group = c.benchmark_group("task_table_decision");
    group.sample_size(10);
    for (n, m) in [(8usize, 2usize), (8, 3), (8, 4), (12, 3), (14, 3)] {
        let p = TaskProblem::random(n, m, true, (n * 10 + m) as u64);
        group.bench_with_input(
            BenchmarkId::from_parameter(format!("{n}x{m}")),
            &p,
            |b, p| b.iter(|| solve_task(p)),
        );
    }
    group.finish();
}

/// A one-room house: the robot and `n` containers scattered in a 20 m square, straight-line
/// travel, probabilities in [0.01, 0.5) (as [`TourProblem::random`] draws them).
fn house(n: usize, seed: u64) -> (House, Distances, Vec<Probability>) {
    use rand::{Rng, SeedableRng};
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let pts: Vec<Point> = (0..=n)
        .map(|_| Point::new(rng.random_range(0.0..20.0), rng.random_range(0.0..20.0)))
        .collect();
    let p = (0..n)
        .map(|_| Probability::clamped(rng.random_range(0.01..0.5), 0.0, 1.0))
        .collect();
    let places = pts.len();
    let metres: Vec<f64> = (0..places * places)
        .map(|k| pts[k / places].distance(pts[k % places]))
        .collect();
    let distances = Distances::from_matrix(n, metres).expect("finite distances");
    let containers = pts[1..]
        .iter()
        .enumerate()
        .map(|(i, &at)| Container {
            id: format!("1|{i}"),
            object_type: ObjectType::new("Dresser"),
            room: Some(0),
            position: at,
            footprint: Footprint {
                center: at,
                size_x: 0.5,
                size_z: 0.5,
                yaw_deg: 0.0,
            },
            access: None,
        })
        .collect();
    let house = House {
        name: format!("bench#{seed}"),
        index: 0,
        rooms: vec![Room {
            id: "room|1".into(),
            room_type: RoomType::new("LivingRoom"),
            floor: Polygon::new(vec![
                Point::new(0.0, 0.0),
                Point::new(20.0, 0.0),
                Point::new(20.0, 20.0),
                Point::new(0.0, 20.0),
            ]),
        }],
        walls: vec![],
        doors: vec![],
        containers,
        obstacles: vec![],
        start: Pose {
            position: pts[0],
            yaw_deg: 0.0,
        },
        map: None,
    };
    (house, distances, p)
}

/// One trial: the planner chooses until it searches `goal`. With `fresh`, every decision gets a
/// new planner, so nothing is reused between decisions.
fn trial(
    house: &House,
    distances: &Distances,
    p: &[Probability],
    goal: usize,
    fresh: bool,
) -> usize {
    let task = Task::single(ObjectType::new("RemoteControl"));
    let config = PlannerConfig {
        limit: CandidateLimit::Exact { max: 16 },
        ..PlannerConfig::default()
    };
    let mut belief = Belief::new(house, distances, &task);
    let mut planner = Planner::new(p.to_vec(), config);
    let mut searches = 0;
    while belief.unsearched_count() > 0 {
        if fresh {
            planner = Planner::new(p.to_vec(), config);
        }
        let c = planner.choose(&belief).expect("a container");
        belief.search(c, Vec::new());
        searches += 1;
        if c == goal {
            break;
        }
    }
    searches
}

fn bench_trial(c: &mut Criterion) {
    let mut group = c.benchmark_group("exact_planner_trial");
    group.sample_size(10);
    // 16 containers: one exact problem from the start; 22 (a val150 house): the paper's
    // heuristic with K = 16 until 16 remain, then one exact problem.
    for n in [16usize, 22] {
        let (house, distances, p) = house(n, 7);
        // The target in the least likely container: the longest trial.
        let goal = (0..n)
            .min_by(|&a, &b| p[a].get().total_cmp(&p[b].get()))
            .unwrap_or(0);
        for fresh in [false, true] {
            let name = if fresh { "resolve_each" } else { "reuse" };
            group.bench_with_input(BenchmarkId::new(name, n), &n, |b, _| {
                b.iter(|| trial(&house, &distances, &p, goal, fresh))
            });
        }
    }
    group.finish();
}

fn bench_team(c: &mut Criterion) {
    let mut group = c.benchmark_group("team_decision");
    // 22 containers, as a val150 house has; the paper's K = 8.
    let (house, distances, p) = house(22, 11);
    let task = Task::single(ObjectType::new("RemoteControl"));
    let config = PlannerConfig::default();
    let mut belief = Belief::new(&house, &distances, &task);
    belief.search(3, Vec::new());
    // What `Search::next_container_leaving` does for the third robot of a team: a view with
    // the others' claims (the two likeliest containers) searched in vain, a fresh plan.
    let mut likeliest: Vec<usize> = (0..22).filter(|&c| c != 3).collect();
    likeliest.sort_by(|&a, &b| p[b].get().total_cmp(&p[a].get()));
    for robots in [1usize, 3] {
        let claims: Vec<usize> = likeliest[..robots - 1].to_vec();
        group.bench_with_input(
            BenchmarkId::new("k8_robots", robots),
            &claims,
            |b, claims| {
                b.iter(|| {
                    let mut view = belief.clone();
                    for &c in claims {
                        view.reveal(c, Vec::new());
                    }
                    Planner::new(p.clone(), config).choose(&view)
                })
            },
        );
    }
    group.finish();
}

criterion_group!(benches, bench, bench_task, bench_trial, bench_team);
criterion_main!(benches);
