//! Occupancy grids: a house turned into square cells the robot can or cannot stand in.
//!
//! A cell is free when its centre lies on some room's floor, away from every wall (drawn with a
//! thickness, door openings cut through), outside every furniture footprint, and at least the
//! robot radius from all of those. Each container gets an *access cell*, the free cell the robot
//! drives to before searching it; [`Distances`](crate::Distances) measures travel between them.
//!
//! The grid is built once per house and is cheap to clone (the cells are shared), so the distance
//! matrix can keep it for retrieving paths later.

use std::sync::Arc;

use serde::{Deserialize, Serialize};
use tracing::{debug, warn};

use crate::error::{Result, WorldError};
use crate::geometry::{Footprint, Point, Rect};
use crate::house::House;
use crate::map::{MapCell, OccupancyMap};
use crate::rules::AccessRule;

/// Parameters of the occupancy grid.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GridParams {
    /// Cell size, metres (the paper's 0.05 m by default).
    pub resolution: f64,
    /// Thickness given to walls, metres. ProcTHOR walls are zero-thickness faces (one per room on
    /// the same line) with furniture standing right against them, so the faithful wall is as thin
    /// as the grid allows: the default 0.05 m is one cell. Walls are never drawn thinner than the
    /// cells their line passes through, so rooms cannot leak into each other at any resolution.
    /// (At 0.1 m, four more containers of multiroom-val150 end up more than 0.5 m from their
    /// access cell at the default robot radius.)
    pub wall_thickness: f64,
    /// Robot radius by which obstacles are inflated, metres. The default 0.18 m is the LoCoBot of
    /// the paper's real-robot experiments (a Kobuki base, 0.35 m across). With the asset
    /// database, every container of multiroom-val150 is reachable for radii up to 0.2 m; at 0.25 m
    /// furniture closes off rooms in three houses.
    pub robot_radius: f64,
    /// Where the robot stands to search a container that names no standing point of its own.
    #[serde(default)]
    pub access: AccessRule,
}

impl Default for GridParams {
    fn default() -> Self {
        Self {
            resolution: 0.05,
            wall_thickness: 0.05,
            robot_radius: 0.18,
            access: AccessRule::Footprint,
        }
    }
}

impl GridParams {
    /// Smallest resolution accepted, metres: finer grids of whole houses do not fit in memory.
    pub const MIN_RESOLUTION: f64 = crate::raster::MIN_RESOLUTION;

    fn check(&self, house: &str) -> Result<()> {
        let bad = |message: String| {
            Err(WorldError::Grid {
                house: house.to_owned(),
                message,
            })
        };
        if !(self.resolution.is_finite() && self.resolution >= Self::MIN_RESOLUTION) {
            return bad(format!(
                "grid resolution {} m is not a number ≥ {} m",
                self.resolution,
                Self::MIN_RESOLUTION
            ));
        }
        if !(self.wall_thickness.is_finite() && self.wall_thickness >= 0.0) {
            return bad(format!(
                "wall thickness {} m is not a number ≥ 0",
                self.wall_thickness
            ));
        }
        if !(self.robot_radius.is_finite() && self.robot_radius >= 0.0) {
            return bad(format!(
                "robot radius {} m is not a number ≥ 0",
                self.robot_radius
            ));
        }
        Ok(())
    }
}

/// A cell of the grid: column `x` (along world x) and row `z` (along world z), from the grid's
/// [`origin`](OccupancyGrid::origin).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct Cell {
    /// Column, along world x.
    pub x: u32,
    /// Row, along world z.
    pub z: u32,
}

impl Cell {
    /// The cell in column `x`, row `z`.
    pub const fn new(x: u32, z: u32) -> Self {
        Self { x, z }
    }
}

/// What occupies a cell, for navigation and drawing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum CellKind {
    /// Not on any room's floor.
    Outside = 0,
    /// Inside a wall.
    Wall = 1,
    /// Inside a piece of furniture (a container or an obstacle).
    Furniture = 2,
    /// Floor, but closer than the robot radius to an obstacle: the robot's centre cannot be here.
    Clearance = 3,
    /// Floor the robot's centre can occupy.
    Free = 4,
}

impl CellKind {
    fn from_u8(v: u8) -> CellKind {
        match v & KIND_MASK {
            1 => CellKind::Wall,
            2 => CellKind::Furniture,
            3 => CellKind::Clearance,
            4 => CellKind::Free,
            _ => CellKind::Outside,
        }
    }

    /// True for walls, furniture and everything off the floor.
    pub fn is_obstacle(self) -> bool {
        matches!(
            self,
            CellKind::Outside | CellKind::Wall | CellKind::Furniture
        )
    }
}

const KIND_MASK: u8 = 0x07;
/// Set on free cells connected to the start cell.
const REACHABLE: u8 = 0x80;
const NO_ROOM: u8 = u8::MAX;
pub use crate::raster::MAX_CELLS;

/// The origin, width and height (cells) of the grid over `bounds`: the bounds plus an Outside
/// margin wide enough that inflation never needs to look past the border.
fn layout(bounds: crate::geometry::Rect, params: &GridParams) -> (Point, f64, f64) {
    let res = params.resolution;
    let pad = (params.robot_radius / res).ceil() + 2.0;
    let origin = Point::new(bounds.min.x - pad * res, bounds.min.z - pad * res);
    let w = (bounds.width() / res).ceil() + 2.0 * pad + 1.0;
    let h = (bounds.depth() / res).ceil() + 2.0 * pad + 1.0;
    (origin, w, h)
}

/// A free/occupied grid over a house, with the robot's start cell and an access cell for every
/// container.
///
/// Cells are square, `resolution` metres wide; cell `(x, z)` covers
/// `[origin.x + x·res, origin.x + (x+1)·res) × [origin.z + z·res, origin.z + (z+1)·res)`. Whether a
/// cell is on a floor, in a wall or in furniture is decided by its centre. The grid has a margin of
/// `Outside` cells around the house, so every cell on its border is an obstacle.
#[derive(Clone, Debug)]
pub struct OccupancyGrid {
    inner: Arc<Inner>,
}

#[derive(Clone, Debug)]
struct Inner {
    params: GridParams,
    origin: Point,
    width: u32,
    height: u32,
    /// One byte per cell, row-major (index `z · width + x`): a [`CellKind`] in the low bits and
    /// [`REACHABLE`].
    cells: Vec<u8>,
    /// The room of each cell's centre (index into `House::rooms`), [`NO_ROOM`] for none. Walls and
    /// furniture keep the room of the floor under them.
    rooms: Vec<u8>,
    free: usize,
    reachable: usize,
    start: u32,
    start_moved: bool,
    access: Vec<Option<Access>>,
    closed_doors: Vec<usize>,
}

#[derive(Clone, Copy, Debug)]
struct Access {
    cell: u32,
    /// Distance from the cell's centre to the footprint, metres.
    gap: f64,
}

impl OccupancyGrid {
    /// Builds the grid of `house`: floors, walls with door openings, furniture footprints, all
    /// inflated by the robot radius; then the start cell and each container's access cell.
    ///
    /// Containers that cannot be reached from the start get no access cell; the grid is still
    /// returned (so it can be drawn), and [`Distances::compute`](crate::Distances::compute) reports
    /// them.
    ///
    /// # Errors
    /// [`WorldError::Grid`] for bad parameters, a house without rooms, non-finite geometry, a grid
    /// too large for memory, more than 254 rooms, or a start off the grid or without any free cell.
    pub fn build(house: &House, params: &GridParams) -> Result<OccupancyGrid> {
        if let Some(map) = &house.map {
            return Self::build_on_map(house, params, map);
        }
        params.check(&house.name)?;
        let err = |message: String| WorldError::Grid {
            house: house.name.clone(),
            message,
        };
        if house.rooms.len() >= NO_ROOM as usize {
            return Err(err(format!(
                "{} rooms; the grid handles at most 254",
                house.rooms.len()
            )));
        }
        check_finite(house).map_err(err)?;
        let bounds = house
            .bounds()
            .ok_or_else(|| err("the house has no rooms".into()))?;

        let res = params.resolution;
        let radius_cells = params.robot_radius / res;
        let (origin, w, h) = layout(bounds, params);
        if w * h > MAX_CELLS as f64 {
            return Err(err(format!(
                "a {w}×{h}-cell grid exceeds the limit of {MAX_CELLS} cells; use a coarser resolution than {res} m"
            )));
        }
        let (width, height) = (w as u32, h as u32);
        let mut g = Inner::outside(*params, origin, width, height);
        g.fill_floors(house, true);
        g.draw_walls(house);
        g.draw_furniture(house);
        g.inflate_outside(radius_cells, false);
        g.finish(house)
    }

    /// How many cells the grid of `house` would have (without a map), before building it: a
    /// cheap check of what a build would cost. `None` for a house without rooms.
    pub fn planned_cells(house: &House, params: &GridParams) -> Option<f64> {
        let (_, w, h) = layout(house.bounds()?, params);
        Some(w * h)
    }

    /// The grid of a house that carries a robot's occupancy map: the map's cells (free, occupied
    /// as walls, unknown as outside) at the map's own resolution, rooms named by the polygons,
    /// furniture footprints drawn on top, everything inflated by the robot radius.
    fn build_on_map(
        house: &House,
        params: &GridParams,
        map: &OccupancyMap,
    ) -> Result<OccupancyGrid> {
        let err = |message: String| WorldError::Grid {
            house: house.name.clone(),
            message,
        };
        if !map.is_consistent() {
            return Err(err(format!("the map {} is inconsistent", map.source)));
        }
        // The map fixes the cell size: resampling a robot's map would move its walls.
        let params = GridParams {
            resolution: map.resolution,
            ..*params
        };
        params.check(&house.name)?;
        if house.rooms.len() >= NO_ROOM as usize {
            return Err(err(format!(
                "{} rooms; the grid handles at most 254",
                house.rooms.len()
            )));
        }
        check_finite(house).map_err(err)?;
        let res = params.resolution;
        let pad = ((params.robot_radius / res).ceil() + 2.0) as u32;
        let (width, height) = (map.width + 2 * pad, map.height + 2 * pad);
        if u64::from(width) * u64::from(height) > MAX_CELLS {
            return Err(err(format!(
                "the map {} is {}×{} cells, over the limit of {MAX_CELLS}",
                map.source, map.width, map.height
            )));
        }
        let origin = Point::new(
            map.origin.x - f64::from(pad) * res,
            map.origin.z - f64::from(pad) * res,
        );
        let mut g = Inner::outside(params, origin, width, height);
        for z in 0..map.height {
            for x in 0..map.width {
                let kind = match map.cells[z as usize * map.width as usize + x as usize] {
                    MapCell::Free => CellKind::Free,
                    MapCell::Occupied => CellKind::Wall,
                    MapCell::Unknown => CellKind::Outside,
                };
                g.cells[(z + pad) as usize * width as usize + (x + pad) as usize] = kind as u8;
            }
        }
        g.fill_floors(house, false);
        g.draw_furniture(house);
        g.inflate_outside(params.robot_radius / res, true);
        g.finish(house)
    }

    /// The parameters the grid was built with.
    pub fn params(&self) -> &GridParams {
        &self.inner.params
    }

    /// Cell size, metres.
    pub fn resolution(&self) -> f64 {
        self.inner.params.resolution
    }

    /// Number of columns (along x).
    pub fn width(&self) -> u32 {
        self.inner.width
    }

    /// Number of rows (along z).
    pub fn height(&self) -> u32 {
        self.inner.height
    }

    /// Number of cells.
    pub fn cell_count(&self) -> usize {
        self.inner.cells.len()
    }

    /// World coordinates of the corner of cell `(0, 0)` with the smallest x and z.
    pub fn origin(&self) -> Point {
        self.inner.origin
    }

    /// The area the grid covers, metres.
    pub fn extent(&self) -> Rect {
        let g = &self.inner;
        let res = g.params.resolution;
        Rect {
            min: g.origin,
            max: Point::new(
                g.origin.x + f64::from(g.width) * res,
                g.origin.z + f64::from(g.height) * res,
            ),
        }
    }

    /// The cell holding `p`, or `None` off the grid (or for a non-finite point).
    pub fn cell_of(&self, p: Point) -> Option<Cell> {
        let g = &self.inner;
        let res = g.params.resolution;
        let x = ((p.x - g.origin.x) / res).floor();
        let z = ((p.z - g.origin.z) / res).floor();
        (x >= 0.0 && z >= 0.0 && x < f64::from(g.width) && z < f64::from(g.height))
            .then(|| Cell::new(x as u32, z as u32))
    }

    /// The centre of `cell`, world coordinates.
    pub fn center(&self, cell: Cell) -> Point {
        self.inner.center(cell.x, cell.z)
    }

    /// What occupies `cell`; `Outside` for a cell off the grid.
    pub fn kind(&self, cell: Cell) -> CellKind {
        self.inner.index(cell).map_or(CellKind::Outside, |i| {
            CellKind::from_u8(self.inner.cells[i])
        })
    }

    /// True when the robot's centre can be in `cell`.
    pub fn is_free(&self, cell: Cell) -> bool {
        self.kind(cell) == CellKind::Free
    }

    /// True when `cell` is free and connected to the start cell.
    pub fn is_reachable(&self, cell: Cell) -> bool {
        self.inner
            .index(cell)
            .is_some_and(|i| self.inner.cells[i] & REACHABLE != 0)
    }

    /// The room (index into [`House::rooms`]) whose floor holds the centre of `cell`.
    pub fn room(&self, cell: Cell) -> Option<usize> {
        self.inner
            .index(cell)
            .map(|i| self.inner.rooms[i])
            .filter(|&r| r != NO_ROOM)
            .map(usize::from)
    }

    /// The reachable cell nearest to `p` by centre distance (`p`'s own cell when it is
    /// reachable; ties to the lowest index), with that distance in metres; with `room`, only
    /// cells of that room count. Where a robot stands when sent to a point of the floor. `None`
    /// when no cell qualifies or `p` is not finite.
    pub fn nearest_reachable(&self, p: Point, room: Option<usize>) -> Option<(Cell, f64)> {
        if !p.is_finite() {
            return None;
        }
        let g = &self.inner;
        let w = g.width as usize;
        g.cells
            .iter()
            .enumerate()
            .filter(|&(i, &c)| {
                c & REACHABLE != 0 && room.is_none_or(|r| usize::from(g.rooms[i]) == r)
            })
            .map(|(i, _)| {
                let centre = g.center((i % w) as u32, (i / w) as u32);
                (centre.distance(p), i)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
            .map(|(d, i)| (g.cell(i as u32), d))
    }

    /// Number of free cells.
    pub fn free_count(&self) -> usize {
        self.inner.free
    }

    /// Number of free cells connected to the start cell.
    pub fn reachable_count(&self) -> usize {
        self.inner.reachable
    }

    /// Number of cells of each kind, indexed by `CellKind as usize`.
    pub fn kind_counts(&self) -> [usize; 5] {
        let mut counts = [0; 5];
        for &c in &self.inner.cells {
            counts[CellKind::from_u8(c) as usize] += 1;
        }
        counts
    }

    /// Every cell with its kind, row by row: what a drawing needs.
    pub fn cells(&self) -> impl Iterator<Item = (Cell, CellKind)> + '_ {
        let w = self.inner.width as usize;
        self.inner.cells.iter().enumerate().map(move |(i, &c)| {
            (
                Cell::new((i % w) as u32, (i / w) as u32),
                CellKind::from_u8(c),
            )
        })
    }

    /// The robot's start cell: the cell of the start pose, or the nearest free cell when that one
    /// is not free (see [`start_moved`](Self::start_moved)).
    pub fn start_cell(&self) -> Cell {
        self.inner.cell(self.inner.start)
    }

    /// This grid with the robot starting at `position` instead (its cell chosen as
    /// [`build`](Self::build) would choose it), when that changes nothing else: the new start
    /// cell is reachable from the old one, so the same cells are reachable and every container
    /// keeps its access cell. `Ok(None)` when the new start is on a part of the floor the old
    /// one cannot reach: only a new build says what is reachable from there.
    ///
    /// # Errors
    /// [`WorldError::Grid`] as [`build`](Self::build) for a start outside the grid or a grid
    /// without free cells; `house` names the house in it.
    pub fn with_start(&self, house: &str, position: Point) -> Result<Option<OccupancyGrid>> {
        let (start, moved) = self.inner.start_for(position, house)?;
        if !Self::raw_reachable(self.inner.cells[start as usize]) {
            return Ok(None);
        }
        let mut inner = (*self.inner).clone();
        inner.start = start;
        inner.start_moved = moved;
        Ok(Some(OccupancyGrid {
            inner: Arc::new(inner),
        }))
    }

    /// True when the start pose's own cell was not free and the start cell is the nearest free one.
    pub fn start_moved(&self) -> bool {
        self.inner.start_moved
    }

    /// The access cell of container `container`: the reachable free cell nearest to its footprint,
    /// in its own room when it has one. `None` when no such cell exists (or for a bad index).
    pub fn access_cell(&self, container: usize) -> Option<Cell> {
        self.inner
            .access
            .get(container)
            .copied()
            .flatten()
            .map(|a| self.inner.cell(a.cell))
    }

    /// Distance, metres, from container `container`'s access cell centre to its footprint: how
    /// far the robot stays from the furniture it searches.
    pub fn access_gap(&self, container: usize) -> Option<f64> {
        self.inner
            .access
            .get(container)
            .copied()
            .flatten()
            .map(|a| a.gap)
    }

    /// Number of containers the grid was built for.
    pub fn container_count(&self) -> usize {
        self.inner.access.len()
    }

    /// Containers without an access cell: no free cell of their room is reachable from the start.
    pub fn unreachable_containers(&self) -> Vec<usize> {
        (0..self.inner.access.len())
            .filter(|&i| self.inner.access[i].is_none())
            .collect()
    }

    /// Interior doors (indices into [`House::doors`]) with no free cell in their opening: narrower
    /// than the robot, or blocked by furniture. Doors to the outside are not checked.
    pub fn closed_doors(&self) -> &[usize] {
        &self.inner.closed_doors
    }

    pub(crate) fn cell_at(&self, index: u32) -> Cell {
        self.inner.cell(index)
    }

    pub(crate) fn start_index(&self) -> u32 {
        self.inner.start
    }

    pub(crate) fn access_index(&self, container: usize) -> Option<u32> {
        self.inner
            .access
            .get(container)
            .copied()
            .flatten()
            .map(|a| a.cell)
    }

    /// Raw cell bytes for the path search.
    pub(crate) fn raw_cells(&self) -> &[u8] {
        &self.inner.cells
    }

    /// True for a raw cell byte the robot can drive through (free and connected to the start).
    pub(crate) const fn raw_reachable(byte: u8) -> bool {
        byte & REACHABLE != 0
    }
}

fn check_finite(house: &House) -> std::result::Result<(), String> {
    for (i, r) in house.rooms.iter().enumerate() {
        if r.floor.vertices.iter().any(|p| !p.is_finite()) {
            return Err(format!(
                "room {} ({}) has a non-finite floor vertex",
                i, r.id
            ));
        }
    }
    for w in &house.walls {
        if !(w.start.is_finite() && w.end.is_finite()) {
            return Err(format!("wall {} has a non-finite endpoint", w.id));
        }
    }
    for d in &house.doors {
        if !(d.start.is_finite() && d.end.is_finite()) {
            return Err(format!("door {} has a non-finite endpoint", d.id));
        }
    }
    let footprints = house
        .containers
        .iter()
        .map(|c| (&c.id, &c.footprint))
        .chain(house.obstacles.iter().map(|o| (&o.id, &o.footprint)));
    for (id, f) in footprints {
        if !(f.center.is_finite()
            && f.size_x.is_finite()
            && f.size_z.is_finite()
            && f.yaw_deg.is_finite())
        {
            return Err(format!("object {id} has a non-finite footprint"));
        }
    }
    if !house.start.position.is_finite() {
        return Err("the start position is not finite".into());
    }
    Ok(())
}

/// Distance from `p` to the rotated rectangle `f` (0 inside).
fn footprint_distance(f: &Footprint, p: Point) -> f64 {
    // The same inverse rotation as `Footprint::contains`.
    let (s, c) = f.yaw_deg.to_radians().sin_cos();
    let (dx, dz) = (p.x - f.center.x, p.z - f.center.z);
    let lx = dx * c - dz * s;
    let lz = dx * s + dz * c;
    let ox = (lx.abs() - f.size_x.abs() / 2.0).max(0.0);
    let oz = (lz.abs() - f.size_z.abs() / 2.0).max(0.0);
    ox.hypot(oz)
}

impl Inner {
    /// A grid of `width × height` outside cells, nothing placed yet.
    fn outside(params: GridParams, origin: Point, width: u32, height: u32) -> Inner {
        let n = width as usize * height as usize;
        Inner {
            params,
            origin,
            width,
            height,
            cells: vec![CellKind::Outside as u8; n],
            rooms: vec![NO_ROOM; n],
            free: 0,
            reachable: 0,
            start: 0,
            start_moved: false,
            access: Vec::new(),
            closed_doors: Vec::new(),
        }
    }

    /// The steps after the cells are drawn: counts, start, reachability, doors, access cells.
    fn finish(mut self, house: &House) -> Result<OccupancyGrid> {
        self.free = self
            .cells
            .iter()
            .filter(|&&c| c == CellKind::Free as u8)
            .count();
        self.place_start(house)?;
        self.reachable = self.flood_from_start();
        self.closed_doors = self.find_closed_doors(house);
        self.access = house
            .containers
            .iter()
            .map(|c| match (c.access, self.params.access) {
                (Some(p), _) => self.access_at(p, &c.footprint),
                (None, AccessRule::Footprint) => self.nearest_reachable(&c.footprint, c.room),
                (None, AccessRule::NearestFree) => self.nearest_to_centre(&c.footprint),
            })
            .collect();
        for (i, a) in self.access.iter().enumerate() {
            if a.is_none() {
                debug!(house = %house.name, container = %house.container_label(i), "no reachable access cell");
            }
        }
        Ok(OccupancyGrid {
            inner: Arc::new(self),
        })
    }

    /// The access cell at a given standing point: its own cell, which must be reachable.
    fn access_at(&self, p: Point, f: &Footprint) -> Option<Access> {
        let res = self.params.resolution;
        let x = ((p.x - self.origin.x) / res).floor();
        let z = ((p.z - self.origin.z) / res).floor();
        if !(x >= 0.0 && z >= 0.0 && x < f64::from(self.width) && z < f64::from(self.height)) {
            return None;
        }
        let i = z as usize * self.width as usize + x as usize;
        (self.cells[i] & REACHABLE != 0).then(|| Access {
            cell: i as u32,
            gap: footprint_distance(f, self.center(x as u32, z as u32)),
        })
    }

    fn center(&self, x: u32, z: u32) -> Point {
        let res = self.params.resolution;
        Point::new(
            self.origin.x + (f64::from(x) + 0.5) * res,
            self.origin.z + (f64::from(z) + 0.5) * res,
        )
    }

    fn index(&self, cell: Cell) -> Option<usize> {
        (cell.x < self.width && cell.z < self.height)
            .then(|| cell.z as usize * self.width as usize + cell.x as usize)
    }

    fn cell(&self, index: u32) -> Cell {
        Cell::new(index % self.width, index / self.width)
    }

    /// Column range `[lo, hi)` of the cells whose centre x lies in `[x0, x1]`, clamped to the grid.
    fn columns(&self, x0: f64, x1: f64) -> (u32, u32) {
        let res = self.params.resolution;
        let lo = ((x0 - self.origin.x) / res - 0.5).ceil().max(0.0);
        let hi = ((x1 - self.origin.x) / res - 0.5).floor() + 1.0;
        (
            lo.min(f64::from(self.width)) as u32,
            hi.clamp(0.0, f64::from(self.width)) as u32,
        )
    }

    /// Row range `[lo, hi)` of the cells whose centre z lies in `[z0, z1]`, clamped to the grid.
    fn rows(&self, z0: f64, z1: f64) -> (u32, u32) {
        let res = self.params.resolution;
        let lo = ((z0 - self.origin.z) / res - 0.5).ceil().max(0.0);
        let hi = ((z1 - self.origin.z) / res - 0.5).floor() + 1.0;
        (
            lo.min(f64::from(self.height)) as u32,
            hi.clamp(0.0, f64::from(self.height)) as u32,
        )
    }

    /// Marks every cell whose centre is on a floor as free floor of that room, by scanlines: the
    /// same even-odd rule as `Polygon::contains`, one row at a time.
    fn fill_floors(&mut self, house: &House, mark_free: bool) {
        let res = self.params.resolution;
        let mut crossings = Vec::new();
        for (ri, room) in house.rooms.iter().enumerate() {
            let v = &room.floor.vertices;
            let Some(b) = room.floor.bounds() else {
                continue;
            };
            let (z_lo, z_hi) = self.rows(b.min.z, b.max.z);
            for z in z_lo..z_hi {
                let pz = self.origin.z + (f64::from(z) + 0.5) * res;
                crossings.clear();
                let mut j = v.len().wrapping_sub(1);
                for i in 0..v.len() {
                    let (a, c) = (v[i], v[j]);
                    if (a.z > pz) != (c.z > pz) {
                        crossings.push((c.x - a.x) * (pz - a.z) / (c.z - a.z) + a.x);
                    }
                    j = i;
                }
                crossings.sort_by(f64::total_cmp);
                for pair in crossings.chunks_exact(2) {
                    // Centres x with pair[0] <= x < pair[1] are inside.
                    let lo = ((pair[0] - self.origin.x) / res - 0.5).ceil().max(0.0);
                    let hi = ((pair[1] - self.origin.x) / res - 0.5).ceil();
                    let lo = lo.min(f64::from(self.width)) as usize;
                    let hi = hi.clamp(0.0, f64::from(self.width)) as usize;
                    let row = z as usize * self.width as usize;
                    for i in row + lo..row + hi.max(lo) {
                        if self.rooms[i] == NO_ROOM {
                            self.rooms[i] = ri as u8;
                            if mark_free {
                                self.cells[i] = CellKind::Free as u8;
                            }
                        }
                    }
                }
            }
        }
    }

    /// Half the drawn wall thickness: never thinner than the cells the wall line passes through
    /// (every such cell has its centre within res·√2/2 of the line), so a wall is a 4-connected
    /// band and nothing leaks through it diagonally.
    fn half_wall(&self) -> f64 {
        (self.params.wall_thickness / 2.0)
            .max(self.params.resolution * std::f64::consts::FRAC_1_SQRT_2)
    }

    /// Draws the walls, split where doors are cut into them, as rectangles `wall_thickness` deep
    /// (extended by half the thickness past the wall's own ends so corners close, flat at door
    /// jambs so a door keeps its width), and marks the floor within the robot radius of them as
    /// clearance, by exact distance from each cell centre.
    fn draw_walls(&mut self, house: &House) {
        let half = self.half_wall();
        let radius = self.params.robot_radius;
        let tol = half.max(self.params.resolution);
        for wall in &house.walls {
            let (dx, dz) = (wall.end.x - wall.start.x, wall.end.z - wall.start.z);
            let len = dx.hypot(dz);
            if len <= 0.0 {
                continue;
            }
            let (ux, uz) = (dx / len, dz / len);
            let local = |p: Point| {
                let (px, pz) = (p.x - wall.start.x, p.z - wall.start.z);
                (px * ux + pz * uz, px * uz - pz * ux)
            };
            // Door openings along this wall: doors lying on its line, whoever's wall they name
            // (the two rooms' copies of a shared wall are both cut).
            let mut cuts: Vec<(f64, f64)> = house
                .doors
                .iter()
                .filter_map(|d| {
                    let ((a0, c0), (a1, c1)) = (local(d.start), local(d.end));
                    (c0.abs() <= tol && c1.abs() <= tol && a0.max(a1) > 0.0 && a0.min(a1) < len)
                        .then(|| (a0.min(a1), a0.max(a1)))
                })
                .collect();
            cuts.sort_by(|a, b| a.0.total_cmp(&b.0));
            // The solid pieces between the cuts, each with its extent along the wall.
            let mut pieces = Vec::new();
            let mut from = -half;
            for (c0, c1) in cuts {
                if c0 > from {
                    pieces.push((from, c0));
                }
                from = from.max(c1);
            }
            if len + half > from {
                pieces.push((from, len + half));
            }
            for (s0, s1) in pieces {
                let reach = half + radius;
                let p0 = Point::new(wall.start.x + s0 * ux, wall.start.z + s0 * uz);
                let p1 = Point::new(wall.start.x + s1 * ux, wall.start.z + s1 * uz);
                self.for_cells_near(p0, p1, reach, |g, i, p| {
                    let (along, across) = local(p);
                    let ox = (s0 - along).max(along - s1).max(0.0);
                    let oz = (across.abs() - half).max(0.0);
                    let d = ox.hypot(oz);
                    if d <= 1e-12 {
                        g.cells[i] = CellKind::Wall as u8;
                    } else if d < radius && g.cells[i] == CellKind::Free as u8 {
                        g.cells[i] = CellKind::Clearance as u8;
                    }
                });
            }
        }
    }

    /// Calls `f(grid, index, centre)` for every cell whose centre is within `margin` of the
    /// bounding box of segment `a`–`b`.
    fn for_cells_near(
        &mut self,
        a: Point,
        b: Point,
        margin: f64,
        mut f: impl FnMut(&mut Inner, usize, Point),
    ) {
        let (x_lo, x_hi) = self.columns(a.x.min(b.x) - margin, a.x.max(b.x) + margin);
        let (z_lo, z_hi) = self.rows(a.z.min(b.z) - margin, a.z.max(b.z) + margin);
        for z in z_lo..z_hi {
            for x in x_lo..x_hi {
                let i = z as usize * self.width as usize + x as usize;
                let p = self.center(x, z);
                f(self, i, p);
            }
        }
    }

    /// Marks the cells whose centre is inside a footprint (and always the cell of its centre, so
    /// that furniture smaller than a cell still blocks) and the floor within the robot radius of
    /// it, by exact distance from each cell centre. Walls stay walls.
    fn draw_furniture(&mut self, house: &House) {
        let radius = self.params.robot_radius;
        let footprints = house
            .containers
            .iter()
            .map(|c| c.footprint)
            .chain(house.obstacles.iter().map(|o| o.footprint));
        for f in footprints {
            let Some(b) = Rect::around(f.corners()) else {
                continue;
            };
            let (x_lo, x_hi) = self.columns(b.min.x - radius, b.max.x + radius);
            let (z_lo, z_hi) = self.rows(b.min.z - radius, b.max.z + radius);
            for z in z_lo..z_hi {
                for x in x_lo..x_hi {
                    let i = z as usize * self.width as usize + x as usize;
                    let kind = self.cells[i];
                    if kind == CellKind::Wall as u8 {
                        continue;
                    }
                    let d = footprint_distance(&f, self.center(x, z));
                    if d <= 0.0 {
                        self.cells[i] = CellKind::Furniture as u8;
                    } else if d < radius && kind == CellKind::Free as u8 {
                        self.cells[i] = CellKind::Clearance as u8;
                    }
                }
            }
            let res = self.params.resolution;
            let cx = ((f.center.x - self.origin.x) / res).floor();
            let cz = ((f.center.z - self.origin.z) / res).floor();
            if cx >= 0.0 && cz >= 0.0 && cx < f64::from(self.width) && cz < f64::from(self.height) {
                let i = cz as usize * self.width as usize + cx as usize;
                if self.cells[i] != CellKind::Wall as u8 {
                    self.cells[i] = CellKind::Furniture as u8;
                }
            }
        }
    }

    /// Turns free cells whose centre is within the robot radius of an `Outside` cell's centre
    /// into clearance: the floor's own edge, where no wall runs along it. (Walls and furniture
    /// got their clearance exactly when drawn.) Stamping a disc around the outside cells that
    /// touch the floor suffices: the outside cell nearest to any free cell has a non-outside
    /// neighbour (one step towards the free cell is closer still).
    ///
    /// With `walls_too` (a robot's map, whose walls are cells rather than drawn lines) wall cells
    /// get the same disc.
    fn inflate_outside(&mut self, radius_cells: f64, walls_too: bool) {
        let r = radius_cells.floor() as i64;
        let r_sq = radius_cells * radius_cells;
        let w = self.width as i64;
        let disc: Vec<i64> = (-r..=r)
            .flat_map(|dz| (-r..=r).map(move |dx| (dx, dz)))
            .filter(|&(dx, dz)| ((dx * dx + dz * dz) as f64) < r_sq && (dx, dz) != (0, 0))
            .map(|(dx, dz)| dz * w + dx)
            .collect();
        if disc.is_empty() {
            return;
        }
        let outside = CellKind::Outside as u8;
        let wall = CellKind::Wall as u8;
        let (w, h) = (self.width as usize, self.height as usize);
        // The margin of Outside cells is wider than the disc and border cells are skipped (they
        // touch no floor), so no offset leaves the grid. The boundary is collected before
        // stamping: stamping turns free cells into clearance, which would hide later ones.
        let mut boundary = Vec::new();
        for z in 1..h.saturating_sub(1) {
            for x in 1..w.saturating_sub(1) {
                let i = z * w + x;
                if (self.cells[i] == outside || (walls_too && self.cells[i] == wall))
                    && [
                        i - 1,
                        i + 1,
                        i - w,
                        i + w,
                        i - w - 1,
                        i - w + 1,
                        i + w - 1,
                        i + w + 1,
                    ]
                    .iter()
                    .any(|&j| !CellKind::from_u8(self.cells[j]).is_obstacle())
                {
                    boundary.push(i);
                }
            }
        }
        for i in boundary {
            for &d in &disc {
                let j = (i as i64 + d) as usize;
                if let Some(c) = self.cells.get_mut(j)
                    && *c == CellKind::Free as u8
                {
                    *c = CellKind::Clearance as u8;
                }
            }
        }
    }

    fn place_start(&mut self, house: &House) -> Result<()> {
        let (start, moved) = self.start_for(house.start.position, &house.name)?;
        self.start = start;
        self.start_moved = moved;
        Ok(())
    }

    /// The start cell for a robot at `p`: its own cell when that is free, else the nearest free
    /// cell by centre distance (ties to the lowest index); and whether it was moved.
    fn start_for(&self, p: Point, house: &str) -> Result<(u32, bool)> {
        let err = |message: String| WorldError::Grid {
            house: house.to_string(),
            message,
        };
        let res = self.params.resolution;
        let x = ((p.x - self.origin.x) / res).floor();
        let z = ((p.z - self.origin.z) / res).floor();
        if !(x >= 0.0 && z >= 0.0 && x < f64::from(self.width) && z < f64::from(self.height)) {
            return Err(err(format!(
                "the start ({:.3}, {:.3}) is outside the house",
                p.x, p.z
            )));
        }
        // The kind alone: once the grid is finished, free cells also carry REACHABLE.
        let free = |c: u8| c & KIND_MASK == CellKind::Free as u8;
        let own = z as usize * self.width as usize + x as usize;
        if free(self.cells[own]) {
            return Ok((own as u32, false));
        }
        let (x, z) = (x as i64, z as i64);
        let w = self.width as usize;
        let nearest = self
            .cells
            .iter()
            .enumerate()
            .filter(|&(_, &c)| free(c))
            .map(|(i, _)| {
                let (cx, cz) = ((i % w) as i64, (i / w) as i64);
                ((cx - x).pow(2) + (cz - z).pow(2), i)
            })
            .min();
        let Some((d_sq, i)) = nearest else {
            return Err(err(
                "no free cell: the robot fits nowhere in the house".into()
            ));
        };
        debug!(
            house = %house,
            kind = ?CellKind::from_u8(self.cells[own]),
            moved_m = (d_sq as f64).sqrt() * res,
            "start cell is not free; starting from the nearest free cell"
        );
        Ok((i as u32, true))
    }

    /// Marks the free cells connected to the start (8-connected, no corner cutting: the moves of
    /// the distance search) and returns how many there are.
    fn flood_from_start(&mut self) -> usize {
        let w = self.width as usize;
        let free = CellKind::Free as u8;
        let mut stack = vec![self.start as usize];
        self.cells[self.start as usize] |= REACHABLE;
        let mut count = 1;
        while let Some(i) = stack.pop() {
            for (j, via) in neighbours(i, w) {
                let ok = self.cells[j] == free
                    && via.is_none_or(|(a, b)| {
                        self.cells[a] & KIND_MASK == free && self.cells[b] & KIND_MASK == free
                    });
                if ok {
                    self.cells[j] |= REACHABLE;
                    count += 1;
                    stack.push(j);
                }
            }
        }
        count
    }

    fn find_closed_doors(&self, house: &House) -> Vec<usize> {
        let depth = self.half_wall() + self.params.resolution;
        let mut closed = Vec::new();
        for (di, door) in house.doors.iter().enumerate() {
            if door.rooms[0] == door.rooms[1] {
                continue;
            }
            let (dx, dz) = (door.end.x - door.start.x, door.end.z - door.start.z);
            let len = dx.hypot(dz);
            let mut open = false;
            if len > 0.0 {
                let (ux, uz) = (dx / len, dz / len);
                let (x_lo, x_hi) = self.columns(
                    door.start.x.min(door.end.x) - depth,
                    door.start.x.max(door.end.x) + depth,
                );
                let (z_lo, z_hi) = self.rows(
                    door.start.z.min(door.end.z) - depth,
                    door.start.z.max(door.end.z) + depth,
                );
                'scan: for z in z_lo..z_hi {
                    for x in x_lo..x_hi {
                        let p = self.center(x, z);
                        let (px, pz) = (p.x - door.start.x, p.z - door.start.z);
                        let along = px * ux + pz * uz;
                        let across = (px * uz - pz * ux).abs();
                        let i = z as usize * self.width as usize + x as usize;
                        if (0.0..=len).contains(&along)
                            && across <= depth
                            && self.cells[i] & KIND_MASK == CellKind::Free as u8
                        {
                            open = true;
                            break 'scan;
                        }
                    }
                }
            }
            if !open {
                warn!(house = %house.name, door = %door.id, width_m = len, "door opening has no free cell");
                closed.push(di);
            }
        }
        closed
    }

    /// The reference code's access cell for footprint `f`: the reachable cell whose centre is
    /// nearest the footprint's centre, in any room (ties to the lowest index).
    fn nearest_to_centre(&self, f: &Footprint) -> Option<Access> {
        let w = self.width as usize;
        self.cells
            .iter()
            .enumerate()
            .filter(|&(_, &c)| c & REACHABLE != 0)
            .map(|(i, _)| {
                let p = self.center((i % w) as u32, (i / w) as u32);
                (p.distance(f.center), i)
            })
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
            .map(|(_, i)| Access {
                cell: i as u32,
                gap: footprint_distance(f, self.center((i % w) as u32, (i / w) as u32)),
            })
    }

    /// The access cell for footprint `f`: a reachable free cell (in `room` when given) at most
    /// one cell farther from the footprint than the nearest one, and of those the one nearest the
    /// footprint's centre (then the lowest index). The one-cell slack keeps rasterisation from
    /// favouring corners: the robot faces the middle of a side. Searches a window around the
    /// footprint, doubling it until the choice is provably the same as over the whole grid.
    fn nearest_reachable(&self, f: &Footprint, room: Option<usize>) -> Option<Access> {
        let b = Rect::around(f.corners())?;
        let room = room.map(|r| u8::try_from(r).unwrap_or(NO_ROOM - 1));
        let slack = self.params.resolution;
        let span = f64::from(self.width.max(self.height)) * self.params.resolution;
        let mut margin = 0.5;
        let mut candidates: Vec<(f64, u32)> = Vec::new();
        loop {
            let (x_lo, x_hi) = self.columns(b.min.x - margin, b.max.x + margin);
            let (z_lo, z_hi) = self.rows(b.min.z - margin, b.max.z + margin);
            candidates.clear();
            let mut nearest = f64::INFINITY;
            for z in z_lo..z_hi {
                for x in x_lo..x_hi {
                    let i = z as usize * self.width as usize + x as usize;
                    if self.cells[i] & REACHABLE == 0 || room.is_some_and(|r| self.rooms[i] != r) {
                        continue;
                    }
                    let gap = footprint_distance(f, self.center(x, z));
                    if gap <= nearest + slack {
                        nearest = nearest.min(gap);
                        candidates.push((gap, i as u32));
                    }
                }
            }
            // Cells outside the window are more than `margin` from the footprint's bounding box,
            // hence from the footprint: if every candidate is nearer, none was missed.
            let complete = nearest + slack < margin || margin > 2.0 * span;
            if complete {
                let pick = candidates
                    .iter()
                    .filter(|&&(gap, _)| gap <= nearest + slack)
                    .map(|&(gap, i)| {
                        let to_centre = self
                            .center(i % self.width, i / self.width)
                            .distance(f.center);
                        (to_centre, i, gap)
                    })
                    .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                return pick.map(|(_, cell, gap)| Access { cell, gap });
            }
            margin *= 2.0;
        }
    }
}

/// The eight neighbours of cell `i` in a grid `w` wide, each with, for diagonal moves, the two
/// orthogonal cells the move passes between (both must be free: no cutting corners). The caller
/// guarantees `i` is not on the border.
pub(crate) fn neighbours(i: usize, w: usize) -> [(usize, Option<(usize, usize)>); 8] {
    let (l, r, u, d) = (i - 1, i + 1, i - w, i + w);
    [
        (l, None),
        (r, None),
        (u, None),
        (d, None),
        (u - 1, Some((u, l))),
        (u + 1, Some((u, r))),
        (d - 1, Some((d, l))),
        (d + 1, Some((d, r))),
    ]
}
