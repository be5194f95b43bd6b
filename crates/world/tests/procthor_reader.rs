//! The ProcTHOR reader on small hand-written houses: conversion, both id styles, type
//! resolution, doors, and every kind of bad input.

#[path = "procthor_fixture/mod.rs"]
mod fixture;

use std::io::Write;
use std::path::{Path, PathBuf};

use ferret_world::procthor::{
    AssetDatabase, HouseItem, HouseRange, HouseReader, LoadOptions, load_scenes, parse_house,
    scene_from_raw,
};
use ferret_world::{HouseLocation, ObjectType, Point, Scene, WorldError};
use serde_json::{Value, json};

fn at(index: usize) -> HouseLocation {
    HouseLocation {
        file: PathBuf::from("dir/houses.jsonl.gz"),
        index,
    }
}

fn parse(v: &Value) -> Result<Scene, WorldError> {
    parse_house(&v.to_string(), &at(3), None)
}

fn db() -> AssetDatabase {
    AssetDatabase::parse(fixture::ASSET_DB, Path::new("db.json")).unwrap()
}

fn close(a: Point, b: Point) -> bool {
    a.distance(b) < 1e-9
}

/// The field of an `Invalid` error, or a panic naming what came instead.
fn invalid_field(r: Result<Scene, WorldError>) -> String {
    match r {
        Err(WorldError::Invalid { at: loc, field, .. }) => {
            assert_eq!(loc, at(3));
            field
        }
        other => panic!("expected an Invalid error, got {other:?}"),
    }
}

fn malformed_message(r: Result<Scene, WorldError>) -> String {
    match r {
        Err(WorldError::Malformed { at: loc, message }) => {
            assert_eq!(loc, at(3));
            message
        }
        other => panic!("expected a Malformed error, got {other:?}"),
    }
}

fn types(scene: &Scene) -> Vec<&str> {
    scene
        .house
        .containers
        .iter()
        .map(|c| c.object_type.as_str())
        .collect()
}

#[test]
fn house_a_without_database_uses_our_mapping() {
    let scene = parse(&fixture::house_a()).unwrap();
    let h = &scene.house;
    assert_eq!(h.name, "houses.jsonl.gz#3");
    assert_eq!(h.index, 3);
    assert_eq!(h.rooms.len(), 2);
    assert_eq!(h.rooms[1].room_type.as_str(), "LivingRoom");
    assert_eq!(h.walls.len(), 4);
    assert_eq!(types(&scene), ["Fridge", "CounterTop", "Sofa", "Dresser"]);
    let rooms: Vec<_> = h.containers.iter().map(|c| c.room).collect();
    assert_eq!(rooms, [Some(0), Some(0), Some(1), Some(1)]);
    // The chair and the lamp are obstacles; the painting on the wall is not on the map.
    let obstacles: Vec<_> = h
        .obstacles
        .iter()
        .map(|o| (o.object_type.as_str(), o.room))
        .collect();
    assert_eq!(obstacles, [("Chair", Some(0)), ("FloorLamp", Some(1))]);
    // Contents: searchable children only (the microwave on the counter is not one).
    let contents = |i: usize| -> Vec<&str> {
        scene
            .truth
            .contents(i)
            .iter()
            .map(|o| o.object_type.as_str())
            .collect()
    };
    assert_eq!(contents(0), ["Egg", "Apple"]);
    assert_eq!(contents(1), ["CellPhone"]);
    assert_eq!(contents(2), ["RemoteControl"]);
    assert_eq!(contents(3), ["Book"]);
    assert_eq!(
        scene.truth.goal_containers(&ObjectType::new("CellPhone")),
        [1]
    );
    // Start pose.
    assert!(close(h.start.position, Point::new(2.0, 1.5)));
    assert_eq!(h.start.yaw_deg, 90.0);
    // Default footprints, rotated by rotation.y.
    let fridge = &h.containers[0];
    assert_eq!(fridge.footprint.yaw_deg, 90.0);
    assert_eq!(
        (fridge.footprint.size_x, fridge.footprint.size_z),
        (0.8, 0.75)
    );
    assert!(close(fridge.footprint.center, Point::new(0.5, 0.5)));
    assert!(close(fridge.position, Point::new(0.5, 0.5)));
}

#[test]
fn door_hole_is_measured_from_the_walls_first_endpoint() {
    let scene = parse(&fixture::house_a()).unwrap();
    let doors = &scene.house.doors;
    // One door; the windows (one even naming a missing wall) are not passages.
    assert_eq!(doors.len(), 1);
    let d = &doors[0];
    assert_eq!(d.wall, "wall|1|4.00|0.00|4.00|3.00");
    assert_eq!(d.rooms, ["room|1".to_string(), "room|2".to_string()]);
    // wall0 runs from (4,3) to (4,0): 0.5..1.5 m along it is z = 2.5 .. 1.5.
    assert!(close(d.start, Point::new(4.0, 2.5)), "{d:?}");
    assert!(close(d.end, Point::new(4.0, 1.5)), "{d:?}");
    assert!((d.width() - 1.0).abs() < 1e-9);
    let w = scene.house.walls.iter().find(|w| w.id == d.wall).unwrap();
    assert!(close(w.start, Point::new(4.0, 3.0)) && close(w.end, Point::new(4.0, 0.0)));
    assert_eq!(w.room_id, "room|1");
}

#[test]
fn door_on_a_wall_whose_first_endpoint_is_its_min_corner() {
    let mut h = fixture::house_a();
    h["doors"][0]["wall0"] = json!("wall|2|4.00|0.00|4.00|3.00");
    let scene = parse(&h).unwrap();
    let d = &scene.house.doors[0];
    assert!(close(d.start, Point::new(4.0, 0.5)), "{d:?}");
    assert!(close(d.end, Point::new(4.0, 1.5)), "{d:?}");
}

#[test]
fn reversed_hole_corners_give_the_same_opening() {
    let mut h = fixture::house_a();
    let hole = h["doors"][0]["holePolygon"].as_array_mut().unwrap();
    hole.swap(0, 1);
    let d = parse(&h).unwrap().house.doors[0].clone();
    assert!(
        close(d.start, Point::new(4.0, 2.5)) && close(d.end, Point::new(4.0, 1.5)),
        "{d:?}"
    );
}

#[test]
fn house_b_id_style_and_object_type_fields() {
    let scene = parse(&fixture::house_b()).unwrap();
    let h = &scene.house;
    assert_eq!(types(&scene), ["Fridge", "CounterTop", "Sofa", "Dresser"]);
    assert_eq!(h.containers[0].id, "Fridge|1|0");
    // `Sofa|1|0` names room 1 but stands in room 2: the polygon decides.
    let rooms: Vec<_> = h.containers.iter().map(|c| c.room).collect();
    assert_eq!(rooms, [Some(0), Some(0), Some(1), Some(1)]);
    assert_eq!(h.container_label(2), "Sofa (Sofa|1|0) in the living room");
}

#[test]
fn object_type_field_beats_the_database_which_beats_our_mapping() {
    let db = db();
    // Mystery_1 has objectType Dresser in the house but is a Safe in the database.
    let scene = parse_house(&fixture::house_a().to_string(), &at(3), Some(&db)).unwrap();
    assert_eq!(types(&scene), ["Fridge", "CounterTop", "Sofa", "Dresser"]);
    // Without the field, the database decides.
    let mut h = fixture::house_a();
    h["objects"][5]
        .as_object_mut()
        .unwrap()
        .remove("objectType");
    let scene = parse_house(&h.to_string(), &at(3), Some(&db)).unwrap();
    assert_eq!(types(&scene), ["Fridge", "CounterTop", "Sofa", "Safe"]);
    // Without database and field, Mystery_1 has no type: an obstacle, not a container.
    let scene = parse(&h).unwrap();
    assert_eq!(types(&scene), ["Fridge", "CounterTop", "Sofa"]);
    assert!(
        scene
            .house
            .obstacles
            .iter()
            .any(|o| o.id == "2|1" && o.object_type.as_str() == "Unknown")
    );
}

#[test]
fn database_bounding_boxes_give_footprints() {
    let db = db();
    let scene = parse_house(&fixture::house_a().to_string(), &at(3), Some(&db)).unwrap();
    let h = &scene.house;
    let fridge = &h.containers[0];
    assert_eq!(
        (fridge.footprint.size_x, fridge.footprint.size_z),
        (0.9, 0.7)
    );
    assert_eq!(fridge.footprint.yaw_deg, 90.0);
    // Rotated by 90°, the fridge's 0.9 m width lies along z.
    let corners = fridge.footprint.corners();
    let span_z = corners.iter().map(|p| p.z).fold(f64::MIN, f64::max)
        - corners.iter().map(|p| p.z).fold(f64::MAX, f64::min);
    assert!((span_z - 0.9).abs() < 1e-9, "{span_z}");
    // The dresser keeps its objectType but takes its asset's box.
    assert_eq!(
        (
            h.containers[3].footprint.size_x,
            h.containers[3].footprint.size_z
        ),
        (0.4, 0.45)
    );
    // Assets the database lacks fall back to per-type sizes.
    let sofa = &h.containers[2];
    assert_eq!(
        (sofa.footprint.size_x, sofa.footprint.size_z),
        ferret_world::procthor::types::default_footprint_size(&sofa.object_type)
    );
    assert_ne!((sofa.footprint.size_x, sofa.footprint.size_z), (0.4, 0.45));
    let chair = &h.obstacles[0];
    assert_eq!(
        (chair.footprint.size_x, chair.footprint.size_z),
        (0.45, 0.5)
    );
}

#[test]
fn scene_from_raw_matches_parse_house() {
    let json = fixture::house_a().to_string();
    let raw = serde_json::from_str(&json).unwrap();
    assert_eq!(
        scene_from_raw(&raw, &at(3), None).unwrap(),
        parse(&fixture::house_a()).unwrap()
    );
}

#[test]
fn object_just_outside_a_room_goes_to_the_nearest() {
    let mut h = fixture::house_a();
    h["objects"][6]["position"] = json!({"x": 8.2, "y": 1.0, "z": 2.6});
    let scene = parse(&h).unwrap();
    assert_eq!(scene.house.obstacles[1].room, Some(1));
}

#[test]
fn object_just_outside_prefers_the_room_its_id_names() {
    // 0.22 m outside the kitchen, 0.2 m outside the living room; the id `1|2` names the kitchen.
    let mut h = fixture::house_a();
    h["objects"][2]["position"] = json!({"x": 4.1, "y": 0.4, "z": 3.2});
    let scene = parse(&h).unwrap();
    assert_eq!(scene.house.obstacles[0].id, "1|2");
    assert_eq!(scene.house.obstacles[0].room, Some(0));
    // An id naming no room: the nearest room.
    h["objects"][2]["id"] = json!("chair");
    assert_eq!(parse(&h).unwrap().house.obstacles[0].room, Some(1));
}

#[test]
fn object_outside_every_room_is_an_error() {
    let mut h = fixture::house_a();
    h["objects"][4]["position"] = json!({"x": 9.0, "y": 0.4, "z": 2.5});
    assert_eq!(invalid_field(parse(&h)), "objects[4].position");
}

#[test]
fn start_outside_every_room_is_an_error() {
    let mut h = fixture::house_a();
    h["metadata"]["agent"]["position"] = json!({"x": -1.0, "y": 0.9, "z": 1.0});
    assert_eq!(invalid_field(parse(&h)), "metadata.agent.position");
}

#[test]
fn door_naming_a_missing_wall_or_room_is_an_error() {
    let mut h = fixture::house_a();
    h["doors"][0]["wall0"] = json!("wall|9|0|0|1|1");
    assert_eq!(invalid_field(parse(&h)), "doors[0].wall0");
    let mut h = fixture::house_a();
    h["doors"][0]["room1"] = json!("room|9");
    assert_eq!(invalid_field(parse(&h)), "doors[0].room1");
}

#[test]
fn door_hole_past_the_wall_or_without_width_is_an_error() {
    let mut h = fixture::house_a();
    h["doors"][0]["holePolygon"][1]["x"] = json!(3.5);
    assert_eq!(invalid_field(parse(&h)), "doors[0].holePolygon");
    let mut h = fixture::house_a();
    h["doors"][0]["holePolygon"][1]["x"] = json!(0.5);
    assert_eq!(invalid_field(parse(&h)), "doors[0].holePolygon");
    let mut h = fixture::house_a();
    h["doors"][0]["holePolygon"].as_array_mut().unwrap().pop();
    assert_eq!(invalid_field(parse(&h)), "doors[0].holePolygon");
}

#[test]
fn degenerate_polygons_are_errors() {
    let mut h = fixture::house_a();
    h["rooms"][1]["floorPolygon"]
        .as_array_mut()
        .unwrap()
        .truncate(2);
    assert_eq!(invalid_field(parse(&h)), "rooms[1].floorPolygon");
    // Three collinear vertices: no area.
    let mut h = fixture::house_a();
    h["rooms"][0]["floorPolygon"] = json!([{"x": 0, "z": 0}, {"x": 1, "z": 1}, {"x": 2, "z": 2}]);
    assert_eq!(invalid_field(parse(&h)), "rooms[0].floorPolygon");
    let mut h = fixture::house_a();
    h["walls"][2]["polygon"] = json!([{"x": 4, "z": 0}, {"x": 4, "y": 2.5, "z": 0}]);
    assert_eq!(invalid_field(parse(&h)), "walls[2].polygon");
    let mut h = fixture::house_a();
    h["rooms"] = json!([]);
    assert_eq!(invalid_field(parse(&h)), "rooms");
}

#[test]
fn huge_and_infinite_coordinates_are_errors() {
    let mut h = fixture::house_a();
    h["rooms"][0]["floorPolygon"][2]["x"] = json!(1e300);
    assert_eq!(invalid_field(parse(&h)), "rooms[0].floorPolygon[2]");
    let mut h = fixture::house_a();
    h["objects"][1]["position"]["z"] = json!(-5e6);
    assert_eq!(invalid_field(parse(&h)), "objects[1].position");
    let mut h = fixture::house_a();
    h["walls"][0]["polygon"][1]["z"] = json!(f64::MAX);
    assert_eq!(invalid_field(parse(&h)), "walls[0].polygon[1]");
    // JSON has no NaN or infinity, and serde_json refuses numbers too large for f64 rather than
    // making them infinite: a malformed house, with the path to the number.
    let mut h = fixture::house_a();
    h["objects"][2]["position"]["x"] = json!(2.123456);
    let text = h.to_string().replacen("2.123456", "1e999", 1);
    assert!(text.contains("1e999"));
    let m = malformed_message(parse_house(&text, &at(3), None));
    assert!(
        m.contains("objects[2].position.x") && m.contains("number out of range"),
        "{m}"
    );
    // The raw schema can hold NaN (e.g. from another producer); conversion rejects it.
    let mut raw: ferret_world::procthor::schema::RawHouse =
        serde_json::from_value(fixture::house_a()).unwrap();
    raw.metadata.agent.position.x = f64::NAN;
    match scene_from_raw(&raw, &at(3), None) {
        Err(WorldError::Invalid { field, .. }) => assert_eq!(field, "metadata.agent.position"),
        other => panic!("{other:?}"),
    }
    raw.metadata.agent.position.x = 2.0;
    raw.objects[0].rotation.y = f64::INFINITY;
    match scene_from_raw(&raw, &at(3), None) {
        Err(WorldError::Invalid { field, .. }) => assert_eq!(field, "objects[0].rotation.y"),
        other => panic!("{other:?}"),
    }
}

#[test]
fn malformed_json_and_missing_fields_name_the_place() {
    let text = fixture::house_a().to_string();
    let m = malformed_message(parse_house(&text[..text.len() / 2], &at(3), None));
    assert!(m.contains("EOF") || m.contains("line"), "{m}");
    let m = malformed_message(parse_house("{not json", &at(3), None));
    assert!(!m.is_empty());
    let m = malformed_message(parse_house(&format!("{text} trailing"), &at(3), None));
    assert!(m.contains("trailing"), "{m}");

    let mut h = fixture::house_a();
    h.as_object_mut().unwrap().remove("rooms");
    let m = malformed_message(parse(&h));
    assert!(m.contains("missing field `rooms`"), "{m}");

    let mut h = fixture::house_a();
    h["objects"][1].as_object_mut().unwrap().remove("position");
    let m = malformed_message(parse(&h));
    assert!(m.contains("objects[1]") && m.contains("position"), "{m}");

    let mut h = fixture::house_a();
    h["walls"][3]["polygon"][0]["x"] = json!("four");
    let m = malformed_message(parse(&h));
    assert!(m.contains("walls[3].polygon[0].x"), "{m}");
}

#[test]
fn duplicate_ids_are_errors() {
    let mut h = fixture::house_a();
    h["rooms"][1]["id"] = json!("room|1");
    assert_eq!(invalid_field(parse(&h)), "rooms[1].id");
    let mut h = fixture::house_a();
    h["objects"][2]["id"] = json!("1|0");
    assert_eq!(invalid_field(parse(&h)), "objects[2].id");
}

// ---- Files ----

fn line(v: &Value) -> String {
    v.to_string() + "\n"
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).unwrap();
    path
}

fn gzip(bytes: &[u8]) -> Vec<u8> {
    let mut enc = flate2::write::GzEncoder::new(Vec::new(), flate2::Compression::fast());
    enc.write_all(bytes).unwrap();
    enc.finish().unwrap()
}

/// Lines: 0 = house A, 1 = a house whose door names a missing wall, 2 = malformed JSON,
/// 3 = blank, 4 = house B.
fn five_lines() -> String {
    let mut bad = fixture::house_a();
    bad["doors"][0]["wall0"] = json!("wall|nope");
    [
        line(&fixture::house_a()),
        line(&bad),
        "{\"rooms\": [\n".into(),
        "  \n".into(),
        line(&fixture::house_b()),
    ]
    .concat()
}

fn opts(range: &str, skip_invalid: bool) -> LoadOptions<'static> {
    LoadOptions {
        shard: None,
        asset_db: None,
        range: range.parse().unwrap(),
        skip_invalid,
        ..Default::default()
    }
}

#[test]
fn jsonl_with_skip_invalid_reports_and_goes_on() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "h.jsonl", five_lines().as_bytes());
    let report = load_scenes(&path, &opts("..", true)).unwrap();
    let names: Vec<_> = report
        .scenes
        .iter()
        .map(|s| s.house.name.as_str())
        .collect();
    assert_eq!(names, ["h.jsonl#0", "h.jsonl#4"]);
    assert_eq!(report.skipped.len(), 2);
    match &report.skipped[0] {
        WorldError::Invalid { at, field, .. } => {
            assert_eq!((at.index, field.as_str()), (1, "doors[0].wall0"));
            assert_eq!(at.file, path);
        }
        other => panic!("{other:?}"),
    }
    assert!(matches!(&report.skipped[1], WorldError::Malformed { at, .. } if at.index == 2));
    let text = report.skipped[0].to_string();
    assert!(
        text.contains("h.jsonl") && text.contains("house 1") && text.contains("doors[0].wall0"),
        "{text}"
    );
}

#[test]
fn jsonl_without_skip_invalid_returns_the_first_error() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "h.jsonl", five_lines().as_bytes());
    match load_scenes(&path, &opts("..", false)) {
        Err(WorldError::Invalid { at, field, .. }) => {
            assert_eq!((at.index, field.as_str()), (1, "doors[0].wall0"))
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn only_lines_in_the_range_are_parsed() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "h.jsonl", five_lines().as_bytes());
    // Lines 1 and 2 are bad but outside these ranges.
    let r = load_scenes(&path, &opts("4", false)).unwrap();
    assert_eq!(r.scenes.len(), 1);
    assert_eq!(r.scenes[0].house.index, 4);
    assert_eq!(r.scenes[0].house.containers[0].id, "Fridge|1|0");
    let r = load_scenes(&path, &opts("..1", false)).unwrap();
    assert_eq!(r.scenes.len(), 1);
    // The blank line holds no house.
    let r = load_scenes(&path, &opts("3..", false)).unwrap();
    assert_eq!(r.scenes.len(), 1);
    let r = load_scenes(&path, &opts("3", false)).unwrap();
    assert!(r.scenes.is_empty() && r.skipped.is_empty());
}

#[test]
fn ranges_outside_the_file_are_errors() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "h.jsonl", five_lines().as_bytes());
    for r in ["5", "5..", "0..6", "9..12"] {
        match load_scenes(&path, &opts(r, true)) {
            Err(WorldError::Range { file, message }) => {
                assert_eq!(file, path);
                assert!(message.contains("5 house"), "{message}");
            }
            other => panic!("{r}: {other:?}"),
        }
    }
    let empty = write(dir.path(), "empty.jsonl", b"");
    assert!(matches!(
        load_scenes(&empty, &opts("..", true)),
        Err(WorldError::NoHouses { .. })
    ));
}

#[test]
fn gzip_jsonl_and_single_json_files_load() {
    let dir = tempfile::tempdir().unwrap();
    let gz = write(dir.path(), "h.jsonl.gz", &gzip(five_lines().as_bytes()));
    let r = load_scenes(&gz, &opts("..", true)).unwrap();
    assert_eq!((r.scenes.len(), r.skipped.len()), (2, 2));
    assert_eq!(r.scenes[1].house.name, "h.jsonl.gz#4");

    // A single pretty-printed house.
    let pretty = serde_json::to_string_pretty(&fixture::house_a()).unwrap();
    let json = write(dir.path(), "one.json", pretty.as_bytes());
    let r = load_scenes(&json, &LoadOptions::default()).unwrap();
    assert_eq!(r.scenes.len(), 1);
    assert_eq!(r.scenes[0].house.name, "one.json#0");
    assert_eq!(
        r.scenes[0],
        parse_house(
            &pretty,
            &HouseLocation {
                file: json.clone(),
                index: 0
            },
            None
        )
        .unwrap()
    );
    assert!(matches!(
        load_scenes(&json, &opts("1", false)),
        Err(WorldError::Range { .. })
    ));
    let json_gz = write(dir.path(), "one.json.gz", &gzip(pretty.as_bytes()));
    assert_eq!(
        load_scenes(&json_gz, &LoadOptions::default())
            .unwrap()
            .scenes
            .len(),
        1
    );
}

#[test]
fn unreadable_files_are_io_errors() {
    let missing = Path::new("/nonexistent/ferret/h.jsonl");
    assert!(matches!(
        load_scenes(missing, &LoadOptions::default()),
        Err(WorldError::Io { .. })
    ));
    // A corrupt gzip stream is an I/O error of the file, not of a house.
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = gzip(five_lines().as_bytes());
    bytes.truncate(bytes.len() / 2);
    let path = write(dir.path(), "cut.jsonl.gz", &bytes);
    assert!(matches!(
        load_scenes(&path, &opts("..", true)),
        Err(WorldError::Io { .. })
    ));
}

#[test]
fn invalid_utf8_is_a_malformed_house() {
    let dir = tempfile::tempdir().unwrap();
    let mut bytes = line(&fixture::house_a()).into_bytes();
    bytes.extend_from_slice(b"{\"rooms\": \"\xff\xfe\"}\n");
    let path = write(dir.path(), "u.jsonl", &bytes);
    let r = load_scenes(&path, &opts("..", true)).unwrap();
    assert_eq!(r.scenes.len(), 1);
    assert!(
        matches!(&r.skipped[..], [WorldError::Malformed { at, message }] if at.index == 1 && message.contains("UTF-8"))
    );
}

#[test]
fn house_range_default_is_everything() {
    assert_eq!(LoadOptions::default().range, HouseRange::ALL);
}

#[test]
fn empty_walls_are_open_connections_not_obstacles() {
    // ProcTHOR joins some rooms by a wall marked `"empty": true`, which the simulator never builds.
    let mut v = fixture::house_a();
    let walls = v["walls"].as_array().unwrap().len();
    v["walls"][0]["empty"] = json!(true);
    let scene = parse(&v).unwrap();
    assert_eq!(scene.house.walls.len(), walls - 1);
    let gone = v["walls"][0]["id"].as_str().unwrap();
    assert!(scene.house.walls.iter().all(|w| w.id != gone));
    // `"empty": false` is an ordinary wall.
    v["walls"][0]["empty"] = json!(false);
    assert_eq!(parse(&v).unwrap().house.walls.len(), walls);
}

#[test]
fn a_shard_parses_only_its_own_lines() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "h.jsonl", five_lines().as_bytes());
    let all = load_scenes(&path, &opts("..", true)).unwrap();
    for (i, skipped) in [(0, 1), (1, 1)] {
        let o = LoadOptions {
            shard: Some((i, 2)),
            ..opts("..", true)
        };
        let report = load_scenes(&path, &o).unwrap();
        let want: Vec<usize> = all
            .scenes
            .iter()
            .map(|s| s.house.index)
            .filter(|h| h % 2 == i)
            .collect();
        let got: Vec<usize> = report.scenes.iter().map(|s| s.house.index).collect();
        assert_eq!(got, want, "shard {i}/2");
        // Line 1 (an invalid house) is parsed, and reported, by shard 1 only; the broken line 2
        // by shard 0 only.
        assert_eq!(
            report.skipped.len(),
            skipped,
            "shard {i}/2: {:?}",
            report.skipped
        );
    }
}

/// What a reader yields, with each error's message (errors are not comparable).
fn read_all(path: &Path, o: &LoadOptions<'_>) -> Vec<Result<Result<Scene, String>, String>> {
    HouseReader::open(path, o)
        .unwrap()
        .map(|item| match item {
            Ok(HouseItem::Scene(s)) => Ok(Ok(*s)),
            Ok(HouseItem::Skipped(e)) => Ok(Err(e.to_string())),
            Err(e) => Err(e.to_string()),
        })
        .collect()
}

/// Forty copies of the five lines: more than the reader parses at once, so that the order across
/// its batches is checked too.
fn many_lines() -> String {
    five_lines().repeat(40)
}

#[test]
fn the_streaming_reader_yields_what_load_scenes_returns() {
    let dir = tempfile::tempdir().unwrap();
    let text = many_lines();
    let path = write(dir.path(), "h.jsonl", text.as_bytes());
    let gz = write(dir.path(), "h.jsonl.gz", &gzip(text.as_bytes()));
    for path in [&path, &gz] {
        for (range, shard) in [("..", None), ("7..113", None), ("..", Some((1, 3)))] {
            let o = LoadOptions {
                shard,
                ..opts(range, true)
            };
            let report = load_scenes(path, &o).unwrap();
            let streamed = read_all(path, &o);
            let scenes: Vec<&Scene> = streamed
                .iter()
                .filter_map(|r| r.as_ref().ok()?.as_ref().ok())
                .collect();
            let skipped: Vec<&String> = streamed
                .iter()
                .filter_map(|r| r.as_ref().ok()?.as_ref().err())
                .collect();
            assert_eq!(scenes, report.scenes.iter().collect::<Vec<_>>());
            let want: Vec<String> = report.skipped.iter().map(ToString::to_string).collect();
            assert_eq!(skipped, want.iter().collect::<Vec<_>>());
            // Independently of load_scenes: every line's house, in file order, parsed alone.
            let mut expect_scenes = Vec::new();
            let mut expect_skipped = Vec::new();
            // Lines keep their newline, as the reader parses them (it shows in JSON error columns).
            for (i, line) in text.split_inclusive('\n').enumerate() {
                let keep = o.range.contains(i) && shard.is_none_or(|(k, n)| i % n == k);
                if !keep || line.trim().is_empty() {
                    continue;
                }
                let at = HouseLocation {
                    file: path.clone(),
                    index: i,
                };
                match parse_house(line, &at, None) {
                    Ok(s) => expect_scenes.push(s),
                    Err(e) => {
                        let text = e.to_string();
                        assert!(text.contains(&format!("house {i}:")), "{text}");
                        expect_skipped.push(text);
                    }
                }
            }
            assert!(!expect_scenes.is_empty() && !expect_skipped.is_empty());
            assert_eq!(scenes, expect_scenes.iter().collect::<Vec<_>>());
            assert_eq!(skipped, expect_skipped.iter().collect::<Vec<_>>());
            let name = path.file_name().unwrap().to_string_lossy().into_owned();
            assert!(skipped[0].contains(&name), "{}", skipped[0]);
        }
    }
}

#[test]
fn the_streaming_reader_stops_at_the_first_invalid_house_after_its_range() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(dir.path(), "h.jsonl", many_lines().as_bytes());
    // House 0 comes first, then the invalid house 1 ends the reading.
    let got = read_all(&path, &opts("..", false));
    assert_eq!(got.len(), 2, "{got:?}");
    assert!(matches!(&got[0], Ok(Ok(s)) if s.house.index == 0));
    match &got[1] {
        Err(e) => assert!(e.contains("house 1") && e.contains("doors[0].wall0"), "{e}"),
        other => panic!("{other:?}"),
    }
    // A range past the end is the error, as load_scenes says, even after an invalid house.
    let got = read_all(&path, &opts("..900", false));
    match got.last() {
        Some(Err(e)) => assert!(e.contains("reaches outside the file"), "{e}"),
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        load_scenes(&path, &opts("..900", false)),
        Err(WorldError::Range { .. })
    ));
}

/// A room type of 100 KB with control characters was read, counted and written into a prior
/// file: a type name is 1 to 100 letters and digits, and the field is named.
#[test]
fn type_names_that_are_not_short_camel_case_are_errors() {
    let mut h = fixture::house_a();
    h["rooms"][1]["roomType"] = json!(format!("Kitchen\u{7}\n{}", "x".repeat(100_000)));
    let err = parse(&h).unwrap_err().to_string();
    assert!(err.contains("rooms[1].roomType"), "{err}");
    assert!(
        err.contains("100009 characters") && err.len() < 500,
        "{err}"
    );
    let mut h = fixture::house_a();
    h["rooms"][0]["roomType"] = json!("");
    assert_eq!(invalid_field(parse(&h)), "rooms[0].roomType");
    let mut h = fixture::house_a();
    h["objects"][0]["children"][1]["objectType"] = json!("Apple Pie");
    assert_eq!(
        invalid_field(parse(&h)),
        "objects[0].children[1].objectType"
    );
    let mut h = fixture::house_a();
    h["objects"][5]["objectType"] = json!("D".repeat(101));
    assert_eq!(invalid_field(parse(&h)), "objects[5].objectType");
    h["objects"][5]["objectType"] = json!("D".repeat(100));
    assert!(parse(&h).is_ok());
}
