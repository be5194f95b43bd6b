//! The reference code's container set and access points on a ProcTHOR-10k-style house made
//! here: which objects are containers, what they hold, and the soft cost on its grid.

#[path = "procthor_fixture/mod.rs"]
mod fixture;

use std::path::{Path, PathBuf};

use ferret_world::procthor::{AssetDatabase, parse_house, parse_house_with};
use ferret_world::{
    AccessRule, ContainerSet, Distances, GridParams, HouseLocation, OccupancyGrid, Place, Scene,
    SoftGrid, TravelCost,
};

fn at() -> HouseLocation {
    HouseLocation {
        file: PathBuf::from("procthor-10k-train.jsonl"),
        index: 1000,
    }
}

fn load(rule: ContainerSet) -> Scene {
    parse_house_with(&fixture::house_10k().to_string(), &at(), None, rule).unwrap()
}

fn ids(scene: &Scene) -> Vec<&str> {
    scene
        .house
        .containers
        .iter()
        .map(|c| c.id.as_str())
        .collect()
}

fn contents(scene: &Scene, id: &str) -> Vec<String> {
    let i = scene.house.container_index(id).unwrap();
    scene
        .truth
        .contents(i)
        .iter()
        .map(|o| o.object_type.to_string())
        .collect()
}

#[test]
fn furniture_is_every_top_level_object_but_the_ignored_types() {
    let scene = load(ContainerSet::Furniture);
    // Types from the id prefixes; the painting, floor lamp and box are ignored (the painting
    // hangs on a wall and is not drawn at all; the lamp and the box stay obstacles).
    assert_eq!(
        ids(&scene),
        [
            "Fridge|1|0",
            "CounterTop|1|1",
            "Chair|1|2",
            "Sofa|2|0",
            "Dresser|2|1"
        ]
    );
    let types: Vec<&str> = scene
        .house
        .containers
        .iter()
        .map(|c| c.object_type.as_str())
        .collect();
    assert_eq!(types, ["Fridge", "CounterTop", "Chair", "Sofa", "Dresser"]);
    let obstacles: Vec<&str> = scene
        .house
        .obstacles
        .iter()
        .map(|o| o.id.as_str())
        .collect();
    assert_eq!(obstacles, ["FloorLamp|2|2", "Box|2|3"]);
    // Direct children only (the pen under the remote is never looked at), every type kept but
    // those that are also top-level types (the chair on the sofa); the microwave counts.
    assert_eq!(
        contents(&scene, "CounterTop|1|1"),
        ["Microwave", "CellPhone"]
    );
    assert_eq!(contents(&scene, "Sofa|2|0"), ["RemoteControl"]);
    assert_eq!(contents(&scene, "Chair|1|2"), Vec::<String>::new());
    // The box's cup vanished with the box.
    assert!(
        !scene
            .truth
            .target_types()
            .iter()
            .any(|t| t.as_str() == "Cup")
    );
}

#[test]
fn furniture_contains_the_receptacles() {
    let db = AssetDatabase::parse(fixture::ASSET_DB, Path::new("db.json")).unwrap();
    let h = fixture::house_b().to_string();
    let receptacles = parse_house(&h, &at(), Some(&db)).unwrap();
    let furniture = parse_house_with(&h, &at(), Some(&db), ContainerSet::Furniture).unwrap();
    let f = ids(&furniture);
    assert!(!ids(&receptacles).is_empty());
    for id in ids(&receptacles) {
        assert!(f.contains(&id), "{id} is a receptacle but no furniture");
    }
    assert!(f.len() > ids(&receptacles).len(), "the chair is furniture");
    // Ids without a type prefix are typed by the asset database alone: the 4|0|0-style house
    // gives the same containers under either rule where both know the type.
    let a = fixture::house_a().to_string();
    let plain = parse_house_with(&a, &at(), Some(&db), ContainerSet::Furniture).unwrap();
    assert!(ids(&plain).contains(&"1|0"));
    assert!(!ids(&plain).contains(&"2|2"), "the floor lamp is ignored");
}

#[test]
fn nearest_free_access_is_the_reachable_cell_nearest_the_centre() {
    let scene = load(ContainerSet::Furniture);
    let params = GridParams {
        access: AccessRule::NearestFree,
        ..GridParams::default()
    };
    let grid = OccupancyGrid::build(&scene.house, &params).unwrap();
    let footprint = OccupancyGrid::build(&scene.house, &GridParams::default()).unwrap();
    for (i, c) in scene.house.containers.iter().enumerate() {
        let cell = grid.access_cell(i).unwrap();
        assert!(grid.is_reachable(cell));
        let d = grid.center(cell).distance(c.position);
        // No reachable cell is nearer the centre.
        let nearer = grid
            .cells()
            .filter(|&(k, _)| grid.is_reachable(k))
            .any(|(k, _)| grid.center(k).distance(c.position) < d - 1e-12);
        assert!(!nearer, "{}", c.id);
        // And never farther from the centre than the footprint rule's cell.
        let other = footprint.access_cell(i).unwrap();
        assert!(d <= footprint.center(other).distance(c.position) + 1e-12);
    }
    // The rule changes only access points, not the cells.
    assert_eq!(grid.kind_counts(), footprint.kind_counts());
}

#[test]
fn soft_cost_of_a_trajectory_is_at_least_its_plain_length() {
    let scene = load(ContainerSet::Furniture);
    let grid = OccupancyGrid::build(&scene.house, &GridParams::default()).unwrap();
    let d = Distances::compute(&scene.house, &grid).unwrap();
    let n = scene.house.containers.len();
    let visits: Vec<Place> = std::iter::once(Place::Start)
        .chain((0..n).rev().map(Place::Container))
        .collect();
    let plain = d.travel_cost(&visits, TravelCost::Plain).unwrap();
    let soft = d.travel_cost(&visits, TravelCost::Soft).unwrap();
    assert!(plain > 1.0);
    assert!(
        soft >= plain && soft <= 1.28 * plain + 1e-9,
        "soft {soft}, plain {plain}"
    );
    for leg in visits.windows(2) {
        let p = d.travel_cost(leg, TravelCost::Plain).unwrap();
        let s = d.travel_cost(leg, TravelCost::Soft).unwrap();
        assert!(s >= p - 1e-9, "{leg:?}: soft {s} < plain {p}");
    }
    // Synthetic distances have no grid, so no soft cost; a bad place has no cost at all.
    let m = Distances::from_matrix(1, vec![0.0, 1.0, 1.0, 0.0]).unwrap();
    assert_eq!(
        m.travel_cost(&[Place::Start, Place::Container(0)], TravelCost::Plain),
        Some(1.0)
    );
    assert_eq!(
        m.travel_cost(&[Place::Start, Place::Container(0)], TravelCost::Soft),
        None
    );
    assert_eq!(
        m.travel_cost(&[Place::Container(5)], TravelCost::Plain),
        None
    );
}

#[test]
fn the_kept_soft_cost_equals_the_soft_cost_computed_afresh() {
    let scene = load(ContainerSet::Furniture);
    let params = GridParams {
        access: AccessRule::NearestFree,
        ..GridParams::default()
    };
    let grid = OccupancyGrid::build(&scene.house, &params).unwrap();
    let d = Distances::compute(&scene.house, &grid).unwrap();
    let w = grid.width() as usize;
    let blocked = grid.cells().map(|(c, _)| !grid.is_reachable(c)).collect();
    let fresh = SoftGrid::new(w, blocked).unwrap();
    let index = |p: Place| {
        let c = match p {
            Place::Start => grid.start_cell(),
            Place::Container(i) => grid.access_cell(i).unwrap(),
        };
        c.z as usize * w + c.x as usize
    };
    let n = scene.house.containers.len();
    let forward: Vec<Place> = std::iter::once(Place::Start)
        .chain((0..n).map(Place::Container))
        .collect();
    let mut trajectories = vec![forward.clone()];
    for k in 1..n {
        let mut t = forward.clone();
        t[1..].rotate_left(k);
        trajectories.push(t.clone());
        t[1..].reverse();
        trajectories.push(t);
    }
    trajectories.push(vec![
        Place::Start,
        Place::Container(0),
        Place::Container(0),
        Place::Start,
    ]);
    // Twice over, so that the second round is answered from legs the first one searched.
    for _ in 0..2 {
        for t in &trajectories {
            let kept = d.travel_cost(t, TravelCost::Soft).unwrap();
            // The visited cells are reachable, so nothing needs freeing: each leg is a search
            // on the grid as it is, with its weights recomputed.
            let afresh = t
                .windows(2)
                .map(|leg| fresh.cost(index(leg[0]), index(leg[1])))
                .sum::<f64>()
                * grid.resolution();
            assert_eq!(kept.to_bits(), afresh.to_bits(), "{t:?}: {kept} ≠ {afresh}");
        }
    }
}
