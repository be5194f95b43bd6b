//! The world benchmark: the 150 evaluation houses (`multiroom-val150.jsonl.gz`) loaded, turned
//! into 0.05 m occupancy grids and full distance matrices, in parallel over houses; and the
//! paper protocol's soft cost of many trajectories per house, kept per house ([`SoftCache`]) and
//! computed afresh for each trajectory.
//!
//! Target: ≤ 10 s wall for load + grids + distances on a 2-core machine, ≤ 1 GB peak memory.
//! Needs FERRET_PROCTHOR_DIR set to a directory holding `multiroom-val150.jsonl.gz` and
//! `databases/asset-database.json`; without it, only a small hand-built house is measured.

use std::hint::black_box;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use criterion::{Criterion, criterion_group, criterion_main};
use ferret_world::distance::{build, build_all};
use ferret_world::procthor::{AssetDatabase, LoadOptions, load_scenes};
use ferret_world::{
    AccessRule, Container, ContainerSet, Footprint, GridParams, House, ObjectType, OccupancyGrid,
    Point, Polygon, Pose, Room, RoomType, Scene, SoftCache, SoftGrid, Wall,
};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

fn val150(c: &mut Criterion) {
    let Some(dir) = std::env::var_os("FERRET_PROCTHOR_DIR").map(PathBuf::from) else {
        println!(
            "skipped val150: set FERRET_PROCTHOR_DIR to a directory holding multiroom-val150.jsonl.gz and databases/asset-database.json to run"
        );
        return;
    };
    let db = AssetDatabase::load(&dir.join("databases/asset-database.json"))
        .expect("the asset database loads");
    let path = dir.join("multiroom-val150.jsonl.gz");
    let opts = LoadOptions {
        shard: None,
        asset_db: Some(&db),
        ..LoadOptions::default()
    };
    let params = GridParams::default();
    let load = || load_scenes(&path, &opts).expect("the houses load").scenes;
    let scenes = load();
    assert_eq!(scenes.len(), 150);
    describe(&scenes, &params);

    let mut g = c.benchmark_group("val150");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(30));
    g.bench_function("load+grid+distances", |b| {
        b.iter(|| {
            let scenes = load();
            let built = build_all(&scenes, &params);
            black_box((scenes, built))
        })
    });
    g.bench_function("load", |b| b.iter(|| black_box(load())));
    g.bench_function("grid", |b| {
        b.iter(|| {
            scenes
                .par_iter()
                .map(|s| OccupancyGrid::build(&s.house, &params))
                .collect::<Vec<_>>()
        })
    });
    g.bench_function("grid+distances", |b| {
        b.iter(|| black_box(build_all(&scenes, &params)))
    });
    g.finish();
    soft_costs(c, &dir, &db);
}

/// A house's soft grid, its start and access cells, and trajectories over them.
struct SoftHouse {
    grid: SoftGrid,
    stops: Vec<usize>,
    trajectories: Vec<Vec<usize>>,
}

/// The soft cost under the paper protocol's containers and access cells on the first 10 houses:
/// per house, 90 trajectories (about what every target × 3 strategies ask) from the start
/// through a random half of the containers in random order, one thread. Random orders ask for
/// far more distinct legs than planners do, so the kept legs help less than in an evaluation.
fn soft_costs(c: &mut Criterion, dir: &std::path::Path, db: &AssetDatabase) {
    let opts = LoadOptions {
        shard: None,
        asset_db: Some(db),
        containers: ContainerSet::Furniture,
        ..LoadOptions::default()
    };
    let params = GridParams {
        access: AccessRule::NearestFree,
        ..GridParams::default()
    };
    let scenes = load_scenes(&dir.join("multiroom-val150.jsonl.gz"), &opts)
        .expect("the houses load")
        .scenes;
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let houses: Vec<SoftHouse> = scenes[..10]
        .iter()
        .filter_map(|s| OccupancyGrid::build(&s.house, &params).ok())
        .map(|grid| {
            let w = grid.width() as usize;
            let index = |c: ferret_world::grid::Cell| c.z as usize * w + c.x as usize;
            let start = index(grid.start_cell());
            let access: Vec<usize> = (0..grid.container_count())
                .filter_map(|i| grid.access_cell(i).map(index))
                .collect();
            let trajectories = (0..90)
                .map(|_| {
                    let mut visits = access.clone();
                    visits.shuffle(&mut rng);
                    visits.truncate(access.len().div_ceil(2));
                    std::iter::once(start).chain(visits).collect()
                })
                .collect();
            let blocked = grid.cells().map(|(c, _)| !grid.is_reachable(c)).collect();
            SoftHouse {
                grid: SoftGrid::new(w, blocked).expect("a grid's cells fill its rows"),
                stops: std::iter::once(start).chain(access).collect(),
                trajectories,
            }
        })
        .collect();
    let mut g = c.benchmark_group("val150 soft cost");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(30));
    g.bench_function("kept per house", |b| {
        b.iter(|| {
            houses
                .iter()
                .map(|h| {
                    let cache = SoftCache::new(&h.grid, &h.stops);
                    h.trajectories
                        .iter()
                        .map(|t| cache.trajectory_cost(t))
                        .sum::<f64>()
                })
                .sum::<f64>()
        })
    });
    g.bench_function("afresh per trajectory", |b| {
        b.iter(|| {
            houses
                .iter()
                .flat_map(|h| h.trajectories.iter().map(|t| h.grid.trajectory_cost(t)))
                .sum::<f64>()
        })
    });
    g.finish();
}

/// Prints what the benchmark covers: failures, sizes, and the median time per house on one
/// thread.
fn describe(scenes: &[Scene], params: &GridParams) {
    let mut ms = Vec::with_capacity(scenes.len());
    let mut failed = Vec::new();
    let (mut cells, mut containers) = (0usize, 0usize);
    for s in scenes {
        let t = Instant::now();
        let built = build(&s.house, params);
        ms.push(t.elapsed().as_secs_f64() * 1e3);
        containers += s.house.containers.len();
        match built {
            Ok((grid, _)) => cells += grid.cell_count(),
            Err(e) => failed.push(e.to_string()),
        }
    }
    ms.sort_by(f64::total_cmp);
    println!(
        "val150: {} houses, {containers} containers, {:.0}k cells per grid on average; \
         one thread: median {:.1} ms per house, max {:.1} ms, total {:.2} s",
        scenes.len(),
        cells as f64 / 1e3 / (scenes.len() - failed.len()).max(1) as f64,
        ms[ms.len() / 2],
        ms[ms.len() - 1],
        ms.iter().sum::<f64>() / 1e3,
    );
    if !failed.is_empty() {
        println!(
            "WARNING: {} houses failed, so their distances are not measured; first: {}",
            failed.len(),
            failed[0]
        );
    }
}

/// Two 6 m × 5 m rooms joined by a door, with a few containers: measured without data.
fn small_house(c: &mut Criterion) {
    let room = |i: usize, x0: f64| {
        let v = [
            Point::new(x0, 0.0),
            Point::new(x0 + 6.0, 0.0),
            Point::new(x0 + 6.0, 5.0),
            Point::new(x0, 5.0),
        ];
        let walls: Vec<Wall> = (0..4)
            .map(|k| Wall {
                id: format!("wall|{i}|{k}"),
                room_id: format!("room|{i}"),
                start: v[k],
                end: v[(k + 1) % 4],
            })
            .collect();
        (
            Room {
                id: format!("room|{i}"),
                room_type: RoomType::new("LivingRoom"),
                floor: Polygon::new(v.to_vec()),
            },
            walls,
        )
    };
    let (r1, w1) = room(1, 0.0);
    let (r2, w2) = room(2, 6.0);
    let containers = [
        (1.0, 1.0, 0),
        (5.0, 4.0, 0),
        (3.0, 2.5, 0),
        (8.0, 1.0, 1),
        (11.0, 4.0, 1),
    ]
    .iter()
    .enumerate()
    .map(|(i, &(x, z, r))| Container {
        id: format!("{r}|{i}"),
        object_type: ObjectType::new("Dresser"),
        room: Some(r),
        position: Point::new(x, z),
        footprint: Footprint {
            center: Point::new(x, z),
            size_x: 1.0,
            size_z: 0.5,
            yaw_deg: 30.0 * i as f64,
        },
        access: None,
    })
    .collect();
    let house = House {
        name: "bench".into(),
        index: 0,
        rooms: vec![r1, r2],
        walls: [w1, w2].concat(),
        doors: vec![ferret_world::Door {
            id: "door|1|2".into(),
            rooms: ["room|1".into(), "room|2".into()],
            wall: "wall|1|1".into(),
            start: Point::new(6.0, 2.0),
            end: Point::new(6.0, 3.0),
        }],
        containers,
        obstacles: Vec::new(),
        start: Pose {
            position: Point::new(0.5, 4.5),
            yaw_deg: 0.0,
        },
        map: None,
    };
    let params = GridParams::default();
    c.bench_function("small house: grid+distances", |b| {
        b.iter(|| black_box(build(&house, &params).expect("the small house maps")))
    });
}

criterion_group!(benches, small_house, val150);
criterion_main!(benches);
