//! Small synthetic houses the property tests of this crate share: one room, Euclidean travel
//! from any start, contents and tasks drawn by proptest.

#![allow(dead_code)]

use std::sync::Arc;

use ferret_plan::{PlannerConfig, Prior, StrategyRegistry};
use ferret_world::{
    Container, Distances, Footprint, GroundTruth, House, ObjectType, Point, Polygon, Pose, Room,
    RoomType, Scene, SmallObject,
};
use proptest::prelude::prop;
use proptest::strategy::Strategy as _;

/// A one-room house with containers at `points`, Euclidean travel, and the given contents.
pub fn house(
    points: &[(f64, f64)],
    types: &[usize],
    contents: &[Vec<usize>],
) -> (House, GroundTruth, Distances) {
    house_at((0.0, 0.0), points, types, contents)
}

/// [`house`] with the robot starting at `start`.
pub fn house_at(
    start: (f64, f64),
    points: &[(f64, f64)],
    types: &[usize],
    contents: &[Vec<usize>],
) -> (House, GroundTruth, Distances) {
    const KINDS: [&str; 4] = ["Fridge", "Bed", "Sofa", "Desk"];
    const OBJECTS: [&str; 3] = ["Egg", "Book", "RemoteControl"];
    let room = Room {
        id: "room|1".into(),
        room_type: RoomType::new("LivingRoom"),
        floor: Polygon::new(vec![
            Point::new(-20.0, -20.0),
            Point::new(20.0, -20.0),
            Point::new(20.0, 20.0),
            Point::new(-20.0, 20.0),
        ]),
    };
    let containers: Vec<Container> = points
        .iter()
        .enumerate()
        .map(|(i, &(x, z))| Container {
            id: format!("1|{i}"),
            object_type: ObjectType::new(KINDS[types[i] % KINDS.len()]),
            room: Some(0),
            position: Point::new(x, z),
            footprint: Footprint {
                center: Point::new(x, z),
                size_x: 0.5,
                size_z: 0.5,
                yaw_deg: 0.0,
            },
            access: None,
        })
        .collect();
    let start = Point::new(start.0, start.1);
    let places: Vec<Point> = std::iter::once(start)
        .chain(points.iter().map(|&(x, z)| Point::new(x, z)))
        .collect();
    let n = places.len();
    let metres = (0..n * n)
        .map(|k| places[k / n].distance(places[k % n]))
        .collect();
    let distances = Distances::from_matrix(points.len(), metres).unwrap();
    let truth = GroundTruth::new(
        contents
            .iter()
            .map(|objs| {
                objs.iter()
                    .map(|&o| SmallObject {
                        id: format!("small|{o}"),
                        object_type: ObjectType::new(OBJECTS[o % OBJECTS.len()]),
                    })
                    .collect()
            })
            .collect(),
    );
    let house = House {
        name: "synthetic#0".into(),
        index: 0,
        rooms: vec![room],
        walls: vec![],
        doors: vec![],
        containers,
        obstacles: vec![],
        start: Pose {
            position: start,
            yaw_deg: 0.0,
        },
        map: None,
    };
    (house, truth, distances)
}

pub fn registry(scenes: &[Scene]) -> StrategyRegistry {
    let prior = Arc::new(Prior::train(scenes, 2.0));
    StrategyRegistry::builtin(Some(prior), PlannerConfig::default(), 12)
}

/// Container positions, container kinds and contents.
pub type HouseParts = (Vec<(f64, f64)>, Vec<usize>, Vec<Vec<usize>>);

pub fn arb_house() -> impl proptest::strategy::Strategy<Value = HouseParts> {
    (2usize..=9).prop_flat_map(|n| {
        (
            prop::collection::vec((-15.0f64..15.0, -15.0f64..15.0), n),
            prop::collection::vec(0usize..4, n),
            prop::collection::vec(prop::collection::vec(0usize..3, 0..3), n),
        )
    })
}

/// Household tasks drawn from a house's target types: pairs and triples under either goal,
/// with no destination, the start, or a container.
pub fn tasks_of(truth: &GroundTruth, n: usize, pick: usize) -> Vec<ferret_plan::Task> {
    use ferret_plan::{Destination, Goal, Task};
    let types: Vec<ObjectType> = truth.target_types().into_iter().collect();
    let mut tasks = Vec::new();
    for m in 2..=types.len().min(3) {
        for goal in [Goal::All, Goal::Any] {
            let destination = match (pick + m) % 3 {
                0 => None,
                1 => Some(Destination::Start),
                _ => Some(Destination::Container { index: pick % n }),
            };
            let targets = types.iter().cycle().skip(pick).take(m).cloned().collect();
            tasks.push(Task::new(targets, goal, destination).unwrap());
        }
    }
    tasks
}
