//! Reading ProcTHOR house files and turning each house into a validated [`Scene`].

use std::collections::{HashMap, VecDeque};
use std::io::{self, BufRead, BufReader, Read};
use std::path::Path;

use flate2::read::MultiGzDecoder;
use rayon::prelude::*;

use super::assets::AssetDatabase;
use super::range::HouseRange;
use super::schema::{RawDoor, RawHouse, RawObject, RawWall, Vec3};
use super::types::{
    default_footprint_size, is_container_type, is_searchable_content, is_wall_mounted,
    object_type_for_asset,
};
use crate::error::{HouseLocation, Result, WorldError};
use crate::geometry::{Footprint, Point, Polygon, segment_distance};
use crate::house::{
    Container, Door, GroundTruth, House, ObjectType, Obstacle, Pose, Room, RoomType, Scene,
    SmallObject, Wall, type_name_problem,
};
use crate::rules::ContainerSet;

/// Coordinates beyond this many metres from the origin are rejected: no house is kilometres
/// across, and such numbers would make the occupancy grid absurdly large.
pub const MAX_COORDINATE: f64 = 1000.0;

/// How far (metres) an object's centre may lie outside every room polygon and still be placed in
/// the nearest room: furniture pushed against a wall can have its centre a few centimetres past
/// the floor edge after rounding.
pub const ROOM_TOLERANCE: f64 = 0.3;

/// How far (metres) the robot's start may lie outside every room: about one grid cell, for a
/// start exactly on a floor edge.
pub const START_TOLERANCE: f64 = 0.05;

/// Rooms smaller than this (m²) are degenerate.
const MIN_ROOM_AREA: f64 = 0.01;

/// Longest line (one house) of a JSON Lines file, and largest single-house file, in bytes
/// (64 MiB; the largest house of ProcTHOR-10k is under 1 MiB). Lines are read through a bounded
/// reader, so a file without newlines (`/dev/zero`) or a gzip bomb fails with
/// [`WorldError::Limit`] instead of exhausting memory.
pub const MAX_LINE_BYTES: usize = 64 << 20;

/// Most containers one house may hold: the distance matrix grows with their square (2 000
/// containers take 32 MB; ProcTHOR houses have a few dozen).
pub const MAX_CONTAINERS: usize = crate::distance::MAX_CONTAINERS;

/// Slack (metres) for a door hole reaching past the ends of its wall through rounding.
const HOLE_SLACK: f64 = 0.02;

/// How to load houses.
#[derive(Clone, Copy, Debug, Default)]
pub struct LoadOptions<'a> {
    /// The generator's asset database, for object types and footprints; `None` uses our own
    /// mapping ([`object_type_for_asset`]) and sizes ([`default_footprint_size`]).
    pub asset_db: Option<&'a AssetDatabase>,
    /// Which houses of the file.
    pub range: HouseRange,
    /// Put invalid houses into [`LoadReport::skipped`] and go on, instead of failing on the first.
    pub skip_invalid: bool,
    /// Which top-level objects are containers.
    pub containers: ContainerSet,
    /// `Some((i, n))` keeps only the houses whose index is `i` modulo `n` (one shard of a
    /// sharded evaluation): the others inside the range are skipped without being parsed, as
    /// lines outside the range are, so that every shard does not pay for parsing every house.
    pub shard: Option<(usize, usize)>,
}

/// What [`load_scenes`] read.
#[derive(Debug, Default)]
pub struct LoadReport {
    /// The valid houses, in file order.
    pub scenes: Vec<Scene>,
    /// Why each invalid house was skipped (only with [`LoadOptions::skip_invalid`]), in file order.
    pub skipped: Vec<WorldError>,
}

/// Loads the houses of a ProcTHOR file: `.json` (one house, possibly pretty-printed), `.jsonl`
/// (one house per line) or either gzip-compressed (`.jsonl.gz`; compression is recognised by
/// content). House `i` is line `i` (0-based); blank lines hold no house but keep their index.
///
/// Everything a [`HouseReader`] yields, collected: lines are decompressed in order and only those
/// inside `opts.range` (and `opts.shard`) are parsed, in parallel.
/// A range reaching outside the file is a [`WorldError::Range`]; an unreadable file is a
/// [`WorldError::Io`]; a file holding no house at all (empty, or blank lines only) is
/// [`WorldError::NoHouses`]; a line longer than [`MAX_LINE_BYTES`] is [`WorldError::Limit`]. An
/// invalid house (including one with more than [`MAX_CONTAINERS`] containers) is returned as the
/// error (the first in file order) unless `opts.skip_invalid` is set.
pub fn load_scenes(path: &Path, opts: &LoadOptions<'_>) -> Result<LoadReport> {
    let mut report = LoadReport::default();
    for item in HouseReader::open(path, opts)? {
        match item? {
            HouseItem::Scene(scene) => report.scenes.push(*scene),
            HouseItem::Skipped(e) => report.skipped.push(e),
        }
    }
    Ok(report)
}

/// One house as a [`HouseReader`] yields it.
#[derive(Debug)]
pub enum HouseItem {
    /// A valid house.
    Scene(Box<Scene>),
    /// Why an invalid house was skipped (only with [`LoadOptions::skip_invalid`]).
    Skipped(WorldError),
}

/// Lines parsed at once, in parallel, per worker thread: enough to keep every thread busy
/// without holding more than a few houses' text per thread.
const PARSE_AHEAD_PER_THREAD: usize = 4;

/// The houses of a ProcTHOR file, read a few at a time in file order: what [`load_scenes`]
/// returns, without holding more than a handful of houses at once. Honours every
/// [`LoadOptions`] field as [`load_scenes`] does.
///
/// Yields each valid house, and with [`LoadOptions::skip_invalid`] each invalid one as
/// [`HouseItem::Skipped`]. Errors are yielded once, after which the reader ends: an error of the
/// whole file ([`WorldError::Io`], [`WorldError::Limit`] for a too long line,
/// [`WorldError::NoHouses`], [`WorldError::Range`]) when it is found, and without
/// `skip_invalid` the first invalid house, at the end of the range: the rest of the range is read
/// (not parsed) first, so that an error of the whole file takes precedence as in
/// [`load_scenes`]. The houses before it have been yielded by then.
pub struct HouseReader<'a> {
    path: std::path::PathBuf,
    opts: LoadOptions<'a>,
    source: Source,
    parsed: VecDeque<Result<Scene>>,
    /// The first invalid house without `skip_invalid`, held until the range has been read.
    invalid: Option<WorldError>,
    finished: bool,
}

impl std::fmt::Debug for HouseReader<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("HouseReader")
            .field("path", &self.path)
            .field("range", &self.opts.range)
            .field("shard", &self.opts.shard)
            .field("finished", &self.finished)
            .finish_non_exhaustive()
    }
}

type BoxedRead = Box<dyn BufRead + Send>;

enum Source {
    /// A single-house file, not yet read.
    Single(Option<BoxedRead>),
    Lines(Lines<BoxedRead>),
}

impl<'a> HouseReader<'a> {
    /// Opens `path` (see [`load_scenes`] for the formats).
    ///
    /// # Errors
    /// [`WorldError::Io`] when the file cannot be opened or read.
    pub fn open(path: &Path, opts: &LoadOptions<'a>) -> Result<Self> {
        let io_err = |source| WorldError::Io {
            file: path.to_path_buf(),
            source,
        };
        let mut file = BufReader::new(crate::input::open_file(path).map_err(io_err)?);
        let gzip = file.fill_buf().map_err(io_err)?.starts_with(&[0x1f, 0x8b]);
        let reader: BoxedRead = if gzip {
            Box::new(BufReader::with_capacity(1 << 16, MultiGzDecoder::new(file)))
        } else {
            Box::new(file)
        };
        let source = if is_single_house_file(path) {
            Source::Single(Some(reader))
        } else {
            Source::Lines(Lines {
                reader,
                next: 0,
                range: opts.range,
                shard: opts.shard,
                error: None,
                buf: Vec::new(),
                houses: 0,
                at_end: false,
            })
        };
        Ok(Self {
            path: path.to_path_buf(),
            opts: *opts,
            source,
            parsed: VecDeque::new(),
            invalid: None,
            finished: false,
        })
    }

    fn at(&self, index: usize) -> HouseLocation {
        HouseLocation {
            file: self.path.clone(),
            index,
        }
    }

    fn io_err(&self, source: io::Error) -> WorldError {
        WorldError::Io {
            file: self.path.clone(),
            source,
        }
    }

    /// Reads and parses the next few houses into `parsed`; `Ok(false)` once the file (or the
    /// range) has been read through and checked.
    fn fill(&mut self) -> Result<bool> {
        let parse_ahead = (rayon::current_num_threads() * PARSE_AHEAD_PER_THREAD).max(1);
        let (db, rule) = (self.opts.asset_db, self.opts.containers);
        let total = match &mut self.source {
            Source::Single(reader) => {
                let Some(reader) = reader.take() else {
                    return Ok(false);
                };
                let mut bytes = Vec::new();
                reader
                    .take(MAX_LINE_BYTES as u64 + 1)
                    .read_to_end(&mut bytes)
                    .map_err(|e| self.io_err(e))?;
                if bytes.len() > MAX_LINE_BYTES {
                    return Err(line_too_long(self.at(0)));
                }
                if bytes.iter().all(u8::is_ascii_whitespace) {
                    return Err(WorldError::NoHouses {
                        file: self.path.clone(),
                    });
                }
                self.check_range(1)?;
                if self.opts.range.contains(0) && in_shard(self.opts.shard, 0) {
                    let scene = house_from_bytes(bytes, &self.at(0), db, rule);
                    self.parsed.push_back(scene);
                }
                return Ok(true);
            }
            Source::Lines(lines) => {
                let batch: Vec<(usize, Vec<u8>)> = lines.by_ref().take(parse_ahead).collect();
                if !batch.is_empty() {
                    // Past an invalid house that stops the reading, lines are only read through.
                    if self.invalid.is_none() {
                        let path = &self.path;
                        let scenes: Vec<Result<Scene>> = batch
                            .into_par_iter()
                            .map(|(i, bytes)| {
                                let at = HouseLocation {
                                    file: path.clone(),
                                    index: i,
                                };
                                house_from_bytes(bytes, &at, db, rule)
                            })
                            .collect();
                        self.parsed.extend(scenes);
                    }
                    return Ok(true);
                }
                match lines.error.take() {
                    Some(LineError::Io(source)) => return Err(self.io_err(source)),
                    Some(LineError::TooLong(index)) => return Err(line_too_long(self.at(index))),
                    None => {}
                }
                if lines.at_end && lines.houses == 0 {
                    return Err(WorldError::NoHouses {
                        file: self.path.clone(),
                    });
                }
                lines.next
            }
        };
        self.check_range(total)?;
        Ok(false)
    }

    /// Refuses a range reaching outside a file of `total` houses.
    fn check_range(&self, total: usize) -> Result<()> {
        let range = self.opts.range;
        if range.start >= total || range.end.is_some_and(|e| e > total) {
            return Err(WorldError::Range {
                file: self.path.clone(),
                message: format!(
                    "range {range} reaches outside the file, which holds {total} house(s)"
                ),
            });
        }
        Ok(())
    }
}

impl Iterator for HouseReader<'_> {
    type Item = Result<HouseItem>;

    fn next(&mut self) -> Option<Self::Item> {
        loop {
            if let Some(r) = self.parsed.pop_front() {
                match r {
                    Ok(scene) => return Some(Ok(HouseItem::Scene(Box::new(scene)))),
                    Err(e) if self.opts.skip_invalid => {
                        tracing::warn!("skipping invalid house: {e}");
                        return Some(Ok(HouseItem::Skipped(e)));
                    }
                    Err(e) => {
                        self.invalid = Some(e);
                        self.parsed.clear();
                        continue;
                    }
                }
            }
            if self.finished {
                return None;
            }
            match self.fill() {
                Ok(true) => {}
                Ok(false) => {
                    self.finished = true;
                    return self.invalid.take().map(Err);
                }
                Err(e) => {
                    self.finished = true;
                    self.parsed.clear();
                    return Some(Err(e));
                }
            }
        }
    }
}

/// Whether house `index` belongs to the shard `(i, n)` (every house without one).
fn in_shard(shard: Option<(usize, usize)>, index: usize) -> bool {
    shard.is_none_or(|(i, n)| n == 0 || index % n == i)
}

/// `.json` and `.json.gz` hold one house; everything else is read as JSON Lines.
fn is_single_house_file(path: &Path) -> bool {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default();
    name.ends_with(".json") || name.ends_with(".json.gz")
}

fn line_too_long(at: HouseLocation) -> WorldError {
    WorldError::Limit {
        at,
        message: format!(
            "the line is longer than the limit of {} MiB per house",
            MAX_LINE_BYTES >> 20
        ),
    }
}

/// Why [`Lines`] stopped early.
enum LineError {
    Io(io::Error),
    /// Line (house index) longer than [`MAX_LINE_BYTES`].
    TooLong(usize),
}

/// The lines of a JSON Lines stream inside a range, with their 0-based indices. Stops at the
/// range's end; remembers a read error instead of yielding it, so that lines can be taken a batch
/// at a time.
/// Lines inside the range are buffered up to [`MAX_LINE_BYTES`]; lines outside it are skipped
/// without being buffered.
struct Lines<R> {
    reader: R,
    /// Index of the next line to read; after the end of the file, the number of lines.
    next: usize,
    range: HouseRange,
    shard: Option<(usize, usize)>,
    error: Option<LineError>,
    buf: Vec<u8>,
    /// Non-blank lines seen so far, inside the range or before it.
    houses: usize,
    /// Whether the end of the stream was reached (rather than the end of the range).
    at_end: bool,
}

impl<R: BufRead> Lines<R> {
    /// Consumes one line without keeping it; false at the end of the stream. A skipped line
    /// counts as a house unless it is blank.
    fn skip_line(&mut self) -> io::Result<(bool, bool)> {
        let mut any = false;
        let mut blank = true;
        loop {
            let chunk = self.reader.fill_buf()?;
            if chunk.is_empty() {
                return Ok((any, blank));
            }
            any = true;
            let (used, done) = match chunk.iter().position(|&b| b == b'\n') {
                Some(p) => (p + 1, true),
                None => (chunk.len(), false),
            };
            blank &= chunk[..used].iter().all(u8::is_ascii_whitespace);
            self.reader.consume(used);
            if done {
                return Ok((true, blank));
            }
        }
    }
}

impl<R: BufRead> Iterator for Lines<R> {
    type Item = (usize, Vec<u8>);

    fn next(&mut self) -> Option<Self::Item> {
        // Once stopped, stay stopped: a read error is not retried, and the end stays the end.
        if self.error.is_some() || self.at_end {
            return None;
        }
        loop {
            if self.range.is_past(self.next) {
                return None;
            }
            let index = self.next;
            if !self.range.contains(index) || !in_shard(self.shard, index) {
                match self.skip_line() {
                    Ok((false, _)) => {
                        self.at_end = true;
                        return None;
                    }
                    Ok((true, blank)) => {
                        self.houses += usize::from(!blank);
                        self.next += 1;
                        continue;
                    }
                    Err(e) => {
                        self.error = Some(LineError::Io(e));
                        return None;
                    }
                }
            }
            self.buf.clear();
            let limit = MAX_LINE_BYTES as u64 + 1;
            match (&mut self.reader)
                .take(limit)
                .read_until(b'\n', &mut self.buf)
            {
                Ok(0) => {
                    self.at_end = true;
                    return None;
                }
                Ok(_) => {}
                Err(e) => {
                    self.error = Some(LineError::Io(e));
                    return None;
                }
            }
            let content = self.buf.len() - usize::from(self.buf.ends_with(b"\n"));
            if content > MAX_LINE_BYTES {
                self.error = Some(LineError::TooLong(index));
                return None;
            }
            self.next += 1;
            if !self.buf.iter().all(u8::is_ascii_whitespace) {
                self.houses += 1;
                return Some((index, std::mem::take(&mut self.buf)));
            }
        }
    }
}

fn house_from_bytes(
    bytes: Vec<u8>,
    at: &HouseLocation,
    db: Option<&AssetDatabase>,
    containers: ContainerSet,
) -> Result<Scene> {
    let text = String::from_utf8(bytes).map_err(|e| WorldError::Malformed {
        at: at.clone(),
        message: format!("not UTF-8: {}", e.utf8_error()),
    })?;
    parse_house_with(&text, at, db, containers)
}

/// Parses and validates one house from its JSON text. Malformed JSON and missing fields are
/// [`WorldError::Malformed`] (with the path of the offending field); unusable values are
/// [`WorldError::Invalid`] (see [`scene_from_raw`]).
pub fn parse_house(
    json: &str,
    at: &HouseLocation,
    asset_db: Option<&AssetDatabase>,
) -> Result<Scene> {
    parse_house_with(json, at, asset_db, ContainerSet::Receptacles)
}

/// [`parse_house`] with a choice of container set (see [`scene_from_raw_with`]).
pub fn parse_house_with(
    json: &str,
    at: &HouseLocation,
    asset_db: Option<&AssetDatabase>,
    containers: ContainerSet,
) -> Result<Scene> {
    let raw: RawHouse = match serde_json::from_str(json) {
        Ok(raw) => raw,
        // Parse again, slower, only to say where the problem is.
        Err(plain) => {
            let mut de = serde_json::Deserializer::from_str(json);
            let message = match serde_path_to_error::deserialize::<_, RawHouse>(&mut de) {
                Err(e) if e.path().to_string() != "." => format!("{}: {}", e.path(), e.inner()),
                _ => plain.to_string(),
            };
            return Err(WorldError::Malformed {
                at: at.clone(),
                message,
            });
        }
    };
    scene_from_raw_with(&raw, at, asset_db, containers)
}

/// Converts a parsed house into a [`Scene`], checking everything the rest of ferret relies on:
/// finite coordinates within [`MAX_COORDINATE`], room polygons with at least three vertices and
/// an area, walls with two distinct floor endpoints, doors naming existing rooms and walls with
/// the hole inside the wall, every object and the start inside a room. Failures are
/// [`WorldError::Invalid`] naming the field, e.g. `doors[2].wall0`.
///
/// Object types come from the `objectType` field when present, else from the asset database when
/// given, else from [`object_type_for_asset`]; a top-level object none of them knows is kept as
/// an obstacle of type `Unknown` (with a warning), a child none of them knows is not a content.
/// Top-level objects of container types become
/// [`Container`]s whose searchable children are their contents; wall-mounted ones (paintings)
/// are dropped; the rest become [`Obstacle`]s. Each object's room is the room polygon holding
/// its position (the id's room index breaks ties), or the nearest room within
/// [`ROOM_TOLERANCE`].
pub fn scene_from_raw(
    raw: &RawHouse,
    at: &HouseLocation,
    asset_db: Option<&AssetDatabase>,
) -> Result<Scene> {
    scene_from_raw_with(raw, at, asset_db, ContainerSet::Receptacles)
}

/// [`scene_from_raw`] with a choice of container set. [`ContainerSet::Receptacles`] is
/// [`scene_from_raw`]'s rule. [`ContainerSet::Furniture`] is the reference code's: every
/// top-level object is a container except those of the [`IGNORED_TYPES`] (which stay obstacles),
/// and a container's contents are its direct children whose type is not the type of any
/// top-level object of the house (ignored ones included). Types come from the id when it
/// starts with one (`Fridge|2|1`, as ProcTHOR-10k writes ids), otherwise as
/// [`scene_from_raw`] finds them; ignored types and top-level types are compared in lower case.
pub fn scene_from_raw_with(
    raw: &RawHouse,
    at: &HouseLocation,
    asset_db: Option<&AssetDatabase>,
    rule: ContainerSet,
) -> Result<Scene> {
    let furniture = rule == ContainerSet::Furniture;
    let type_of = |o: &RawObject| {
        if furniture {
            id_type(&o.id).or_else(|| resolve_type(o, asset_db))
        } else {
            resolve_type(o, asset_db)
        }
    };
    // The reference's set of top-level types, for dropping children that are furniture too.
    let top_level: std::collections::HashSet<String> = if furniture {
        raw.objects
            .iter()
            .filter_map(type_of)
            .map(|t| t.as_str().to_lowercase())
            .collect()
    } else {
        Default::default()
    };
    let invalid = |field: String, message: String| WorldError::Invalid {
        at: at.clone(),
        field,
        message,
    };

    // Rooms.
    if raw.rooms.is_empty() {
        return Err(invalid("rooms".into(), "the house has no rooms".into()));
    }
    let mut rooms = Vec::with_capacity(raw.rooms.len());
    let mut room_index: HashMap<&str, usize> = HashMap::with_capacity(raw.rooms.len());
    for (i, r) in raw.rooms.iter().enumerate() {
        if room_index.insert(r.id.as_str(), i).is_some() {
            return Err(invalid(
                format!("rooms[{i}].id"),
                format!("duplicate room id {:?}", r.id),
            ));
        }
        let mut vertices = Vec::with_capacity(r.floor_polygon.len());
        for (j, v) in r.floor_polygon.iter().enumerate() {
            vertices
                .push(point(v).map_err(|m| invalid(format!("rooms[{i}].floorPolygon[{j}]"), m))?);
        }
        let floor = Polygon::new(vertices);
        let field = || format!("rooms[{i}].floorPolygon");
        if floor.vertices.len() < 3 {
            return Err(invalid(
                field(),
                format!("{} vertices; a room needs at least 3", floor.vertices.len()),
            ));
        }
        let area = floor.area();
        if area.is_nan() || area < MIN_ROOM_AREA {
            return Err(invalid(
                field(),
                format!("degenerate polygon of area {area} m²"),
            ));
        }
        if let Some(problem) = type_name_problem(&r.room_type, "room type", "LivingRoom") {
            return Err(invalid(format!("rooms[{i}].roomType"), problem));
        }
        rooms.push(Room {
            id: r.id.clone(),
            room_type: RoomType::new(r.room_type.clone()),
            floor,
        });
    }

    // Walls.
    let mut walls = Vec::with_capacity(raw.walls.len());
    let mut wall_index: HashMap<&str, usize> = HashMap::with_capacity(raw.walls.len());
    for (i, w) in raw.walls.iter().enumerate() {
        if wall_index.insert(w.id.as_str(), i).is_some() {
            return Err(invalid(
                format!("walls[{i}].id"),
                format!("duplicate wall id {:?}", w.id),
            ));
        }
        walls.push(wall(w).map_err(|(f, m)| invalid(format!("walls[{i}].{f}"), m))?);
    }

    // Doors. Windows are not passages and are not converted.
    let mut doors = Vec::with_capacity(raw.doors.len());
    for (i, d) in raw.doors.iter().enumerate() {
        let field = |f: &str| format!("doors[{i}].{f}");
        for (f, room) in [("room0", &d.room0), ("room1", &d.room1)] {
            if !room_index.contains_key(room.as_str()) {
                return Err(invalid(field(f), format!("no room {room:?} in this house")));
            }
        }
        let Some(&w) = wall_index.get(d.wall0.as_str()) else {
            return Err(invalid(
                field("wall0"),
                format!("no wall {:?} in this house", d.wall0),
            ));
        };
        doors.push(door(d, &walls[w]).map_err(|(f, m)| invalid(field(f), m))?);
    }

    // Empty walls (open connections between rooms) stay addressable for doors above but are not
    // obstacles: drawing them would cut rooms apart that the simulator joins.
    let walls: Vec<Wall> = walls
        .into_iter()
        .zip(&raw.walls)
        .filter(|(_, r)| !r.empty)
        .map(|(w, _)| w)
        .collect();

    // Furniture.
    let mut containers = Vec::new();
    let mut contents = Vec::new();
    let mut obstacles = Vec::new();
    let mut object_ids: HashMap<&str, usize> = HashMap::with_capacity(raw.objects.len());
    for (i, o) in raw.objects.iter().enumerate() {
        let field = |f: &str| format!("objects[{i}].{f}");
        if object_ids.insert(o.id.as_str(), i).is_some() {
            return Err(invalid(
                field("id"),
                format!("duplicate object id {:?}", o.id),
            ));
        }
        let position = point(&o.position).map_err(|m| invalid(field("position"), m))?;
        let yaw_deg = o.rotation.y;
        if !yaw_deg.is_finite() {
            return Err(invalid(
                field("rotation.y"),
                format!("{yaw_deg} is not a finite angle"),
            ));
        }
        let object_type = match type_of(o) {
            Some(t) => t,
            None => {
                tracing::warn!(
                    "{at}: objects[{i}]: unknown asset {:?}; kept as an obstacle",
                    o.asset_id
                );
                ObjectType::new("Unknown")
            }
        };
        if let Some(problem) = type_name_problem(object_type.as_str(), "object type", "Fridge") {
            return Err(invalid(field("objectType"), problem));
        }
        if is_wall_mounted(&object_type) {
            continue;
        }
        let hint =
            id_room_hint(&o.id).and_then(|r| room_index.get(format!("room|{r}").as_str()).copied());
        let room = assign_room(&rooms, position, hint, ROOM_TOLERANCE).map_err(|(d, r)| {
            invalid(
                field("position"),
                format!(
                    "({:.3}, {:.3}) is outside every room (nearest, {}, is {d:.2} m away)",
                    position.x, position.z, rooms[r].id
                ),
            )
        })?;
        let (size_x, size_z) = asset_db
            .and_then(|db| db.footprint_size(&o.asset_id))
            .unwrap_or_else(|| default_footprint_size(&object_type));
        let footprint = Footprint {
            center: position,
            size_x,
            size_z,
            yaw_deg,
        };
        let is_container = if furniture {
            !is_ignored_type(&object_type)
        } else {
            is_container_type(&object_type)
        };
        if is_container {
            if containers.len() == MAX_CONTAINERS {
                return Err(WorldError::Limit {
                    at: at.clone(),
                    message: format!(
                        "{}: more than the limit of {MAX_CONTAINERS} containers per house",
                        field("id")
                    ),
                });
            }
            let mut held = Vec::new();
            for (j, c) in o.children.iter().enumerate() {
                let Some(t) = type_of(c) else { continue };
                if let Some(problem) = type_name_problem(t.as_str(), "object type", "CellPhone") {
                    return Err(invalid(
                        field(&format!("children[{j}].objectType")),
                        problem,
                    ));
                }
                let keep = if furniture {
                    !top_level.contains(&t.as_str().to_lowercase())
                } else {
                    is_searchable_content(&t)
                };
                if keep {
                    held.push(SmallObject {
                        id: c.id.clone(),
                        object_type: t,
                    });
                }
            }
            contents.push(held);
            containers.push(Container {
                id: o.id.clone(),
                object_type,
                room: Some(room),
                position,
                footprint,
                access: None,
            });
        } else {
            obstacles.push(Obstacle {
                id: o.id.clone(),
                object_type,
                room: Some(room),
                footprint,
            });
        }
    }

    // The robot's start.
    let agent = &raw.metadata.agent;
    let position =
        point(&agent.position).map_err(|m| invalid("metadata.agent.position".into(), m))?;
    let yaw_deg = agent.rotation.y;
    if !yaw_deg.is_finite() {
        return Err(invalid(
            "metadata.agent.rotation.y".into(),
            format!("{yaw_deg} is not a finite angle"),
        ));
    }
    assign_room(&rooms, position, None, START_TOLERANCE).map_err(|(d, r)| {
        invalid(
            "metadata.agent.position".into(),
            format!(
                "start ({:.3}, {:.3}) is outside every room (nearest, {}, is {d:.2} m away)",
                position.x, position.z, rooms[r].id
            ),
        )
    })?;

    let file_name = at.file.file_name().map_or_else(
        || at.file.display().to_string(),
        |n| n.to_string_lossy().into_owned(),
    );
    let house = House {
        name: format!("{file_name}#{}", at.index),
        index: at.index,
        rooms,
        walls,
        doors,
        containers,
        obstacles,
        start: Pose { position, yaw_deg },
        map: None,
    };
    Ok(Scene {
        house,
        truth: GroundTruth::new(contents),
    })
}

/// The floor point of a ProcTHOR vector, if its x and z are usable.
fn point(v: &Vec3) -> std::result::Result<Point, String> {
    for (axis, value) in [("x", v.x), ("z", v.z)] {
        if !value.is_finite() {
            return Err(format!("{axis} = {value} is not a finite number"));
        }
        if value.abs() > MAX_COORDINATE {
            return Err(format!("{axis} = {value} m is beyond ±{MAX_COORDINATE} m"));
        }
    }
    Ok(Point::new(v.x, v.z))
}

/// A wall from its polygon: the first point is its start (door holes are measured from there),
/// the next point with a different floor position its end. The id (`wall|room|x0|z0|x1|z1`)
/// lists the endpoints smallest first and so does not tell the direction; it is not used.
fn wall(w: &RawWall) -> std::result::Result<Wall, (String, String)> {
    let mut points = Vec::with_capacity(w.polygon.len());
    for (j, v) in w.polygon.iter().enumerate() {
        points.push(point(v).map_err(|m| (format!("polygon[{j}]"), m))?);
    }
    let start = *points
        .first()
        .ok_or_else(|| ("polygon".to_owned(), "no points".to_owned()))?;
    let end = points
        .iter()
        .copied()
        .find(|p| p.distance(start) > 1e-6)
        .ok_or_else(|| {
            (
                "polygon".to_owned(),
                "degenerate wall: all points at one floor position".to_owned(),
            )
        })?;
    let room_id = if w.room_id.is_empty() {
        // Older files leave roomId out; the id's second field names the room.
        w.id.split('|')
            .nth(1)
            .map(|r| format!("room|{r}"))
            .unwrap_or_default()
    } else {
        w.room_id.clone()
    };
    Ok(Wall {
        id: w.id.clone(),
        room_id,
        start,
        end,
    })
}

/// A door's opening in world coordinates: `holePolygon` x is measured along `wall0` from the
/// wall's first endpoint (as the ProcTHOR generator places doors; the hole's y is height and its
/// z unused).
fn door(d: &RawDoor, wall: &Wall) -> std::result::Result<Door, (&'static str, String)> {
    let hole = |m: String| ("holePolygon", m);
    if d.hole_polygon.len() < 2 {
        return Err(hole(format!(
            "{} points; a hole needs 2 corners",
            d.hole_polygon.len()
        )));
    }
    let (a, b) = (d.hole_polygon[0].x, d.hole_polygon[1].x);
    if !a.is_finite() || !b.is_finite() {
        return Err(hole(format!("x = {a}, {b} is not finite")));
    }
    let (lo, hi) = (a.min(b), a.max(b));
    let length = wall.start.distance(wall.end);
    if hi - lo < 1e-3 {
        return Err(hole(format!("zero width ({lo} to {hi} m along the wall)")));
    }
    if lo < -HOLE_SLACK || hi > length + HOLE_SLACK {
        return Err(hole(format!(
            "the hole {lo:.3}..{hi:.3} m reaches past the ends of wall {} ({length:.3} m long)",
            wall.id
        )));
    }
    let (ux, uz) = (
        (wall.end.x - wall.start.x) / length,
        (wall.end.z - wall.start.z) / length,
    );
    let along = |t: f64| {
        let t = t.clamp(0.0, length);
        Point::new(wall.start.x + ux * t, wall.start.z + uz * t)
    };
    Ok(Door {
        id: d.id.clone(),
        rooms: [d.room0.clone(), d.room1.clone()],
        wall: d.wall0.clone(),
        start: along(lo),
        end: along(hi),
    })
}

/// The object types the reference code never treats as containers, in lower case: its ignore
/// list as it takes effect (the list also spells `basketBall`, which never matches a
/// lower-cased type).
pub const IGNORED_TYPES: [&str; 15] = [
    "baseballbat",
    "boots",
    "desklamp",
    "painting",
    "floorlamp",
    "houseplant",
    "roomdecor",
    "showercurtain",
    "showerhead",
    "television",
    "vacuumcleaner",
    "photo",
    "plunger",
    "basketball",
    "box",
];

/// True for a type of [`IGNORED_TYPES`], compared in lower case.
pub fn is_ignored_type(t: &ObjectType) -> bool {
    let lower = t.as_str().to_lowercase();
    IGNORED_TYPES.contains(&lower.as_str())
}

/// The type an id starts with (`Fridge|2|1` → `Fridge`, `Bowl|surface|6|39` → `Bowl`), as
/// ProcTHOR-10k writes ids; `None` for ids of other releases (`4|0|0`, `small|4|5`), whose
/// first field is a number or a lower-case word.
fn id_type(id: &str) -> Option<ObjectType> {
    let first = id.split('|').next()?;
    (first.starts_with(|c: char| c.is_ascii_uppercase())
        && first.chars().all(|c| c.is_ascii_alphanumeric()))
    .then(|| ObjectType::new(first))
}

/// The object type: the `objectType` field, else the asset database, else our own mapping.
fn resolve_type(o: &RawObject, asset_db: Option<&AssetDatabase>) -> Option<ObjectType> {
    if let Some(t) = o.object_type.as_deref().filter(|t| !t.is_empty()) {
        return Some(ObjectType::new(t));
    }
    asset_db
        .and_then(|db| db.object_type(&o.asset_id).cloned())
        .or_else(|| object_type_for_asset(&o.asset_id))
}

/// The room index an object id names: the first field (`4|0|0`), or the second when the first
/// is not a number (`small|4|5`, `Fridge|2|0`).
fn id_room_hint(id: &str) -> Option<usize> {
    let mut fields = id.split('|');
    let first = fields.next()?;
    first.parse().ok().or_else(|| fields.next()?.parse().ok())
}

/// The room holding `p`: among rooms whose polygon contains it, `hint` if it is one, else the
/// first; when none contains it, `hint` if within `tolerance`, else the nearest room within
/// `tolerance`. Otherwise the distance to and index of the nearest room.
fn assign_room(
    rooms: &[Room],
    p: Point,
    hint: Option<usize>,
    tolerance: f64,
) -> std::result::Result<usize, (f64, usize)> {
    let mut first_inside = None;
    for (i, r) in rooms.iter().enumerate() {
        if r.floor.contains(p) {
            if hint == Some(i) {
                return Ok(i);
            }
            first_inside.get_or_insert(i);
        }
    }
    if let Some(i) = first_inside {
        return Ok(i);
    }
    let hint_near = |&h: &usize| {
        rooms
            .get(h)
            .is_some_and(|r| boundary_distance(&r.floor, p) <= tolerance)
    };
    if let Some(h) = hint.filter(hint_near) {
        return Ok(h);
    }
    let (dist, nearest) = rooms
        .iter()
        .enumerate()
        .map(|(i, r)| (boundary_distance(&r.floor, p), i))
        .min_by(|a, b| a.0.total_cmp(&b.0))
        .unwrap_or((f64::INFINITY, 0));
    if dist <= tolerance {
        Ok(nearest)
    } else {
        Err((dist, nearest))
    }
}

/// Distance from `p` to the nearest edge of `poly`.
fn boundary_distance(poly: &Polygon, p: Point) -> f64 {
    let v = &poly.vertices;
    (0..v.len())
        .map(|i| segment_distance(v[i], v[(i + 1) % v.len()], p))
        .fold(f64::INFINITY, f64::min)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn id_room_hints_follow_both_styles() {
        assert_eq!(id_room_hint("4|0|0"), Some(4));
        assert_eq!(id_room_hint("4|1"), Some(4));
        assert_eq!(id_room_hint("small|4|5"), Some(4));
        assert_eq!(id_room_hint("Fridge|2|0"), Some(2));
        assert_eq!(id_room_hint("Fridge"), None);
        assert_eq!(id_room_hint(""), None);
    }

    #[test]
    fn id_types_come_only_from_type_prefixes() {
        assert_eq!(id_type("Fridge|2|1"), Some(ObjectType::new("Fridge")));
        assert_eq!(id_type("Bowl|surface|6|39"), Some(ObjectType::new("Bowl")));
        assert_eq!(id_type("4|0|0"), None);
        assert_eq!(id_type("small|4|5"), None);
        assert_eq!(id_type(""), None);
        assert!(is_ignored_type(&ObjectType::new("BasketBall")));
        assert!(is_ignored_type(&ObjectType::new("HousePlant")));
        assert!(!is_ignored_type(&ObjectType::new("Chair")));
    }

    #[test]
    fn segment_distance_handles_ends_and_points() {
        let (a, b) = (Point::new(0.0, 0.0), Point::new(2.0, 0.0));
        assert!((segment_distance(a, b, Point::new(1.0, 1.0)) - 1.0).abs() < 1e-12);
        assert!((segment_distance(a, b, Point::new(3.0, 0.0)) - 1.0).abs() < 1e-12);
        assert!((segment_distance(a, a, Point::new(0.0, 2.0)) - 2.0).abs() < 1e-12);
    }

    #[test]
    fn single_house_files_are_told_by_name() {
        assert!(is_single_house_file(Path::new("a/house.json")));
        assert!(is_single_house_file(Path::new("house.JSON.gz")));
        assert!(!is_single_house_file(Path::new("houses.jsonl")));
        assert!(!is_single_house_file(Path::new("houses.jsonl.gz")));
    }
}
