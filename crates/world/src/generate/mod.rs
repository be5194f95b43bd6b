//! The procedural house generator: the embedded default every command uses when given no houses.
//!
//! [`generate_house`] draws a house in the ProcTHOR schema 1.0.0 ([`RawHouse`]), so generated
//! houses go through exactly the same reader as real ones ([`default_scenes`]) and can be written
//! to the same files ([`write_houses`]). A house has 1–10 rooms of ProcTHOR's four types
//! (kitchen, living room, bedroom, bathroom) with everyday sizes, laid out without overlap by
//! recursive splitting of a rectangle; doors along a spanning tree of the rooms plus a few extra
//! and one front door; containers of types that belong in each room, standing against walls and
//! facing into the room, off the doorways, leaving every door and container reachable; small
//! objects drawn from a commonsense table of our own; and a start pose on free floor.
//!
//! Every house depends only on `(seed, index)`: a ChaCha8 generator seeded with `seed` and set to
//! stream `index`, so house 7 of seed 1 is the same whether 10 or 10 000 houses are generated, in
//! whatever order or thread.
//!
//! ```
//! use ferret_world::generate::{generate_house, GeneratorOptions};
//!
//! let opts = GeneratorOptions::default();
//! let house = generate_house(1, 0, &opts);
//! assert_eq!(house, generate_house(1, 0, &opts));
//! assert!((1..=10).contains(&house.rooms.len()));
//! assert_eq!(house.metadata.schema, "1.0.0");
//! ```

mod commonsense;
mod furnish;
mod layout;

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::Path;

use rand::seq::IndexedRandom;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::error::{HouseLocation, Result, WorldError};
use crate::house::Scene;
use crate::procthor::schema::{
    RawAgent, RawDoor, RawHouse, RawMetadata, RawObject, RawRoom, RawWall, Vec3,
};

use furnish::Placed;
use layout::{Edge, Floorplan, IPoint, metres};

/// The most rooms a generated house has.
pub const MAX_ROOMS: usize = 10;

/// Most houses generated at once, as many as ProcTHOR-10k holds: every count of generated
/// houses (`--generate`, `ferret generate --count`, `generate_houses` in Python) is bounded by
/// it, so that a mistyped count is an error rather than an allocation that fails or takes all
/// memory.
pub const MAX_HOUSES: usize = 10_000;

/// The file name generated scenes carry in their [`HouseLocation`].
pub const GENERATED_FILE: &str = "<generated>";

/// Options of the generator.
#[derive(Clone, Debug, PartialEq)]
pub struct GeneratorOptions {
    /// Fewest rooms per house (at least 1).
    pub min_rooms: usize,
    /// Most rooms per house (at most [`MAX_ROOMS`]); the count is uniform in between.
    pub max_rooms: usize,
    /// Radius (metres) of the robot furniture must leave room for: every door and container of
    /// a generated house is reachable by a robot this wide.
    pub robot_radius: f64,
    /// Scales the average number of small objects per container (1.0: about 2.7).
    pub contents_scale: f64,
}

impl Default for GeneratorOptions {
    fn default() -> Self {
        Self {
            min_rooms: 1,
            max_rooms: MAX_ROOMS,
            robot_radius: 0.15,
            contents_scale: 1.0,
        }
    }
}

impl GeneratorOptions {
    /// The room-count range actually used: both ends clamped to `1..=MAX_ROOMS`, the upper end
    /// no smaller than the lower.
    pub fn room_range(&self) -> (usize, usize) {
        let lo = self.min_rooms.clamp(1, MAX_ROOMS);
        (lo, self.max_rooms.clamp(lo, MAX_ROOMS))
    }

    /// The robot radius actually used: non-finite or negative values become 0.15 m, and it is
    /// capped at 0.3 m, beyond which doors of 0.9 m no longer let it through.
    fn radius(&self) -> f64 {
        if self.robot_radius.is_finite() && self.robot_radius >= 0.0 {
            self.robot_radius.min(0.3)
        } else {
            0.15
        }
    }

    fn scale(&self) -> f64 {
        if self.contents_scale.is_finite() && self.contents_scale >= 0.0 {
            self.contents_scale.min(4.0)
        } else {
            1.0
        }
    }
}

/// The house with index `index` of the sequence `seed`. The same arguments give the same house.
pub fn generate_house(seed: u64, index: usize, opts: &GeneratorOptions) -> RawHouse {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index as u64);
    let (lo, hi) = opts.room_range();
    let n = rng.random_range(lo..=hi);
    let plan = layout::floorplan(n, &mut rng);
    let furnished = furnish::furnish(&plan, opts.radius(), &footprint_size, &mut rng);
    assemble(&plan, &furnished, opts.scale(), &mut rng)
}

/// Refuses a count of houses to generate past [`MAX_HOUSES`].
///
/// # Errors
/// [`WorldError::Range`] naming the limit.
pub fn check_count(count: usize) -> Result<()> {
    if count > MAX_HOUSES {
        return Err(crate::WorldError::Range {
            file: GENERATED_FILE.into(),
            message: format!("{count} houses: at most {MAX_HOUSES} are generated at once"),
        });
    }
    Ok(())
}

/// Houses `0..count` of the sequence `seed`, generated in parallel (callers bound `count` with
/// [`check_count`]).
pub fn generate_houses(count: usize, seed: u64, opts: &GeneratorOptions) -> Vec<RawHouse> {
    (0..count)
        .into_par_iter()
        .map(|i| generate_house(seed, i, opts))
        .collect()
}

/// The embedded default: `count` generated houses (default options) read through the ProcTHOR
/// reader, located in the file [`GENERATED_FILE`].
///
/// # Errors
/// [`WorldError::Range`] for more than [`MAX_HOUSES`]; those of the
/// reader.
pub fn default_scenes(count: usize, seed: u64) -> Result<Vec<Scene>> {
    check_count(count)?;
    generate_houses(count, seed, &GeneratorOptions::default())
        .into_iter()
        .enumerate()
        .map(|(index, raw)| scene_of(&raw, index))
        .collect()
}

/// House `index` of [`default_scenes`]`(_, seed)`, generated alone: the same scene, so that a
/// caller can walk the houses one at a time instead of holding them all.
///
/// # Errors
/// [`WorldError::Range`] for an index past [`MAX_HOUSES`]; those of
/// the reader.
pub fn default_scene(index: usize, seed: u64) -> Result<Scene> {
    check_count(index.saturating_add(1))?;
    scene_of(
        &generate_house(seed, index, &GeneratorOptions::default()),
        index,
    )
}

fn scene_of(raw: &RawHouse, index: usize) -> Result<Scene> {
    let at = HouseLocation {
        file: GENERATED_FILE.into(),
        index,
    };
    crate::procthor::scene_from_raw(raw, &at, None)
}

/// Writes houses as ProcTHOR files, chosen by extension: `.jsonl.gz` (or any `.gz`) gzip JSON
/// Lines, `.jsonl` JSON Lines, `.json` a single house (exactly one must be given).
pub fn write_houses(path: &Path, houses: &[RawHouse]) -> Result<()> {
    let io_err = |source: std::io::Error| WorldError::Io {
        file: path.to_path_buf(),
        source,
    };
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_lowercase())
        .unwrap_or_default();
    let format = if name.ends_with(".gz") {
        Format::GzipLines
    } else if name.ends_with(".jsonl") {
        Format::Lines
    } else if name.ends_with(".json") {
        if houses.len() != 1 {
            return Err(io_err(std::io::Error::new(
                std::io::ErrorKind::InvalidInput,
                format!(
                    "a .json file holds exactly one house, not {}; use .jsonl or .jsonl.gz",
                    houses.len()
                ),
            )));
        }
        Format::Single
    } else {
        return Err(io_err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            "unknown extension: use .jsonl.gz, .jsonl or .json",
        )));
    };
    let file = File::create(path).map_err(io_err)?;
    match format {
        Format::GzipLines => {
            let mut gz =
                flate2::write::GzEncoder::new(BufWriter::new(file), flate2::Compression::default());
            write_lines(&mut gz, houses).map_err(io_err)?;
            gz.finish().and_then(|mut w| w.flush()).map_err(io_err)
        }
        Format::Lines => {
            let mut w = BufWriter::new(file);
            write_lines(&mut w, houses).map_err(io_err)?;
            w.flush().map_err(io_err)
        }
        Format::Single => {
            let mut w = BufWriter::new(file);
            serde_json::to_writer(&mut w, &houses[0])
                .map_err(std::io::Error::other)
                .map_err(io_err)?;
            w.write_all(b"\n").and_then(|()| w.flush()).map_err(io_err)
        }
    }
}

enum Format {
    GzipLines,
    Lines,
    Single,
}

fn write_lines<W: Write>(w: &mut W, houses: &[RawHouse]) -> std::io::Result<()> {
    for house in houses {
        serde_json::to_writer(&mut *w, house).map_err(std::io::Error::other)?;
        w.write_all(b"\n")?;
    }
    Ok(())
}

/// Footprint (size along the object's own x and z, metres) of a container type: the reader's
/// table, so that footprints survive the round trip through a file.
fn footprint_size(object_type: &str) -> (f64, f64) {
    crate::procthor::types::default_footprint_size(&crate::house::ObjectType::new(object_type))
}

/// Metres rounded to the millimetre, for tidy files.
fn mm(v: f64) -> f64 {
    (v * 1000.0).round() / 1000.0
}

fn v3(x: f64, y: f64, z: f64) -> Vec3 {
    Vec3 {
        x: mm(x),
        y: mm(y),
        z: mm(z),
    }
}

/// ProcTHOR's wall id: the endpoints in ascending (x, z) order, two decimals.
fn wall_id(owner: &str, a: IPoint, b: IPoint) -> String {
    let (p, q) = if a <= b { (a, b) } else { (b, a) };
    format!(
        "wall|{owner}|{:.2}|{:.2}|{:.2}|{:.2}",
        metres(p.0),
        metres(p.1),
        metres(q.0),
        metres(q.1)
    )
}

fn wall(owner: &str, room_id: &str, a: IPoint, b: IPoint, height: f64) -> RawWall {
    let (ax, az, bx, bz) = (metres(a.0), metres(a.1), metres(b.0), metres(b.1));
    RawWall {
        id: wall_id(owner, a, b),
        room_id: room_id.to_owned(),
        polygon: vec![
            v3(ax, 0.0, az),
            v3(bx, 0.0, bz),
            v3(ax, height, az),
            v3(bx, height, bz),
        ],
        // Every generated wall is a real wall (not ProcTHOR's `empty` open connection).
        ..RawWall::default()
    }
}

/// `Fridge` → `ferret_fridge`, `TVStand` → `ferret_tv_stand`: asset ids of our own.
fn asset_id(object_type: &str) -> String {
    let words = crate::house::ObjectType::new(object_type).words();
    format!("ferret_{}", words.replace(' ', "_"))
}

/// A Poisson count with the given mean (Knuth's method; means here are small), capped.
fn poisson<R: Rng>(mean: f64, cap: usize, rng: &mut R) -> usize {
    let limit = (-mean).exp();
    let mut p = 1.0;
    let mut k = 0;
    loop {
        p *= rng.random::<f64>();
        if p <= limit || k >= cap {
            return k;
        }
        k += 1;
    }
}

/// Turns a furnished floor plan into a ProcTHOR house.
fn assemble<R: Rng>(
    plan: &Floorplan,
    furnished: &furnish::Furnished,
    scale: f64,
    rng: &mut R,
) -> RawHouse {
    let wall_height = mm(rng.random_range(2.5..3.0));
    let num = |i: usize| (i + 1).to_string();
    let room_id = |i: usize| format!("room|{}", i + 1);

    let rooms: Vec<RawRoom> = plan
        .rooms
        .iter()
        .enumerate()
        .map(|(i, r)| RawRoom {
            id: room_id(i),
            room_type: r.kind.name().to_owned(),
            floor_polygon: r
                .polygon()
                .map(|p| v3(metres(p.0), 0.0, metres(p.1)))
                .collect(),
        })
        .collect();

    let mut walls = Vec::new();
    for (i, r) in plan.rooms.iter().enumerate() {
        for e in &r.edges {
            walls.push(wall(&num(i), &room_id(i), e.a, e.b, wall_height));
        }
    }
    // The outside faces of outer walls, running the other way, as ProcTHOR writes them.
    for (i, r) in plan.rooms.iter().enumerate() {
        for e in r.edges.iter().filter(|e| e.neighbour.is_none()) {
            walls.push(wall("exterior", &room_id(i), e.b, e.a, wall_height));
        }
    }

    let other_wall = |edge: &Edge, room1: Option<usize>| match room1 {
        Some(j) => wall_id(&num(j), edge.a, edge.b),
        None => wall_id("exterior", edge.a, edge.b),
    };
    let doors: Vec<RawDoor> = plan
        .doors
        .iter()
        .map(|d| {
            let edge = &plan.rooms[d.room0].edges[d.edge];
            let id = match d.room1 {
                Some(j) => format!("door|{}|{}", d.room0.min(j) + 1, d.room0.max(j) + 1),
                None => format!("door|exterior|{}", d.room0 + 1),
            };
            RawDoor {
                id,
                room0: room_id(d.room0),
                room1: room_id(d.room1.unwrap_or(d.room0)),
                wall0: wall_id(&num(d.room0), edge.a, edge.b),
                wall1: other_wall(edge, d.room1),
                hole_polygon: vec![
                    v3(metres(d.offset), 0.0, 0.0),
                    v3(metres(d.offset + d.width), 2.1, 0.0),
                ],
                asset_id: format!("ferret_doorway_{}cm", d.width * 5),
            }
        })
        .collect();
    let windows: Vec<RawDoor> = plan
        .windows
        .iter()
        .enumerate()
        .map(|(k, w)| {
            let edge = &plan.rooms[w.room].edges[w.edge];
            RawDoor {
                id: format!("window|{}|{k}", w.room + 1),
                room0: room_id(w.room),
                room1: room_id(w.room),
                wall0: wall_id(&num(w.room), edge.a, edge.b),
                wall1: wall_id("exterior", edge.a, edge.b),
                hole_polygon: vec![
                    v3(metres(w.offset), 0.9, 0.0),
                    v3(
                        metres(w.offset + w.width),
                        2.0_f64.min(wall_height - 0.2),
                        0.0,
                    ),
                ],
                asset_id: format!("ferret_window_{}cm", w.width * 5),
            }
        })
        .collect();

    let mut objects = Vec::new();
    for (i, pieces) in furnished.rooms.iter().enumerate() {
        let kind = plan.rooms[i].kind;
        let mut small = 0usize;
        for (k, piece) in pieces.iter().enumerate() {
            let (height, _) = commonsense::heights(piece.object_type);
            let mut children = Vec::new();
            if piece.object_type == "TVStand" {
                // Furniture on furniture: the reader must not count it as something to find.
                children.push(RawObject {
                    id: format!("{}|{k}|0", i + 1),
                    asset_id: asset_id("Television"),
                    object_type: Some("Television".to_owned()),
                    position: v3(piece.center.0, height + 0.35, piece.center.1),
                    rotation: v3(0.0, piece.yaw, 0.0),
                    kinematic: true,
                    children: Vec::new(),
                });
            }
            children.extend(contents(piece, kind, i, &mut small, scale, rng));
            objects.push(RawObject {
                id: format!("{}|{k}", i + 1),
                asset_id: asset_id(piece.object_type),
                object_type: Some(piece.object_type.to_owned()),
                position: v3(piece.center.0, height / 2.0, piece.center.1),
                rotation: v3(0.0, piece.yaw, 0.0),
                kinematic: true,
                children,
            });
        }
    }

    let ((sx, sz), yaw) = furnished.start;
    RawHouse {
        rooms,
        walls,
        doors,
        windows,
        objects,
        metadata: RawMetadata {
            agent: RawAgent {
                position: v3(sx, 0.95, sz),
                rotation: v3(0.0, yaw, 0.0),
            },
            schema: "1.0.0".to_owned(),
            room_spec_id: Some(format!("ferret-{}-room", plan.rooms.len())),
        },
    }
}

/// The small objects on or in `piece`, numbered on from `*small` within room `room`.
fn contents<R: Rng>(
    piece: &Placed,
    kind: layout::RoomKind,
    room: usize,
    small: &mut usize,
    scale: f64,
    rng: &mut R,
) -> Vec<RawObject> {
    let mut weights = commonsense::object_weights(piece.object_type, kind);
    let mean = commonsense::mean_contents(piece.object_type) * scale;
    if weights.is_empty() || mean <= 0.0 {
        return Vec::new();
    }
    let count = poisson(mean, (2.0 * mean).ceil() as usize + 2, rng);
    let (_, surface) = commonsense::heights(piece.object_type);
    let b = &piece.bx;
    let mut out = Vec::with_capacity(count);
    for _ in 0..count {
        let indices: Vec<usize> = (0..weights.len()).collect();
        let Ok(&pick) = indices.choose_weighted(rng, |&i| weights[i].1) else {
            break;
        };
        let object_type = weights[pick].0;
        // A second one of the same kind in one place is possible but less likely.
        weights[pick].1 *= 0.3;
        let x = b.x0 + (b.x1 - b.x0) * rng.random_range(0.2..0.8);
        let z = b.z0 + (b.z1 - b.z0) * rng.random_range(0.2..0.8);
        out.push(RawObject {
            id: format!("small|{}|{}", room + 1, *small),
            asset_id: asset_id(object_type),
            object_type: Some(object_type.to_owned()),
            position: v3(x, surface + 0.05, z),
            rotation: v3(0.0, piece.yaw, 0.0),
            kinematic: false,
            children: Vec::new(),
        });
        *small += 1;
    }
    out
}
