//! Tests on the real ProcTHOR data. They run only when FERRET_PROCTHOR_DIR names the data
//! directory (the ProcTHOR house files and the generator's databases), and print the figures they measure.

use std::path::{Path, PathBuf};
use std::time::Instant;

use ferret_world::procthor::types::object_type_for_asset;
use ferret_world::procthor::{AssetDatabase, HouseRange, LoadOptions, LoadReport, load_scenes};
use ferret_world::{Point, Scene};

fn data_dir() -> Option<PathBuf> {
    match std::env::var_os("FERRET_PROCTHOR_DIR") {
        Some(d) => Some(PathBuf::from(d)),
        None => {
            println!(
                "skipped: set FERRET_PROCTHOR_DIR to the directory of ProcTHOR house files to run"
            );
            None
        }
    }
}

fn asset_db(dir: &Path) -> AssetDatabase {
    AssetDatabase::load(&dir.join("databases/asset-database.json")).expect("asset database loads")
}

fn load(path: &Path, db: Option<&AssetDatabase>) -> LoadReport {
    let opts = LoadOptions {
        shard: None,
        asset_db: db,
        range: HouseRange::ALL,
        skip_invalid: true,
        ..Default::default()
    };
    let started = Instant::now();
    let report = load_scenes(path, &opts).expect("file loads");
    println!(
        "{}: {} houses in {:.3} s ({} database)",
        path.display(),
        report.scenes.len(),
        started.elapsed().as_secs_f64(),
        if db.is_some() { "with" } else { "without" }
    );
    for e in &report.skipped {
        println!("  invalid: {e}");
    }
    report
}

fn mean(xs: impl Iterator<Item = usize>) -> f64 {
    let v: Vec<usize> = xs.collect();
    v.iter().sum::<usize>() as f64 / v.len().max(1) as f64
}

/// Sanity every real house must pass, beyond what the reader validates.
fn check_scene(s: &Scene) {
    let h = &s.house;
    for (i, c) in h.containers.iter().enumerate() {
        let r = c
            .room
            .unwrap_or_else(|| panic!("{}: container {} has no room", h.name, c.id));
        assert!(
            h.rooms[r].floor.contains(c.position),
            "{}: {}",
            h.name,
            h.container_label(i)
        );
    }
    assert!(
        h.room_at(h.start.position).is_some(),
        "{}: start off the floor",
        h.name
    );
    for d in &h.doors {
        let w = d.width();
        assert!(
            (0.5..=3.0).contains(&w),
            "{}: door {} is {w} m wide",
            h.name,
            d.id
        );
        // A door joins its two rooms: just either side of its middle lies room0 or room1.
        let mid = Point::new((d.start.x + d.end.x) / 2.0, (d.start.z + d.end.z) / 2.0);
        let (ux, uz) = ((d.end.x - d.start.x) / w, (d.end.z - d.start.z) / w);
        for side in [-0.1, 0.1] {
            let p = Point::new(mid.x - uz * side, mid.z + ux * side);
            if let Some(r) = h.room_at(p) {
                assert!(
                    d.rooms.contains(&h.rooms[r].id),
                    "{}: door {} opens into {}",
                    h.name,
                    d.id,
                    h.rooms[r].id
                );
            }
        }
    }
}

#[test]
fn own_mapping_agrees_with_the_asset_database() {
    let Some(dir) = data_dir() else { return };
    let db = asset_db(&dir);
    assert_eq!(db.len(), 1653);
    let mut agree = 0;
    let mut disagreements = Vec::new();
    for (asset, expected) in db.iter() {
        let ours = object_type_for_asset(asset);
        if ours.as_ref() == Some(expected) {
            agree += 1;
        } else {
            disagreements.push(format!("{asset}: database {expected}, ours {ours:?}"));
        }
    }
    let share = agree as f64 / db.len() as f64;
    println!(
        "mapping agreement: {agree}/{} = {:.2} %",
        db.len(),
        100.0 * share
    );
    for d in &disagreements {
        println!("  {d}");
    }
    assert!(share >= 0.98, "agreement {:.2} % < 98 %", 100.0 * share);
}

#[test]
fn multiroom_val150_loads_with_and_without_the_database() {
    let Some(dir) = data_dir() else { return };
    let db = asset_db(&dir);
    let path = dir.join("multiroom-val150.jsonl.gz");
    let with = load(&path, Some(&db));
    let without = load(&path, None);
    for r in [&with, &without] {
        assert_eq!(r.scenes.len(), 150);
        assert!(r.skipped.is_empty());
        r.scenes.iter().for_each(check_scene);
    }
    let containers = mean(with.scenes.iter().map(|s| s.house.containers.len()));
    let objects = mean(with.scenes.iter().map(|s| s.truth.object_count()));
    let obstacles = mean(with.scenes.iter().map(|s| s.house.obstacles.len()));
    let rooms = mean(with.scenes.iter().map(|s| s.house.rooms.len()));
    let doors = mean(with.scenes.iter().map(|s| s.house.doors.len()));
    println!(
        "multiroom-val150 per house: {rooms:.2} rooms, {doors:.2} doors, {containers:.2} containers, \
         {objects:.2} small objects in containers, {obstacles:.2} obstacles"
    );
    assert!(
        (18.0..=26.0).contains(&containers),
        "mean containers {containers}"
    );
    assert!(
        (45.0..=75.0).contains(&objects),
        "mean small objects {objects}"
    );
    // Our own mapping finds the same containers and contents as the database.
    for (a, b) in with.scenes.iter().zip(&without.scenes) {
        assert_eq!(a.house.name, b.house.name);
        let types = |s: &Scene| {
            s.house
                .containers
                .iter()
                .map(|c| c.object_type.clone())
                .collect::<Vec<_>>()
        };
        assert_eq!(types(a), types(b), "{}", a.house.name);
        assert_eq!(a.truth, b.truth, "{}", a.house.name);
    }
    // House 0 as seen in the data: a bedroom with two beds, a fridge in the kitchen.
    let h0 = &with.scenes[0].house;
    assert_eq!(h0.name, "multiroom-val150.jsonl.gz#0");
    assert_eq!(h0.rooms.len(), 4);
    let fridge = h0.container_index("6|1").expect("the fridge 6|1");
    assert_eq!(h0.containers[fridge].object_type.as_str(), "Fridge");
    assert_eq!(
        h0.container_room(fridge).map(|r| r.room_type.as_str()),
        Some("Kitchen")
    );
    // door|4|5 sits on wall|5|8.38|0.00|8.38|6.70, whose polygon runs from z = 6.7 down to 0.
    let door = h0
        .doors
        .iter()
        .find(|d| d.id == "door|4|5")
        .expect("door|4|5");
    assert!((door.start.x - 8.375).abs() < 1e-9 && (door.end.x - 8.375).abs() < 1e-9);
    assert!(
        (door.start.z - (6.7 - 1.7087475753404238)).abs() < 1e-6,
        "{door:?}"
    );
    assert!(
        (door.end.z - (6.7 - 3.700923869667206)).abs() < 1e-6,
        "{door:?}"
    );
}

#[test]
fn a_range_of_multiroom_val150_loads_only_those_houses() {
    let Some(dir) = data_dir() else { return };
    let opts = LoadOptions {
        shard: None,
        range: "140..150".parse().unwrap(),
        ..LoadOptions::default()
    };
    let r = load_scenes(&dir.join("multiroom-val150.jsonl.gz"), &opts).unwrap();
    let indices: Vec<usize> = r.scenes.iter().map(|s| s.house.index).collect();
    assert_eq!(indices, (140..150).collect::<Vec<_>>());
    let opts = LoadOptions {
        shard: None,
        range: "140..151".parse().unwrap(),
        ..LoadOptions::default()
    };
    assert!(load_scenes(&dir.join("multiroom-val150.jsonl.gz"), &opts).is_err());
}

#[test]
fn small_and_one_room_houses_load_with_and_without_the_database() {
    let Some(dir) = data_dir() else { return };
    let db = asset_db(&dir);
    for (file, houses) in [
        ("smallhouse-train1000.jsonl.gz", 1000),
        ("smallhouse-val100.jsonl.gz", 100),
        ("oneroom-train500.jsonl.gz", 500),
        ("oneroom-val100.jsonl.gz", 100),
    ] {
        let path = dir.join(file);
        let with = load(&path, Some(&db));
        let without = load(&path, None);
        for r in [&with, &without] {
            assert_eq!(r.scenes.len(), houses, "{file}");
            assert!(r.skipped.is_empty(), "{file}");
            r.scenes.iter().for_each(check_scene);
        }
        println!(
            "{file} per house: {:.2} containers, {:.2} small objects",
            mean(with.scenes.iter().map(|s| s.house.containers.len())),
            mean(with.scenes.iter().map(|s| s.truth.object_count()))
        );
    }
}
