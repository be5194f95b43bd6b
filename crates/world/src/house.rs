//! The house model: what the robot knows (`House`) kept apart from what it must discover
//! (`GroundTruth`).
//!
//! Planning code receives a `&House` and so cannot read container contents by accident; only the
//! trial simulator and the oracle are handed the `GroundTruth` of a [`Scene`].

use std::collections::BTreeSet;
use std::fmt;

use serde::{Deserialize, Serialize};

use crate::geometry::{Footprint, Point, Polygon, Rect};

/// An object type in ProcTHOR's CamelCase vocabulary (`Fridge`, `RemoteControl`).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct ObjectType(pub String);

/// Longest room or object type name a file may give: the longest in ProcTHOR is 17 letters.
/// Names travel into prompts, prior files and pages; a 100 KB name is a damaged file.
pub const MAX_TYPE_NAME: usize = 100;

/// Why `name` cannot be a room or object type read from a file, if it cannot: a type is 1 to
/// [`MAX_TYPE_NAME`] letters and digits (CamelCase, `kind` such as `example`).
pub fn type_name_problem(name: &str, kind: &str, example: &str) -> Option<String> {
    let chars = name.chars().count();
    if chars > 0 && chars <= MAX_TYPE_NAME && name.chars().all(char::is_alphanumeric) {
        return None;
    }
    // A long or binary name is shown by its start only.
    let shown: String = name.chars().take(40).collect();
    let more = if chars > 40 { "…" } else { "" };
    Some(format!(
        "{shown:?}{more} ({chars} characters) is not a CamelCase {kind} such as {example}: 1 to {MAX_TYPE_NAME} letters and digits"
    ))
}

impl ObjectType {
    /// An object type from its CamelCase name.
    pub fn new(name: impl Into<String>) -> Self {
        Self(name.into())
    }

    /// The CamelCase name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The name as words for prompts and plots: `RemoteControl` → `remote control`,
    /// `TVStand` → `tv stand`.
    pub fn words(&self) -> String {
        camel_to_words(&self.0)
    }
}

impl fmt::Display for ObjectType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// A room type (`Kitchen`, `LivingRoom`, `Bedroom`, `Bathroom`, ...).
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize)]
#[serde(transparent)]
pub struct RoomType(pub String);

impl RoomType {
    /// A room type from its CamelCase name.
    pub fn new(name: impl Into<String>) -> Self {
        Self(name.into())
    }

    /// The CamelCase name.
    pub fn as_str(&self) -> &str {
        &self.0
    }

    /// The name as words: `LivingRoom` → `living room`.
    pub fn words(&self) -> String {
        camel_to_words(&self.0)
    }
}

impl fmt::Display for RoomType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(&self.0)
    }
}

/// Splits CamelCase into lower-case words, keeping runs of capitals together (`TVStand` → `tv stand`).
fn camel_to_words(s: &str) -> String {
    let chars: Vec<char> = s.chars().collect();
    let mut out = String::with_capacity(s.len() + 4);
    for (i, &c) in chars.iter().enumerate() {
        if i > 0 && c.is_uppercase() {
            let prev = chars[i - 1];
            let next_lower = chars.get(i + 1).is_some_and(|n| n.is_lowercase());
            if prev.is_lowercase() || prev.is_ascii_digit() || (prev.is_uppercase() && next_lower) {
                out.push(' ');
            }
        }
        out.extend(c.to_lowercase());
    }
    out
}

/// A room: its id (`room|4`), type and floor polygon.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Room {
    /// The ProcTHOR id, e.g. `room|4`.
    pub id: String,
    /// The room's type.
    pub room_type: RoomType,
    /// The floor polygon, metres.
    pub floor: Polygon,
}

/// A wall segment on the floor plane. ProcTHOR walls have no thickness; the grid gives them one.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Wall {
    /// The ProcTHOR id, `wall|<room>|x0|z0|x1|z1`.
    pub id: String,
    /// The room the wall belongs to (`room|4`), or `exterior`.
    pub room_id: String,
    /// First endpoint; door offsets are measured from here.
    pub start: Point,
    /// Second endpoint.
    pub end: Point,
}

/// A door: an opening in a wall between two rooms (or a room and the outside).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Door {
    /// The ProcTHOR id.
    pub id: String,
    /// The rooms on either side (`room0`, `room1`); equal for a door to the outside.
    pub rooms: [String; 2],
    /// The wall the door is cut into (`wall0`).
    pub wall: String,
    /// One end of the opening, world coordinates.
    pub start: Point,
    /// The other end of the opening, world coordinates.
    pub end: Point,
}

impl Door {
    /// Width of the opening, metres.
    pub fn width(&self) -> f64 {
        self.start.distance(self.end)
    }
}

/// A container: a top-level piece of furniture that can hold objects. Its contents are not here;
/// they live in the [`GroundTruth`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Container {
    /// The ProcTHOR object id (`4|0|0` or `Fridge|2|0`).
    pub id: String,
    /// The container's type.
    pub object_type: ObjectType,
    /// Index into [`House::rooms`] of the room it stands in, when it stands in one.
    pub room: Option<usize>,
    /// Where it stands.
    pub position: Point,
    /// Its footprint on the floor.
    pub footprint: Footprint,
    /// Where the robot stands to search it, when the scene says so; otherwise the grid picks the
    /// reachable cell nearest to the footprint.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub access: Option<Point>,
}

/// Furniture that is not a container: an obstacle on the map (floor lamps, chairs, ...).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Obstacle {
    /// The ProcTHOR object id.
    pub id: String,
    /// Its type.
    pub object_type: ObjectType,
    /// Index into [`House::rooms`], when it stands in a room.
    pub room: Option<usize>,
    /// Its footprint on the floor.
    pub footprint: Footprint,
}

/// A robot pose: position and heading.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Pose {
    /// Position on the floor.
    pub position: Point,
    /// Heading about the vertical axis, degrees.
    pub yaw_deg: f64,
}

/// What the robot knows of a house before searching: rooms, walls, doors, furniture and containers
/// (but not what they hold), and where it starts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct House {
    /// A label naming where the house came from, e.g. `multiroom-val150.jsonl.gz#3`.
    pub name: String,
    /// The house's index in its file.
    pub index: usize,
    /// Rooms.
    pub rooms: Vec<Room>,
    /// Walls, including exterior ones.
    pub walls: Vec<Wall>,
    /// Doors (windows are not passages and are not kept).
    pub doors: Vec<Door>,
    /// Containers: the robot's search actions.
    pub containers: Vec<Container>,
    /// Other furniture.
    pub obstacles: Vec<Obstacle>,
    /// The robot's start pose.
    pub start: Pose,
    /// A robot's occupancy map, when the house came from a scene with one: the grid is then
    /// built from the map's cells instead of the walls.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub map: Option<std::sync::Arc<crate::map::OccupancyMap>>,
}

impl House {
    /// The bounding rectangle of all rooms; `None` for a house without rooms.
    pub fn bounds(&self) -> Option<Rect> {
        Rect::around(
            self.rooms
                .iter()
                .flat_map(|r| r.floor.vertices.iter().copied()),
        )
    }

    /// Index of the room containing `p`, if any.
    pub fn room_at(&self, p: Point) -> Option<usize> {
        self.rooms.iter().position(|r| r.floor.contains(p))
    }

    /// The room a container stands in, if any.
    pub fn container_room(&self, container: usize) -> Option<&Room> {
        self.containers
            .get(container)
            .and_then(|c| c.room)
            .and_then(|r| self.rooms.get(r))
    }

    /// Index of the container with this id.
    pub fn container_index(&self, id: &str) -> Option<usize> {
        self.containers.iter().position(|c| c.id == id)
    }

    /// A human name for a container: `Fridge (4|1) in the kitchen`.
    pub fn container_label(&self, container: usize) -> String {
        match self.containers.get(container) {
            None => format!("container #{container}"),
            Some(c) => match self.container_room(container) {
                Some(room) => format!(
                    "{} ({}) in the {}",
                    c.object_type,
                    c.id,
                    room.room_type.words()
                ),
                None => format!("{} ({})", c.object_type, c.id),
            },
        }
    }
}

/// A small object inside or on a container.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct SmallObject {
    /// The ProcTHOR object id.
    pub id: String,
    /// Its type.
    pub object_type: ObjectType,
}

/// What the containers of a house really hold. Only the trial simulator and the oracle may look.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct GroundTruth {
    contents: Vec<Vec<SmallObject>>,
}

impl GroundTruth {
    /// Ground truth from the contents of each container, in [`House::containers`] order.
    pub fn new(contents: Vec<Vec<SmallObject>>) -> Self {
        Self { contents }
    }

    /// What container `container` holds (empty for an unknown index).
    pub fn contents(&self, container: usize) -> &[SmallObject] {
        self.contents.get(container).map_or(&[], Vec::as_slice)
    }

    /// True when the container holds an object of type `target`.
    pub fn holds(&self, container: usize, target: &ObjectType) -> bool {
        self.contents(container)
            .iter()
            .any(|o| &o.object_type == target)
    }

    /// The goal containers for `target`: every container holding one.
    pub fn goal_containers(&self, target: &ObjectType) -> Vec<usize> {
        (0..self.contents.len())
            .filter(|&c| self.holds(c, target))
            .collect()
    }

    /// Every small-object type found in some container, sorted.
    pub fn target_types(&self) -> BTreeSet<ObjectType> {
        self.contents
            .iter()
            .flatten()
            .map(|o| o.object_type.clone())
            .collect()
    }

    /// Number of small objects in all containers.
    pub fn object_count(&self) -> usize {
        self.contents.iter().map(Vec::len).sum()
    }

    /// Number of containers described.
    pub fn container_count(&self) -> usize {
        self.contents.len()
    }
}

/// A house together with its ground truth: what a loader or the generator produces.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Scene {
    /// What the robot knows.
    pub house: House,
    /// What the containers hold.
    pub truth: GroundTruth,
}

impl Scene {
    /// The scene with only what is counted of it: the types of its rooms and containers, which
    /// room each container stands in, and the types of what each holds. Walls, doors, other
    /// furniture, floor outlines and object ids are dropped, so that training on tens of
    /// thousands of houses holds a fraction of their geometry in memory. Not a scene to plan on.
    #[must_use]
    pub fn into_types_only(mut self) -> Scene {
        let h = &mut self.house;
        h.walls = Vec::new();
        h.doors = Vec::new();
        h.obstacles = Vec::new();
        h.map = None;
        for room in &mut h.rooms {
            room.floor.vertices = Vec::new();
        }
        h.rooms.shrink_to_fit();
        h.containers.shrink_to_fit();
        for held in &mut self.truth.contents {
            for object in held.iter_mut() {
                object.id = String::new();
            }
            held.shrink_to_fit();
        }
        self
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn camel_case_becomes_words() {
        assert_eq!(ObjectType::new("RemoteControl").words(), "remote control");
        assert_eq!(ObjectType::new("TVStand").words(), "tv stand");
        assert_eq!(ObjectType::new("CD").words(), "cd");
        assert_eq!(RoomType::new("LivingRoom").words(), "living room");
    }

    #[test]
    fn goal_containers_lists_every_holder() {
        let o = |t: &str| SmallObject {
            id: t.into(),
            object_type: ObjectType::new(t),
        };
        let truth = GroundTruth::new(vec![vec![o("Egg")], vec![], vec![o("Egg"), o("Apple")]]);
        assert_eq!(truth.goal_containers(&ObjectType::new("Egg")), vec![0, 2]);
        assert!(truth.goal_containers(&ObjectType::new("Book")).is_empty());
        assert_eq!(truth.target_types().len(), 2);
        assert_eq!(truth.object_count(), 3);
    }
}
