//! Occupancy grids and distances on small hand-built houses, and properties on random rooms.

use ferret_world::distance::travel_field;
use ferret_world::grid::{Cell, CellKind};
use ferret_world::{
    Container, Distances, Door, Footprint, GridParams, House, ObjectType, Obstacle, OccupancyGrid,
    Place, Point, Polygon, Pose, Room, RoomType, Wall, WorldError,
};
use proptest::prelude::*;

const RES: f64 = 0.05;

fn rect_room(id: usize, room_type: &str, x0: f64, z0: f64, x1: f64, z1: f64) -> (Room, Vec<Wall>) {
    let c = [
        Point::new(x0, z0),
        Point::new(x1, z0),
        Point::new(x1, z1),
        Point::new(x0, z1),
    ];
    let walls = (0..4)
        .map(|i| Wall {
            id: format!("wall|{id}|{i}"),
            room_id: format!("room|{id}"),
            start: c[i],
            end: c[(i + 1) % 4],
        })
        .collect();
    (
        Room {
            id: format!("room|{id}"),
            room_type: RoomType::new(room_type),
            floor: Polygon::new(c.to_vec()),
        },
        walls,
    )
}

fn container(
    id: &str,
    kind: &str,
    room: usize,
    center: Point,
    size_x: f64,
    size_z: f64,
    yaw_deg: f64,
) -> Container {
    Container {
        id: id.into(),
        object_type: ObjectType::new(kind),
        room: Some(room),
        position: center,
        footprint: Footprint {
            center,
            size_x,
            size_z,
            yaw_deg,
        },
        access: None,
    }
}

fn house(
    rooms: Vec<(Room, Vec<Wall>)>,
    doors: Vec<Door>,
    containers: Vec<Container>,
    start: Point,
) -> House {
    let (rooms, walls): (Vec<Room>, Vec<Vec<Wall>>) = rooms.into_iter().unzip();
    House {
        name: "test-house".into(),
        index: 0,
        rooms,
        walls: walls.concat(),
        doors,
        containers,
        obstacles: Vec::new(),
        start: Pose {
            position: start,
            yaw_deg: 0.0,
        },
        map: None,
    }
}

fn door(start: Point, end: Point) -> Door {
    Door {
        id: "door|1|2".into(),
        rooms: ["room|1".into(), "room|2".into()],
        wall: "wall|1|1".into(),
        start,
        end,
    }
}

/// Two 4 m × 3 m rooms side by side, sharing the wall x = 4, a table in the right one.
fn two_rooms(doors: Vec<Door>) -> House {
    house(
        vec![
            rect_room(1, "Kitchen", 0.0, 0.0, 4.0, 3.0),
            rect_room(2, "Bedroom", 4.0, 0.0, 8.0, 3.0),
        ],
        doors,
        vec![container(
            "2|0",
            "DiningTable",
            1,
            Point::new(6.5, 1.5),
            1.0,
            0.8,
            0.0,
        )],
        Point::new(1.0, 1.5),
    )
}

fn octile(a: Cell, b: Cell) -> f64 {
    let dx = f64::from(a.x.abs_diff(b.x));
    let dz = f64::from(a.z.abs_diff(b.z));
    (dx.max(dz) - dx.min(dz)) + dx.min(dz) * std::f64::consts::SQRT_2
}

fn path_length(points: &[Point]) -> f64 {
    points.windows(2).map(|w| w[0].distance(w[1])).sum()
}

fn kind_at(grid: &OccupancyGrid, x: f64, z: f64) -> CellKind {
    grid.kind(grid.cell_of(Point::new(x, z)).expect("point on the grid"))
}

#[test]
fn two_rooms_joined_by_a_door_are_connected_through_it() {
    let h = two_rooms(vec![door(Point::new(4.0, 1.0), Point::new(4.0, 2.0))]);
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    assert!(grid.closed_doors().is_empty());
    let d = Distances::compute(&h, &grid).unwrap();
    let access = grid.access_cell(0).unwrap();
    assert_eq!(grid.room(access), Some(1));
    let a = grid.center(access);
    // The access cell faces the middle of a long side of the table, the radius from it.
    assert!(
        (a.x - 6.5).abs() < RES && (a.z < 1.1 - 0.18 || a.z > 1.9 + 0.18),
        "{a:?}"
    );
    let gap = grid.access_gap(0).unwrap();
    assert!((0.18..0.18 + RES).contains(&gap), "gap {gap}");
    // The path bends round the lower door jamb (the opening is free for z in [1.18, 1.82]); an
    // 8-connected path is at most 1/cos(22.5°) ≈ 1.0824 times the Euclidean length.
    let s = grid.center(grid.start_cell());
    let dist = d.between(Place::Start, Place::Container(0));
    let jamb = Point::new(4.0, 1.18);
    let euclid = s.distance(jamb) + jamb.distance(a);
    assert!(dist >= euclid - RES, "{dist} vs {euclid}");
    assert!(dist <= euclid * 1.0824 + RES, "{dist} vs {euclid}");
    assert_eq!(d.between(Place::Container(0), Place::Start), dist);
    assert_eq!(d.between(Place::Container(0), Place::Container(0)), 0.0);
    // The path crosses x = 4 inside the door.
    let path = d.path(Place::Start, Place::Container(0)).unwrap();
    let dense = densify(&path, RES / 2.0);
    let crossing = dense.iter().find(|p| (p.x - 4.0).abs() < RES).unwrap();
    assert!((1.0..=2.0).contains(&crossing.z), "{crossing:?}");
}

#[test]
fn a_door_hole_in_the_middle_of_a_wall_is_open_and_the_rest_is_wall() {
    let h = two_rooms(vec![door(Point::new(4.0, 1.0), Point::new(4.0, 2.2))]);
    let params = GridParams {
        robot_radius: 0.0,
        ..GridParams::default()
    };
    let grid = OccupancyGrid::build(&h, &params).unwrap();
    for z in [1.05, 1.5, 2.15] {
        assert_eq!(kind_at(&grid, 4.0, z), CellKind::Free, "door at z = {z}");
    }
    for z in [0.2, 0.9, 2.3, 2.8] {
        assert_eq!(kind_at(&grid, 4.0, z), CellKind::Wall, "wall at z = {z}");
        assert_eq!(kind_at(&grid, 4.04, z), CellKind::Wall, "wall at z = {z}");
    }
    // Away from walls the floor is free; beyond the house it is outside.
    assert_eq!(kind_at(&grid, 2.0, 1.5), CellKind::Free);
    assert_eq!(kind_at(&grid, 8.12, 1.5), CellKind::Outside);
    // With the default radius the opening narrows by the radius at each jamb but stays open.
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    assert_eq!(kind_at(&grid, 4.0, 1.6), CellKind::Free);
    assert_eq!(kind_at(&grid, 4.0, 1.1), CellKind::Clearance);
    assert_eq!(kind_at(&grid, 3.0, 2.9), CellKind::Clearance);
}

#[test]
fn a_wall_without_a_door_makes_the_other_room_unreachable() {
    let h = two_rooms(vec![]);
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    assert_eq!(grid.unreachable_containers(), vec![0]);
    assert!(grid.access_cell(0).is_none());
    match Distances::compute(&h, &grid) {
        Err(WorldError::Unreachable { house, names }) => {
            assert_eq!(house, "test-house");
            assert_eq!(names, vec!["DiningTable (2|0) in the bedroom".to_string()]);
        }
        other => panic!("expected Unreachable, got {other:?}"),
    }
}

#[test]
fn a_door_narrower_than_the_robot_is_closed() {
    // 0.35 m opening, robot 0.36 m across.
    let h = two_rooms(vec![door(Point::new(4.0, 1.0), Point::new(4.0, 1.35))]);
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    assert_eq!(grid.closed_doors(), &[0]);
    assert!(matches!(
        Distances::compute(&h, &grid),
        Err(WorldError::Unreachable { .. })
    ));
    // A smaller robot passes.
    let small = GridParams {
        robot_radius: 0.1,
        ..GridParams::default()
    };
    let grid = OccupancyGrid::build(&h, &small).unwrap();
    assert!(grid.closed_doors().is_empty());
    assert!(Distances::compute(&h, &grid).is_ok());
}

#[test]
fn the_access_cell_stays_in_the_containers_own_room() {
    // A shelf in the right room against the shared wall: the nearest free cells are across the
    // wall in the left room, but the robot must come round through the door at the far end.
    let mut h = two_rooms(vec![door(Point::new(4.0, 0.1), Point::new(4.0, 1.1))]);
    h.containers = vec![container(
        "2|0",
        "Shelf",
        1,
        Point::new(4.2, 2.5),
        0.3,
        0.8,
        0.0,
    )];
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    let access = grid.access_cell(0).unwrap();
    assert_eq!(grid.room(access), Some(1));
    assert!(grid.center(access).x > 4.0);
    let d = Distances::compute(&h, &grid).unwrap();
    let a = grid.center(access);
    let s = grid.center(grid.start_cell());
    assert!(d.between(Place::Start, Place::Container(0)) > s.distance(a) + 0.3);
}

#[test]
fn a_rotated_footprint_blocks_the_cells_along_its_long_axis() {
    let mut h = house(
        vec![rect_room(1, "LivingRoom", 0.0, 0.0, 6.0, 6.0)],
        vec![],
        vec![],
        Point::new(0.5, 0.5),
    );
    // 2 m × 0.3 m, turned 45°: its long axis runs along (1, −1) (Unity turns clockwise).
    h.obstacles.push(Obstacle {
        id: "1|5".into(),
        object_type: ObjectType::new("Sofa"),
        room: Some(0),
        footprint: Footprint {
            center: Point::new(3.0, 3.0),
            size_x: 2.0,
            size_z: 0.3,
            yaw_deg: 45.0,
        },
    });
    let params = GridParams {
        robot_radius: 0.0,
        ..GridParams::default()
    };
    let grid = OccupancyGrid::build(&h, &params).unwrap();
    for t in [-0.65, -0.3, 0.0, 0.3, 0.65] {
        assert_eq!(
            kind_at(&grid, 3.0 + t, 3.0 - t),
            CellKind::Furniture,
            "along the axis at {t}"
        );
    }
    for t in [-0.65, -0.3, 0.3, 0.65] {
        assert_eq!(
            kind_at(&grid, 3.0 + t, 3.0 + t),
            CellKind::Free,
            "across the axis at {t}"
        );
    }
    assert_eq!(
        kind_at(&grid, 3.0 + 0.8, 3.0 - 0.8),
        CellKind::Free,
        "beyond the end"
    );
    // Exactly the cells whose centres are inside, plus none else.
    let furniture = grid
        .cells()
        .filter(|&(_, k)| k == CellKind::Furniture)
        .count();
    let inside = grid
        .cells()
        .filter(|&(c, _)| h.obstacles[0].footprint.contains(grid.center(c)))
        .count();
    assert_eq!(furniture, inside);
    let expected = 2.0 * 0.3 / (RES * RES);
    assert!(
        (furniture as f64 - expected).abs() < 0.1 * expected,
        "{furniture} cells, area says {expected}"
    );
}

#[test]
fn distances_on_an_empty_rectangle_are_octile_distances() {
    let h = house(
        vec![rect_room(1, "LivingRoom", 0.0, 0.0, 7.0, 5.0)],
        vec![],
        vec![],
        Point::new(0.8, 0.7),
    );
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    let from = grid.start_cell();
    let field = travel_field(&grid, from).unwrap();
    let mut checked = 0;
    for ((cell, kind), metres) in grid.cells().zip(&field) {
        if kind == CellKind::Free {
            assert!(
                (metres - octile(from, cell) * RES).abs() < 1e-12,
                "{cell:?}: {metres}"
            );
            checked += 1;
        } else {
            assert_eq!(*metres, f64::INFINITY, "{cell:?} is {kind:?}");
        }
    }
    // The free floor is the room less the band of half a wall (one cell, drawn no thinner than
    // res·√2, so half is 0.035 m) and the robot radius, give or take a row of cells per side.
    let band = RES * std::f64::consts::FRAC_1_SQRT_2 + 0.18;
    let side = |l: f64| ((l - 2.0 * band) / RES).round();
    assert!(
        (checked as f64 - side(7.0) * side(5.0)).abs() <= 2.0 * (side(7.0) + side(5.0)),
        "{checked}"
    );
    // The far corner is about 6.4 m × 4.2 m away.
    assert!(field.iter().filter(|d| d.is_finite()).any(|&d| d > 7.0));
    assert!(travel_field(&grid, Cell::new(0, 0)).is_none());
}

#[test]
fn paths_start_and_end_at_the_places_and_have_the_matrix_length() {
    let mut h = two_rooms(vec![door(Point::new(4.0, 2.0), Point::new(4.0, 2.9))]);
    h.containers.push(container(
        "1|0",
        "Fridge",
        0,
        Point::new(0.4, 0.4),
        0.7,
        0.7,
        0.0,
    ));
    h.obstacles.push(Obstacle {
        id: "1|1".into(),
        object_type: ObjectType::new("Chair"),
        room: Some(0),
        footprint: Footprint {
            center: Point::new(2.5, 1.5),
            size_x: 0.6,
            size_z: 1.5,
            yaw_deg: 20.0,
        },
    });
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    let d = Distances::compute(&h, &grid).unwrap();
    let places = [Place::Start, Place::Container(0), Place::Container(1)];
    for &a in &places {
        for &b in &places {
            let path = d.path(a, b).unwrap();
            assert_eq!(path.first().copied(), d.point(a));
            assert_eq!(path.last().copied(), d.point(b));
            assert!(
                (path_length(&path) - d.between(a, b)).abs() < 1e-9,
                "{a:?}→{b:?}"
            );
            // Every cell the path passes is reachable.
            for p in densify(&path, RES / 4.0) {
                assert!(
                    grid.is_reachable(grid.cell_of(p).unwrap()),
                    "{p:?} on {a:?}→{b:?}"
                );
            }
        }
    }
    assert!(d.path(Place::Start, Place::Container(7)).is_none());
    let synthetic = Distances::from_matrix(1, vec![0.0, 1.0, 1.0, 0.0]).unwrap();
    assert!(synthetic.path(Place::Start, Place::Container(0)).is_none());
}

#[test]
fn an_occupied_start_moves_to_the_nearest_free_cell() {
    let mut h = two_rooms(vec![door(Point::new(4.0, 1.0), Point::new(4.0, 2.0))]);
    h.start.position = Point::new(6.5, 1.5); // on the table
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    assert!(grid.start_moved());
    let s = grid.center(grid.start_cell());
    assert!(grid.is_free(grid.start_cell()));
    // No free cell is nearer to the start's own cell.
    let own = grid.cell_of(h.start.position).unwrap();
    let d2 = |c: Cell| {
        (i64::from(c.x) - i64::from(own.x)).pow(2) + (i64::from(c.z) - i64::from(own.z)).pow(2)
    };
    let nearest = grid
        .cells()
        .filter(|&(_, k)| k == CellKind::Free)
        .map(|(c, _)| d2(c))
        .min()
        .unwrap();
    assert_eq!(d2(grid.start_cell()), nearest);
    // The table is 1 m × 0.8 m: that is about 0.4 + 0.18 m off its centre in z.
    assert!(
        (s.distance(Point::new(6.5, 1.5)) - 0.6).abs() < 2.0 * RES,
        "{s:?}"
    );
    let d = Distances::compute(&h, &grid).unwrap();
    // At most round the table.
    assert!(d.between(Place::Start, Place::Container(0)) < 2.0 * (1.0 + 0.8 + 4.0 * 0.215));
}

#[test]
fn bad_parameters_and_houses_are_errors_not_panics() {
    let h = two_rooms(vec![]);
    for params in [
        GridParams {
            resolution: 0.0,
            ..GridParams::default()
        },
        GridParams {
            resolution: f64::NAN,
            ..GridParams::default()
        },
        GridParams {
            robot_radius: -1.0,
            ..GridParams::default()
        },
        GridParams {
            wall_thickness: f64::INFINITY,
            ..GridParams::default()
        },
    ] {
        assert!(
            matches!(
                OccupancyGrid::build(&h, &params),
                Err(WorldError::Grid { .. })
            ),
            "{params:?}"
        );
    }
    let mut off = h.clone();
    off.start.position = Point::new(100.0, 100.0);
    assert!(matches!(
        OccupancyGrid::build(&off, &GridParams::default()),
        Err(WorldError::Grid { .. })
    ));
    let mut nan = h.clone();
    nan.containers[0].footprint.size_x = f64::NAN;
    assert!(matches!(
        OccupancyGrid::build(&nan, &GridParams::default()),
        Err(WorldError::Grid { .. })
    ));
    let mut huge = h.clone();
    huge.rooms[0].floor.vertices[0] = Point::new(-1e7, -1e7);
    assert!(matches!(
        OccupancyGrid::build(&huge, &GridParams::default()),
        Err(WorldError::Grid { .. })
    ));
    let mut empty = h.clone();
    empty.rooms.clear();
    assert!(matches!(
        OccupancyGrid::build(&empty, &GridParams::default()),
        Err(WorldError::Grid { .. })
    ));
    // A grid from another house.
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    let mut more = h.clone();
    more.containers.push(more.containers[0].clone());
    assert!(matches!(
        Distances::compute(&more, &grid),
        Err(WorldError::Grid { .. })
    ));
}

#[test]
fn grid_accessors_agree() {
    let h = two_rooms(vec![door(Point::new(4.0, 1.0), Point::new(4.0, 2.0))]);
    let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
    assert_eq!(grid.resolution(), RES);
    assert_eq!(
        grid.cell_count(),
        grid.width() as usize * grid.height() as usize
    );
    let counts = grid.kind_counts();
    assert_eq!(counts.iter().sum::<usize>(), grid.cell_count());
    assert_eq!(counts[CellKind::Free as usize], grid.free_count());
    assert_eq!(
        grid.reachable_count(),
        grid.free_count(),
        "both rooms are connected"
    );
    // Free floor: two rooms of 12 m² less a band of ~0.215 m along every wall and the table.
    let free_m2 = grid.free_count() as f64 * RES * RES;
    assert!(free_m2 > 14.0 && free_m2 < 19.0, "{free_m2}");
    let p = Point::new(1.23, 2.34);
    let c = grid.cell_of(p).unwrap();
    assert!(
        (grid.center(c).x - p.x).abs() <= RES / 2.0 && (grid.center(c).z - p.z).abs() <= RES / 2.0
    );
    assert_eq!(grid.room(c), Some(0));
    assert!(grid.cell_of(Point::new(-50.0, 0.0)).is_none());
    assert!(grid.cell_of(Point::new(f64::NAN, 0.0)).is_none());
    let e = grid.extent();
    assert!(e.min.x < 0.0 && e.max.x > 8.0 && e.min.z < 0.0 && e.max.z > 3.0);
}

/// Points every `step` metres along a polyline.
fn densify(path: &[Point], step: f64) -> Vec<Point> {
    let mut out = vec![path[0]];
    for w in path.windows(2) {
        let n = (w[0].distance(w[1]) / step).ceil().max(1.0) as usize;
        for k in 1..=n {
            let t = k as f64 / n as f64;
            out.push(Point::new(
                w[0].x + t * (w[1].x - w[0].x),
                w[0].z + t * (w[1].z - w[0].z),
            ));
        }
    }
    out
}

/// Dijkstra with a binary heap and floating-point sums, 8-connected, no corner cutting.
fn reference_dijkstra(grid: &OccupancyGrid, from: Cell) -> Vec<f64> {
    use std::cmp::Reverse;
    use std::collections::BinaryHeap;
    let w = grid.width();
    let idx = |c: Cell| (c.z * w + c.x) as usize;
    let ok = |x: i64, z: i64| x >= 0 && z >= 0 && grid.is_reachable(Cell::new(x as u32, z as u32));
    let mut dist = vec![f64::INFINITY; grid.cell_count()];
    let mut heap = BinaryHeap::new();
    dist[idx(from)] = 0.0;
    heap.push(Reverse((0u64, from.x, from.z)));
    while let Some(Reverse((d_bits, x, z))) = heap.pop() {
        let d = f64::from_bits(d_bits);
        if d > dist[idx(Cell::new(x, z))] {
            continue;
        }
        let (x, z) = (i64::from(x), i64::from(z));
        for (dx, dz) in [
            (-1, 0),
            (1, 0),
            (0, -1),
            (0, 1),
            (-1, -1),
            (1, -1),
            (-1, 1),
            (1, 1),
        ] {
            let (nx, nz) = (x + dx, z + dz);
            if !ok(nx, nz) || (dx != 0 && dz != 0 && !(ok(x + dx, z) && ok(x, z + dz))) {
                continue;
            }
            let step = if dx != 0 && dz != 0 {
                std::f64::consts::SQRT_2
            } else {
                1.0
            } * RES;
            let n = Cell::new(nx as u32, nz as u32);
            if d + step < dist[idx(n)] - 1e-12 {
                dist[idx(n)] = d + step;
                // Non-negative floats order like their bit patterns.
                heap.push(Reverse(((d + step).to_bits(), n.x, n.z)));
            }
        }
    }
    dist
}

fn random_room() -> impl Strategy<Value = House> {
    let furniture = (
        0.3f64..0.95,
        0.3f64..0.95,
        0.2f64..1.2,
        0.2f64..1.2,
        0.0f64..360.0,
    );
    (
        2.0f64..6.0,
        2.0f64..6.0,
        prop::collection::vec(furniture.clone(), 1..5),
        prop::collection::vec(furniture, 0..6),
        (0.05f64..0.95, 0.05f64..0.95),
    )
        .prop_map(|(w, d, containers, obstacles, (sx, sz))| {
            let at = |fx: f64, fz: f64| Point::new(fx * w, fz * d);
            let mut h = house(
                vec![rect_room(1, "LivingRoom", 0.0, 0.0, w, d)],
                vec![],
                containers
                    .iter()
                    .enumerate()
                    .map(|(i, &(fx, fz, sx, sz, yaw))| {
                        container(&format!("1|{i}"), "Box", 0, at(fx, fz), sx, sz, yaw)
                    })
                    .collect(),
                at(sx, sz),
            );
            h.obstacles = obstacles
                .iter()
                .enumerate()
                .map(|(i, &(fx, fz, sx, sz, yaw))| Obstacle {
                    id: format!("1|o{i}"),
                    object_type: ObjectType::new("Chair"),
                    room: Some(0),
                    footprint: Footprint {
                        center: at(fx, fz),
                        size_x: sx,
                        size_z: sz,
                        yaw_deg: yaw,
                    },
                })
                .collect();
            h
        })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(48))]

    #[test]
    fn distances_are_a_metric_on_random_rooms(h in random_room()) {
        let grid = OccupancyGrid::build(&h, &GridParams::default()).unwrap();
        let d = match Distances::compute(&h, &grid) {
            Ok(d) => d,
            Err(WorldError::Unreachable { names, .. }) => {
                // Exactly the containers without an access cell are named.
                let expected: Vec<String> =
                    grid.unreachable_containers().iter().map(|&i| h.container_label(i)).collect();
                prop_assert!(!names.is_empty());
                prop_assert_eq!(names, expected);
                return Ok(());
            }
            Err(e) => return Err(TestCaseError::fail(e.to_string())),
        };
        let places: Vec<Place> =
            std::iter::once(Place::Start).chain((0..h.containers.len()).map(Place::Container)).collect();
        for &a in &places {
            for &b in &places {
                let dab = d.between(a, b);
                let (pa, pb) = (d.point(a).unwrap(), d.point(b).unwrap());
                prop_assert!(dab >= pa.distance(pb) - 1e-9, "{a:?}→{b:?}: {dab} < straight {}", pa.distance(pb));
                // Symmetric: the reverse path, found by a fresh search, is as long.
                let back = path_length(&d.path(b, a).unwrap());
                prop_assert!((back - dab).abs() <= RES, "{a:?}↔{b:?}: {dab} vs {back}");
                for &c in &places {
                    prop_assert!(d.between(a, c) <= dab + d.between(b, c) + RES);
                }
            }
        }
        // The bucket search agrees with a textbook Dijkstra on a binary heap, on every cell.
        let field = travel_field(&grid, grid.start_cell()).unwrap();
        let reference = reference_dijkstra(&grid, grid.start_cell());
        for (i, (a, b)) in field.iter().zip(&reference).enumerate() {
            prop_assert!(a == b || (a - b).abs() < 1e-9, "cell {i}: {a} vs {b}");
        }
        for i in 0..h.containers.len() {
            let cell = grid.access_cell(i).unwrap();
            let at = (cell.z * grid.width() + cell.x) as usize;
            prop_assert!((d.between(Place::Start, Place::Container(i)) - field[at]).abs() < 1e-9);
            prop_assert!(grid.is_reachable(cell));
            prop_assert_eq!(grid.room(cell), Some(0));
        }
    }
}
