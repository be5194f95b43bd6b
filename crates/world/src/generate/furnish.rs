//! Furniture: which containers each room gets, where they stand, and where the robot starts.
//!
//! Containers stand against walls facing into the room (a few, like coffee tables, stand free),
//! never overlap each other or the floor in front of a door, and every placement is checked on a
//! conservative clearance grid of the room: after each piece, the robot must still reach every
//! door of the room and get close to every piece. Rooms are joined by their doors, so a house
//! whose rooms each pass this check is connected.

use rand::Rng;
use rand::seq::{IndexedRandom, SliceRandom};

use super::layout::{Floorplan, PlanRoom, RoomKind, TICK, metres};

/// Half the wall thickness the occupancy grid gives walls (0.1 m), metres.
const WALL_HALF: f64 = 0.05;
/// Gap between a wall line and the back of a piece standing against it, metres.
const WALL_GAP: f64 = WALL_HALF + 0.01;
/// Clearance-grid cell, metres (the occupancy grid's default resolution).
const CELL: f64 = TICK;
/// Depth of the floor kept clear in front of a door, metres.
const DOOR_ZONE_DEPTH: f64 = 0.75;
/// The same when a room is too crowded otherwise: room for the robot to step through.
const DOOR_ZONE_MIN_DEPTH: f64 = 0.45;
/// How far beyond each end of a door the clear zone extends, metres.
const DOOR_ZONE_SIDE: f64 = 0.05;
/// How close (beyond its inflated footprint) the robot must get to a container, metres.
const ACCESS_REACH: f64 = 0.2;
/// Clearance around free-standing pieces (dining and coffee tables), metres.
const WALKWAY: f64 = 0.6;
/// Least distance between the robot's start and a wall, metres.
const START_WALL_CLEARANCE: f64 = 0.5;
/// Gap between a coffee table and the sofa it stands in front of, metres.
const COFFEE_TABLE_GAP: f64 = 0.45;

/// A wall of a rectangular room.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Side {
    /// z = z0; pieces face +z (yaw 0).
    South,
    /// z = z1; pieces face −z (yaw 180).
    North,
    /// x = x0; pieces face +x (yaw 90).
    West,
    /// x = x1; pieces face −x (yaw 270).
    East,
}

const SIDES: [Side; 4] = [Side::South, Side::North, Side::West, Side::East];

impl Side {
    fn yaw(self) -> f64 {
        match self {
            Side::South => 0.0,
            Side::North => 180.0,
            Side::West => 90.0,
            Side::East => 270.0,
        }
    }

    fn opposite(self) -> Side {
        match self {
            Side::South => Side::North,
            Side::North => Side::South,
            Side::West => Side::East,
            Side::East => Side::West,
        }
    }

    /// True for walls that run along x (pieces against them are laid out along x).
    fn runs_along_x(self) -> bool {
        matches!(self, Side::South | Side::North)
    }
}

/// Unit vector a piece with heading `yaw` (a multiple of 90°) faces: local +z rotated the way
/// [`Footprint::corners`](crate::Footprint::corners) rotates it.
fn facing(yaw: f64) -> (f64, f64) {
    let (s, c) = yaw.to_radians().sin_cos();
    (s.round(), c.round())
}

/// An axis-aligned box on the floor, metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct Bx {
    pub x0: f64,
    pub z0: f64,
    pub x1: f64,
    pub z1: f64,
}

impl Bx {
    fn around(center: (f64, f64), extent: (f64, f64)) -> Bx {
        Bx {
            x0: center.0 - extent.0 / 2.0,
            z0: center.1 - extent.1 / 2.0,
            x1: center.0 + extent.0 / 2.0,
            z1: center.1 + extent.1 / 2.0,
        }
    }

    fn grow(&self, by: f64) -> Bx {
        Bx {
            x0: self.x0 - by,
            z0: self.z0 - by,
            x1: self.x1 + by,
            z1: self.z1 + by,
        }
    }

    /// True when the boxes overlap or come closer than `gap`.
    fn near(&self, other: &Bx, gap: f64) -> bool {
        self.x0 < other.x1 + gap
            && other.x0 < self.x1 + gap
            && self.z0 < other.z1 + gap
            && other.z0 < self.z1 + gap
    }

    fn within(&self, outer: &Bx) -> bool {
        self.x0 >= outer.x0 && self.z0 >= outer.z0 && self.x1 <= outer.x1 && self.z1 <= outer.z1
    }

    /// Straight-line distance from a point to the box (0 inside).
    fn distance(&self, x: f64, z: f64) -> f64 {
        let dx = (self.x0 - x).max(x - self.x1).max(0.0);
        let dz = (self.z0 - z).max(z - self.z1).max(0.0);
        dx.hypot(dz)
    }

    fn contains(&self, x: f64, z: f64) -> bool {
        x >= self.x0 && x <= self.x1 && z >= self.z0 && z <= self.z1
    }
}

/// A placed piece of furniture.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct Placed {
    pub object_type: &'static str,
    /// Centre, metres.
    pub center: (f64, f64),
    /// Heading, degrees: 0, 90, 180 or 270.
    pub yaw: f64,
    /// Size along the piece's own x and z axes, metres.
    pub size: (f64, f64),
    /// Its box on the floor.
    pub bx: Bx,
    /// The wall it stands against, if any.
    pub side: Option<Side>,
}

/// How a piece finds its place.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Rule {
    /// Against a random wall, anywhere along it.
    Wall,
    /// Against a random wall, near its middle (beds).
    WallCentred,
    /// Against the same wall as a piece of this type, right next to it (side tables by a bed).
    Beside(&'static str),
    /// Against the wall opposite a piece of this type, facing it (a TV stand facing the sofa).
    Facing(&'static str),
    /// Free-standing in front of a piece of this type (a coffee table before the sofa).
    InFrontOf(&'static str),
    /// Free-standing in the middle of the room with a walkway around it.
    Middle,
    /// At a long side of the dining table, facing it; nowhere when there is no table.
    AtTable,
}

/// What furniture a room of each type gets: (type, probability, rule). Written by hand from
/// everyday homes; the first entries of each list are the pieces that define the room. Chairs,
/// lamps and plants are obstacles, not containers (see
/// [`is_container_type`](crate::procthor::types::is_container_type)).
fn room_furniture(kind: RoomKind) -> &'static [(&'static str, f64, Rule)] {
    use Rule::*;
    match kind {
        RoomKind::Kitchen => &[
            ("CounterTop", 1.0, Wall),
            ("Fridge", 1.0, Wall),
            ("CounterTop", 0.35, Wall),
            ("DiningTable", 0.5, Middle),
            ("Chair", 0.9, AtTable),
            ("Chair", 0.9, AtTable),
            ("Chair", 0.5, AtTable),
            ("GarbageCan", 0.7, Wall),
            ("ShelvingUnit", 0.3, Wall),
            ("HousePlant", 0.25, Wall),
        ],
        RoomKind::LivingRoom => &[
            ("Sofa", 1.0, Wall),
            ("TVStand", 0.9, Facing("Sofa")),
            ("CoffeeTable", 0.75, InFrontOf("Sofa")),
            ("SideTable", 0.6, Beside("Sofa")),
            ("ArmChair", 0.6, Wall),
            ("ShelvingUnit", 0.5, Wall),
            ("DiningTable", 0.25, Middle),
            ("Chair", 0.9, AtTable),
            ("Chair", 0.9, AtTable),
            ("ArmChair", 0.2, Wall),
            ("Desk", 0.15, Wall),
            ("GarbageCan", 0.3, Wall),
            ("FloorLamp", 0.5, Wall),
            ("HousePlant", 0.4, Wall),
        ],
        RoomKind::Bedroom => &[
            ("Bed", 1.0, WallCentred),
            ("SideTable", 0.85, Beside("Bed")),
            ("SideTable", 0.5, Beside("Bed")),
            ("Dresser", 0.75, Wall),
            ("Desk", 0.4, Wall),
            ("ShelvingUnit", 0.3, Wall),
            ("ArmChair", 0.2, Wall),
            ("GarbageCan", 0.35, Wall),
            ("FloorLamp", 0.3, Wall),
            ("HousePlant", 0.2, Wall),
        ],
        RoomKind::Bathroom => &[
            ("Toilet", 1.0, Wall),
            ("Sink", 1.0, Wall),
            ("Bathtub", 0.45, Wall),
            ("GarbageCan", 0.6, Wall),
            ("ShelvingUnit", 0.15, Wall),
        ],
    }
}

/// A room's clearance grid: cells of [`CELL`] metres, blocked where the centre of a robot of the
/// given radius cannot be, with a margin of one cell for the occupancy grid's rasterisation.
struct RoomGrid {
    origin: (f64, f64),
    nx: usize,
    nz: usize,
    /// Blocked by walls alone.
    walls: Vec<bool>,
    /// Cells just inside each door opening of the room.
    anchors: Vec<usize>,
    inflate: f64,
}

impl RoomGrid {
    fn new(room: &Bx, door_spans: &[(Side, f64, f64)], radius: f64) -> RoomGrid {
        let nx = ((room.x1 - room.x0) / CELL).round().max(1.0) as usize;
        let nz = ((room.z1 - room.z0) / CELL).round().max(1.0) as usize;
        let inflate = radius + CELL;
        let band = WALL_HALF + inflate;
        let mut walls = vec![false; nx * nz];
        let mut anchors = Vec::new();
        for j in 0..nz {
            for i in 0..nx {
                let (x, z) = (
                    room.x0 + (i as f64 + 0.5) * CELL,
                    room.z0 + (j as f64 + 0.5) * CELL,
                );
                let near_wall = x - room.x0 < band
                    || room.x1 - x < band
                    || z - room.z0 < band
                    || room.z1 - z < band;
                if !near_wall {
                    continue;
                }
                // Inside a door opening the cell is free if it is clear of both jambs and of
                // the other walls.
                let in_doorway = door_spans.iter().any(|&(side, from, to)| {
                    let (dist, along) = match side {
                        Side::South => (z - room.z0, x),
                        Side::North => (room.z1 - z, x),
                        Side::West => (x - room.x0, z),
                        Side::East => (room.x1 - x, z),
                    };
                    let across_ok = match side {
                        Side::South | Side::North => x - room.x0 >= band && room.x1 - x >= band,
                        Side::West | Side::East => z - room.z0 >= band && room.z1 - z >= band,
                    };
                    dist < band && along >= from + inflate && along <= to - inflate && across_ok
                });
                if in_doorway {
                    anchors.push(j * nx + i);
                } else {
                    walls[j * nx + i] = true;
                }
            }
        }
        RoomGrid {
            origin: (room.x0, room.z0),
            nx,
            nz,
            walls,
            anchors,
            inflate,
        }
    }

    fn centre(&self, cell: usize) -> (f64, f64) {
        let (i, j) = (cell % self.nx, cell / self.nx);
        (
            self.origin.0 + (i as f64 + 0.5) * CELL,
            self.origin.1 + (j as f64 + 0.5) * CELL,
        )
    }

    /// Cells reachable from the first door of the room with `pieces` standing in it (4-connected,
    /// stricter than the occupancy grid's 8), or `None` when some door cannot be reached.
    fn reachable(&self, pieces: &[Bx]) -> Option<Vec<bool>> {
        // One byte per cell and a stack rather than a queue: the cells reached are the same in
        // any order, and this runs for every placement tried in every generated house (most of
        // training the default prior, which every `ferret eval` process does).
        const FREE: u8 = 0;
        const BLOCKED: u8 = 1;
        const SEEN: u8 = 2;
        let mut state: Vec<u8> = self.walls.iter().map(|&w| u8::from(w)).collect();
        for b in pieces {
            for c in self.cells_in(&b.grow(self.inflate)) {
                state[c] = BLOCKED;
            }
        }
        let seed = match self.anchors.first() {
            Some(&a) => a,
            None => state.iter().position(|&s| s == FREE)?,
        };
        if state[seed] != FREE {
            return None;
        }
        let (nx, n) = (self.nx, state.len());
        // Each cell travels with its column, so that no step divides.
        let mut stack = vec![(seed, seed % nx)];
        state[seed] = SEEN;
        while let Some((c, i)) = stack.pop() {
            let mut visit = |m: usize, mi: usize| {
                if state[m] == FREE {
                    state[m] = SEEN;
                    stack.push((m, mi));
                }
            };
            if i > 0 {
                visit(c - 1, i - 1);
            }
            if i + 1 < nx {
                visit(c + 1, i + 1);
            }
            if c >= nx {
                visit(c - nx, i);
            }
            if c + nx < n {
                visit(c + nx, i);
            }
        }
        self.anchors
            .iter()
            .all(|&a| state[a] == SEEN)
            .then(|| state.into_iter().map(|s| s == SEEN).collect())
    }

    /// True when the robot can reach every door and come close to every piece.
    fn all_accessible(&self, pieces: &[Bx]) -> bool {
        let Some(seen) = self.reachable(pieces) else {
            return false;
        };
        let reach = self.inflate + ACCESS_REACH;
        pieces.iter().all(|b| {
            self.cells_in(&b.grow(reach)).any(|c| {
                let (x, z) = self.centre(c);
                seen[c] && b.distance(x, z) <= reach
            })
        })
    }

    /// The cells whose centres lie in `b`.
    fn cells_in(&self, b: &Bx) -> impl Iterator<Item = usize> + '_ {
        let index =
            |v: f64, origin: f64, n: usize| (((v - origin) / CELL).max(0.0) as usize).min(n);
        let (i0, i1) = (
            index(b.x0, self.origin.0, self.nx),
            index(b.x1, self.origin.0, self.nx) + 1,
        );
        let (j0, j1) = (
            index(b.z0, self.origin.1, self.nz),
            index(b.z1, self.origin.1, self.nz) + 1,
        );
        let b = *b;
        // The centre of cell (i, j) as `centre` computes it, without dividing the flat index.
        let (ox, oz) = self.origin;
        (j0..j1.min(self.nz)).flat_map(move |j| {
            let z = oz + (j as f64 + 0.5) * CELL;
            (i0..i1.min(self.nx))
                .filter(move |&i| b.contains(ox + (i as f64 + 0.5) * CELL, z))
                .map(move |i| j * self.nx + i)
        })
    }
}

/// The furniture of a whole house, per room, and the robot's start.
pub(super) struct Furnished {
    pub rooms: Vec<Vec<Placed>>,
    /// Start position (metres) and heading (degrees).
    pub start: ((f64, f64), f64),
}

/// A room's box in metres.
fn room_box(room: &PlanRoom) -> Bx {
    let r = room.rect;
    Bx {
        x0: metres(r.x0),
        z0: metres(r.z0),
        x1: metres(r.x1),
        z1: metres(r.z1),
    }
}

/// The door openings of room `index`: (side, from, to) in metres along the side's axis.
fn door_spans(plan: &Floorplan, index: usize) -> Vec<(Side, f64, f64)> {
    let room = &plan.rooms[index];
    let r = room.rect;
    plan.doors
        .iter()
        .filter_map(|d| {
            // Both rooms see the opening cut into room0's edge.
            if d.room0 != index && d.room1 != Some(index) {
                return None;
            }
            let edge = &plan.rooms[d.room0].edges[d.edge];
            let (p, q) = (edge.at(d.offset), edge.at(d.offset + d.width));
            let side = if p.0 == q.0 {
                if p.0 == r.x0 { Side::West } else { Side::East }
            } else if p.1 == r.z0 {
                Side::South
            } else {
                Side::North
            };
            let (from, to) = if side.runs_along_x() {
                (p.0.min(q.0), p.0.max(q.0))
            } else {
                (p.1.min(q.1), p.1.max(q.1))
            };
            Some((side, metres(from), metres(to)))
        })
        .collect()
}

/// The floor kept clear in front of a door.
fn door_zone(room: &Bx, side: Side, from: f64, to: f64, depth: f64) -> Bx {
    let (a, b) = (from - DOOR_ZONE_SIDE, to + DOOR_ZONE_SIDE);
    match side {
        Side::South => Bx {
            x0: a,
            x1: b,
            z0: room.z0,
            z1: room.z0 + depth,
        },
        Side::North => Bx {
            x0: a,
            x1: b,
            z0: room.z1 - depth,
            z1: room.z1,
        },
        Side::West => Bx {
            x0: room.x0,
            x1: room.x0 + depth,
            z0: a,
            z1: b,
        },
        Side::East => Bx {
            x0: room.x1 - depth,
            x1: room.x1,
            z0: a,
            z1: b,
        },
    }
}

/// Places the furniture of every room and chooses the robot's start.
pub(super) fn furnish<R: Rng>(
    plan: &Floorplan,
    radius: f64,
    size_of: &dyn Fn(&str) -> (f64, f64),
    rng: &mut R,
) -> Furnished {
    let mut rooms = Vec::with_capacity(plan.rooms.len());
    let mut grids = Vec::with_capacity(plan.rooms.len());
    for (index, room) in plan.rooms.iter().enumerate() {
        let bx = room_box(room);
        let spans = door_spans(plan, index);
        let grid = RoomGrid::new(&bx, &spans, radius);
        // A room whose defining pieces did not all fit is furnished afresh a few times, the last
        // times with less floor kept clear before its doors (the clearance grid still keeps
        // every door passable).
        let mut best: Option<(usize, Vec<Placed>)> = None;
        for attempt in 0..ROOM_ATTEMPTS {
            let depth = if attempt + 2 < ROOM_ATTEMPTS {
                DOOR_ZONE_DEPTH
            } else {
                DOOR_ZONE_MIN_DEPTH
            };
            let zones: Vec<Bx> = spans
                .iter()
                .map(|&(s, a, b)| door_zone(&bx, s, a, b, depth))
                .collect();
            let ctx = Ctx {
                room: &bx,
                zones: &zones,
                grid: &grid,
            };
            let (required, placed) = furnish_room(&ctx, room.kind, size_of, rng);
            let all = required == required_count(room.kind);
            if best.as_ref().is_none_or(|b| required > b.0) {
                best = Some((required, placed));
            }
            if all {
                break;
            }
        }
        rooms.push(best.map(|b| b.1).unwrap_or_default());
        grids.push(grid);
    }
    let start = choose_start(&grids, &rooms, rng);
    Furnished { rooms, start }
}

/// How often a room is furnished afresh when a defining piece does not fit.
const ROOM_ATTEMPTS: usize = 5;

fn required_count(kind: RoomKind) -> usize {
    room_furniture(kind).iter().filter(|f| f.1 >= 1.0).count()
}

/// One furnishing of a room: the pieces placed and how many of them are defining ones.
fn furnish_room<R: Rng>(
    ctx: &Ctx<'_>,
    kind: RoomKind,
    size_of: &dyn Fn(&str) -> (f64, f64),
    rng: &mut R,
) -> (usize, Vec<Placed>) {
    let mut placed: Vec<Placed> = Vec::new();
    let mut required = 0;
    for &(object_type, p, rule) in room_furniture(kind) {
        if p < 1.0 && !rng.random_bool(p) {
            continue;
        }
        let tries = if p >= 1.0 { 40 } else { 16 };
        if let Some(piece) = place(
            ctx,
            &placed,
            object_type,
            size_of(object_type),
            rule,
            tries,
            rng,
        ) {
            placed.push(piece);
            required += usize::from(p >= 1.0);
        }
    }
    (required, placed)
}

/// What a placement must respect in its room.
struct Ctx<'a> {
    room: &'a Bx,
    zones: &'a [Bx],
    grid: &'a RoomGrid,
}

fn place<R: Rng>(
    ctx: &Ctx<'_>,
    placed: &[Placed],
    object_type: &'static str,
    size: (f64, f64),
    rule: Rule,
    tries: usize,
    rng: &mut R,
) -> Option<Placed> {
    let anchor = |t: &str| {
        placed
            .iter()
            .find(|p| p.object_type == t && p.side.is_some())
    };
    for attempt in 0..tries {
        // Relations are tried first; later attempts fall back to any wall.
        let relational = attempt < tries / 2;
        let candidate = match rule {
            Rule::Wall => against_wall(ctx.room, size, None, None, rng),
            Rule::WallCentred => {
                let side = *SIDES.choose(rng)?;
                let at = relational.then(|| 0.5 + rng.random_range(-0.1..0.1));
                against_wall(ctx.room, size, Some(side), at, rng)
            }
            Rule::Beside(t) => match anchor(t) {
                Some(a) if relational => beside(ctx.room, a, size, rng.random_bool(0.5)),
                _ => against_wall(ctx.room, size, None, None, rng),
            },
            Rule::Facing(t) => match anchor(t) {
                Some(a) if relational => facing_piece(ctx.room, a, size, rng),
                _ => against_wall(ctx.room, size, None, None, rng),
            },
            Rule::InFrontOf(t) => match anchor(t) {
                Some(a) if relational => Some(in_front_of(a, size)),
                _ => middle(ctx.room, size, rng),
            },
            // A table that fits nowhere in the middle goes against a wall.
            Rule::Middle if relational => middle(ctx.room, size, rng),
            Rule::Middle => against_wall(ctx.room, size, None, None, rng),
            Rule::AtTable => {
                let table = placed.iter().find(|p| p.object_type == "DiningTable")?;
                at_table(table, size, rng)
            }
        };
        let Some(mut piece) = candidate else { continue };
        piece.object_type = object_type;
        if acceptable(ctx, placed, &piece, rule) {
            return Some(piece);
        }
    }
    None
}

/// Whether `piece` fits: inside the room clear of walls, off the door zones, clear of the other
/// pieces, and leaving everything in the room accessible.
fn acceptable(ctx: &Ctx<'_>, placed: &[Placed], piece: &Placed, rule: Rule) -> bool {
    let inner = ctx.room.grow(-WALL_GAP + 1e-9);
    if !piece.bx.within(&inner) || ctx.zones.iter().any(|z| piece.bx.near(z, 0.0)) {
        return false;
    }
    // Free-standing tables keep a walkway round them; pieces against walls may stand close.
    let walkway = rule == Rule::Middle && piece.side.is_none();
    let gap = if walkway { WALKWAY } else { 0.02 };
    if placed.iter().any(|p| piece.bx.near(&p.bx, gap)) {
        return false;
    }
    if walkway && !piece.bx.within(&ctx.room.grow(-(WALL_HALF + WALKWAY))) {
        return false;
    }
    let mut boxes: Vec<Bx> = placed.iter().map(|p| p.bx).collect();
    boxes.push(piece.bx);
    ctx.grid.all_accessible(&boxes)
}

/// The piece's extent on the floor for a heading.
fn extent(size: (f64, f64), yaw: f64) -> (f64, f64) {
    if yaw == 90.0 || yaw == 270.0 {
        (size.1, size.0)
    } else {
        size
    }
}

/// A piece standing against `side` with its centre at fraction `at` along the free stretch of
/// the wall (random side and place when `None`).
fn against_wall<R: Rng>(
    room: &Bx,
    size: (f64, f64),
    side: Option<Side>,
    at: Option<f64>,
    rng: &mut R,
) -> Option<Placed> {
    let side = match side {
        Some(s) => s,
        None => *SIDES.choose(rng)?,
    };
    let (lo, hi) = if side.runs_along_x() {
        (room.x0, room.x1)
    } else {
        (room.z0, room.z1)
    };
    let (lo, hi) = (lo + WALL_GAP + size.0 / 2.0, hi - WALL_GAP - size.0 / 2.0);
    if hi < lo {
        return None;
    }
    let t = at.unwrap_or_else(|| rng.random_range(0.0..=1.0));
    let along = lo + (hi - lo) * t;
    Some(on_wall(room, side, along, size))
}

/// A piece against `side` centred at `along` (metres along the wall's axis).
fn on_wall(room: &Bx, side: Side, along: f64, size: (f64, f64)) -> Placed {
    let off = WALL_GAP + size.1 / 2.0;
    let center = match side {
        Side::South => (along, room.z0 + off),
        Side::North => (along, room.z1 - off),
        Side::West => (room.x0 + off, along),
        Side::East => (room.x1 - off, along),
    };
    let yaw = side.yaw();
    Placed {
        object_type: "",
        center,
        yaw,
        size,
        bx: Bx::around(center, extent(size, yaw)),
        side: Some(side),
    }
}

/// A piece against the same wall as `anchor`, touching it on the left or right.
fn beside(room: &Bx, anchor: &Placed, size: (f64, f64), left: bool) -> Option<Placed> {
    let side = anchor.side?;
    let (a_lo, a_hi) = if side.runs_along_x() {
        (anchor.bx.x0, anchor.bx.x1)
    } else {
        (anchor.bx.z0, anchor.bx.z1)
    };
    let along = if left {
        a_lo - 0.05 - size.0 / 2.0
    } else {
        a_hi + 0.05 + size.0 / 2.0
    };
    Some(on_wall(room, side, along, size))
}

/// A piece against the wall opposite `anchor`, roughly in line with it.
fn facing_piece<R: Rng>(
    room: &Bx,
    anchor: &Placed,
    size: (f64, f64),
    rng: &mut R,
) -> Option<Placed> {
    let side = anchor.side?.opposite();
    let along = if side.runs_along_x() {
        anchor.center.0
    } else {
        anchor.center.1
    };
    Some(on_wall(
        room,
        side,
        along + rng.random_range(-0.3..0.3),
        size,
    ))
}

/// A free-standing piece in front of `anchor`, with the same heading.
fn in_front_of(anchor: &Placed, size: (f64, f64)) -> Placed {
    let (fx, fz) = facing(anchor.yaw);
    let d = anchor.size.1 / 2.0 + COFFEE_TABLE_GAP + size.1 / 2.0;
    let center = (anchor.center.0 + fx * d, anchor.center.1 + fz * d);
    Placed {
        object_type: "",
        center,
        yaw: anchor.yaw,
        size,
        bx: Bx::around(center, extent(size, anchor.yaw)),
        side: None,
    }
}

/// A chair at one of the long sides of `table`, facing it.
fn at_table<R: Rng>(table: &Placed, size: (f64, f64), rng: &mut R) -> Option<Placed> {
    // The table's long sides face along its own ±z.
    let (fx, fz) = facing(table.yaw);
    let sign = if rng.random_bool(0.5) { 1.0 } else { -1.0 };
    let d = table.size.1 / 2.0 + 0.05 + size.1 / 2.0;
    let slide = rng.random_range(-0.3..=0.3) * (table.size.0 - size.0).max(0.0);
    // Along the long side: the table's local x axis.
    let (ax, az) = (fz, -fx);
    let center = (
        table.center.0 + sign * fx * d + ax * slide,
        table.center.1 + sign * fz * d + az * slide,
    );
    // Facing the table: opposite to the direction we moved out.
    let yaw = if sign > 0.0 {
        (table.yaw + 180.0) % 360.0
    } else {
        table.yaw
    };
    Some(Placed {
        object_type: "",
        center,
        yaw,
        size,
        bx: Bx::around(center, extent(size, yaw)),
        side: None,
    })
}

/// A free-standing piece near the middle of the room, its long side along the room's.
fn middle<R: Rng>(room: &Bx, size: (f64, f64), rng: &mut R) -> Option<Placed> {
    let (w, d) = (room.x1 - room.x0, room.z1 - room.z0);
    let long_x = (w >= d) == (size.0 >= size.1);
    let yaw = if long_x { 0.0 } else { 90.0 };
    let ext = extent(size, yaw);
    let slack_x = ((w - ext.0) / 2.0 - WALKWAY - WALL_HALF).max(0.0);
    let slack_z = ((d - ext.1) / 2.0 - WALKWAY - WALL_HALF).max(0.0);
    let center = (
        (room.x0 + room.x1) / 2.0 + rng.random_range(-1.0..=1.0) * slack_x * 0.5,
        (room.z0 + room.z1) / 2.0 + rng.random_range(-1.0..=1.0) * slack_z * 0.5,
    );
    Some(Placed {
        object_type: "",
        center,
        yaw,
        size,
        bx: Bx::around(center, ext),
        side: None,
    })
}

/// A start pose on free floor with room to turn: a random room, a random reachable cell away from
/// the walls whose neighbours are reachable too, a heading along an axis. Crowded houses settle
/// for less room around the start, never for a start off the free floor.
fn choose_start<R: Rng>(
    grids: &[RoomGrid],
    rooms: &[Vec<Placed>],
    rng: &mut R,
) -> ((f64, f64), f64) {
    let yaw = *[0.0, 90.0, 180.0, 270.0].choose(rng).unwrap_or(&0.0);
    let mut order: Vec<usize> = (0..grids.len()).collect();
    order.shuffle(rng);
    let reachable: Vec<Option<Vec<bool>>> = grids
        .iter()
        .zip(rooms)
        .map(|(grid, placed)| {
            let boxes: Vec<Bx> = placed.iter().map(|p| p.bx).collect();
            grid.reachable(&boxes)
        })
        .collect();
    // (cells of free neighbourhood around the start, clearance from walls in metres; `None`
    // allows a doorway, the last resort in a room that furniture fills up to its door)
    let stages = [
        (3, Some(START_WALL_CLEARANCE)),
        (2, Some(0.0)),
        (1, Some(0.0)),
        (0, Some(0.0)),
        (0, None),
    ];
    for (margin, clearance) in stages {
        for &r in &order {
            let (grid, Some(seen)) = (&grids[r], &reachable[r]) else {
                continue;
            };
            // Out of the wall band, so that the start is never in a doorway.
            let inner = Bx {
                x0: grid.origin.0,
                z0: grid.origin.1,
                x1: grid.origin.0 + grid.nx as f64 * CELL,
                z1: grid.origin.1 + grid.nz as f64 * CELL,
            }
            .grow(clearance.map_or(0.0, |c| -c.max(WALL_HALF + grid.inflate)));
            let roomy = |c: usize| {
                let (x, z) = grid.centre(c);
                let (i, j) = ((c % grid.nx) as isize, (c / grid.nx) as isize);
                inner.contains(x, z)
                    && (-margin..=margin).all(|di| {
                        (-margin..=margin).all(|dj| {
                            let (a, b) = (i + di, j + dj);
                            a >= 0
                                && b >= 0
                                && (a as usize) < grid.nx
                                && (b as usize) < grid.nz
                                && seen[b as usize * grid.nx + a as usize]
                        })
                    })
            };
            let cells: Vec<usize> = (0..seen.len()).filter(|&c| roomy(c)).collect();
            if let Some(&c) = cells.choose(rng) {
                return (grid.centre(c), yaw);
            }
        }
    }
    // Unreachable in practice: every room keeps a way between its doors. The middle of the first
    // room is still on its floor.
    let centre = grids.first().map_or((0.5, 0.5), |g| {
        (
            g.origin.0 + g.nx as f64 * CELL / 2.0,
            g.origin.1 + g.nz as f64 * CELL / 2.0,
        )
    });
    (centre, yaw)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pieces_against_walls_face_into_the_room() {
        let room = Bx {
            x0: 0.0,
            z0: 0.0,
            x1: 4.0,
            z1: 3.0,
        };
        for side in SIDES {
            let p = on_wall(&room, side, 1.5, (1.0, 0.5));
            let (fx, fz) = facing(p.yaw);
            let ahead = (p.center.0 + fx, p.center.1 + fz);
            let behind = (p.center.0 - fx, p.center.1 - fz);
            assert!(room.contains(ahead.0, ahead.1), "{side:?} faces out");
            assert!(
                !room.contains(behind.0, behind.1),
                "{side:?} back not at the wall"
            );
            assert!(p.bx.within(&room.grow(-WALL_HALF)));
        }
    }

    #[test]
    fn a_blocked_doorway_is_detected() {
        let room = Bx {
            x0: 0.0,
            z0: 0.0,
            x1: 3.0,
            z1: 3.0,
        };
        let grid = RoomGrid::new(
            &room,
            &[(Side::South, 1.0, 2.0), (Side::North, 1.0, 2.0)],
            0.15,
        );
        assert!(!grid.anchors.is_empty());
        assert!(grid.all_accessible(&[]));
        // A wall-to-wall cabinet across the middle separates the doors.
        let barrier = Bx {
            x0: 0.0,
            z0: 1.4,
            x1: 3.0,
            z1: 1.6,
        };
        assert!(!grid.all_accessible(&[barrier]));
        // A narrow one leaves a way round.
        let small = Bx {
            x0: 0.0,
            z0: 1.4,
            x1: 1.5,
            z1: 1.6,
        };
        assert!(grid.all_accessible(&[small]));
    }
}
