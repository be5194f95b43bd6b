//! Scene files and robot maps: parsing, errors that name the field, and grids on both.

use std::path::Path;

use ferret_world::distance::{self, Place};
use ferret_world::{GridParams, MapCell, OccupancyMap, SceneFile, WorldError};
use proptest::prelude::*;

/// Two 4 m × 3 m rooms side by side, a door in the shared wall, a container in each.
const TWO_ROOMS: &str = r#"
ferret_scene: 1
name: two rooms
rooms:
  - {name: kitchen, type: Kitchen, polygon: [[0, 0], [4, 0], [4, 3], [0, 3]]}
  - {name: bedroom, type: Bedroom, polygon: [[4, 0], [8, 0], [8, 3], [4, 3]]}
doors:
  - {from: [4, 0.2], to: [4, 1.2]}
containers:
  - {id: fridge, type: Fridge, pose: [0.5, 2.5, 0], size: [0.6, 0.6], contents: [Egg]}
  - {id: bed, type: Bed, pose: [7.0, 2.4, 90], size: [2.0, 1.4], contents: [Pillow, CellPhone]}
start: [1.0, 1.0, 0]
"#;

fn params() -> GridParams {
    GridParams::default()
}

fn parse(text: &str) -> Result<ferret_world::Scene, WorldError> {
    let file = Path::new("test.yaml");
    SceneFile::parse(text, file)?.to_scene(file, None)
}

fn scene_error(text: &str) -> (String, String) {
    match parse(text) {
        Err(WorldError::Scene { field, message, .. }) => (field, message),
        other => panic!("expected a scene error, got {other:?}"),
    }
}

#[test]
fn a_polygon_scene_becomes_a_house_with_walls_doors_and_contents() {
    let scene = parse(TWO_ROOMS).unwrap();
    let h = &scene.house;
    assert_eq!(h.rooms.len(), 2);
    assert_eq!(h.walls.len(), 8, "one wall per polygon edge");
    assert_eq!(h.doors.len(), 1);
    let mut sides = h.doors[0].rooms.clone();
    sides.sort();
    assert_eq!(sides, ["bedroom".to_string(), "kitchen".to_string()]);
    assert_eq!(h.containers[1].room, Some(1), "room found from the polygon");
    assert!(
        scene
            .truth
            .holds(1, &ferret_world::ObjectType::new("CellPhone"))
    );
    assert!(
        !scene
            .truth
            .holds(0, &ferret_world::ObjectType::new("CellPhone"))
    );
    // The bed is reached through the door: farther than the straight line.
    let (_, d) = distance::build(h, &params()).unwrap();
    let direct = h.start.position.distance(h.containers[1].position);
    let travelled = d.between(Place::Start, Place::Container(1));
    assert!(
        travelled.is_finite() && travelled > direct - 1.5,
        "{travelled} vs {direct}"
    );
}

#[test]
fn without_the_door_the_other_room_is_unreachable() {
    let closed = TWO_ROOMS.replace("doors:\n  - {from: [4, 0.2], to: [4, 1.2]}\n", "");
    assert_ne!(closed, TWO_ROOMS);
    let scene = parse(&closed).unwrap();
    match distance::build(&scene.house, &params()) {
        Err(WorldError::Unreachable { names, .. }) => {
            assert_eq!(names.len(), 1);
            assert!(names[0].contains("Bed"), "{names:?}");
        }
        other => panic!(
            "expected the bed to be unreachable, got {:?}",
            other.map(|_| ())
        ),
    }
}

#[test]
fn json_scenes_read_like_yaml_ones() {
    let yaml: serde_json::Value = serde_yaml_ng::from_str(TWO_ROOMS).unwrap();
    let json = serde_json::to_string(&yaml).unwrap();
    assert_eq!(parse(&json).unwrap(), parse(TWO_ROOMS).unwrap());
}

#[test]
fn errors_name_the_field() {
    let cases = [
        (
            TWO_ROOMS.replace("ferret_scene: 1", "ferret_scene: 2"),
            "ferret_scene",
            "version 2",
        ),
        (
            TWO_ROOMS.replace("id: bed,", "id: fridge,"),
            "containers[1].id",
            "earlier",
        ),
        (
            TWO_ROOMS.replace(
                "{id: fridge, type: Fridge,",
                "{id: fridge, type: Fridge, room: attic,",
            ),
            "containers[0].room",
            "attic",
        ),
        (
            TWO_ROOMS.replace("[[0, 0], [4, 0], [4, 3], [0, 3]]", "[[0, 0], [4, 0]]"),
            "rooms[0].polygon",
            "2 vertices",
        ),
        (
            TWO_ROOMS.replace("size: [2.0, 1.4]", "size: [2.0, -1]"),
            "containers[1].size",
            "positive",
        ),
        (
            TWO_ROOMS.replace("pose: [7.0, 2.4, 90]", "pose: [17.0, 2.4, 90]"),
            "containers[1].pose",
            "no room",
        ),
        (
            TWO_ROOMS.replace("start: [1.0, 1.0, 0]", "start: [-5, 1.0, 0]"),
            "start",
            "no room",
        ),
        (
            TWO_ROOMS.replace("to: [4, 1.2]", "to: [5, 1.2]"),
            "doors[0]",
            "no room's edge",
        ),
        (
            TWO_ROOMS.replace("contents: [Egg]", "contents: [\"two eggs\"]"),
            "containers[0].contents[0]",
            "CamelCase",
        ),
    ];
    for (text, field, words) in cases {
        let (f, m) = scene_error(&text);
        assert_eq!(f, field, "{m}");
        assert!(m.contains(words), "{field}: {m}");
    }
    // Fields the format does not know, and missing ones, are named by the parser.
    let (f, m) = scene_error(&TWO_ROOMS.replace("start:", "begin:"));
    assert!(m.contains("begin") || f.contains("begin"), "{f}: {m}");
    let (f, m) = scene_error(&TWO_ROOMS.replace("type: Bed, ", ""));
    assert_eq!(f, "containers[1]");
    assert!(m.contains("type"), "{m}");
}

/// A PGM map (P5) of `rows` given top row first: '#' occupied, '.' free, '?' unknown.
fn write_map(dir: &Path, rows: &[&str], resolution: f64, origin: [f64; 2]) -> std::path::PathBuf {
    let (w, h) = (rows[0].len(), rows.len());
    let mut pgm = format!("P5\n{w} {h}\n255\n").into_bytes();
    for r in rows {
        pgm.extend(r.bytes().map(|c| match c {
            b'#' => 0u8,
            b'.' => 254,
            _ => 205,
        }));
    }
    std::fs::write(dir.join("map.pgm"), pgm).unwrap();
    let yaml = dir.join("map.yaml");
    std::fs::write(
        &yaml,
        format!(
            "image: map.pgm\nresolution: {resolution}\norigin: [{}, {}, 0.0]\nnegate: 0\noccupied_thresh: 0.65\nfree_thresh: 0.196\n",
            origin[0], origin[1]
        ),
    )
    .unwrap();
    yaml
}

/// A 3 m × 2 m map at 0.1 m: a wall across the middle with a gap at the top.
fn walled_rows() -> Vec<String> {
    let mut rows = Vec::new();
    for r in 0..20 {
        let mut row = String::new();
        for c in 0..30 {
            let border = r == 0 || r == 19 || c == 0 || c == 29;
            let wall = c == 15 && r >= 8;
            row.push(if border || wall { '#' } else { '.' });
        }
        rows.push(row);
    }
    rows
}

#[test]
fn ros_maps_are_read_with_their_thresholds_and_the_y_axis_up() {
    let dir = tempfile::tempdir().unwrap();
    let rows = ["#.?", "..."];
    let yaml = write_map(dir.path(), &rows, 0.5, [-1.0, 2.0]);
    let map = OccupancyMap::load_ros(&yaml).unwrap();
    assert_eq!((map.width, map.height), (3, 2));
    // The image's top row is the map's upper row (higher y).
    assert_eq!(
        map.cell_at(ferret_world::Point::new(-0.75, 2.75)),
        Some(MapCell::Occupied)
    );
    assert_eq!(
        map.cell_at(ferret_world::Point::new(-0.25, 2.75)),
        Some(MapCell::Free)
    );
    assert_eq!(
        map.cell_at(ferret_world::Point::new(0.25, 2.75)),
        Some(MapCell::Unknown)
    );
    assert_eq!(
        map.cell_at(ferret_world::Point::new(-0.75, 2.25)),
        Some(MapCell::Free)
    );
    assert_eq!(map.cell_at(ferret_world::Point::new(-1.25, 2.25)), None);
    // negate: 1 flips what dark means.
    let text = std::fs::read_to_string(&yaml)
        .unwrap()
        .replace("negate: 0", "negate: 1");
    std::fs::write(&yaml, text).unwrap();
    let flipped = OccupancyMap::load_ros(&yaml).unwrap();
    assert_eq!(
        flipped.cell_at(ferret_world::Point::new(-0.75, 2.75)),
        Some(MapCell::Free)
    );
    assert_eq!(
        flipped.cell_at(ferret_world::Point::new(-0.25, 2.75)),
        Some(MapCell::Occupied)
    );
}

#[test]
fn bad_map_files_are_named_with_their_field() {
    let dir = tempfile::tempdir().unwrap();
    let yaml = write_map(dir.path(), &["..", ".."], 0.1, [0.0, 0.0]);
    let good = std::fs::read_to_string(&yaml).unwrap();
    let cases = [
        (
            good.replace("resolution: 0.1", "resolution: -1"),
            "resolution",
        ),
        (
            good.replace("origin: [0, 0, 0.0]", "origin: [0, 0, 0.5]"),
            "origin",
        ),
        (good.replace("negate: 0", "negate: 3"), "negate"),
        (
            good.replace("free_thresh: 0.196", "free_thresh: 0.9"),
            "occupied_thresh",
        ),
        (
            good.replace("image: map.pgm", "image: map.pgm\ncolour: blue"),
            "",
        ),
    ];
    for (text, field) in cases {
        assert_ne!(text, good, "{field}");
        std::fs::write(&yaml, &text).unwrap();
        match OccupancyMap::load_ros(&yaml) {
            Err(WorldError::Map {
                field: f, message, ..
            }) => {
                assert!(
                    f == field || message.contains("colour"),
                    "{field}: {f}: {message}"
                )
            }
            other => panic!("{field}: expected a map error, got {:?}", other.map(|_| ())),
        }
    }
    std::fs::write(&yaml, good.replace("map.pgm", "missing.pgm")).unwrap();
    let e = OccupancyMap::load_ros(&yaml).unwrap_err().to_string();
    assert!(e.contains("missing.pgm"), "{e}");
    std::fs::write(&yaml, &good).unwrap();
    std::fs::write(dir.path().join("map.pgm"), b"P5\n2 2\n255\n\x00").unwrap();
    let e = OccupancyMap::load_ros(&yaml).unwrap_err().to_string();
    assert!(e.contains("map.pgm"), "{e}");
}

fn map_scene(dir: &Path, rows: &[String], access: Option<[f64; 2]>) -> ferret_world::Scene {
    let rows: Vec<&str> = rows.iter().map(String::as_str).collect();
    write_map(dir, &rows, 0.1, [0.0, 0.0]);
    let access = access.map_or(String::new(), |a| format!(", access: [{}, {}]", a[0], a[1]));
    let text = format!(
        r#"
ferret_scene: 1
name: walled
map: {{ros: map.yaml}}
rooms:
  - {{name: left, type: LivingRoom, polygon: [[0, 0], [1.5, 0], [1.5, 2], [0, 2]]}}
  - {{name: right, type: Bedroom, polygon: [[1.5, 0], [3, 0], [3, 2], [1.5, 2]]}}
containers:
  - {{id: shelf, type: Shelf, pose: [2.5, 1.7, 0], size: [0.2, 0.2]{access}}}
start: [0.5, 1.7, 0]
"#
    );
    let path = dir.join("scene.yaml");
    std::fs::write(&path, text).unwrap();
    SceneFile::load(&path).unwrap()
}

#[test]
fn a_map_scene_routes_around_the_maps_walls() {
    let dir = tempfile::tempdir().unwrap();
    let scene = map_scene(dir.path(), &walled_rows(), None);
    assert!(scene.house.walls.is_empty(), "the map holds the walls");
    let params = GridParams {
        robot_radius: 0.1,
        ..GridParams::default()
    };
    let (grid, d) = distance::build(&scene.house, &params).unwrap();
    assert!(
        (grid.resolution() - 0.1).abs() < 1e-12,
        "the map's resolution is kept"
    );
    let direct = scene
        .house
        .start
        .position
        .distance(scene.house.containers[0].position);
    let around = d.between(Place::Start, Place::Container(0));
    // The straight line at y = 1.7 passes through the gap above the wall (which covers
    // y < 1.2), so the path is nearly direct; close the gap and the shelf is unreachable.
    assert!(
        around.is_finite() && around < direct + 0.5,
        "{around} vs {direct}"
    );
    let mut closed = walled_rows();
    for row in closed.iter_mut() {
        row.replace_range(15..16, "#");
    }
    let blocked = map_scene(dir.path(), &closed, None);
    assert!(matches!(
        distance::build(&blocked.house, &params),
        Err(WorldError::Unreachable { .. })
    ));
}

#[test]
fn the_wall_in_the_map_makes_the_robot_go_around() {
    let dir = tempfile::tempdir().unwrap();
    // Start low on the left, container low on the right: the wall (image rows 8.., the map's
    // lower 1.2 m) is in between, the gap above it.
    let text_rows = walled_rows();
    let scene = map_scene(dir.path(), &text_rows, None);
    let mut house = scene.house.clone();
    house.start.position = ferret_world::Point::new(0.5, 0.3);
    house.containers[0].footprint.center = ferret_world::Point::new(2.5, 0.3);
    house.containers[0].position = ferret_world::Point::new(2.5, 0.3);
    let params = GridParams {
        robot_radius: 0.1,
        ..GridParams::default()
    };
    let (_, d) = distance::build(&house, &params).unwrap();
    let travelled = d.between(Place::Start, Place::Container(0));
    // Up to the gap above y = 1.2 and back down: at least 2·√(1² + 0.9²) ≈ 2.69 m less the
    // access cell's gap, against 2 m straight across.
    assert!(travelled > 2.45, "{travelled}");
}

#[test]
fn an_access_pose_is_where_the_robot_stands_or_the_container_is_unreachable() {
    let dir = tempfile::tempdir().unwrap();
    let params = GridParams {
        robot_radius: 0.1,
        ..GridParams::default()
    };
    let free = map_scene(dir.path(), &walled_rows(), Some([2.0, 1.0]));
    let (grid, _) = distance::build(&free.house, &params).unwrap();
    let cell = grid.access_cell(0).unwrap();
    let centre = grid.center(cell);
    assert!(
        centre.distance(ferret_world::Point::new(2.0, 1.0)) < 0.08,
        "{centre:?}"
    );
    // Standing inside the wall: no access, reported as unreachable.
    let walled = map_scene(dir.path(), &walled_rows(), Some([1.55, 0.5]));
    assert!(matches!(
        distance::build(&walled.house, &params),
        Err(WorldError::Unreachable { .. })
    ));
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(64))]

    /// Whatever numbers a person types, a scene either loads or fails with a scene error; it
    /// never panics, and a loaded scene's containers are where the file says.
    #[test]
    fn scenes_with_arbitrary_numbers_load_or_fail_cleanly(
        x in -20.0f64..20.0, y in -20.0f64..20.0, yaw in -720.0f64..720.0,
        sx in -1.0f64..3.0, sy in -1.0f64..3.0,
    ) {
        let text = TWO_ROOMS.replace(
            "pose: [7.0, 2.4, 90], size: [2.0, 1.4]",
            &format!("pose: [{x}, {y}, {yaw}], size: [{sx}, {sy}]"),
        );
        match parse(&text) {
            Ok(scene) => {
                let c = &scene.house.containers[1];
                prop_assert!((c.position.x - x).abs() < 1e-9 && (c.position.z - y).abs() < 1e-9);
                prop_assert!(sx > 0.0 && sy > 0.0);
                prop_assert!(scene.house.rooms[c.room.unwrap()].floor.contains(c.position));
                let _ = distance::build(&scene.house, &params());
            }
            Err(WorldError::Scene { field, .. }) => prop_assert!(field.starts_with("containers[1]")),
            Err(e) => prop_assert!(false, "unexpected error {e}"),
        }
    }
}

/// A scene's map reference may point at any file (`map: {ros: .env}`); its contents used to be
/// repeated in the error (`invalid type: string "OPENAI_API_KEY=sk-..."`).
#[test]
fn errors_about_a_referenced_file_never_repeat_its_contents() {
    let dir = tempfile::tempdir().unwrap();
    let secrets = [
        "OPENAI_API_KEY=sk-proj-Zq8xSECRETv1",
        "sk-proj-Zq8xSECRETv1: 1",
        "image: sk-proj-Zq8xSECRETv1\nresolution: sk-proj-Zq8xSECRETv2\norigin: [0, 0, 0]",
        "resolution: 12345678901\nimage: a\norigin: [0, 0, 0]\nnegate: sk-proj-Zq8xSECRETv3",
        "-----BEGIN OPENSSH PRIVATE KEY-----\nb3BlbnNzaC1rZXktdjEAAAAABG5vbmUAAAAEbm9uZQAAAAAAAAAB\n",
    ];
    for (i, text) in secrets.iter().enumerate() {
        std::fs::write(dir.path().join(".env"), text).unwrap();
        let scene = dir.path().join(format!("s{i}.yaml"));
        std::fs::write(
            &scene,
            TWO_ROOMS.replace("rooms:", "map: {ros: .env}\nrooms:"),
        )
        .unwrap();
        let e = SceneFile::load(&scene).unwrap_err().to_string();
        for secret in ["SECRET", "b3BlbnNzaC1", "12345678901", "OPENAI_API_KEY"] {
            assert!(!e.contains(secret), "case {i} repeats the file: {e}");
        }
        assert!(e.contains(".env"), "{e}");
    }
}

/// Overlapping rooms were accepted silently: the floor they share got two room types and a
/// wall was drawn across a room.
#[test]
fn overlapping_rooms_are_refused_and_rooms_sharing_a_wall_are_not() {
    let overlapping = [
        // The bedroom starts 1 m inside the kitchen.
        TWO_ROOMS.replace("[[4, 0], [8, 0], [8, 3], [4, 3]]", "[[3, 0], [8, 0], [8, 3], [3, 3]]"),
        // A closet inside the kitchen, touching none of its walls.
        TWO_ROOMS.replace(
            "  - {name: bedroom",
            "  - {name: closet, type: Closet, polygon: [[1, 1], [2, 1], [2, 2], [1, 2]]}\n  - {name: bedroom",
        ),
        // The same outline twice.
        TWO_ROOMS.replace("[[4, 0], [8, 0], [8, 3], [4, 3]]", "[[0, 0], [4, 0], [4, 3], [0, 3]]"),
        // A room covering both, vertices on neither's outline.
        TWO_ROOMS.replace(
            "  - {name: bedroom",
            "  - {name: hall, type: Hallway, polygon: [[-1, -1], [9, -1], [9, 4], [-1, 4]]}\n  - {name: bedroom",
        ),
    ];
    for text in &overlapping {
        assert_ne!(text, TWO_ROOMS);
        let (field, message) = scene_error(text);
        assert!(
            field.starts_with("rooms[") && field.ends_with("].polygon"),
            "{field}: {message}"
        );
        assert!(message.contains("overlaps rooms[0]"), "{field}: {message}");
    }
    // Sharing a wall, a corner, or part of a wall (an L around a square) is fine, and so is an
    // outline 1 cm off.
    let fine = [
        TWO_ROOMS.to_string(),
        TWO_ROOMS.replace("[[4, 0], [8, 0], [8, 3], [4, 3]]", "[[3.99, 0], [8, 0], [8, 3], [3.99, 3]]"),
        TWO_ROOMS.replace(
            "  - {name: bedroom",
            "  - {name: hall, type: Hallway, polygon: [[4, 3], [6, 3], [6, 5], [4, 5]]}\n  - {name: bedroom",
        ),
    ];
    for text in &fine {
        parse(text).unwrap_or_else(|e| panic!("{e}\n{text}"));
    }
}

/// A moved start is one search on the grid of the first: the same distances, entry for entry,
/// as a grid built afresh with that start, wherever on the reachable floor it is.
#[test]
fn a_moved_start_gives_the_distances_of_a_new_build() {
    let scene = parse(TWO_ROOMS).unwrap();
    let (grid, distances) = distance::build(&scene.house, &params()).unwrap();
    let mut moved_to = 0;
    for x in 0..16 {
        for z in 0..6 {
            let mut house = scene.house.clone();
            house.start.position =
                ferret_world::Point::new(0.25 + 0.5 * f64::from(x), 0.25 + 0.5 * f64::from(z));
            let fresh = distance::build(&house, &params());
            match grid.with_start(&house.name, house.start.position).unwrap() {
                Some(g) => {
                    let (fresh_grid, fresh) = fresh.unwrap();
                    assert_eq!(g.start_cell(), fresh_grid.start_cell());
                    assert_eq!(g.start_moved(), fresh_grid.start_moved());
                    let moved = distances.with_start(&house, &g).unwrap();
                    assert_eq!(moved.matrix(), fresh.matrix(), "{:?}", house.start.position);
                    assert_eq!(
                        moved.path(Place::Start, Place::Container(1)),
                        fresh.path(Place::Start, Place::Container(1))
                    );
                    moved_to += 1;
                }
                // Off the floor the first start reaches: a new build finds the containers
                // unreachable (or the start off the floor), never other distances.
                None => assert!(fresh.is_err(), "{:?}", house.start.position),
            }
        }
    }
    assert!(moved_to > 40, "{moved_to}");
    // Outside the grid: the error a build gives.
    assert!(
        grid.with_start("x", ferret_world::Point::new(-50.0, 0.0))
            .is_err()
    );
}
