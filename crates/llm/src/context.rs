//! A house described in words: what prompt templates are rendered with.
//!
//! Rooms are named by their type in words (`living room`); when a house has several rooms of one
//! type they are numbered in house order (`bedroom 1`, `bedroom 2`). Containers are named by their
//! type in words; in P-DIRECT's list a container is "`<container> in the <room>`", numbered
//! (`countertop 2 in the kitchen`) when the house has several containers of that type in that room
//! — numbered over all of them, so a container keeps its number as others are searched. Containers
//! standing in no room are said to be in the `house`.
//!
//! **Room distances (P-DIRECT).** The world crate gives travel distances between the robot's start
//! and containers only. The distance between rooms A and B is the mean travel distance from a
//! container in A to a container in B (over all such pairs): a stand-in for centre-to-centre travel
//! that follows walls and doors, unlike a straight line between room centroids. Likewise the
//! robot's distance to a room is the mean travel distance from where it stands to that room's
//! containers. Rooms without containers have no distances (nothing there to search) but are still
//! listed among the rooms.

use std::collections::BTreeMap;

use ferret_world::{Distances, House, ObjectType, Place, RoomType};
use serde::Serialize;

use crate::error::{LlmError, Result};

/// Words for a container's room when it stands in none.
const NO_ROOM: &str = "house";

/// One line of the house description: a room and the containers in it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RoomEntry {
    /// The room's label (`kitchen`, `bedroom 2`).
    pub room: String,
    /// Container types in words, first-appearance order, a repeated type once with its count
    /// (`countertop (2)`).
    pub containers: Vec<String>,
}

/// A house in words, computed once per house and shared by all its prompts.
#[derive(Clone, Debug, PartialEq)]
pub struct HouseContext {
    room_labels: Vec<String>,
    entries: Vec<RoomEntry>,
    container_labels: Vec<String>,
}

impl HouseContext {
    /// Describes `house`.
    pub fn new(house: &House) -> Self {
        let mut per_type: BTreeMap<&RoomType, usize> = BTreeMap::new();
        for r in &house.rooms {
            *per_type.entry(&r.room_type).or_default() += 1;
        }
        let mut seen: BTreeMap<&RoomType, usize> = BTreeMap::new();
        let room_labels: Vec<String> = house
            .rooms
            .iter()
            .map(|r| {
                let words = r.room_type.words();
                if per_type.get(&r.room_type).copied().unwrap_or(0) > 1 {
                    let n = seen.entry(&r.room_type).or_default();
                    *n += 1;
                    format!("{words} {n}")
                } else {
                    words
                }
            })
            .collect();

        let room_label = |room: Option<usize>| -> String {
            room.and_then(|r| room_labels.get(r))
                .cloned()
                .unwrap_or_else(|| NO_ROOM.to_string())
        };

        // House description: rooms in house order, then containers outside any room.
        let mut entries = Vec::new();
        let mut slots: Vec<Option<usize>> = (0..house.rooms.len()).map(Some).collect();
        slots.push(None);
        for slot in slots {
            let mut types: Vec<(String, usize)> = Vec::new();
            for c in house.containers.iter().filter(|c| {
                c.room == slot || (slot.is_none() && c.room.is_some_and(|r| r >= house.rooms.len()))
            }) {
                let w = c.object_type.words();
                match types.iter_mut().find(|(t, _)| *t == w) {
                    Some((_, n)) => *n += 1,
                    None => types.push((w, 1)),
                }
            }
            if !types.is_empty() {
                entries.push(RoomEntry {
                    room: room_label(slot),
                    containers: types
                        .into_iter()
                        .map(|(t, n)| if n > 1 { format!("{t} ({n})") } else { t })
                        .collect(),
                });
            }
        }

        // Option labels, numbered over all containers sharing type and room.
        let base: Vec<(String, String)> = house
            .containers
            .iter()
            .map(|c| (c.object_type.words(), room_label(c.room)))
            .collect();
        let mut totals: BTreeMap<&(String, String), usize> = BTreeMap::new();
        for b in &base {
            *totals.entry(b).or_default() += 1;
        }
        let mut counters: BTreeMap<&(String, String), usize> = BTreeMap::new();
        let container_labels = base
            .iter()
            .map(|b| {
                let (container, room) = b;
                if totals.get(b).copied().unwrap_or(0) > 1 {
                    let n = counters.entry(b).or_default();
                    *n += 1;
                    format!("{container} {n} in the {room}")
                } else {
                    format!("{container} in the {room}")
                }
            })
            .collect();

        Self {
            room_labels,
            entries,
            container_labels,
        }
    }

    /// Room labels in house order.
    pub fn room_labels(&self) -> &[String] {
        &self.room_labels
    }

    /// The label of room `room` (`house` for none).
    pub fn room_label(&self, room: Option<usize>) -> String {
        room.and_then(|r| self.room_labels.get(r))
            .cloned()
            .unwrap_or_else(|| NO_ROOM.to_string())
    }

    /// The house description: each room with containers, and what it holds.
    pub fn entries(&self) -> &[RoomEntry] {
        &self.entries
    }

    /// P-DIRECT's label for container `c` (`countertop 2 in the kitchen`).
    pub fn container_label(&self, c: usize) -> Option<&str> {
        self.container_labels.get(c).map(String::as_str)
    }
}

/// One probability question: is `target` in a container of this type in this room? All
/// containers sharing (type, room) share the question, so it is asked once per house. Rooms are
/// named as in the house description (`bedroom 2` when a type repeats), so the question speaks of
/// the same room the listing does.
#[derive(Clone, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct ProbabilityQuery {
    /// What is searched for.
    pub target: ObjectType,
    /// The container type.
    pub container: ObjectType,
    /// The room's label (`living room`, `bedroom 2`; `house` for a container in no room).
    pub room: String,
}

impl ProbabilityQuery {
    /// The question in words, for messages: `remote control in the sofa in the living room`.
    pub fn describe(&self) -> String {
        format!(
            "{} in the {} in the {}",
            self.target.words(),
            self.container.words(),
            self.room
        )
    }
}

/// The distinct questions for a house and target, and which question each container takes its
/// probability from.
#[derive(Clone, Debug, PartialEq)]
pub struct QueryPlan {
    /// Distinct questions, in order of first container.
    pub queries: Vec<ProbabilityQuery>,
    /// For container `i`, the index into `queries` of its question.
    pub of_container: Vec<usize>,
}

impl QueryPlan {
    /// The questions for `target` in `house`.
    pub fn new(house: &House, target: &ObjectType) -> Self {
        Self::with_context(house, &HouseContext::new(house), target)
    }

    /// The questions for `target` in `house`, whose words `labels` already describe (so the
    /// caller that renders the prompts describes the house once).
    pub fn with_context(house: &House, labels: &HouseContext, target: &ObjectType) -> Self {
        let mut queries: Vec<ProbabilityQuery> = Vec::new();
        let mut index: BTreeMap<ProbabilityQuery, usize> = BTreeMap::new();
        let of_container = (0..house.containers.len())
            .map(|c| {
                let room = house.containers[c].room.filter(|&r| r < house.rooms.len());
                let q = ProbabilityQuery {
                    target: target.clone(),
                    container: house.containers[c].object_type.clone(),
                    room: labels.room_label(room),
                };
                *index.entry(q.clone()).or_insert_with(|| {
                    queries.push(q);
                    queries.len() - 1
                })
            })
            .collect();
        Self {
            queries,
            of_container,
        }
    }
}

impl QueryPlan {
    /// The questions for `target` in `house` by container type and room *type* (`bedroom`, not
    /// `bedroom 2`): what a question naming no house asks (P-YESNO), so that one answer serves
    /// every house with such a room. The queries' `room` holds the room type in words.
    pub fn by_room_type(house: &House, target: &ObjectType) -> Self {
        let mut queries: Vec<ProbabilityQuery> = Vec::new();
        let mut index: BTreeMap<ProbabilityQuery, usize> = BTreeMap::new();
        let of_container = house
            .containers
            .iter()
            .map(|c| {
                let room = c
                    .room
                    .and_then(|r| house.rooms.get(r))
                    .map_or_else(|| NO_ROOM.to_string(), |r| r.room_type.words());
                let q = ProbabilityQuery {
                    target: target.clone(),
                    container: c.object_type.clone(),
                    room,
                };
                *index.entry(q.clone()).or_insert_with(|| {
                    queries.push(q);
                    queries.len() - 1
                })
            })
            .collect();
        Self {
            queries,
            of_container,
        }
    }
}

/// Labels of listed places: one capital letter each, a single token in common tokenizers (digits
/// are not: Qwen writes `12` as two tokens, so a number label cannot be read from one token's
/// alternatives).
pub const LABELS: &str = "ABCDEFGHIJKLMNOPQRSTUVWXYZ";

/// The most places one listing question names (one per letter).
pub const MAX_LISTED: usize = LABELS.len();

/// One place of a house's listing: a container type in a room (containers of one type in one
/// room are one place: nothing in words tells them apart).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ListedPlace {
    /// The container type in words (`counter top`).
    pub container: String,
    /// The room's label (`kitchen`, `bedroom 2`; `house` for none).
    pub room: String,
}

/// The places of a house that listing prompts (P-CHOICE, P-BATCH) name, and the parts they are
/// asked in. A house with more places than [`MAX_LISTED`] is asked in several parts of nearly equal
/// size, each a question of its own.
#[derive(Clone, Debug, PartialEq)]
pub struct Listing {
    /// Distinct (container type, room) places, in order of first container.
    pub places: Vec<ListedPlace>,
    /// For container `i`, the index into `places` of its place.
    pub of_container: Vec<usize>,
    /// The parts: indices into `places`, each at most [`MAX_LISTED`] long, together every place
    /// once, in order.
    pub parts: Vec<Vec<usize>>,
}

impl Listing {
    /// The listing of `house`, named as `labels` describes it.
    pub fn new(house: &House, labels: &HouseContext) -> Self {
        let mut places: Vec<ListedPlace> = Vec::new();
        let of_container = house
            .containers
            .iter()
            .map(|c| {
                let place = ListedPlace {
                    container: c.object_type.words(),
                    room: labels.room_label(c.room.filter(|&r| r < house.rooms.len())),
                };
                match places.iter().position(|p| *p == place) {
                    Some(i) => i,
                    None => {
                        places.push(place);
                        places.len() - 1
                    }
                }
            })
            .collect();
        let n = places.len();
        let count = n.div_ceil(MAX_LISTED).max(1);
        let parts = (0..count)
            .map(|k| (k * n / count..(k + 1) * n / count).collect())
            .filter(|p: &Vec<usize>| !p.is_empty())
            .collect();
        Self {
            places,
            of_container,
            parts,
        }
    }
}

/// One listed place as a template sees it.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ListedOption {
    /// Its letter (`A`), or its name (`sofa in the living room`) in a prompt that names places.
    pub label: String,
    /// The container type in words.
    pub container: String,
    /// The room's label.
    pub room: String,
}

/// What listing templates (P-CHOICE, P-BATCH) are rendered with.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ListingContext {
    /// The target in words.
    pub target: String,
    /// Room labels in house order.
    pub rooms: Vec<String>,
    /// The house description.
    pub house: Vec<RoomEntry>,
    /// The places asked about, lettered from `A` in the order given.
    pub options: Vec<ListedOption>,
}

impl ListingContext {
    /// The context asking about `places` (indices into `listing.places`, in the order they are
    /// to be lettered) for `target`.
    pub fn new(
        ctx: &HouseContext,
        listing: &Listing,
        places: &[usize],
        target: &ObjectType,
    ) -> Self {
        Self::labelled(ctx, listing, places, target, false)
    }

    /// The same, with each place's label its name (`sofa in the living room`) when `names`.
    pub fn labelled(
        ctx: &HouseContext,
        listing: &Listing,
        places: &[usize],
        target: &ObjectType,
        names: bool,
    ) -> Self {
        Self {
            target: target.words(),
            rooms: ctx.room_labels.clone(),
            house: ctx.entries.clone(),
            options: places
                .iter()
                .zip(LABELS.chars())
                .map(|(&p, letter)| {
                    let place = &listing.places[p];
                    ListedOption {
                        label: if names {
                            format!("{} in the {}", place.container, place.room)
                        } else {
                            letter.to_string()
                        },
                        container: place.container.clone(),
                        room: place.room.clone(),
                    }
                })
                .collect(),
        }
    }

    /// The option letters, in order.
    pub fn labels(&self) -> Vec<String> {
        self.options.iter().map(|o| o.label.clone()).collect()
    }
}

/// What probability templates are rendered with.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct ProbabilityContext {
    /// The target in words (`remote control`).
    pub target: String,
    /// The container type in words (`sofa`).
    pub container: String,
    /// The room's label (`living room`, `bedroom 2`), `house` for none.
    pub room: String,
    /// Room labels in house order.
    pub rooms: Vec<String>,
    /// The house description.
    pub house: Vec<RoomEntry>,
}

impl ProbabilityContext {
    /// The context for `query` in a house described by `ctx`.
    pub fn new(ctx: &HouseContext, query: &ProbabilityQuery) -> Self {
        Self {
            target: query.target.words(),
            container: query.container.words(),
            room: query.room.clone(),
            rooms: ctx.room_labels.clone(),
            house: ctx.entries.clone(),
        }
    }
}

/// A distance between two rooms, for P-DIRECT.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RoomDistance {
    /// One room's label.
    pub from: String,
    /// The other's.
    pub to: String,
    /// Metres, one decimal (`7.4`).
    pub metres: String,
}

/// The robot's distance to a room, for P-DIRECT.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotDistance {
    /// The room's label.
    pub room: String,
    /// Metres, one decimal.
    pub metres: String,
}

/// Where the robot is, for P-DIRECT.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RobotContext {
    /// The room it is in (`house` when outside every room).
    pub room: String,
    /// The container it stands at, labelled as in the list, once it has searched one.
    pub at: Option<String>,
    /// Its distance to each room with containers.
    pub distances: Vec<RobotDistance>,
}

/// One search location offered to the LLM.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DirectOption {
    /// Its 1-based position in the list.
    pub number: usize,
    /// `countertop 2 in the kitchen`.
    pub label: String,
    /// The container type in words.
    pub container: String,
    /// The room label.
    pub room: String,
}

/// What P-DIRECT templates are rendered with.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DirectContext {
    /// The target in words.
    pub target: String,
    /// Room labels in house order.
    pub rooms: Vec<String>,
    /// Distances between rooms with containers (each pair once).
    pub room_distances: Vec<RoomDistance>,
    /// Where the robot is.
    pub robot: RobotContext,
    /// The unsearched containers, in house order.
    pub options: Vec<DirectOption>,
}

impl DirectContext {
    /// The context for choosing among `unsearched` containers with the robot at `robot`. Returns
    /// it with the container index of each option.
    pub fn new(
        house: &House,
        ctx: &HouseContext,
        distances: &Distances,
        target: &ObjectType,
        robot: Place,
        unsearched: &[usize],
    ) -> Result<(Self, Vec<usize>)> {
        let n = house.containers.len();
        if distances.container_count() != n {
            return Err(LlmError::Context(format!(
                "{}: distances cover {} containers, the house has {n}",
                house.name,
                distances.container_count()
            )));
        }
        if let Some(&bad) = unsearched.iter().find(|&&c| c >= n) {
            return Err(LlmError::Context(format!(
                "{}: no container {bad}",
                house.name
            )));
        }
        if let Place::Container(c) = robot
            && c >= n
        {
            return Err(LlmError::Context(format!(
                "{}: the robot stands at container {c}, which does not exist",
                house.name
            )));
        }
        // Containers by room slot (None = outside every room), rooms in house order.
        let mut by_room: Vec<(Option<usize>, Vec<usize>)> = Vec::new();
        for (c, container) in house.containers.iter().enumerate() {
            let room = container.room.filter(|&r| r < house.rooms.len());
            match by_room.iter_mut().find(|(r, _)| *r == room) {
                Some((_, cs)) => cs.push(c),
                None => by_room.push((room, vec![c])),
            }
        }
        by_room.sort_by_key(|(r, _)| r.map_or(usize::MAX, |r| r));
        let metres = |d: f64| format!("{d:.1}");
        let mean = |sum: f64, count: usize| sum / count.max(1) as f64;

        let mut room_distances = Vec::new();
        for (i, (ra, ca)) in by_room.iter().enumerate() {
            for (rb, cb) in by_room.iter().skip(i + 1) {
                let sum: f64 = ca
                    .iter()
                    .flat_map(|&a| cb.iter().map(move |&b| (a, b)))
                    .map(|(a, b)| distances.between(Place::Container(a), Place::Container(b)))
                    .sum();
                room_distances.push(RoomDistance {
                    from: ctx.room_label(*ra),
                    to: ctx.room_label(*rb),
                    metres: metres(mean(sum, ca.len() * cb.len())),
                });
            }
        }
        let robot_room = match robot {
            Place::Start => house.room_at(house.start.position),
            Place::Container(c) => house.containers[c].room,
        };
        let robot_ctx = RobotContext {
            room: ctx.room_label(robot_room),
            at: match robot {
                Place::Start => None,
                Place::Container(c) => ctx.container_label(c).map(str::to_string),
            },
            distances: by_room
                .iter()
                .map(|(r, cs)| RobotDistance {
                    room: ctx.room_label(*r),
                    metres: metres(mean(
                        cs.iter()
                            .map(|&c| distances.between(robot, Place::Container(c)))
                            .sum(),
                        cs.len(),
                    )),
                })
                .collect(),
        };
        let mut order: Vec<usize> = unsearched.to_vec();
        order.sort_unstable();
        order.dedup();
        let options = order
            .iter()
            .enumerate()
            .map(|(i, &c)| DirectOption {
                number: i + 1,
                label: ctx.container_label(c).unwrap_or_default().to_string(),
                container: house.containers[c].object_type.words(),
                room: ctx.room_label(house.containers[c].room),
            })
            .collect();
        Ok((
            Self {
                target: target.words(),
                rooms: ctx.room_labels.clone(),
                room_distances,
                robot: robot_ctx,
                options,
            },
            order,
        ))
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use ferret_world::{Container, Footprint, Point, Polygon, Pose, Room};

    /// A three-room house: kitchen (fridge, 2 countertops), two bedrooms (bed; bed, dresser),
    /// and the start in the kitchen.
    pub(crate) fn small_house() -> House {
        let square = |x0: f64| {
            Polygon::new(vec![
                Point::new(x0, 0.0),
                Point::new(x0 + 4.0, 0.0),
                Point::new(x0 + 4.0, 4.0),
                Point::new(x0, 4.0),
            ])
        };
        let room = |i: usize, t: &str| Room {
            id: format!("room|{i}"),
            room_type: RoomType::new(t),
            floor: square(4.0 * i as f64),
        };
        let container = |id: &str, t: &str, room: usize, x: f64| Container {
            id: id.into(),
            object_type: ObjectType::new(t),
            room: Some(room),
            position: Point::new(x, 2.0),
            footprint: Footprint {
                center: Point::new(x, 2.0),
                size_x: 1.0,
                size_z: 1.0,
                yaw_deg: 0.0,
            },
            access: None,
        };
        House {
            name: "test#0".into(),
            index: 0,
            rooms: vec![room(0, "Kitchen"), room(1, "Bedroom"), room(2, "Bedroom")],
            walls: vec![],
            doors: vec![],
            containers: vec![
                container("0|1", "Fridge", 0, 1.0),
                container("0|2", "CounterTop", 0, 2.0),
                container("0|3", "CounterTop", 0, 3.0),
                container("1|1", "Bed", 1, 6.0),
                container("2|1", "Bed", 2, 10.0),
                container("2|2", "Dresser", 2, 11.0),
            ],
            obstacles: vec![],
            start: Pose {
                position: Point::new(0.5, 0.5),
                yaw_deg: 0.0,
            },
            map: None,
        }
    }

    /// Straight-line distances between positions (start + containers).
    pub(crate) fn straight_distances(house: &House) -> Distances {
        let places: Vec<Point> = std::iter::once(house.start.position)
            .chain(house.containers.iter().map(|c| c.position))
            .collect();
        let n = places.len();
        let m = (0..n * n)
            .map(|k| places[k / n].distance(places[k % n]))
            .collect();
        Distances::from_matrix(house.containers.len(), m).unwrap()
    }

    #[test]
    fn rooms_and_containers_in_words() {
        let house = small_house();
        let ctx = HouseContext::new(&house);
        assert_eq!(ctx.room_labels(), ["kitchen", "bedroom 1", "bedroom 2"]);
        assert_eq!(
            ctx.entries()[0],
            RoomEntry {
                room: "kitchen".into(),
                containers: vec!["fridge".into(), "counter top (2)".into()]
            }
        );
        assert_eq!(ctx.entries()[2].containers, ["bed", "dresser"]);
        assert_eq!(ctx.container_label(1), Some("counter top 1 in the kitchen"));
        assert_eq!(ctx.container_label(2), Some("counter top 2 in the kitchen"));
        assert_eq!(ctx.container_label(3), Some("bed in the bedroom 1"));
        assert_eq!(ctx.container_label(0), Some("fridge in the kitchen"));
    }

    #[test]
    fn one_query_per_container_type_and_room() {
        let house = small_house();
        let plan = QueryPlan::new(&house, &ObjectType::new("CellPhone"));
        // fridge@kitchen, countertop@kitchen (twice → once), bed@bedroom 1, bed@bedroom 2,
        // dresser@bedroom 2: the two bedrooms are asked about apart, named as the house listing
        // names them.
        assert_eq!(plan.queries.len(), 5);
        assert_eq!(plan.of_container, [0, 1, 1, 2, 3, 4]);
        assert_eq!(plan.queries[2].room, "bedroom 1");
        assert_eq!(plan.queries[3].room, "bedroom 2");
        assert_eq!(
            plan.queries[4].describe(),
            "cell phone in the dresser in the bedroom 2"
        );
    }

    #[test]
    fn direct_context_distances_and_options() {
        let house = small_house();
        let ctx = HouseContext::new(&house);
        let d = straight_distances(&house);
        let (dc, order) = DirectContext::new(
            &house,
            &ctx,
            &d,
            &ObjectType::new("CellPhone"),
            Place::Container(1),
            &[5, 3, 2],
        )
        .unwrap();
        assert_eq!(order, [2, 3, 5]);
        let labels: Vec<&str> = dc.options.iter().map(|o| o.label.as_str()).collect();
        assert_eq!(
            labels,
            [
                "counter top 2 in the kitchen",
                "bed in the bedroom 1",
                "dresser in the bedroom 2"
            ]
        );
        assert_eq!(dc.robot.room, "kitchen");
        assert_eq!(dc.robot.at.as_deref(), Some("counter top 1 in the kitchen"));
        // kitchen (x = 1, 2, 3) to bedroom 1 (x = 6): mean 4.0
        assert_eq!(
            dc.room_distances[0],
            RoomDistance {
                from: "kitchen".into(),
                to: "bedroom 1".into(),
                metres: "4.0".into()
            }
        );
        assert_eq!(dc.room_distances.len(), 3);
        // from x = 2 to the bedroom 2 containers (10, 11): mean 8.5
        assert_eq!(dc.robot.distances[2].metres, "8.5");
        assert!(
            DirectContext::new(&house, &ctx, &d, &ObjectType::new("X"), Place::Start, &[9])
                .is_err()
        );
    }

    #[test]
    fn yes_no_questions_name_room_types() {
        let house = small_house();
        let plan = QueryPlan::by_room_type(&house, &ObjectType::new("CellPhone"));
        // The beds of bedroom 1 and bedroom 2 are one question about a bed in a bedroom.
        assert_eq!(plan.queries.len(), 4);
        assert_eq!(plan.of_container, [0, 1, 1, 2, 2, 3]);
        assert_eq!(
            plan.queries[2].describe(),
            "cell phone in the bed in the bedroom"
        );
    }

    #[test]
    fn listings_name_each_place_once_and_letter_them() {
        let house = small_house();
        let ctx = HouseContext::new(&house);
        let listing = Listing::new(&house, &ctx);
        assert_eq!(listing.places.len(), 5);
        assert_eq!(listing.of_container, [0, 1, 1, 2, 3, 4]);
        assert_eq!(listing.parts, [vec![0, 1, 2, 3, 4]]);
        let l = ListingContext::new(&ctx, &listing, &[4, 0], &ObjectType::new("Apple"));
        assert_eq!(l.labels(), ["A", "B"]);
        assert_eq!(l.options[0].container, "dresser");
        assert_eq!(l.options[0].room, "bedroom 2");
        assert_eq!(l.options[1].container, "fridge");
    }

    /// A house of one room holding `n` containers of distinct types.
    fn house_of(n: usize) -> House {
        let mut house = small_house();
        let template = house.containers[0].clone();
        house.containers = (0..n)
            .map(|i| ferret_world::Container {
                id: format!("c|{i}"),
                object_type: ObjectType::new(format!("Type{i}")),
                ..template.clone()
            })
            .collect();
        house
    }

    proptest::proptest! {
        /// Parts cover every place once, in order, each within the letters, and differ in size
        /// by at most one.
        #[test]
        fn parts_cover_every_place_once(n in 1usize..120) {
            let house = house_of(n);
            let listing = Listing::new(&house, &HouseContext::new(&house));
            let flat: Vec<usize> = listing.parts.iter().flatten().copied().collect();
            proptest::prop_assert_eq!(flat, (0..n).collect::<Vec<_>>());
            proptest::prop_assert_eq!(listing.parts.len(), n.div_ceil(MAX_LISTED));
            let sizes: Vec<usize> = listing.parts.iter().map(Vec::len).collect();
            proptest::prop_assert!(sizes.iter().all(|&s| (1..=MAX_LISTED).contains(&s)));
            let (lo, hi) = (sizes.iter().min().copied(), sizes.iter().max().copied());
            proptest::prop_assert!(hi.unwrap_or(0) - lo.unwrap_or(0) <= 1);
        }
    }
}
