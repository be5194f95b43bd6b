//! Input that holds no houses or would exhaust memory fails with an error naming the file, the
//! house and the limit.

#[path = "procthor_fixture/mod.rs"]
mod fixture;

use std::io::Write;
use std::path::{Path, PathBuf};

use ferret_world::procthor::{LoadOptions, MAX_CONTAINERS, MAX_LINE_BYTES, load_scenes};
use ferret_world::{GridParams, OccupancyGrid, WorldError};
use proptest::prelude::*;
use serde_json::json;

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

fn range(r: &str) -> LoadOptions<'static> {
    LoadOptions {
        shard: None,
        range: r.parse().unwrap(),
        ..LoadOptions::default()
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// Empty files and files of blank lines only used to load as zero houses, so `houses check`
    /// passed them.
    #[test]
    fn files_of_blank_lines_hold_no_houses(
        blank in proptest::collection::vec(prop_oneof![Just(b' '), Just(b'\t'), Just(b'\r'), Just(b'\n')], 0..200),
        compressed in any::<bool>(),
        name in prop_oneof![Just("h.jsonl"), Just("h.json")],
    ) {
        let dir = tempfile::tempdir().unwrap();
        let bytes = if compressed { gzip(&blank) } else { blank.clone() };
        let path = write(dir.path(), name, &bytes);
        match load_scenes(&path, &LoadOptions::default()) {
            Err(WorldError::NoHouses { file }) => prop_assert_eq!(file, path),
            other => prop_assert!(false, "{:?}", other),
        }
    }
}

#[test]
fn a_line_longer_than_the_limit_names_the_house_and_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let house = fixture::house_a().to_string();
    // A line of exactly the limit is read (here: blank, so no house); one byte more is refused.
    let mut text = house.clone().into_bytes();
    text.push(b'\n');
    text.extend(std::iter::repeat_n(b' ', MAX_LINE_BYTES));
    text.push(b'\n');
    text.extend(std::iter::repeat_n(b' ', MAX_LINE_BYTES + 1));
    text.push(b'\n');
    text.extend_from_slice(house.as_bytes());
    text.push(b'\n');
    let path = write(dir.path(), "long.jsonl.gz", &gzip(&text));
    match load_scenes(&path, &LoadOptions::default()) {
        Err(WorldError::Limit { at, message }) => {
            assert_eq!((at.file.as_path(), at.index), (path.as_path(), 2));
            assert!(message.contains("64 MiB"), "{message}");
        }
        other => panic!("{other:?}"),
    }
    // Lines outside the range are skipped, however long.
    let r = load_scenes(&path, &range("3")).unwrap();
    assert_eq!(r.scenes.len(), 1);
    assert_eq!(r.scenes[0].house.index, 3);
    let r = load_scenes(&path, &range("..2")).unwrap();
    assert_eq!(r.scenes.len(), 1);

    // A stream without any newline, like /dev/zero.
    let zeros = write(
        dir.path(),
        "zeros.jsonl.gz",
        &gzip(&vec![0u8; MAX_LINE_BYTES + 10]),
    );
    assert!(matches!(
        load_scenes(&zeros, &LoadOptions::default()),
        Err(WorldError::Limit { at, .. }) if at.index == 0
    ));
    // A single-house file is bounded the same way.
    let big = write(
        dir.path(),
        "big.json.gz",
        &gzip(&vec![b' '; MAX_LINE_BYTES + 1]),
    );
    assert!(matches!(
        load_scenes(&big, &LoadOptions::default()),
        Err(WorldError::Limit { at, .. }) if at.index == 0
    ));
}

/// A house with `n` fridges in its first room (on top of each other: only the count matters).
fn house_with_containers(n: usize) -> serde_json::Value {
    let mut h = fixture::house_a();
    let objects: Vec<serde_json::Value> = (0..n)
        .map(|i| {
            json!({"id": format!("1|{}", 100 + i), "assetId": "Fridge_1", "objectType": "Fridge",
                   "position": {"x": 0.5, "y": 0.9, "z": 0.5}, "rotation": {"x": 0, "y": 0, "z": 0}})
        })
        .collect();
    h["objects"] = json!(objects);
    h
}

#[test]
fn houses_with_too_many_containers_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let ok = house_with_containers(MAX_CONTAINERS).to_string();
    let bad = house_with_containers(MAX_CONTAINERS + 1).to_string();
    let path = write(
        dir.path(),
        "many.jsonl",
        format!("{ok}\n{bad}\n").as_bytes(),
    );
    let r = load_scenes(
        &path,
        &LoadOptions {
            shard: None,
            skip_invalid: true,
            ..LoadOptions::default()
        },
    )
    .unwrap();
    assert_eq!(r.scenes.len(), 1);
    assert_eq!(r.scenes[0].house.containers.len(), MAX_CONTAINERS);
    match &r.skipped[..] {
        [WorldError::Limit { at, message }] => {
            assert_eq!(at.index, 1);
            assert!(message.contains("2000 containers"), "{message}");
            assert!(
                message.contains(&format!("objects[{MAX_CONTAINERS}]")),
                "{message}"
            );
        }
        other => panic!("{other:?}"),
    }
}

#[test]
fn grids_beyond_the_cell_limit_name_the_house_and_the_limit() {
    let dir = tempfile::tempdir().unwrap();
    let path = write(
        dir.path(),
        "h.jsonl",
        format!("{}\n", fixture::house_a()).as_bytes(),
    );
    let scene = load_scenes(&path, &LoadOptions::default())
        .unwrap()
        .scenes
        .remove(0);
    let params = GridParams {
        resolution: GridParams::MIN_RESOLUTION,
        robot_radius: 10.0,
        ..GridParams::default()
    };
    match OccupancyGrid::build(&scene.house, &params) {
        Err(WorldError::Grid { house, message }) => {
            assert_eq!(house, "h.jsonl#0");
            assert!(
                message.contains(&ferret_world::grid::MAX_CELLS.to_string()),
                "{message}"
            );
        }
        other => panic!("{:?}", other.map(|g| g.cell_count())),
    }
}

#[cfg(unix)]
#[test]
fn an_endless_asset_database_is_refused_at_once_and_a_huge_one_at_the_limit() {
    use ferret_world::procthor::AssetDatabase;
    let e = AssetDatabase::load(Path::new("/dev/zero"))
        .unwrap_err()
        .to_string();
    assert!(e.contains("/dev/zero") && e.contains("device"), "{e}");
    let dir = tempfile::tempdir().unwrap();
    let big = dir.path().join("asset-database.json");
    // Sparse: 64 MiB and one byte of zeros without writing them.
    std::fs::File::create(&big)
        .unwrap()
        .set_len(MAX_LINE_BYTES as u64 + 1)
        .unwrap();
    let e = AssetDatabase::load(&big).unwrap_err().to_string();
    assert!(
        e.contains("asset-database.json") && e.contains("64 MiB"),
        "{e}"
    );
}

/// A path to something that is not a regular file, named like an input.
#[cfg(unix)]
fn special(dir: &Path, name: &str, fifo: bool) -> PathBuf {
    let path = dir.join(name);
    if fifo {
        let c = std::ffi::CString::new(path.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
    } else {
        std::os::unix::fs::symlink("/dev/zero", &path).unwrap();
    }
    path
}

/// `/dev/zero` behind a `.json` or `.yaml` name used to be read until memory ran out, and a FIFO
/// blocked forever; both are refused at once, naming the file.
#[cfg(unix)]
#[test]
fn devices_and_fifos_are_refused_at_once_whatever_their_name() {
    use ferret_world::SceneFile;
    let dir = tempfile::tempdir().unwrap();
    for fifo in [false, true] {
        for name in ["z.json", "z.jsonl.gz", "z.yaml"] {
            let path = special(dir.path(), &format!("{fifo}-{name}"), fifo);
            let started = std::time::Instant::now();
            let e = if name.ends_with(".yaml") {
                SceneFile::load(&path).unwrap_err()
            } else {
                assert!(!ferret_world::scene::is_scene_file(&path));
                load_scenes(&path, &LoadOptions::default()).unwrap_err()
            };
            let text = e.to_string();
            assert!(text.contains(path.to_str().unwrap()), "{text}");
            assert!(
                text.contains(if fifo { "FIFO" } else { "device" }),
                "{text}"
            );
            assert!(
                started.elapsed().as_secs() < 2,
                "{name}: {:?}",
                started.elapsed()
            );
        }
    }
}

/// A scene nested 100 000 brackets deep took libyaml 34 s to reject; it is refused before
/// parsing.
#[test]
fn deeply_nested_scenes_are_refused_before_parsing() {
    use ferret_world::SceneFile;
    let text = format!(
        "ferret_scene: 1\nname: x\nrooms: {}{}\n",
        "[".repeat(100_000),
        "]".repeat(100_000)
    );
    let started = std::time::Instant::now();
    let e = SceneFile::parse(&text, Path::new("deep.yaml")).unwrap_err();
    assert!(
        started.elapsed().as_millis() < 500,
        "{:?}",
        started.elapsed()
    );
    assert!(e.to_string().contains("nest more than 64"), "{e}");
}

/// A 110 KB scene whose containers all alias one long contents list expanded to millions of
/// values (500 MB at its peak); the values after alias expansion are counted and refused past
/// the limit, naming the file.
#[test]
fn aliases_are_refused_past_the_node_budget() {
    use ferret_world::SceneFile;
    let mut text = String::from(
        "ferret_scene: 1\nname: aliases\nrooms:\n  - {name: hall, type: LivingRoom, polygon: [[0, 0], [40, 0], [40, 40], [0, 40]]}\nstart: [0.5, 0.5, 0]\ncontainers:\n",
    );
    let books = vec!["Book"; 10_000].join(", ");
    text.push_str(&format!(
        "  - {{id: c0, type: Shelf, pose: [1, 1, 0], contents: &books [{books}]}}\n"
    ));
    for i in 1..150 {
        text.push_str(&format!(
            "  - {{id: c{i}, type: Shelf, pose: [{}, {}, 0], contents: *books}}\n",
            1 + i % 30,
            2 + i / 30
        ));
    }
    assert!(text.len() < 100_000, "{}", text.len());
    let Err(e) = SceneFile::parse(&text, Path::new("aliases.yaml")) else {
        panic!("a scene of 1.5 million values after alias expansion was read");
    };
    let message = e.to_string();
    assert!(message.contains("aliases.yaml"), "{message}");
    assert!(message.contains("aliases"), "{message}");
    // A few aliases within the budget still read.
    let small = "ferret_scene: 1\nname: ok\nrooms:\n  - {name: hall, type: LivingRoom, polygon: [[0, 0], [4, 0], [4, 4], [0, 4]]}\nstart: [0.5, 0.5, 0]\ncontainers:\n  - {id: a, type: Shelf, pose: [1, 1, 0], contents: &c [Book, Pen]}\n  - {id: b, type: Shelf, pose: [3, 3, 0], contents: *c}\n";
    let scene = SceneFile::parse(small, Path::new("ok.yaml")).unwrap();
    assert_eq!(scene.containers.len(), 2);
}
