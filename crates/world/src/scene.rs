//! Scene files: a home described by the person who owns the robot, in YAML or JSON.
//!
//! ```yaml
//! ferret_scene: 1                # format version
//! name: apartment
//! map: {ros: map.yaml}           # optional: a map_server map, relative to this file
//! rooms:
//!   - {name: kitchen, type: Kitchen, polygon: [[0, 0], [4, 0], [4, 3], [0, 3]]}
//! doors:                         # optional; openings in the walls drawn from the polygons
//!   - {from: [4, 1], to: [4, 2]}
//! containers:
//!   - id: fridge
//!     type: Fridge
//!     room: kitchen              # optional: else the room whose polygon holds the pose
//!     pose: [0.4, 2.5, 90]       # x, y metres; yaw degrees counter-clockwise (ROS)
//!     size: [0.8, 0.7]           # optional footprint along its own x and y, default 0.5 × 0.5
//!     access: [0.9, 2.5]         # optional: where the robot stands to search it
//!     contents: [Egg, Apple]     # optional: what it holds, for simulated robots only
//! obstacles: []                  # optional: furniture that is not searched
//! start: [2, 1.5, 0]             # the robot's usual start pose
//! ```
//!
//! Coordinates are the robot's map frame: x and y in metres (ferret's x and z). Without a map the
//! grid is drawn from the room polygons, with a wall along every polygon edge and openings where
//! doors are; with a map, the map decides what is free and the polygons only name the rooms.

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use serde::{Deserialize, Serialize};

use crate::error::{Result, WorldError};
use crate::geometry::{Footprint, Point, Polygon};
use crate::house::{
    Container, Door, GroundTruth, House, ObjectType, Obstacle, Pose, Room, RoomType, Scene,
    SmallObject, Wall,
};
use crate::map::OccupancyMap;

/// The scene format version this build reads and writes.
pub const SCENE_VERSION: u32 = 1;

/// How deep (metres) two rooms' polygons may run into each other before the scene is refused:
/// hand-drawn outlines of neighbouring rooms are rarely exact to the centimetre.
pub const ROOM_OVERLAP_TOLERANCE: f64 = 0.02;

/// Footprint used when a container or obstacle gives no `size`, metres.
pub const DEFAULT_SIZE: [f64; 2] = [0.5, 0.5];

/// A scene file as written.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    /// Format version; must be [`SCENE_VERSION`].
    pub ferret_scene: u32,
    /// The scene's name.
    pub name: String,
    /// An occupancy map to navigate on instead of the polygons' walls.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map: Option<MapRef>,
    /// Rooms.
    pub rooms: Vec<RoomSpec>,
    /// Doors: openings in the polygon walls (ignored with a map, which shows them itself).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub doors: Vec<DoorSpec>,
    /// Containers: what the robot searches.
    pub containers: Vec<ContainerSpec>,
    /// Furniture that is not searched.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub obstacles: Vec<ObstacleSpec>,
    /// The robot's start pose `[x, y, yaw°]`.
    pub start: [f64; 3],
}

/// Where the map comes from.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct MapRef {
    /// A `map_server` YAML file, relative to the scene file.
    pub ros: PathBuf,
}

/// A room.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RoomSpec {
    /// Its name, unique in the scene (`kitchen`, `bedroom 2`).
    pub name: String,
    /// Its type in ProcTHOR's CamelCase (`Kitchen`, `LivingRoom`, `Bedroom`, `Bathroom`,
    /// `DiningRoom`, ...).
    #[serde(rename = "type")]
    pub room_type: String,
    /// The floor outline `[[x, y], ...]`, at least three vertices.
    pub polygon: Vec<[f64; 2]>,
}

/// A door: an opening between `from` and `to` on a wall.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DoorSpec {
    /// One end of the opening.
    pub from: [f64; 2],
    /// The other end.
    pub to: [f64; 2],
}

/// A container.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ContainerSpec {
    /// Its id, unique in the scene.
    pub id: String,
    /// Its object type in CamelCase (`Fridge`, `Dresser`, `Sofa`).
    #[serde(rename = "type")]
    pub object_type: String,
    /// The room it stands in; by default the room whose polygon holds its pose.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub room: Option<String>,
    /// Centre and heading `[x, y, yaw°]` (yaw counter-clockwise, as in ROS).
    pub pose: [f64; 3],
    /// Footprint `[along its x, along its y]`, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size: Option<[f64; 2]>,
    /// Where the robot stands to search it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub access: Option<[f64; 2]>,
    /// Object types inside, for simulated robots; a real robot reports what it sees instead.
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub contents: Vec<String>,
}

/// Furniture that is not searched.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ObstacleSpec {
    /// Its id.
    pub id: String,
    /// Its object type.
    #[serde(rename = "type")]
    pub object_type: String,
    /// Centre and heading `[x, y, yaw°]`.
    pub pose: [f64; 3],
    /// Footprint, metres.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub size: Option<[f64; 2]>,
}

/// True when `path` looks like a scene file: `.yaml`/`.yml`, or JSON whose top level has a
/// `ferret_scene` field.
pub fn is_scene_file(path: &Path) -> bool {
    match path.extension().and_then(|e| e.to_str()) {
        Some("yaml" | "yml") => true,
        Some("json") => crate::input::read_file(path, crate::procthor::MAX_LINE_BYTES as u64)
            .ok()
            .and_then(|b| serde_json::from_slice::<serde_json::Value>(&b).ok())
            .is_some_and(|v| v.get("ferret_scene").is_some()),
        _ => false,
    }
}

impl SceneFile {
    /// Parses a scene from YAML or JSON text (JSON is YAML); `file` names it in errors.
    ///
    /// # Errors
    /// [`WorldError::Scene`] with the field path for text that does not fit the format.
    pub fn parse(text: &str, file: &Path) -> Result<SceneFile> {
        if text.len() > crate::procthor::MAX_LINE_BYTES {
            return Err(WorldError::Scene {
                file: file.to_path_buf(),
                field: String::new(),
                message: format!("larger than {} bytes", crate::procthor::MAX_LINE_BYTES),
            });
        }
        crate::input::check_yaml(text).map_err(|message| WorldError::Scene {
            file: file.to_path_buf(),
            field: String::new(),
            message,
        })?;
        let de = serde_yaml_ng::Deserializer::from_str(text);
        let scene: SceneFile = serde_path_to_error::deserialize(de).map_err(|e| {
            let field = e.path().to_string();
            WorldError::Scene {
                file: file.to_path_buf(),
                field: if field == "." { String::new() } else { field },
                message: e.into_inner().to_string(),
            }
        })?;
        if scene.ferret_scene != SCENE_VERSION {
            return Err(WorldError::Scene {
                file: file.to_path_buf(),
                field: "ferret_scene".into(),
                message: format!(
                    "version {} is not supported (this build reads version {SCENE_VERSION})",
                    scene.ferret_scene
                ),
            });
        }
        Ok(scene)
    }

    /// Reads a scene file and, when it names one, its map.
    ///
    /// # Errors
    /// I/O errors, [`WorldError::Scene`] and [`WorldError::Map`].
    pub fn load(path: &Path) -> Result<Scene> {
        let text = crate::input::read_text(path, crate::procthor::MAX_LINE_BYTES as u64).map_err(
            |source| WorldError::Io {
                file: path.to_path_buf(),
                source,
            },
        )?;
        let file = SceneFile::parse(&text, path)?;
        let map = match &file.map {
            Some(m) => {
                let yaml = if m.ros.is_absolute() {
                    m.ros.clone()
                } else {
                    path.parent().unwrap_or(Path::new(".")).join(&m.ros)
                };
                Some(Arc::new(OccupancyMap::load_ros(&yaml)?))
            }
            None => None,
        };
        file.to_scene(path, map)
    }

    /// The scene as ferret's house (named as the scene) and ground truth. `file` names the scene
    /// in errors; `map` is the loaded map when the scene names one.
    ///
    /// # Errors
    /// [`WorldError::Scene`] naming the field: duplicate or empty ids, polygons with fewer than
    /// three vertices, non-finite or negative numbers, unknown rooms, containers in no room, a
    /// start outside every room and off the map.
    pub fn to_scene(&self, file: &Path, map: Option<Arc<OccupancyMap>>) -> Result<Scene> {
        let err = |field: String, message: String| WorldError::Scene {
            file: file.to_path_buf(),
            field,
            message,
        };
        let finite = |field: String, v: &[f64]| -> Result<()> {
            if v.iter()
                .all(|x| x.is_finite() && x.abs() <= crate::procthor::MAX_COORDINATE)
            {
                Ok(())
            } else {
                Err(err(
                    field,
                    format!(
                        "must be finite numbers within ±{}",
                        crate::procthor::MAX_COORDINATE
                    ),
                ))
            }
        };
        if self.name.trim().is_empty() {
            return Err(err("name".into(), "is empty".into()));
        }
        if self.map.is_some() != map.is_some() {
            return Err(err(
                "map".into(),
                "the scene names a map that was not loaded".into(),
            ));
        }
        if self.rooms.is_empty() {
            return Err(err(
                "rooms".into(),
                "a scene needs at least one room".into(),
            ));
        }
        if self.containers.is_empty() {
            return Err(err(
                "containers".into(),
                "a scene needs at least one container".into(),
            ));
        }
        if self.containers.len() > crate::distance::MAX_CONTAINERS {
            return Err(err(
                "containers".into(),
                format!(
                    "{} containers; at most {}",
                    self.containers.len(),
                    crate::distance::MAX_CONTAINERS
                ),
            ));
        }
        let mut rooms = Vec::with_capacity(self.rooms.len());
        let mut room_index = BTreeMap::new();
        for (i, r) in self.rooms.iter().enumerate() {
            let at = |f: &str| format!("rooms[{i}].{f}");
            if r.name.trim().is_empty() {
                return Err(err(at("name"), "is empty".into()));
            }
            if room_index.insert(r.name.clone(), i).is_some() {
                return Err(err(
                    at("name"),
                    format!("{:?} is used by an earlier room", r.name),
                ));
            }
            if let Some(problem) =
                crate::house::type_name_problem(&r.room_type, "room type", "LivingRoom")
            {
                return Err(err(at("type"), problem));
            }
            if r.polygon.len() < 3 {
                return Err(err(
                    at("polygon"),
                    format!("{} vertices; a room needs at least 3", r.polygon.len()),
                ));
            }
            finite(at("polygon"), &r.polygon.concat())?;
            let floor = Polygon::new(r.polygon.iter().map(|p| Point::new(p[0], p[1])).collect());
            if floor.area() <= 0.0 {
                return Err(err(at("polygon"), "encloses no area".into()));
            }
            rooms.push(Room {
                id: r.name.clone(),
                room_type: RoomType::new(r.room_type.clone()),
                floor,
            });
        }
        // Rooms drawn over each other would give one floor two room types and draw walls across
        // a room; rooms that only share walls are fine.
        for (i, r) in rooms.iter().enumerate() {
            if let Some(j) = rooms[..i]
                .iter()
                .position(|earlier| earlier.floor.overlaps(&r.floor, ROOM_OVERLAP_TOLERANCE))
            {
                return Err(err(
                    format!("rooms[{i}].polygon"),
                    format!(
                        "overlaps rooms[{j}] ({:?}); rooms may share walls but not floor",
                        rooms[j].id
                    ),
                ));
            }
        }
        let room_at = |p: Point| rooms.iter().position(|r| r.floor.contains(p));
        // Without a map, a wall runs along every polygon edge; rooms sharing an edge both draw it.
        let walls: Vec<Wall> = if map.is_none() {
            rooms
                .iter()
                .flat_map(|r| {
                    let v = &r.floor.vertices;
                    (0..v.len()).map(move |k| Wall {
                        id: format!("{}|wall|{k}", r.id),
                        room_id: r.id.clone(),
                        start: v[k],
                        end: v[(k + 1) % v.len()],
                    })
                })
                .collect()
        } else {
            Vec::new()
        };
        let mut doors = Vec::with_capacity(self.doors.len());
        for (i, d) in self.doors.iter().enumerate() {
            finite(format!("doors[{i}]"), &[d.from, d.to].concat())?;
            let (a, b) = (
                Point::new(d.from[0], d.from[1]),
                Point::new(d.to[0], d.to[1]),
            );
            if a.distance(b) <= 0.0 {
                return Err(err(
                    format!("doors[{i}]"),
                    "from and to are the same point".into(),
                ));
            }
            // The rooms on either side, for drawing and listing; a door to the outside has one.
            let mid = Point::new((a.x + b.x) / 2.0, (a.z + b.z) / 2.0);
            let (nx, nz) = ((b.z - a.z) / a.distance(b), -(b.x - a.x) / a.distance(b));
            let side = |s: f64| room_at(Point::new(mid.x + s * 0.2 * nx, mid.z + s * 0.2 * nz));
            let name = |r: Option<usize>| r.map(|r| rooms[r].id.clone()).unwrap_or_default();
            let wall = walls
                .iter()
                .find(|w| on_segment(w.start, w.end, mid))
                .map(|w| w.id.clone());
            if map.is_none() && wall.is_none() {
                return Err(err(
                    format!("doors[{i}]"),
                    "lies on no room's edge; a door is an opening in a wall".into(),
                ));
            }
            doors.push(Door {
                id: format!("door|{i}"),
                rooms: [name(side(1.0)), name(side(-1.0))],
                wall: wall.unwrap_or_default(),
                start: a,
                end: b,
            });
        }
        let mut ids = BTreeSet::new();
        let mut containers = Vec::with_capacity(self.containers.len());
        let mut contents = Vec::with_capacity(self.containers.len());
        for (i, c) in self.containers.iter().enumerate() {
            let at = |f: &str| format!("containers[{i}].{f}");
            check_object(&c.id, &c.object_type, &mut ids).map_err(|(f, m)| err(at(f), m))?;
            finite(at("pose"), &c.pose)?;
            let footprint = footprint(c.pose, c.size).map_err(|m| err(at("size"), m))?;
            let position = footprint.center;
            let room = match &c.room {
                Some(name) => Some(*room_index.get(name).ok_or_else(|| {
                    err(
                        at("room"),
                        format!("{name:?} is not one of the scene's rooms"),
                    )
                })?),
                None => Some(room_at(position).ok_or_else(|| {
                    err(
                        at("pose"),
                        format!(
                            "({}, {}) is in no room's polygon; give `room`",
                            c.pose[0], c.pose[1]
                        ),
                    )
                })?),
            };
            let access = match c.access {
                Some(p) => {
                    finite(at("access"), &p)?;
                    Some(Point::new(p[0], p[1]))
                }
                None => None,
            };
            let mut held = Vec::with_capacity(c.contents.len());
            for (k, t) in c.contents.iter().enumerate() {
                if let Some(problem) =
                    crate::house::type_name_problem(t, "object type", "CellPhone")
                {
                    return Err(err(format!("containers[{i}].contents[{k}]"), problem));
                }
                held.push(SmallObject {
                    id: format!("{}|{t}|{k}", c.id),
                    object_type: ObjectType::new(t.clone()),
                });
            }
            contents.push(held);
            containers.push(Container {
                id: c.id.clone(),
                object_type: ObjectType::new(c.object_type.clone()),
                room,
                position,
                footprint,
                access,
            });
        }
        let mut obstacles = Vec::with_capacity(self.obstacles.len());
        for (i, o) in self.obstacles.iter().enumerate() {
            let at = |f: &str| format!("obstacles[{i}].{f}");
            check_object(&o.id, &o.object_type, &mut ids).map_err(|(f, m)| err(at(f), m))?;
            finite(at("pose"), &o.pose)?;
            let footprint = footprint(o.pose, o.size).map_err(|m| err(at("size"), m))?;
            obstacles.push(Obstacle {
                id: o.id.clone(),
                object_type: ObjectType::new(o.object_type.clone()),
                room: room_at(footprint.center),
                footprint,
            });
        }
        finite("start".into(), &self.start)?;
        let start = Point::new(self.start[0], self.start[1]);
        let on_map = map.as_ref().is_some_and(|m| m.cell_at(start).is_some());
        if room_at(start).is_none() && !on_map {
            return Err(err(
                "start".into(),
                format!(
                    "({}, {}) is in no room and not on the map",
                    start.x, start.z
                ),
            ));
        }
        let house = House {
            name: self.name.clone(),
            index: 0,
            rooms,
            walls,
            doors,
            containers,
            obstacles,
            start: Pose {
                position: start,
                yaw_deg: heading_from_ros(self.start[2]),
            },
            map,
        };
        Ok(Scene {
            house,
            truth: GroundTruth::new(contents),
        })
    }
}

fn check_object(
    id: &str,
    object_type: &str,
    ids: &mut BTreeSet<String>,
) -> std::result::Result<(), (&'static str, String)> {
    if id.trim().is_empty() {
        return Err(("id", "is empty".into()));
    }
    if !ids.insert(id.to_string()) {
        return Err((
            "id",
            format!("{id:?} is used by an earlier container or obstacle"),
        ));
    }
    if let Some(problem) = crate::house::type_name_problem(object_type, "object type", "Dresser") {
        return Err(("type", problem));
    }
    Ok(())
}

/// The footprint of a pose and size; the scene's counter-clockwise yaw becomes ferret's
/// clockwise one (see [`Footprint::corners`]).
fn footprint(pose: [f64; 3], size: Option<[f64; 2]>) -> std::result::Result<Footprint, String> {
    let [sx, sz] = size.unwrap_or(DEFAULT_SIZE);
    let max = crate::procthor::MAX_COORDINATE;
    if !(sx.is_finite() && sz.is_finite() && sx > 0.0 && sz > 0.0 && sx <= max && sz <= max) {
        return Err(format!(
            "[{sx}, {sz}] must be two positive sizes in metres, at most {max}"
        ));
    }
    Ok(Footprint {
        center: Point::new(pose[0], pose[1]),
        size_x: sx,
        size_z: sz,
        yaw_deg: -pose[2],
    })
}

/// A robot heading in ferret's (ProcTHOR's) convention, degrees clockwise from +z, from a map
/// frame yaw, degrees counter-clockwise from +x.
pub fn heading_from_ros(yaw_deg: f64) -> f64 {
    90.0 - yaw_deg
}

/// The map-frame yaw of a ferret heading (the inverse of [`heading_from_ros`]).
pub fn heading_to_ros(heading_deg: f64) -> f64 {
    90.0 - heading_deg
}

/// True when `p` lies on segment `a`–`b` (within 1 cm).
fn on_segment(a: Point, b: Point, p: Point) -> bool {
    let len = a.distance(b);
    if len <= 0.0 {
        return false;
    }
    let (ux, uz) = ((b.x - a.x) / len, (b.z - a.z) / len);
    let (px, pz) = (p.x - a.x, p.z - a.z);
    let along = px * ux + pz * uz;
    let across = (px * uz - pz * ux).abs();
    across <= 0.01 && (-0.01..=len + 0.01).contains(&along)
}
