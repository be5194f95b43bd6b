//! Travel distances between the robot's start and the containers.
//!
//! Distances are shortest 8-connected paths on the [`OccupancyGrid`] between the start cell and the
//! containers' access cells: a straight step costs one cell, a diagonal step √2 cells, times the
//! resolution; diagonal steps may not cut the corner of an obstacle.
//!
//! # Exactness
//! A path of `a` straight and `b` diagonal steps is `a + b·√2` cells long. The search keeps the
//! two step counts of every cell as integers and compares lengths as `a + b·√2` evaluated afresh
//! in `f64` (one rounding each), never as a running floating-point sum. Two different lengths
//! differ by `|Δa + Δb·√2| ≥ 1/(|Δa| + √2·|Δb|)` cells (its product with `Δa − Δb·√2` is a
//! non-zero integer), i.e. by more than 4·10⁻⁶ for paths under 10⁵ steps, far above `f64`
//! rounding, so the search orders paths exactly and the reported metres are
//! `(a + b·√2)·resolution` to within a few ulps.
//!
//! # Speed
//! Every step costs at least one cell, so the search is Dial's algorithm with buckets one cell
//! wide (Dinitz): every cell whose length lies in `[k, k+1)` is final once all shorter ones are
//! settled, whatever the order inside the bucket, and a step adds at most √2 < 2, so three
//! circular buckets suffice. Each push and pop is O(1). A search stops as soon as every target is
//! settled, and because the grid graph is undirected the matrix is filled by symmetry: from the
//! start to every container, from container `i` to containers `j > i` only. The moves allowed
//! from each cell are precomputed as a bit mask, once per grid (a grid at another start shares
//! them), and a small pool keeps finished searches' per-cell arrays for the next. On
//! multiroom-val150 (87 k cells and 23 places per house on average) a house takes a median
//! 17 ms on one thread.

use std::sync::{Arc, Mutex, OnceLock};

use rayon::prelude::*;

use crate::error::{Result, WorldError};
use crate::geometry::Point;
use crate::grid::{Cell, GridParams, OccupancyGrid, neighbours};
use crate::house::{House, Scene};
use crate::rules::TravelCost;
use crate::soft::{SoftCache, SoftGrid};

/// Most containers a house may have for its distances to be computed: the matrix holds
/// (containers + 1)² distances, so 2 000 containers take 32 MB (60 000 would take 28 GB).
pub const MAX_CONTAINERS: usize = 2000;

/// A place the robot can be: its start, or at (the access cell of) a container.
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
#[serde(rename_all = "lowercase")]
pub enum Place {
    /// The robot's start pose.
    Start,
    /// Container `i` of [`House::containers`](crate::House::containers).
    Container(usize),
}

impl Place {
    /// Row/column of this place in the matrix: 0 for the start, `i + 1` for container `i`.
    fn slot(self) -> usize {
        match self {
            Place::Start => 0,
            Place::Container(i) => i + 1,
        }
    }
}

/// Shortest travel distances (metres) between the start and every container and between
/// containers. Every entry is a real distance: a house with an unreachable container never gets a
/// `Distances` (see [`WorldError::Unreachable`]).
#[derive(Clone, Debug)]
pub struct Distances {
    containers: usize,
    /// (containers + 1)² entries, row-major, slot 0 = start.
    metres: Vec<f64>,
    /// The grid and the cell of every slot, when the distances came from a grid.
    routes: Option<Routes>,
}

#[derive(Clone, Debug)]
struct Routes {
    grid: OccupancyGrid,
    /// Flat cell index of every slot.
    cells: Vec<u32>,
    /// The moves of every cell of `grid` (see [`moves_of`]), shared by the same grid at
    /// another start: computing them visits every neighbour of every cell, more than a short
    /// search does.
    moves: Arc<[u8]>,
    /// The soft cost of this grid, made on first use: an evaluation asks it for every trial of
    /// the house, mostly for legs it has already searched. Shared by clones (same grid, same
    /// cells); `None` inside when the grid makes no soft grid.
    soft: Arc<OnceLock<Option<SoftCache>>>,
}

impl Routes {
    fn new(grid: OccupancyGrid, cells: Vec<u32>, moves: Arc<[u8]>) -> Self {
        Self {
            grid,
            cells,
            moves,
            soft: Arc::default(),
        }
    }

    fn soft(&self) -> Option<&SoftCache> {
        self.soft
            .get_or_init(|| {
                let blocked = self
                    .grid
                    .raw_cells()
                    .iter()
                    .map(|&b| !OccupancyGrid::raw_reachable(b))
                    .collect();
                let grid = SoftGrid::new(self.grid.width() as usize, blocked)?;
                let stops: Vec<usize> = self.cells.iter().map(|&c| c as usize).collect();
                Some(SoftCache::new(&grid, &stops))
            })
            .as_ref()
    }
}

impl Distances {
    /// Distances from a full matrix over `containers + 1` places (slot 0 = start), e.g. for tests
    /// and synthetic problems. Returns `None` when the matrix has the wrong size or holds a
    /// negative or non-finite entry.
    pub fn from_matrix(containers: usize, metres: Vec<f64>) -> Option<Self> {
        let n = containers + 1;
        (metres.len() == n * n && metres.iter().all(|d| d.is_finite() && *d >= 0.0)).then_some(
            Self {
                containers,
                metres,
                routes: None,
            },
        )
    }

    /// Shortest-path distances on `grid` (built from `house`) from the start and from every
    /// container's access cell to every container.
    ///
    /// # Errors
    /// [`WorldError::Unreachable`] naming (with [`House::container_label`]) every container
    /// without an access cell; [`WorldError::Grid`] when `grid` was built for a house with a
    /// different number of containers, or the house has more than [`MAX_CONTAINERS`].
    ///
    /// # Examples
    /// ```
    /// use ferret_world::{Distances, GridParams, OccupancyGrid, Place};
    /// # use ferret_world::{Container, Footprint, House, ObjectType, Point, Polygon, Pose, Room, RoomType};
    /// # let corners = vec![Point::new(0.0, 0.0), Point::new(4.0, 0.0), Point::new(4.0, 3.0), Point::new(0.0, 3.0)];
    /// # let table = Footprint { center: Point::new(3.0, 1.5), size_x: 1.0, size_z: 0.8, yaw_deg: 0.0 };
    /// # let house = House {
    /// #     name: "doc".into(), index: 0, walls: vec![], doors: vec![], obstacles: vec![],
    /// #     rooms: vec![Room { id: "room|1".into(), room_type: RoomType::new("LivingRoom"), floor: Polygon::new(corners) }],
    /// #     containers: vec![Container { id: "1|0".into(), object_type: ObjectType::new("DiningTable"),
    /// #         room: Some(0), position: table.center, footprint: table, access: None }],
    /// #     start: Pose { position: Point::new(0.5, 0.5), yaw_deg: 0.0 }, map: None,
    /// # };
    /// // `house`: one 4 m × 3 m room with a table in it.
    /// let grid = OccupancyGrid::build(&house, &GridParams::default())?;
    /// let d = Distances::compute(&house, &grid)?;
    /// assert!(d.between(Place::Start, Place::Container(0)) > 0.0);
    /// let path = d.path(Place::Start, Place::Container(0)).unwrap();
    /// assert_eq!(path.first().copied(), d.point(Place::Start));
    /// # Ok::<(), ferret_world::WorldError>(())
    /// ```
    pub fn compute(house: &House, grid: &OccupancyGrid) -> Result<Distances> {
        if house.containers.len() > MAX_CONTAINERS {
            return Err(WorldError::Grid {
                house: house.name.clone(),
                message: format!(
                    "{} containers exceed the limit of {MAX_CONTAINERS} per house",
                    house.containers.len()
                ),
            });
        }
        if grid.container_count() != house.containers.len() {
            return Err(WorldError::Grid {
                house: house.name.clone(),
                message: format!(
                    "the grid was built for {} containers, the house has {}",
                    grid.container_count(),
                    house.containers.len()
                ),
            });
        }
        let unreachable = grid.unreachable_containers();
        if !unreachable.is_empty() {
            return Err(WorldError::Unreachable {
                house: house.name.clone(),
                names: unreachable
                    .iter()
                    .map(|&i| house.container_label(i))
                    .collect(),
            });
        }
        let cells: Vec<u32> = std::iter::once(Some(grid.start_index()))
            .chain((0..house.containers.len()).map(|i| grid.access_index(i)))
            .collect::<Option<_>>()
            .ok_or_else(|| WorldError::Grid {
                house: house.name.clone(),
                message: "a container lost its access cell".into(),
            })?;
        let n = cells.len();
        let res = grid.resolution();
        let mut metres = vec![0.0; n * n];
        // Row `s` is searched with targets `s+1..` only (the graph is undirected). A search
        // settles every cell nearer than its farthest target; in file order the containers of a
        // room are neighbours, so the last searches mostly stay in the last rooms. (Reordering
        // the places to make those tails tight by straight-line distance measured no better on
        // multiroom-val150.)
        let moves = moves_of(grid);
        let mut search = Search::new(grid, Arc::clone(&moves));
        for s in 0..n.saturating_sub(1) {
            fill_row(&mut search, house, &cells, s, res, &mut metres)?;
        }
        Ok(Distances {
            containers: n - 1,
            metres,
            routes: Some(Routes::new(grid.clone(), cells, moves)),
        })
    }

    /// The distances on `grid`, which is the grid of these distances with the robot's start
    /// moved ([`OccupancyGrid::with_start`]): the distances between containers are kept, those
    /// from the start are one search from the new start cell. Entry for entry what
    /// [`Distances::compute`] gives on `grid`, for the cost of one of its searches rather than
    /// one per container.
    ///
    /// # Errors
    /// [`WorldError::Grid`] when these distances have no grid, or `grid` is not their grid with
    /// another start (another size, other access cells); [`WorldError::Unreachable`] when a
    /// container cannot be reached from the new start.
    pub fn with_start(&self, house: &House, grid: &OccupancyGrid) -> Result<Distances> {
        let err = |message: &str| WorldError::Grid {
            house: house.name.clone(),
            message: message.to_string(),
        };
        let routes = self
            .routes
            .as_ref()
            .ok_or_else(|| err("distances without a grid cannot move their start"))?;
        let same_access = grid.container_count() == self.containers
            && (0..self.containers).all(|i| grid.access_index(i) == Some(routes.cells[i + 1]));
        if grid.width() != routes.grid.width()
            || grid.height() != routes.grid.height()
            || !same_access
        {
            return Err(err(
                "the grid is not the one these distances were measured on",
            ));
        }
        let mut cells = routes.cells.clone();
        cells[0] = grid.start_index();
        let mut metres = self.metres.clone();
        // The same floor at another start (what `OccupancyGrid::with_start` makes) moves alike.
        let moves = if grid.raw_cells() == routes.grid.raw_cells() {
            Arc::clone(&routes.moves)
        } else {
            moves_of(grid)
        };
        let mut search = Search::new(grid, Arc::clone(&moves));
        metres[0] = 0.0;
        fill_row(
            &mut search,
            house,
            &cells,
            0,
            grid.resolution(),
            &mut metres,
        )?;
        Ok(Distances {
            containers: self.containers,
            metres,
            routes: Some(Routes::new(grid.clone(), cells, moves)),
        })
    }

    /// Number of containers.
    pub fn container_count(&self) -> usize {
        self.containers
    }

    /// Travel distance in metres from `a` to `b`.
    ///
    /// # Panics
    /// When a place names a container beyond [`container_count`](Self::container_count); places
    /// come from the same house, so that is a programming error.
    pub fn between(&self, a: Place, b: Place) -> f64 {
        let n = self.containers + 1;
        self.metres[a.slot() * n + b.slot()]
    }

    /// The whole matrix, row-major over `container_count() + 1` places, slot 0 = start.
    pub fn matrix(&self) -> &[f64] {
        &self.metres
    }

    /// Where the robot stands at `place` (the centre of the start or access cell), when the
    /// distances came from a grid.
    pub fn point(&self, place: Place) -> Option<Point> {
        let r = self.routes.as_ref()?;
        let &i = r.cells.get(place.slot())?;
        Some(r.grid.center(r.grid.cell_at(i)))
    }

    /// The grid the distances were measured on, if any.
    pub fn grid(&self) -> Option<&OccupancyGrid> {
        self.routes.as_ref().map(|r| &r.grid)
    }

    /// The reported cost, metres, of a trajectory visiting `places` in order: the sum of the
    /// plain distances, or the soft cost of [`soft`](crate::soft) on this grid with every visited
    /// cell freed first. `None` for the soft cost of synthetic distances (they have no grid) or
    /// for a place that does not exist; the soft cost of a leg no 8-connected path joins
    /// (possible only with cells that need corner cutting, never in practice) is infinite.
    /// The soft cost's weights and legs are kept (a [`SoftCache`] shared by clones of these
    /// distances), so later trajectories on this grid cost little more than their new legs.
    pub fn travel_cost(&self, places: &[Place], cost: TravelCost) -> Option<f64> {
        let n = self.containers + 1;
        if places.iter().any(|p| p.slot() >= n) {
            return None;
        }
        match cost {
            TravelCost::Plain => Some(places.windows(2).map(|l| self.between(l[0], l[1])).sum()),
            TravelCost::Soft => {
                let r = self.routes.as_ref()?;
                let cells: Vec<usize> = places.iter().map(|p| r.cells[p.slot()] as usize).collect();
                Some(r.soft()?.trajectory_cost(&cells) * r.grid.resolution())
            }
        }
    }

    /// The shortest path from `a` to `b` as points on the floor (cell centres, from `a`'s cell to
    /// `b`'s, keeping only the corners), when the distances came from a grid (synthetic matrices
    /// have no paths) and both places exist. Its length equals [`between`](Self::between) to
    /// within floating-point rounding. The search is rerun on demand.
    pub fn path(&self, a: Place, b: Place) -> Option<Vec<Point>> {
        let r = self.routes.as_ref()?;
        let (&from, &to) = (r.cells.get(a.slot())?, r.cells.get(b.slot())?);
        self.trace_points(from, to)
    }

    /// The shortest path between two cells of the grid, corners only.
    fn trace_points(&self, from: u32, to: u32) -> Option<Vec<Point>> {
        let r = self.routes.as_ref()?;
        let mut search = Search::new(&r.grid, Arc::clone(&r.moves));
        search.run::<true>(from, &[to]);
        let cells = search.trace(from, to)?;
        let mut points = Vec::with_capacity(cells.len());
        for (k, &c) in cells.iter().enumerate() {
            // Keep a cell only where the direction of travel changes (and both ends).
            let keep = k == 0
                || k + 1 == cells.len()
                || i64::from(c) - i64::from(cells[k - 1]) != i64::from(cells[k + 1]) - i64::from(c);
            if keep {
                points.push(r.grid.center(r.grid.cell_at(c)));
            }
        }
        Some(points)
    }
}

/// Travel to one spot of the floor from the start and from every container: where a robot
/// brings what it found when that is no place of the map (a room, a point). Made by
/// [`Distances::spot`] for the distances it belongs to.
#[derive(Clone, Debug, PartialEq)]
pub struct Spot {
    /// Where the robot stands there: the centre of its cell.
    point: Point,
    /// Its flat cell index.
    cell: u32,
    /// Metres to it from every place, by matrix slot (0 = start).
    metres: Vec<f64>,
}

impl Spot {
    /// Where the robot stands there (the centre of its grid cell).
    pub fn point(&self) -> Point {
        self.point
    }

    /// Travel from `place` to the spot, metres (infinite for a place beyond the house).
    pub fn from(&self, place: Place) -> f64 {
        self.metres
            .get(place.slot())
            .copied()
            .unwrap_or(f64::INFINITY)
    }
}

impl Distances {
    /// The spot of `cell` (a cell of these distances' grid, e.g. from
    /// [`OccupancyGrid::nearest_reachable`]): one search from it to the start and every
    /// container.
    ///
    /// # Errors
    /// [`WorldError::Grid`] when these distances came from no grid or `cell` is not reachable
    /// from the start (`house` names the house in it).
    pub fn spot(&self, house: &House, cell: Cell) -> Result<Spot> {
        let err = |message: String| WorldError::Grid {
            house: house.name.clone(),
            message,
        };
        let r = self
            .routes
            .as_ref()
            .ok_or_else(|| err("a spot of the floor needs distances measured on a grid".into()))?;
        let point = r.grid.center(cell);
        if !r.grid.is_reachable(cell) {
            return Err(err(format!(
                "({:.2}, {:.2}) cannot be reached from the start",
                point.x, point.z
            )));
        }
        let source = cell.z * r.grid.width() + cell.x;
        let mut search = Search::new(&r.grid, Arc::clone(&r.moves));
        search.run::<false>(source, &r.cells);
        let res = r.grid.resolution();
        let metres = r
            .cells
            .iter()
            .map(|&c| search.length(c).map(|l| l * res))
            .collect::<Option<Vec<f64>>>()
            .ok_or_else(|| {
                err(format!(
                    "({:.2}, {:.2}) has no path to every container",
                    point.x, point.z
                ))
            })?;
        Ok(Spot {
            point,
            cell: source,
            metres,
        })
    }

    /// The shortest path from `from` to `spot` as points on the floor (as [`path`](Self::path)
    /// gives between places), when these distances came from a grid.
    pub fn path_to_spot(&self, from: Place, spot: &Spot) -> Option<Vec<Point>> {
        let r = self.routes.as_ref()?;
        let &start = r.cells.get(from.slot())?;
        self.trace_points(start, spot.cell)
    }
}

/// Builds the grid and the distances of one house.
///
/// # Errors
/// As [`OccupancyGrid::build`] and [`Distances::compute`].
pub fn build(house: &House, params: &GridParams) -> Result<(OccupancyGrid, Distances)> {
    let grid = OccupancyGrid::build(house, params)?;
    let distances = Distances::compute(house, &grid)?;
    Ok((grid, distances))
}

/// Builds the grids and distances of many houses in parallel (rayon), in order.
pub fn build_all(scenes: &[Scene], params: &GridParams) -> Vec<Result<(OccupancyGrid, Distances)>> {
    scenes.par_iter().map(|s| build(&s.house, params)).collect()
}

/// Travel distance in metres from cell `from` to every cell of `grid` (row-major, as
/// [`OccupancyGrid::cells`]), `f64::INFINITY` where the robot cannot go: a cost map for drawing
/// or for placing a robot. `None` when `from` is not a cell reachable from the start.
pub fn travel_field(grid: &OccupancyGrid, from: Cell) -> Option<Vec<f64>> {
    if !grid.is_reachable(from) {
        return None;
    }
    let source = from.z * grid.width() + from.x;
    let mut search = Search::new(grid, moves_of(grid));
    search.run::<false>(source, &[]);
    let res = grid.resolution();
    Some(
        (0..search.steps.len())
            .map(|i| search.length(i as u32).map_or(f64::INFINITY, |l| l * res))
            .collect(),
    )
}

/// Packed step counts: straight steps in bits 32..63, diagonal steps in the low 32 bits, and the
/// top bit set once the cell is settled.
const SETTLED: u64 = 1 << 63;
const UNSEEN: u64 = SETTLED - 1;
const STRAIGHT: u64 = 1 << 32;
const DIAGONAL: u64 = 1;

/// Searches from place `s` of `cells` (0 the start, then the containers' access cells) and
/// writes its distances to every later place into both halves of the symmetric `metres`.
fn fill_row(
    search: &mut Search,
    house: &House,
    cells: &[u32],
    s: usize,
    resolution: f64,
    metres: &mut [f64],
) -> Result<()> {
    let n = cells.len();
    search.run::<false>(cells[s], &cells[s + 1..]);
    for t in s + 1..n {
        let length = search
            .length(cells[t])
            .ok_or_else(|| WorldError::Unreachable {
                house: house.name.clone(),
                names: vec![house.container_label(t - 1)],
            })?;
        metres[s * n + t] = length * resolution;
        metres[t * n + s] = length * resolution;
    }
    Ok(())
}

/// The length in cells of a path with packed step counts `steps`: `a + b·√2`, one rounding each.
fn cells_of(steps: u64) -> f64 {
    ((steps >> 32) & 0x7fff_ffff) as f64 + (steps & 0xffff_ffff) as f64 * std::f64::consts::SQRT_2
}

/// For each cell of `grid`, bit `k` set when move `k` of [`neighbours`] leads to a reachable
/// cell without cutting a corner (0 for cells that are not reachable).
fn moves_of(grid: &OccupancyGrid) -> Arc<[u8]> {
    let cells = grid.raw_cells();
    let w = grid.width() as usize;
    let reachable = |i: usize| OccupancyGrid::raw_reachable(cells[i]);
    // Reachable cells are never on the grid's border (it is a margin of Outside cells), so
    // all eight neighbours of a reachable cell exist.
    (0..cells.len())
        .map(|u| {
            if !reachable(u) {
                return 0;
            }
            neighbours(u, w)
                .iter()
                .enumerate()
                .fold(0u8, |mask, (k, &(v, via))| {
                    let ok = reachable(v) && via.is_none_or(|(a, b)| reachable(a) && reachable(b));
                    mask | (u8::from(ok) << k)
                })
        })
        .collect()
}

/// The per-cell arrays of a [`Search`], kept between searches: a path for a reply is one short
/// search, and allocating a grid's worth of arrays cost it more than the search.
#[derive(Default)]
struct Buffers {
    steps: Vec<u64>,
    key: Vec<f64>,
    targets: Vec<u8>,
    parent: Vec<u32>,
    buckets: [Vec<u32>; 3],
}

/// The arrays of finished searches, for the next ones. One pool for the process, not one set
/// per thread: a server runs each request on a thread of its own, and a set kept on every
/// thread that ever searched would hold a grid's worth of memory per thread (about 21 bytes a
/// cell). Bounded by [`SPARE_SETS`] and [`SPARE_CELLS`].
static SPARE: Mutex<Vec<Buffers>> = Mutex::new(Vec::new());

/// Most sets of arrays the pool keeps: about as many as searches run at once on a small machine.
const SPARE_SETS: usize = 4;

/// Largest grid, in cells, whose arrays the pool keeps (about 11 MB a set): ProcTHOR houses
/// have at most about 200 000; a larger grid allocates its own, as every search once did.
const SPARE_CELLS: usize = 1 << 19;

/// A set of arrays from the pool, or empty ones.
fn take_spare() -> Buffers {
    SPARE
        .lock()
        .ok()
        .and_then(|mut pool| pool.pop())
        .unwrap_or_default()
}

/// Gives `buffers` back to the pool when it keeps them (not too large, and room left).
fn give_back(buffers: Buffers) {
    if buffers.steps.capacity() > SPARE_CELLS {
        return;
    }
    if let Ok(mut pool) = SPARE.lock()
        && pool.len() < SPARE_SETS
    {
        pool.push(buffers);
    }
}

/// A reusable single-source shortest-path search over a grid's reachable cells.
struct Search {
    /// The grid's [`moves_of`].
    moves: Arc<[u8]>,
    /// Flat-index offsets of the eight moves.
    offsets: [isize; 8],
    /// Packed step counts of the best path found so far, [`UNSEEN`] for none, plus [`SETTLED`].
    steps: Vec<u64>,
    /// `cells_of(steps)` of unsettled cells (∞ for unseen), and −1 once settled, so that one
    /// comparison `len < key` both rejects settled cells and finds improvements.
    key: Vec<f64>,
    /// Number of search targets on each cell (several containers may share an access cell).
    targets: Vec<u8>,
    parent: Vec<u32>,
    buckets: [Vec<u32>; 3],
}

impl Drop for Search {
    fn drop(&mut self) {
        give_back(self.take_buffers());
    }
}

impl Search {
    /// A search on `grid` whose moves are `moves` (its [`moves_of`]), in arrays from the pool
    /// when it has some.
    fn new(grid: &OccupancyGrid, moves: Arc<[u8]>) -> Self {
        Self::with_buffers(grid, moves, take_spare())
    }

    /// A search on `grid` in `buffers`, whatever searches they held before.
    fn with_buffers(grid: &OccupancyGrid, moves: Arc<[u8]>, buffers: Buffers) -> Self {
        let n = grid.raw_cells().len();
        let w = grid.width() as usize;
        // Offsets from a cell far enough from the border that none underflows.
        let centre = w + 1;
        let offsets = neighbours(centre, w).map(|(v, _)| v as isize - centre as isize);
        let Buffers {
            mut steps,
            mut key,
            mut targets,
            parent,
            buckets,
        } = buffers;
        // `run` writes every entry of `steps` and `key` before it reads one (and of `parent`
        // when it keeps parents); `targets` must start empty.
        steps.resize(n, UNSEEN);
        key.resize(n, f64::INFINITY);
        targets.clear();
        targets.resize(n, 0);
        Search {
            moves,
            offsets,
            steps,
            key,
            targets,
            parent,
            buckets,
        }
    }

    /// Its arrays, leaving it empty.
    fn take_buffers(&mut self) -> Buffers {
        Buffers {
            steps: std::mem::take(&mut self.steps),
            key: std::mem::take(&mut self.key),
            targets: std::mem::take(&mut self.targets),
            parent: std::mem::take(&mut self.parent),
            buckets: std::mem::take(&mut self.buckets),
        }
    }

    /// Settles cells from `source` in order of distance until every cell of `targets` is settled
    /// (or every reachable cell is). With `PARENTS`, remembers each cell's predecessor.
    fn run<const PARENTS: bool>(&mut self, source: u32, targets: &[u32]) {
        self.steps.fill(UNSEEN);
        self.key.fill(f64::INFINITY);
        if PARENTS {
            self.parent.clear();
            self.parent.resize(self.steps.len(), u32::MAX);
        }
        for b in &mut self.buckets {
            b.clear();
        }
        // Callers pass reachable sources (the start and access cells are, by construction).
        let src = source as usize;
        if src >= self.steps.len() {
            return;
        }
        let mut remaining = 0usize;
        for &t in targets {
            if let Some(slot) = self.targets.get_mut(t as usize) {
                if *slot == 0 {
                    remaining += 1;
                }
                *slot = slot.saturating_add(1);
            }
        }
        self.steps[src] = 0;
        self.key[src] = 0.0;
        self.buckets[0].push(source);
        let mut bucket = 0usize;
        'search: loop {
            while let Some(u) = self.buckets[bucket % 3].pop() {
                let u = u as usize;
                if self.key[u] < 0.0 {
                    continue; // already settled; this entry is stale
                }
                self.key[u] = -1.0;
                let here = self.steps[u];
                self.steps[u] = here | SETTLED;
                if self.targets[u] != 0 {
                    remaining -= 1;
                    if remaining == 0 {
                        break 'search;
                    }
                }
                // The two candidate lengths, computed exactly as `cells_of` would.
                let (a, b) = ((here >> 32) as f64, (here & 0xffff_ffff) as f64);
                let straight = (a + 1.0) + b * std::f64::consts::SQRT_2;
                let diagonal = a + (b + 1.0) * std::f64::consts::SQRT_2;
                let mut mask = self.moves[u];
                while mask != 0 {
                    let k = mask.trailing_zeros() as usize;
                    mask &= mask - 1;
                    let v = u.wrapping_add_signed(self.offsets[k]);
                    // Moves 0..4 are straight, 4..8 diagonal (see `neighbours`).
                    let (next, len) = if k < 4 {
                        (here + STRAIGHT, straight)
                    } else {
                        (here + DIAGONAL, diagonal)
                    };
                    if len < self.key[v] {
                        self.key[v] = len;
                        self.steps[v] = next;
                        if PARENTS {
                            self.parent[v] = u as u32;
                        }
                        self.buckets[len as usize % 3].push(v as u32);
                    }
                }
            }
            if self.buckets.iter().all(Vec::is_empty) {
                break;
            }
            bucket += 1;
        }
        for &t in targets {
            if let Some(slot) = self.targets.get_mut(t as usize) {
                *slot = 0;
            }
        }
    }

    /// True when cell `i` was settled by the last run.
    fn is_settled(&self, i: usize) -> bool {
        self.steps.get(i).is_some_and(|s| s & SETTLED != 0)
    }

    /// Length in cells of the shortest path to settled cell `t`.
    fn length(&self, t: u32) -> Option<f64> {
        let t = t as usize;
        self.is_settled(t).then(|| cells_of(self.steps[t]))
    }

    /// The cells from `from` to `to` after a `run::<true>` from `from`.
    fn trace(&self, from: u32, to: u32) -> Option<Vec<u32>> {
        self.length(to)?;
        let mut path = vec![to];
        let mut c = to;
        while c != from {
            c = *self.parent.get(c as usize)?;
            if c == u32::MAX || path.len() > self.steps.len() {
                return None;
            }
            path.push(c);
        }
        path.reverse();
        Some(path)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::HouseLocation;
    use crate::generate::{GeneratorOptions, generate_houses};
    use crate::procthor::scene_from_raw;

    /// Generated houses of several sizes with their grids.
    fn grids() -> Vec<(House, OccupancyGrid)> {
        generate_houses(6, 11, &GeneratorOptions::default())
            .iter()
            .enumerate()
            .map(|(index, raw)| {
                let at = HouseLocation {
                    file: "<generated>".into(),
                    index,
                };
                let house = scene_from_raw(raw, &at, None).unwrap().house;
                let grid = OccupancyGrid::build(&house, &crate::GridParams::default()).unwrap();
                (house, grid)
            })
            .collect()
    }

    /// What a search tells from one place: the length (its bits) to every cell, and the path
    /// to every place.
    type FromPlace = (Vec<Option<u64>>, Vec<Vec<u32>>);

    /// Everything a search tells from each place of `grid`: the length to every cell (a search
    /// with no target settles them all) and the path to every other place.
    fn measure(search: &mut Search, grid: &OccupancyGrid) -> Vec<FromPlace> {
        let places: Vec<u32> = std::iter::once(grid.start_index())
            .chain((0..grid.container_count()).filter_map(|i| grid.access_index(i)))
            .collect();
        places
            .iter()
            .map(|&from| {
                search.run::<false>(from, &[]);
                let lengths = (0..search.steps.len() as u32)
                    .map(|c| search.length(c).map(f64::to_bits))
                    .collect();
                search.run::<true>(from, &places);
                let paths = places
                    .iter()
                    .map(|&to| search.trace(from, to).unwrap_or_default())
                    .collect();
                (lengths, paths)
            })
            .collect()
    }

    /// A search in arrays another search left (on a larger grid, a smaller one, the same one)
    /// finds what a search in new arrays finds.
    #[test]
    fn a_search_in_used_arrays_finds_what_one_in_new_arrays_finds() {
        let grids = grids();
        let sizes: Vec<usize> = grids.iter().map(|(_, g)| g.cell_count()).collect();
        assert!(sizes.iter().min() < sizes.iter().max(), "{sizes:?}");
        let fresh: Vec<_> = grids
            .iter()
            .map(|(_, g)| {
                measure(
                    &mut Search::with_buffers(g, moves_of(g), Buffers::default()),
                    g,
                )
            })
            .collect();
        // Forwards, backwards and forwards again, each search in the arrays of the one before.
        let order = (0..grids.len())
            .chain((0..grids.len()).rev())
            .chain(0..grids.len());
        let mut used = Buffers::default();
        for i in order {
            let g = &grids[i].1;
            let mut search = Search::with_buffers(g, moves_of(g), used);
            assert!(
                measure(&mut search, g) == fresh[i],
                "house {i} ({} cells)",
                sizes[i]
            );
            used = search.take_buffers();
        }
    }

    /// The pool never holds more than its sets, nor the arrays of a grid above its size.
    /// A spot at a container's access cell is that container: the same distance from every
    /// place, and a way there of that length. A point inside furniture stands on the nearest
    /// reachable cell; a room's cells are its own.
    #[test]
    fn a_spot_is_measured_as_the_places_are() {
        for (house, grid) in grids() {
            let d = Distances::compute(&house, &grid).unwrap();
            let n = house.containers.len();
            for c in [0, n / 2, n - 1] {
                let cell = grid.access_cell(c).unwrap();
                let spot = d.spot(&house, cell).unwrap();
                for from in std::iter::once(Place::Start).chain((0..n).map(Place::Container)) {
                    let want = d.between(from, Place::Container(c));
                    assert!(
                        (spot.from(from) - want).abs() < 1e-9,
                        "{}: {from:?}",
                        house.name
                    );
                }
                let path = d.path_to_spot(Place::Start, &spot).unwrap();
                let length: f64 = path.windows(2).map(|w| w[0].distance(w[1])).sum();
                assert!((length - spot.from(Place::Start)).abs() < 1e-6);
                assert_eq!(path.last().copied(), Some(spot.point()));
            }
            let inside = house.containers[0].footprint.center;
            let (cell, off) = grid.nearest_reachable(inside, None).unwrap();
            assert!(grid.is_reachable(cell) && off > 0.0, "{}", house.name);
            for r in 0..house.rooms.len() {
                if let Some((cell, _)) =
                    grid.nearest_reachable(house.rooms[r].floor.centroid(), Some(r))
                {
                    assert_eq!(grid.room(cell), Some(r));
                    assert!(d.spot(&house, cell).is_ok());
                }
            }
            // A cell nobody reaches is refused, naming the point.
            let outside = grid
                .cells()
                .find(|&(c, _)| !grid.is_reachable(c))
                .unwrap()
                .0;
            let err = d.spot(&house, outside).unwrap_err().to_string();
            assert!(err.contains("cannot be reached"), "{err}");
        }
        let synthetic = Distances::from_matrix(1, vec![0.0, 1.0, 1.0, 0.0]).unwrap();
        let house = &grids()[0].0;
        assert!(synthetic.spot(house, crate::grid::Cell::new(0, 0)).is_err());
    }

    #[test]
    fn the_pool_of_arrays_stays_bounded() {
        let (_, g) = &grids()[0];
        let searches: Vec<Search> = (0..3 * SPARE_SETS)
            .map(|_| Search::new(g, moves_of(g)))
            .collect();
        drop(searches);
        let large = Buffers {
            steps: Vec::with_capacity(SPARE_CELLS + 1),
            ..Buffers::default()
        };
        give_back(large);
        let pool = SPARE.lock().unwrap();
        // Other tests may take sets meanwhile, so the pool may be empty here, never over.
        assert!(pool.len() <= SPARE_SETS, "{} sets", pool.len());
        assert!(pool.iter().all(|b| b.steps.capacity() <= SPARE_CELLS));
    }
}
