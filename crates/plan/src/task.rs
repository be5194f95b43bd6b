//! Household tasks: what a robot is asked in one trial. One target and nothing more is the
//! object search of the paper; a task may ask for up to [`MAX_TARGETS`] target types, every one
//! of them ([`Goal::All`]) or any one ([`Goal::Any`]), and that the robot bring what it found to
//! a [`Destination`]. Opening a container reveals all of it, so a target seen while looking
//! for another is found.
//!
//! ```
//! use ferret_plan::{Destination, Goal, Task};
//! use ferret_world::ObjectType;
//!
//! let task: Task = "all:Mug,Apple@start".parse()?;
//! assert_eq!(task.goal(), Goal::All);
//! assert_eq!(task.targets(), [ObjectType::new("Mug"), ObjectType::new("Apple")]);
//! assert_eq!(task.destination(), Some(&Destination::Start));
//! assert_eq!(task.to_string(), "all:Mug,Apple@start");
//! // One target, no destination: the paper's trial.
//! assert!(Task::single(ObjectType::new("Mug")).is_single());
//! assert!("all:Mug,Mug".parse::<Task>().is_err());
//! # Ok::<(), ferret_plan::TaskError>(())
//! ```

use std::fmt;
use std::str::FromStr;

use ferret_world::{Distances, House, ObjectType, Place, Point, Spot};
use serde::{Deserialize, Serialize};

/// Most targets one task may ask for: the task planner's states grow as 2^targets.
pub const MAX_TARGETS: usize = 4;

/// How far from a destination point the robot may stand, metres: a point farther than this from
/// any floor the robot can reach is refused rather than moved somewhere else.
pub const POINT_TOLERANCE_M: f64 = 0.5;

/// Whether every target is wanted or any one of them.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Goal {
    /// Every target ("the keys, the wallet and the phone").
    #[default]
    All,
    /// Any one of them ("a mug or a cup").
    Any,
}

impl Goal {
    /// `all` or `any`.
    pub fn as_str(self) -> &'static str {
        match self {
            Goal::All => "all",
            Goal::Any => "any",
        }
    }
}

impl fmt::Display for Goal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

impl FromStr for Goal {
    type Err = TaskError;

    fn from_str(s: &str) -> Result<Self, TaskError> {
        match s.trim() {
            "all" => Ok(Goal::All),
            "any" => Ok(Goal::Any),
            other => Err(TaskError::new(
                "goal",
                format!("`{other}` is not a goal: expected `all` or `any`"),
            )),
        }
    }
}

/// Where the robot brings what it found, on one house's map.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase", tag = "kind")]
pub enum Destination {
    /// Back where the robot started: "bring it to me".
    Start,
    /// At a container (where the robot stands to search it), by index into the house's
    /// containers.
    Container {
        /// The container's index.
        index: usize,
    },
    /// In a room, at its centre: the reachable cell of the room nearest to the centroid of its
    /// floor.
    Room {
        /// The room's index into the house's rooms.
        index: usize,
    },
    /// At a point of the floor: the reachable cell nearest to it, within
    /// [`POINT_TOLERANCE_M`].
    Point {
        /// World x, metres.
        x: f64,
        /// World z, metres.
        z: f64,
    },
}

impl Destination {
    /// The destination written as a task names it in `house` (`start`, `container:<id>`,
    /// `room:<id>`, `<x>,<z>`).
    pub fn label(&self, house: &House) -> String {
        match self {
            Destination::Start => "start".into(),
            Destination::Container { index } => format!(
                "container:{}",
                house
                    .containers
                    .get(*index)
                    .map_or_else(|| index.to_string(), |c| c.id.clone())
            ),
            Destination::Room { index } => format!(
                "room:{}",
                house
                    .rooms
                    .get(*index)
                    .map_or_else(|| index.to_string(), |r| r.id.clone())
            ),
            Destination::Point { x, z } => format!("{x},{z}"),
        }
    }

    /// Parses a destination as [`label`](Self::label) writes it, container and room ids looked
    /// up in `house`.
    ///
    /// # Errors
    /// [`TaskError`] on field `destination` for an unknown form, id or a point that is not two
    /// finite numbers.
    pub fn parse_in(text: &str, house: &House) -> Result<Self, TaskError> {
        let err = |message: String| TaskError::new("destination", message);
        let text = text.trim();
        if text == "start" {
            return Ok(Destination::Start);
        }
        if let Some(id) = text.strip_prefix("container:") {
            return house
                .container_index(id)
                .map(|index| Destination::Container { index })
                .ok_or_else(|| err(format!("{}: no container `{id}`", house.name)));
        }
        if let Some(id) = text.strip_prefix("room:") {
            return house
                .rooms
                .iter()
                .position(|r| r.id == id)
                .map(|index| Destination::Room { index })
                .ok_or_else(|| err(format!("{}: no room `{id}`", house.name)));
        }
        parse_point(text).ok_or_else(|| {
            err(format!(
                "`{text}` is not a destination: expected `start`, `container:<id>`, `room:<id>` or a point `<x>,<z>` in metres"
            ))
        })
    }

    /// Travel to this destination from the start and from every container of `house` on
    /// `distances`.
    ///
    /// # Errors
    /// [`TaskError`] on field `destination` for a container or room the house does not have, a
    /// point outside the reachable floor, and a room or point on distances that came from no
    /// grid.
    pub fn legs(&self, house: &House, distances: &Distances) -> Result<DestinationLegs, TaskError> {
        let err = |message: String| TaskError::new("destination", message);
        let n = distances.container_count();
        let places = || std::iter::once(Place::Start).chain((0..n).map(Place::Container));
        let to_place = |to: Place| DestinationLegs {
            metres: places().map(|p| distances.between(p, to)).collect(),
            place: Some(to),
            spot: None,
        };
        let spot = |room: Option<usize>, near: Point| -> Result<Spot, TaskError> {
            let grid = distances.grid().ok_or_else(|| {
                err(format!(
                    "{}: a room or point destination needs a map measured on a grid",
                    house.name
                ))
            })?;
            let (cell, off) = grid.nearest_reachable(near, room).ok_or_else(|| {
                err(match room {
                    Some(r) => format!(
                        "{}: the robot can reach no floor of room {}",
                        house.name,
                        house.rooms.get(r).map_or("?", |r| r.id.as_str())
                    ),
                    None => format!("{}: the robot can reach no floor at all", house.name),
                })
            })?;
            if room.is_none() && off > POINT_TOLERANCE_M {
                return Err(err(format!(
                    "{}: ({}, {}) is not on floor the robot can reach (the nearest is {off:.2} m away)",
                    house.name, near.x, near.z
                )));
            }
            distances.spot(house, cell).map_err(|e| err(e.to_string()))
        };
        let at_spot = |s: Spot| DestinationLegs::to_spot(distances, s);
        match *self {
            Destination::Start => Ok(to_place(Place::Start)),
            Destination::Container { index } if index < n => Ok(to_place(Place::Container(index))),
            Destination::Container { index } => Err(err(format!(
                "{}: container {index} does not exist ({n} containers)",
                house.name
            ))),
            Destination::Room { index } => {
                let room = house.rooms.get(index).ok_or_else(|| {
                    err(format!(
                        "{}: room {index} does not exist ({} rooms)",
                        house.name,
                        house.rooms.len()
                    ))
                })?;
                spot(Some(index), room.floor.centroid()).map(at_spot)
            }
            Destination::Point { x, z } => spot(None, Point::new(x, z)).map(at_spot),
        }
    }
}

fn parse_point(text: &str) -> Option<Destination> {
    let text = text.strip_prefix("point:").unwrap_or(text);
    let (x, z) = text.split_once(',')?;
    let (x, z): (f64, f64) = (x.trim().parse().ok()?, z.trim().parse().ok()?);
    (x.is_finite() && z.is_finite()).then_some(Destination::Point { x, z })
}

/// A destination on one map: how far it is from the start and from every container, and where
/// it is for drawing.
#[derive(Clone, Debug, PartialEq)]
pub struct DestinationLegs {
    /// Metres to the destination from the start (0) and every container (`i + 1`).
    metres: Vec<f64>,
    /// The place it is, when it is one (the start, a container).
    place: Option<Place>,
    /// The spot of the floor it is, otherwise.
    spot: Option<Spot>,
}

impl DestinationLegs {
    /// Legs of a destination given as distances, metres, from the start (first) and from every
    /// container: for synthetic maps and tests. `None` unless every entry is finite and ≥ 0.
    pub fn from_metres(metres: Vec<f64>) -> Option<Self> {
        metres
            .iter()
            .all(|d| d.is_finite() && *d >= 0.0)
            .then_some(Self {
                metres,
                place: None,
                spot: None,
            })
    }

    /// Legs to `spot` (a spot of `distances`' floor, see [`Distances::spot`]): a destination
    /// that is no place of this map, such as another robot's start.
    pub fn to_spot(distances: &Distances, spot: Spot) -> Self {
        let n = distances.container_count();
        Self {
            metres: std::iter::once(Place::Start)
                .chain((0..n).map(Place::Container))
                .map(|p| spot.from(p))
                .collect(),
            place: None,
            spot: Some(spot),
        }
    }

    /// Travel from `place` to the destination, metres.
    pub fn from(&self, place: Place) -> f64 {
        let slot = match place {
            Place::Start => 0,
            Place::Container(i) => i + 1,
        };
        self.metres.get(slot).copied().unwrap_or(f64::INFINITY)
    }

    /// The place the destination is, when it is the start or a container.
    pub fn place(&self) -> Option<Place> {
        self.place
    }

    /// Where the robot stands at the destination, when the map came from a grid.
    pub fn point(&self, distances: &Distances) -> Option<Point> {
        match (&self.spot, self.place) {
            (Some(s), _) => Some(s.point()),
            (None, Some(p)) => distances.point(p),
            (None, None) => None,
        }
    }

    /// The way from `from` to the destination as points on the floor, when the map came from a
    /// grid.
    pub fn path(&self, distances: &Distances, from: Place) -> Option<Vec<Point>> {
        match (&self.spot, self.place) {
            (Some(s), _) => distances.path_to_spot(from, s),
            (None, Some(p)) => distances.path(from, p),
            (None, None) => None,
        }
    }
}

/// A task: 1 to [`MAX_TARGETS`] distinct target types, a goal and an optional destination.
/// Its constructors refuse anything else, so planners never see an empty or repeated target.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "TaskFields", into = "TaskFields")]
pub struct Task {
    targets: Vec<ObjectType>,
    goal: Goal,
    destination: Option<Destination>,
}

/// The serialized fields of a [`Task`], checked on the way in.
#[derive(Clone, Debug, Serialize, Deserialize)]
struct TaskFields {
    targets: Vec<ObjectType>,
    #[serde(default)]
    goal: Goal,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    destination: Option<Destination>,
}

impl TryFrom<TaskFields> for Task {
    type Error = TaskError;
    fn try_from(f: TaskFields) -> Result<Self, TaskError> {
        Task::new(f.targets, f.goal, f.destination)
    }
}

impl From<Task> for TaskFields {
    fn from(t: Task) -> Self {
        TaskFields {
            targets: t.targets,
            goal: t.goal,
            destination: t.destination,
        }
    }
}

impl Task {
    /// One target, no destination: the paper's object search.
    pub fn single(target: ObjectType) -> Self {
        Self {
            targets: vec![target],
            goal: Goal::All,
            destination: None,
        }
    }

    /// A task of `targets` (in the order given) under `goal`, brought to `destination`.
    ///
    /// # Errors
    /// [`TaskError`] on field `targets` when there are none, more than [`MAX_TARGETS`], an empty
    /// name or the same type twice.
    pub fn new(
        targets: Vec<ObjectType>,
        goal: Goal,
        destination: Option<Destination>,
    ) -> Result<Self, TaskError> {
        let err = |message: String| TaskError::new("targets", message);
        if targets.is_empty() {
            return Err(err("a task needs at least one target".into()));
        }
        if targets.len() > MAX_TARGETS {
            return Err(err(format!(
                "{} targets: a task asks for at most {MAX_TARGETS}",
                targets.len()
            )));
        }
        if targets.iter().any(|t| t.as_str().trim().is_empty()) {
            return Err(err("a target's name is empty".into()));
        }
        for (i, t) in targets.iter().enumerate() {
            if targets[..i].contains(t) {
                return Err(err(format!("{t} is asked for twice")));
            }
        }
        Ok(Self {
            targets,
            goal,
            destination,
        })
    }

    /// The target types, in the order asked.
    pub fn targets(&self) -> &[ObjectType] {
        &self.targets
    }

    /// The first target: the only one of a single-target task.
    pub fn first(&self) -> &ObjectType {
        &self.targets[0]
    }

    /// Every target or any one.
    pub fn goal(&self) -> Goal {
        self.goal
    }

    /// Where the robot brings what it found, if anywhere.
    pub fn destination(&self) -> Option<&Destination> {
        self.destination.as_ref()
    }

    /// The same task brought to `destination` instead.
    pub fn with_destination(self, destination: Option<Destination>) -> Self {
        Self {
            destination,
            ..self
        }
    }

    /// True for one target and no destination: the paper's trial, planned exactly as before
    /// tasks existed.
    pub fn is_single(&self) -> bool {
        self.targets.len() == 1 && self.destination.is_none()
    }

    /// Whether the goal holds once the targets marked true in `found` (task order) are found.
    pub fn holds(&self, found: impl IntoIterator<Item = bool>) -> bool {
        let mut found = found.into_iter();
        match self.goal {
            Goal::All => found.all(|f| f),
            Goal::Any => found.any(|f| f),
        }
    }

    /// The targets written as one name: the target itself for one, joined by `+` for `all` and
    /// by `|` for `any` (`Mug+Apple`, `Mug|Cup`).
    pub fn targets_label(&self) -> String {
        let sep = match self.goal {
            Goal::All => "+",
            Goal::Any => "|",
        };
        self.targets
            .iter()
            .map(ObjectType::as_str)
            .collect::<Vec<_>>()
            .join(sep)
    }
}

impl fmt::Display for Task {
    /// `<goal>:<T1>,<T2>…[@<destination>]`, the destination as far as it is written without a
    /// house (`start`, a point; containers and rooms by index).
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:", self.goal)?;
        for (i, t) in self.targets.iter().enumerate() {
            if i > 0 {
                f.write_str(",")?;
            }
            f.write_str(t.as_str())?;
        }
        match &self.destination {
            None => Ok(()),
            Some(Destination::Start) => f.write_str("@start"),
            Some(Destination::Point { x, z }) => write!(f, "@{x},{z}"),
            Some(Destination::Container { index }) => write!(f, "@container#{index}"),
            Some(Destination::Room { index }) => write!(f, "@room#{index}"),
        }
    }
}

impl FromStr for Task {
    type Err = TaskError;

    /// `<goal>:<T1>,<T2>…[@start|@<x>,<z>]`; a bare `<T>` is one target.
    fn from_str(s: &str) -> Result<Self, TaskError> {
        let s = s.trim();
        let (body, destination) = match s.split_once('@') {
            Some((b, d)) => {
                let d = d.trim();
                let dest = if d == "start" {
                    Destination::Start
                } else {
                    parse_point(d).ok_or_else(|| {
                        TaskError::new(
                            "destination",
                            format!("`{d}` is not `start` or a point `<x>,<z>`"),
                        )
                    })?
                };
                (b, Some(dest))
            }
            None => (s, None),
        };
        let (goal, list) = match body.split_once(':') {
            Some((g, l)) => (g.parse()?, l),
            None => (Goal::All, body),
        };
        let targets = list.split(',').map(|t| ObjectType::new(t.trim())).collect();
        Task::new(targets, goal, destination)
    }
}

/// A task that cannot be: which field is wrong and why.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{field}: {message}")]
pub struct TaskError {
    /// The field at fault: `targets`, `goal` or `destination`.
    pub field: &'static str,
    /// What is wrong with it.
    pub message: String,
}

impl TaskError {
    /// An error of `field`.
    pub fn new(field: &'static str, message: impl Into<String>) -> Self {
        Self {
            field,
            message: message.into(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bad_tasks_name_their_field() {
        let e = |s: &str| s.parse::<Task>().unwrap_err();
        assert_eq!(e("all:A,B,C,D,E").field, "targets");
        assert!(e("all:A,B,A").message.contains("twice"));
        assert_eq!(e("some:A,B").field, "goal");
        assert_eq!(e("all:A@moon").field, "destination");
        assert_eq!(e("all:").field, "targets");
        assert!(Task::new(vec![], Goal::Any, None).is_err());
    }

    #[test]
    fn tasks_round_trip_through_text_and_json() {
        for s in [
            "all:Mug",
            "any:Mug,Cup",
            "all:A,B,C@start",
            "all:A,B@1.5,-2",
        ] {
            let t: Task = s.parse().unwrap();
            assert_eq!(t.to_string(), s);
            let json = serde_json::to_string(&t).unwrap();
            assert_eq!(serde_json::from_str::<Task>(&json).unwrap(), t);
        }
        // JSON goes through the same checks.
        assert!(serde_json::from_str::<Task>(r#"{"targets":["A","A"]}"#).is_err());
        assert_eq!(
            "Mug".parse::<Task>().unwrap(),
            Task::single(ObjectType::new("Mug"))
        );
    }

    #[test]
    fn goals_hold_as_named() {
        let all: Task = "all:A,B".parse().unwrap();
        let any: Task = "any:A,B".parse().unwrap();
        assert!(!all.holds([true, false]) && all.holds([true, true]));
        assert!(any.holds([false, true]) && !any.holds([false, false]));
        assert_eq!(all.targets_label(), "A+B");
        assert_eq!(any.targets_label(), "A|B");
    }
}
