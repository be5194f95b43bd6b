//! The paper's reported travel cost: a "soft" path length that charges cells near obstacles more.
//!
//! The paper's reference code plans on plain shortest paths but reports, for every trial, a
//! path length on a weighted grid: each free cell weighs
//! `W = 50 + 8·g1 + 5·g2 + 1·g3`, where `g1` marks the cells within a 3 × 3 square of an
//! obstacle, `g2` the cells within a plus of `g1`, and `g3` the cells within a 3 × 3 square of
//! `g2`. A step between neighbours `p`, `q` costs `ℓ·(W(p) + W(q))/2` with `ℓ = 1` for an edge
//! neighbour and `√2` for a diagonal one (diagonal steps may pass between two blocked cells), and
//! the sum is divided by 50, so open floor costs exactly one cell per straight step. Along a wall
//! a cell costs 1.28 at distance 1, 1.12 at 2 and 1.02 at 3.
//!
//! Every point the robot visits is freed before the weights are computed (a container's access
//! point may sit right next to it), and a trajectory's cost is the sum of its legs on that one
//! grid. Cells outside the grid count as free, as the reference's zero-padded convolutions do.
//!
//! [`SoftGrid`] works on any blocked/free grid (its unit tests are check values worked out from
//! the reference's formulas); [`SoftCache`] gives the same costs bit for bit for many
//! trajectories on one grid without redoing the work they share;
//! [`Distances::travel_cost`](crate::Distances::travel_cost) keeps one per house's occupancy
//! grid.

use std::cell::RefCell;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, HashMap, VecDeque};
use std::sync::atomic::{AtomicU64, Ordering as AtomicOrdering};
use std::sync::{Mutex, PoisonError};

/// Weight of a free cell in open floor: the reference's base weight, divided out at the end.
const BASE: f64 = 50.0;

/// A blocked/free grid, row-major (`index = row · width + column`), with soft cell weights.
#[derive(Clone, Debug)]
pub struct SoftGrid {
    width: usize,
    height: usize,
    blocked: Vec<bool>,
}

impl SoftGrid {
    /// A grid `width` cells wide from its `blocked` flags, row-major. `None` when the length is
    /// not a multiple of `width` (or `width` is 0 with cells given).
    pub fn new(width: usize, blocked: Vec<bool>) -> Option<Self> {
        if width == 0 {
            return blocked.is_empty().then_some(Self {
                width,
                height: 0,
                blocked,
            });
        }
        blocked.len().is_multiple_of(width).then(|| Self {
            width,
            height: blocked.len() / width,
            blocked,
        })
    }

    /// Grid width (columns).
    pub fn width(&self) -> usize {
        self.width
    }

    /// Grid height (rows).
    pub fn height(&self) -> usize {
        self.height
    }

    /// Marks cell `i` free (out-of-range indices are ignored).
    pub fn free(&mut self, i: usize) {
        if let Some(b) = self.blocked.get_mut(i) {
            *b = false;
        }
    }

    /// The soft weight of every cell in units of open floor (1 for a free cell far from
    /// obstacles, up to 1.28), `None` for blocked cells.
    pub fn weights(&self) -> Vec<Option<f64>> {
        let g1 = self.inflate(&self.blocked, true);
        let g2 = self.inflate(&g1, false);
        let g3 = self.inflate(&g2, true);
        (0..self.blocked.len())
            .map(|i| {
                (!self.blocked[i]).then(|| {
                    (BASE
                        + 8.0 * f64::from(u8::from(g1[i]))
                        + 5.0 * f64::from(u8::from(g2[i]))
                        + f64::from(u8::from(g3[i])))
                        / BASE
                })
            })
            .collect()
    }

    /// Cells of `g` or next to one: the 8 neighbours with `square`, the 4 edge neighbours
    /// otherwise. Outside the grid counts as free.
    fn inflate(&self, g: &[bool], square: bool) -> Vec<bool> {
        let (w, h) = (self.width as isize, self.height as isize);
        let mut out = g.to_vec();
        for r in 0..h {
            for c in 0..w {
                let i = (r * w + c) as usize;
                if !g[i] {
                    continue;
                }
                for dr in -1..=1isize {
                    for dc in -1..=1isize {
                        if !square && dr != 0 && dc != 0 {
                            continue;
                        }
                        let (rr, cc) = (r + dr, c + dc);
                        if (0..h).contains(&rr) && (0..w).contains(&cc) {
                            out[(rr * w + cc) as usize] = true;
                        }
                    }
                }
            }
        }
        out
    }

    /// The soft cost in cells from `from` to `to` on this grid as it is (nothing freed),
    /// `f64::INFINITY` when `to` cannot be reached or either cell is blocked or off the grid.
    pub fn cost(&self, from: usize, to: usize) -> f64 {
        let weights = self.weights();
        self.dijkstra(&weights, from, to)
    }

    /// The reference's pairwise cost: `from` and `to` are freed first, then the soft cost.
    pub fn pair_cost(&self, from: usize, to: usize) -> f64 {
        let mut g = self.clone();
        g.free(from);
        g.free(to);
        g.cost(from, to)
    }

    /// The reference's cost of a trajectory visiting `points` in order: all of them freed on one
    /// copy of the grid, then the soft cost of each leg, summed (a leg between equal cells costs
    /// 0). `f64::INFINITY` when a leg cannot be travelled. For many trajectories on one grid,
    /// [`SoftCache::trajectory_cost`] gives the same costs without recomputing the weights.
    pub fn trajectory_cost(&self, points: &[usize]) -> f64 {
        SoftCache::new(self, points).trajectory_cost(points)
    }

    /// The plain length in cells (every free cell weighs 1, same moves as the soft cost): the
    /// reference's planner metric, for comparison.
    pub fn plain_cost(&self, from: usize, to: usize) -> f64 {
        let weights: Vec<Option<f64>> = self.blocked.iter().map(|&b| (!b).then_some(1.0)).collect();
        self.dijkstra(&weights, from, to)
    }

    /// Exact Dijkstra from `from` to `to` over 8-connected moves with the mean of the two cell
    /// weights per step (times √2 diagonally); corner cutting is allowed.
    fn dijkstra(&self, weights: &[Option<f64>], from: usize, to: usize) -> f64 {
        let n = weights.len();
        if from >= n || to >= n || weights[from].is_none() || weights[to].is_none() {
            return f64::INFINITY;
        }
        if from == to {
            return 0.0;
        }
        let (w, h) = (self.width as isize, self.height as isize);
        let mut dist = vec![f64::INFINITY; n];
        let mut done = vec![false; n];
        let mut heap = BinaryHeap::new();
        dist[from] = 0.0;
        heap.push(Entry(0.0, from));
        while let Some(Entry(d, u)) = heap.pop() {
            if done[u] {
                continue;
            }
            done[u] = true;
            if u == to {
                return d;
            }
            let Some(wu) = weights[u] else { continue };
            let (r, c) = ((u / self.width) as isize, (u % self.width) as isize);
            for dr in -1..=1isize {
                for dc in -1..=1isize {
                    if dr == 0 && dc == 0 {
                        continue;
                    }
                    let (rr, cc) = (r + dr, c + dc);
                    if !((0..h).contains(&rr) && (0..w).contains(&cc)) {
                        continue;
                    }
                    let v = (rr * w + cc) as usize;
                    let Some(wv) = weights[v] else { continue };
                    let length = if dr != 0 && dc != 0 {
                        std::f64::consts::SQRT_2
                    } else {
                        1.0
                    };
                    let next = d + length * 0.5 * (wu + wv);
                    if next < dist[v] {
                        dist[v] = next;
                        heap.push(Entry(next, v));
                    }
                }
            }
        }
        f64::INFINITY
    }
}

/// Bit of a free cell's level: the cell is in `g1` (an obstacle among its 8 neighbours).
const G1: u8 = 1;
/// Bit of a free cell's level: the cell is in `g2`.
const G2: u8 = 2;
/// Bit of a free cell's level: the cell is in `g3`.
const G3: u8 = 4;
/// The level of a blocked cell.
const BLOCKED: u8 = 8;
/// How far (in rows and columns) an obstacle raises the weight of a cell: `g3` reaches 3 cells.
const REACH: isize = 3;

/// The weight of a cell of level `level` in units of open floor, `None` when blocked. The same
/// expression as [`SoftGrid::weights`], so both give the same bits.
fn level_weight(level: u8) -> Option<f64> {
    let bit = |b: u8| f64::from(u8::from(level & b != 0));
    (level & BLOCKED == 0).then(|| (BASE + 8.0 * bit(G1) + 5.0 * bit(G2) + bit(G3)) / BASE)
}

/// The level bits an obstacle at offset (`dr`, `dc`) gives a cell. Inflating by a square, a plus
/// and a square again reaches, in closed form: `g1` within a 3 × 3 square; `g2` within
/// Chebyshev distance 2 and Manhattan distance 3; `g3` within Chebyshev 3 and Manhattan 5. Each
/// offset decomposes into steps that stay between the obstacle and the cell, so the grid's edge
/// cuts no chain the inflations would follow.
fn reach_bits(dr: isize, dc: isize) -> u8 {
    let (chebyshev, manhattan) = (dr.abs().max(dc.abs()), dr.abs() + dc.abs());
    let mut bits = 0;
    if chebyshev <= 1 {
        bits |= G1;
    }
    if chebyshev <= 2 && manhattan <= 3 {
        bits |= G2;
    }
    if chebyshev <= REACH && manhattan <= 5 {
        bits |= G3;
    }
    bits
}

/// Index of grid cell `p` in a `width` × `height` grid framed by one ring of cells, `None` off
/// the grid.
fn framed_index(width: usize, height: usize, p: usize) -> Option<usize> {
    (p < width * height).then(|| (p / width + 1) * (width + 2) + p % width + 1)
}

/// One house's soft cost, ready for many trajectories.
///
/// [`SoftGrid::trajectory_cost`] recomputes the weights of the whole grid and runs one Dijkstra
/// search per leg for every trajectory; an evaluation asks for thousands of trajectories on one
/// grid, most of their legs between the same few places. This keeps:
/// - the level of every cell (which of `g1`, `g2`, `g3` hold it), computed once. Freeing a
///   visited cell changes only the levels within 3 cells of it, so a trajectory through blocked
///   cells patches a copy of the levels there instead of inflating the whole grid again;
/// - the cost of every leg already searched while nothing had to be freed (the visited points
///   are usually free cells, then the freed grid is the grid itself), and of every leg to a stop
///   that a search settled on its way;
/// - searches paused at the end of their leg (per thread, 4 MiB at most): a later leg from the
///   same cell to a stop not settled yet carries the search on instead of starting again. Each
///   cell is then settled once per start cell at most, and only as far as the legs asked for
///   reach: on multiroom-val150 under the paper protocol, searching on to every stop settles
///   more cells in all, and so does starting every leg afresh.
///
/// Costs equal [`SoftGrid::trajectory_cost`]'s to the bit: weights come from the same
/// expression, legs are summed in the same order, and Dijkstra's proof holds for floating-point
/// sums (rounding is monotone and never makes a sum smaller than a part), so a search settles
/// every cell at the least sum over its paths whatever order it settles cells of equal cost in,
/// whichever cells it looks for and wherever it pauses.
pub struct SoftCache {
    width: usize,
    height: usize,
    /// [`G1`] | [`G2`] | [`G3`] bits of every free cell, [`BLOCKED`] for blocked cells, framed
    /// by one ring of blocked cells (row-major, `width + 2` wide) so that a search's steps need
    /// no bounds checks.
    levels: Vec<u8>,
    /// The cells trajectories are expected to visit (framed indices), sorted, each once.
    stops: Vec<usize>,
    /// Soft cost in cells of the unpatched grid's legs, by (from, to) cell.
    legs: Mutex<HashMap<(usize, usize), f64>>,
    /// Tells this cache's paused searches apart from other caches' (see [`Paused`]).
    id: u64,
}

/// The next [`SoftCache::id`].
static NEXT_CACHE_ID: AtomicU64 = AtomicU64::new(0);

impl std::fmt::Debug for SoftCache {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("SoftCache")
            .field("width", &self.width)
            .field("height", &self.height)
            .field("stops", &self.stops.len())
            .finish_non_exhaustive()
    }
}

impl SoftCache {
    /// The soft cost of `grid`, for trajectories that mostly visit `stops` (e.g. a house's start
    /// and access cells; others work too, their legs are only remembered less).
    pub fn new(grid: &SoftGrid, stops: &[usize]) -> Self {
        let g1 = grid.inflate(&grid.blocked, true);
        let g2 = grid.inflate(&g1, false);
        let g3 = grid.inflate(&g2, true);
        let framed = grid.width + 2;
        let mut levels = vec![BLOCKED; framed * (grid.height + 2)];
        for (i, &blocked) in grid.blocked.iter().enumerate() {
            let (r, c) = (i / grid.width, i % grid.width);
            levels[(r + 1) * framed + c + 1] = if blocked {
                BLOCKED
            } else {
                (u8::from(g1[i]) * G1) | (u8::from(g2[i]) * G2) | (u8::from(g3[i]) * G3)
            };
        }
        let mut stops: Vec<usize> = stops
            .iter()
            .filter_map(|&p| framed_index(grid.width, grid.height, p))
            .collect();
        stops.sort_unstable();
        stops.dedup();
        Self {
            width: grid.width,
            height: grid.height,
            levels,
            stops,
            legs: Mutex::default(),
            id: NEXT_CACHE_ID.fetch_add(1, AtomicOrdering::Relaxed),
        }
    }

    /// The cost of a trajectory visiting `points` in order, exactly as
    /// [`SoftGrid::trajectory_cost`] on the grid this cache was made from.
    pub fn trajectory_cost(&self, points: &[usize]) -> f64 {
        let blocked = |p: usize| {
            self.framed(p)
                .is_some_and(|f| self.levels[f] & BLOCKED != 0)
        };
        if points.iter().any(|&p| blocked(p)) {
            let levels = self.freed(points);
            return points
                .windows(2)
                .map(|leg| {
                    self.leg(&levels, leg[0], leg[1], |search, from, to| {
                        search.start(levels.len(), from);
                        search.settle(&levels, self.width + 2, to, &[]);
                        search.cost_to(to)
                    })
                })
                .sum();
        }
        points
            .windows(2)
            .map(|leg| {
                self.leg(&self.levels, leg[0], leg[1], |search, from, to| {
                    self.remembered(search, from, to)
                })
            })
            .sum()
    }

    /// Index in the framed `levels` of grid cell `p`, `None` off the grid.
    fn framed(&self, p: usize) -> Option<usize> {
        framed_index(self.width, self.height, p)
    }

    /// Grid cell of index `f` of the framed `levels` (inside the frame).
    fn unframed(&self, f: usize) -> usize {
        let framed = self.width + 2;
        (f / framed - 1) * self.width + f % framed - 1
    }

    /// The levels with every point of `points` freed, patched around each newly freed cell.
    fn freed(&self, points: &[usize]) -> Vec<u8> {
        let mut levels = self.levels.clone();
        let (w, h) = (self.width as isize, self.height as isize);
        for &p in points {
            let Some(f) = self.framed(p) else { continue };
            if levels[f] & BLOCKED == 0 {
                continue;
            }
            levels[f] = 0;
            let (r, c) = ((p / self.width) as isize, (p % self.width) as isize);
            for rr in (r - REACH).max(0)..=(r + REACH).min(h - 1) {
                for cc in (c - REACH).max(0)..=(c + REACH).min(w - 1) {
                    let q = ((rr + 1) * (w + 2) + cc + 1) as usize;
                    if levels[q] & BLOCKED == 0 {
                        levels[q] = self.level_at(&levels, rr, cc);
                    }
                }
            }
        }
        levels
    }

    /// The level of free cell (`r`, `c`) from the obstacles of the grid around it in the framed
    /// `levels` (the frame itself is not an obstacle: off the grid counts as free).
    fn level_at(&self, levels: &[u8], r: isize, c: isize) -> u8 {
        let (w, h) = (self.width as isize, self.height as isize);
        let mut bits = 0;
        for dr in -REACH..=REACH {
            for dc in -REACH..=REACH {
                let b = reach_bits(dr, dc);
                let (rr, cc) = (r + dr, c + dc);
                if b & !bits == 0 || !((0..h).contains(&rr) && (0..w).contains(&cc)) {
                    continue;
                }
                if levels[((rr + 1) * (w + 2) + cc + 1) as usize] & BLOCKED != 0 {
                    bits |= b;
                }
            }
        }
        bits
    }

    /// One leg's cost on the framed `levels`: ∞ off the grid or from or to a blocked cell, 0
    /// between equal cells, else `search` (given this thread's scratch buffers and the framed
    /// indices of both ends).
    fn leg(
        &self,
        levels: &[u8],
        from: usize,
        to: usize,
        search: impl FnOnce(&mut Search, usize, usize) -> f64,
    ) -> f64 {
        let free = |p: usize| self.framed(p).filter(|&f| levels[f] & BLOCKED == 0);
        let (Some(f), Some(t)) = (free(from), free(to)) else {
            return f64::INFINITY;
        };
        if f == t {
            return 0.0;
        }
        SCRATCH.with(|cell| match cell.try_borrow_mut() {
            Ok(mut scratch) => search(&mut scratch, f, t),
            // Only re-entry could find it taken; a fresh one gives the same answer.
            Err(_) => search(&mut Search::default(), f, t),
        })
    }

    /// The cost between framed cells `from` and `to` on the unpatched grid: remembered, or
    /// searched, carrying on this thread's paused search from `from` when there is one; every
    /// stop settled on the way is remembered, and the search is paused again at `to`.
    fn remembered(&self, search: &mut Search, from: usize, to: usize) -> f64 {
        let key = |t: usize| (self.unframed(from), self.unframed(t));
        if let Some(&c) = self
            .legs
            .lock()
            .unwrap_or_else(PoisonError::into_inner)
            .get(&key(to))
        {
            return c;
        }
        let n = self.levels.len();
        match search.unpause(self.id, from) {
            // A cell that is no stop may have been passed without its cost being kept.
            Some(paused) if !paused.settled(to) => search.resume(n, paused),
            _ => search.start(n, from),
        }
        let exhausted = search.settle(&self.levels, self.width + 2, to, &self.stops);
        let mut legs = self.legs.lock().unwrap_or_else(PoisonError::into_inner);
        for &(cell, c) in &search.found {
            legs.insert(key(cell), c);
        }
        drop(legs);
        let cost = search.cost_to(to);
        if !exhausted {
            search.pause(self.id, from);
        }
        cost
    }
}

impl Drop for SoftCache {
    fn drop(&mut self) {
        // Searches paused on other threads go when those threads need the room.
        let _ = SCRATCH.try_with(|cell| {
            if let Ok(mut scratch) = cell.try_borrow_mut() {
                scratch.paused.retain(|p| p.cache != self.id);
            }
        });
    }
}

thread_local! {
    /// Dijkstra buffers as large as the largest grid searched on this thread, reused by every
    /// search rather than allocated per leg, and the searches paused on this thread.
    static SCRATCH: RefCell<Search> = RefCell::new(Search::default());
}

/// Most memory the searches paused on one thread may hold: the least recently paused go first.
/// A house's evaluation runs on one thread and leaves from some 20 cells; a paused search on
/// multiroom-val150 holds 15 kB on average, so this keeps a few houses' worth.
#[cfg(not(test))]
const PAUSED_BYTES: usize = 4 << 20;
/// Small enough that the tests' small grids see paused searches forgotten, too.
#[cfg(test)]
const PAUSED_BYTES: usize = 2 << 10;

/// A search stopped at the end of a leg, to be carried on when a later leg from the same cell
/// needs a cell it has not settled: so every cell is settled at most once per start cell, not
/// once per leg.
struct Paused {
    /// [`SoftCache::id`] of the cache searched.
    cache: u64,
    /// Start cell (framed index).
    from: usize,
    /// Bucket round the search stopped in.
    round: usize,
    /// Settled cells, one bit each.
    settled: Vec<u64>,
    /// Cells reached and not settled, with their best cost so far.
    frontier: Vec<(usize, f64)>,
}

impl Paused {
    fn settled(&self, cell: usize) -> bool {
        self.settled
            .get(cell / 64)
            .is_some_and(|w| w >> (cell % 64) & 1 != 0)
    }

    fn bytes(&self) -> usize {
        self.settled.len() * size_of::<u64>() + self.frontier.len() * size_of::<(usize, f64)>()
    }
}

/// Reusable buffers of one Dijkstra search on framed levels.
#[derive(Default)]
struct Search {
    /// Cost of the best path found so far (∞ for none), −1 once settled, so that one comparison
    /// `next < dist` both skips settled cells and finds improvements.
    dist: Vec<f64>,
    /// Settled cells, one bit each (what pausing keeps of `dist`'s −1s).
    settled: Vec<u64>,
    /// Cells the current search looks for.
    wanted: Vec<bool>,
    /// Cells whose cost lies in `[k, k + 1)`, in bucket `k mod 4`, in round `k`.
    buckets: [Vec<usize>; 4],
    round: usize,
    /// (framed cell, cost) of every wanted cell the last search settled, and, when the search
    /// ran out of cells, ∞ for those it could not reach.
    found: Vec<(usize, f64)>,
    /// Searches paused on this thread, the most recently paused first.
    paused: VecDeque<Paused>,
}

impl Search {
    /// The cost to framed cell `cell` found by the last search, ∞ when it did not settle it.
    fn cost_to(&self, cell: usize) -> f64 {
        self.found
            .iter()
            .find(|&&(c, _)| c == cell)
            .map_or(f64::INFINITY, |&(_, d)| d)
    }

    /// A new search from framed cell `from` on `n` framed cells.
    fn start(&mut self, n: usize, from: usize) {
        self.clear(n);
        self.dist[from] = 0.0;
        self.buckets[0].push(from);
    }

    /// The search `paused` again, on `n` framed cells.
    fn resume(&mut self, n: usize, paused: Paused) {
        self.clear(n);
        for (w, &word) in paused.settled.iter().enumerate() {
            let mut bits = word;
            while bits != 0 {
                self.dist[w * 64 + bits.trailing_zeros() as usize] = -1.0;
                bits &= bits - 1;
            }
        }
        self.settled = paused.settled;
        for (v, d) in paused.frontier {
            self.dist[v] = d;
            self.buckets[d as usize & 3].push(v);
        }
        self.round = paused.round;
    }

    fn clear(&mut self, n: usize) {
        self.dist.clear();
        self.dist.resize(n, f64::INFINITY);
        self.settled.clear();
        self.settled.resize(n.div_ceil(64), 0);
        for b in &mut self.buckets {
            b.clear();
        }
        self.round = 0;
    }

    /// Takes this thread's paused search from `from` on cache `cache`, if any.
    fn unpause(&mut self, cache: u64, from: usize) -> Option<Paused> {
        let i = self
            .paused
            .iter()
            .position(|p| p.cache == cache && p.from == from)?;
        self.paused.remove(i)
    }

    /// Keeps the current search (from `from` on cache `cache`) to carry on later, forgetting
    /// the least recently paused ones beyond [`PAUSED_BYTES`].
    fn pause(&mut self, cache: u64, from: usize) {
        let mut frontier = Vec::new();
        for b in &self.buckets {
            for &v in b {
                // A cell may wait in several buckets; its cost is the one in `dist`.
                if self.dist[v] >= 0.0 {
                    frontier.push((v, self.dist[v]));
                    self.dist[v] = -1.0;
                }
            }
        }
        let paused = Paused {
            cache,
            from,
            round: self.round,
            settled: std::mem::take(&mut self.settled),
            frontier,
        };
        self.paused.push_front(paused);
        let mut bytes = 0;
        let keep = self
            .paused
            .iter()
            .take_while(|p| {
                bytes += p.bytes();
                bytes <= PAUSED_BYTES
            })
            .count();
        self.paused.truncate(keep);
    }

    /// Carries on the search until `to` is settled; records in `found` its cost and that of
    /// every cell of `passing` settled on the way, and, when every reachable cell is settled
    /// (returns `true`), ∞ for those out of reach.
    ///
    /// Steps as [`SoftGrid::dijkstra`]'s, each costing `ℓ·(W(p) + W(q))/2` evaluated the same
    /// way, so a path's cost is the same left-to-right sum. Rounding is monotone and never makes
    /// a sum smaller than a part, so Dijkstra's proof holds for these floating-point sums: a cell
    /// settles at the least sum over all paths to it, whichever order cells of equal cost are
    /// settled in. That frees the queue: every step costs at least 1 (each weight is ≥ 1) and at
    /// most 1.28·√2 < 2, so cells are kept in buckets one unit wide (Dinitz): every cell whose
    /// cost lies in `[k, k + 1)` is final once all cheaper buckets are settled (a path through an
    /// unsettled cell costs at least `k + 1`, an integer, so rounding cannot bring it below).
    /// Costs in reach span three buckets; four circular ones make the index a mask. It also
    /// lets a search stop anywhere and carry on later from its settled cells and frontier.
    fn settle(&mut self, levels: &[u8], framed: usize, to: usize, passing: &[usize]) -> bool {
        self.found.clear();
        self.wanted.resize(levels.len(), false);
        for &t in passing.iter().chain([&to]) {
            self.wanted[t] = true;
        }
        // The cost of a step from a cell of level `a` to one of level `b`, at `a << 4 | b`,
        // computed as `SoftGrid::dijkstra` computes it (NaN for blocked cells, never used).
        let weight = |l: usize| level_weight(l as u8).unwrap_or(f64::NAN);
        let step = |length: f64| -> [f64; 256] {
            std::array::from_fn(|ab| length * 0.5 * (weight(ab >> 4) + weight(ab & 15)))
        };
        let (straight_step, diagonal_step) = (step(1.0), step(std::f64::consts::SQRT_2));
        let straight = [framed.wrapping_neg(), usize::MAX, 1, framed];
        let diagonal = [
            framed.wrapping_neg().wrapping_sub(1),
            framed.wrapping_neg().wrapping_add(1),
            framed - 1,
            framed + 1,
        ];
        let exhausted = 'search: loop {
            while let Some(u) = self.buckets[self.round & 3].pop() {
                let d = self.dist[u];
                if d < 0.0 {
                    continue; // settled already; this entry is stale
                }
                self.dist[u] = -1.0;
                self.settled[u / 64] |= 1 << (u % 64);
                if self.wanted[u] {
                    self.found.push((u, d));
                }
                let lu = usize::from(levels[u]) << 4;
                for (offsets, step) in [(straight, &straight_step), (diagonal, &diagonal_step)] {
                    for off in offsets {
                        // The frame keeps every step from a grid cell inside `levels`.
                        let v = u.wrapping_add(off);
                        let lv = levels[v];
                        if lv & BLOCKED != 0 {
                            continue;
                        }
                        let next = d + step[lu | usize::from(lv)];
                        if next < self.dist[v] {
                            self.dist[v] = next;
                            self.buckets[next as usize & 3].push(v);
                        }
                    }
                }
                // Stopping only after `to`'s steps are taken leaves every settled cell's steps
                // taken, so that a paused search can carry on from its frontier alone.
                if u == to {
                    break 'search false;
                }
            }
            if self.buckets.iter().all(Vec::is_empty) {
                // Every reachable cell is settled: the cells looked for and not found are out of
                // reach.
                for &t in passing.iter().chain([&to]) {
                    if self.dist[t] >= 0.0 {
                        self.found.push((t, f64::INFINITY));
                        self.dist[t] = -1.0;
                    }
                }
                break true;
            }
            self.round += 1;
        };
        for &t in passing.iter().chain([&to]) {
            self.wanted[t] = false;
        }
        exhausted
    }
}

/// A heap entry ordered by smallest cost first, then lowest cell.
#[derive(PartialEq)]
struct Entry(f64, usize);

impl Eq for Entry {}

impl Ord for Entry {
    fn cmp(&self, other: &Self) -> Ordering {
        other.0.total_cmp(&self.0).then(other.1.cmp(&self.1))
    }
}

impl PartialOrd for Entry {
    fn partial_cmp(&self, other: &Self) -> Option<Ordering> {
        Some(self.cmp(other))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    /// A grid from rows of `#` (blocked) and `.` (free); cell (i, j) is row i, column j.
    fn grid(rows: &[&str]) -> SoftGrid {
        let width = rows[0].len();
        let blocked = rows
            .iter()
            .flat_map(|r| r.chars().map(|c| c == '#'))
            .collect();
        SoftGrid::new(width, blocked).unwrap()
    }

    fn free(h: usize, w: usize) -> Vec<String> {
        vec![".".repeat(w); h]
    }

    fn at(g: &SoftGrid, i: usize, j: usize) -> usize {
        i * g.width() + j
    }

    fn bits(w: &[Option<f64>]) -> Vec<Option<u64>> {
        w.iter().map(|c| c.map(f64::to_bits)).collect()
    }

    fn close(a: f64, b: f64) {
        assert!(a == b || (a - b).abs() < 5e-7, "{a} ≠ {b}");
    }

    fn check(g: &SoftGrid, from: (usize, usize), to: (usize, usize), soft: f64, plain: f64) {
        let (a, b) = (at(g, from.0, from.1), at(g, to.0, to.1));
        close(g.pair_cost(a, b), soft);
        let mut freed = g.clone();
        freed.free(a);
        freed.free(b);
        close(freed.plain_cost(a, b), plain);
    }

    #[test]
    fn c1_open_floor_costs_plain_length() {
        let rows = free(10, 10);
        let g = grid(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        check(&g, (0, 0), (0, 9), 9.0, 9.0);
        check(&g, (0, 0), (9, 9), 12.727922, 12.727922);
        check(&g, (2, 3), (7, 5), 5.828427, 5.828427);
    }

    #[test]
    fn c2_corridor_between_two_walls() {
        let mut rows = free(5, 12);
        rows[0] = "#".repeat(12);
        rows[4] = "#".repeat(12);
        let g = grid(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        check(&g, (2, 0), (2, 11), 12.32, 11.0);
        check(&g, (1, 0), (1, 11), 13.474113, 11.0);
    }

    fn c3() -> SoftGrid {
        let mut rows = free(7, 10);
        rows[3] = "#####.####".into();
        grid(&rows.iter().map(String::as_str).collect::<Vec<_>>())
    }

    #[test]
    fn c3_wall_with_a_gap() {
        let g = c3();
        check(&g, (0, 0), (6, 0), 14.120916, 12.485281);
        check(&g, (0, 9), (6, 9), 12.080916, 10.485281);
        check(&g, (1, 5), (5, 5), 4.96, 4.0);
    }

    #[test]
    fn c4_single_obstacle() {
        let mut rows = free(9, 9);
        rows[4] = "....#....".into();
        let g = grid(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        check(&g, (4, 0), (4, 8), 9.956711, 8.828427);
        check(&g, (0, 0), (8, 8), 13.029444, 11.899495);
    }

    #[test]
    fn c4_penalty_window_around_one_obstacle() {
        let mut rows = free(7, 7);
        rows[3] = "...#...".into();
        let g = grid(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        let expected = [
            [0, 1, 1, 1, 1, 1, 0],
            [1, 1, 6, 6, 6, 1, 1],
            [1, 6, 14, 14, 14, 6, 1],
            [1, 6, 14, -1, 14, 6, 1],
            [1, 6, 14, 14, 14, 6, 1],
            [1, 1, 6, 6, 6, 1, 1],
            [0, 1, 1, 1, 1, 1, 0],
        ];
        let w = g.weights();
        for (i, row) in expected.iter().enumerate() {
            for (j, &penalty) in row.iter().enumerate() {
                match w[at(&g, i, j)] {
                    None => assert_eq!(penalty, -1),
                    Some(c) => close(c * 50.0 - 50.0, f64::from(penalty)),
                }
            }
        }
    }

    #[test]
    fn c5_a_blocked_start_is_freed() {
        let mut rows = free(7, 7);
        rows[3] = "##.....".into();
        let g = grid(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        close(g.pair_cost(at(&g, 3, 0), at(&g, 3, 6)), 7.784407);
        // Not freed, the blocked start cannot be left.
        assert_eq!(g.cost(at(&g, 3, 0), at(&g, 3, 6)), f64::INFINITY);
    }

    #[test]
    fn c6_a_full_wall_cuts_the_grid() {
        let g = grid(&[".....", "#####", "....."]);
        check(&g, (0, 0), (2, 0), f64::INFINITY, f64::INFINITY);
    }

    #[test]
    fn c7_diagonal_steps_may_cut_corners() {
        let g = grid(&[".#", "#."]);
        check(&g, (0, 0), (1, 1), 1.810193, std::f64::consts::SQRT_2);
    }

    #[test]
    fn c8_around_a_short_wall() {
        let mut rows = free(5, 5);
        for row in &mut rows[1..=3] {
            *row = "..#..".into();
        }
        let g = grid(&rows.iter().map(String::as_str).collect::<Vec<_>>());
        check(&g, (2, 0), (2, 4), 7.014499, 5.656854);
    }

    #[test]
    fn c9_trajectories_sum_their_legs() {
        let g = c3();
        let t = |p: &[(usize, usize)]| {
            g.trajectory_cost(&p.iter().map(|&(i, j)| at(&g, i, j)).collect::<Vec<_>>())
        };
        let cost = t(&[(0, 0), (6, 9), (0, 9)]);
        close(cost, 25.181833);
        // What the reference stores: metres at 0.05 m per cell.
        close(cost * 0.05, 1.259092);
        close(t(&[(0, 0), (6, 0), (0, 9)]), 27.221833);
        // Repeated points cost nothing.
        close(t(&[(0, 0), (0, 0), (6, 0), (6, 0), (0, 9)]), 27.221833);
    }

    #[test]
    fn c10_every_visited_point_is_freed() {
        let g = grid(&["...#...", "...#...", "...#..."]);
        let (mid, left, right) = (at(&g, 1, 3), at(&g, 1, 0), at(&g, 1, 6));
        close(g.trajectory_cost(&[mid, left, right]), 10.65);
        assert_eq!(g.pair_cost(left, right), f64::INFINITY);
    }

    /// The straightforward trajectory cost the cache must match: every point freed on a copy,
    /// the whole grid's weights recomputed, one search per leg.
    fn trajectory_oracle(g: &SoftGrid, points: &[usize]) -> f64 {
        let mut g = g.clone();
        for &p in points {
            g.free(p);
        }
        let weights = g.weights();
        points
            .windows(2)
            .map(|leg| g.dijkstra(&weights, leg[0], leg[1]))
            .sum()
    }

    /// A random grid up to 14 × 14 with about `density` of its cells blocked.
    fn random_grid(density: f64) -> impl Strategy<Value = SoftGrid> {
        (1usize..15, 1usize..15).prop_flat_map(move |(w, h)| {
            proptest::collection::vec(proptest::bool::weighted(density), w * h)
                .prop_map(move |cells| SoftGrid::new(w, cells).unwrap())
        })
    }

    /// Cell indices, a few of them off the grid of `n` cells.
    fn random_points(n: usize, len: std::ops::Range<usize>) -> impl Strategy<Value = Vec<usize>> {
        proptest::collection::vec(prop_oneof![9 => 0..n, 1 => n..n + 3], len)
    }

    #[test]
    fn the_cache_keeps_the_check_values() {
        let g = c3();
        let stops: Vec<usize> = [(0, 0), (6, 9), (0, 9), (6, 0)]
            .iter()
            .map(|&(i, j)| at(&g, i, j))
            .collect();
        let cache = SoftCache::new(&g, &stops);
        let t =
            |p: &[usize]| cache.trajectory_cost(&p.iter().map(|&k| stops[k]).collect::<Vec<_>>());
        // Asked twice and in both orders, so that remembered legs and full searches answer too.
        for _ in 0..2 {
            close(t(&[0, 1, 2]), 25.181833);
            close(t(&[0, 3, 2]), 27.221833);
            close(
                t(&[2, 1, 0]),
                trajectory_oracle(&g, &[stops[2], stops[1], stops[0]]),
            );
        }
        let g = grid(&["...#...", "...#...", "...#..."]);
        let cache = SoftCache::new(&g, &[]);
        close(
            cache.trajectory_cost(&[at(&g, 1, 3), at(&g, 1, 0), at(&g, 1, 6)]),
            10.65,
        );
        assert_eq!(
            cache.trajectory_cost(&[at(&g, 1, 0), at(&g, 1, 6)]),
            f64::INFINITY
        );
    }

    proptest! {
        /// Freeing cells one at a time and patching the levels around each gives the weights a
        /// full recomputation gives on the freed grid, bit for bit.
        #[test]
        fn patched_weights_equal_recomputed(
            (g, points) in random_grid(0.4).prop_flat_map(|g| {
                let n = g.width() * g.height();
                (Just(g), random_points(n, 0..8))
            }),
        ) {
            let cache = SoftCache::new(&g, &[]);
            let weights = |levels: &[u8]| -> Vec<Option<f64>> {
                (0..g.width() * g.height())
                    .map(|p| cache.framed(p).and_then(|f| level_weight(levels[f])))
                    .collect()
            };
            prop_assert_eq!(bits(&weights(&cache.levels)), bits(&g.weights()));
            let mut freed = g.clone();
            for &p in &points {
                freed.free(p);
            }
            prop_assert_eq!(bits(&weights(&cache.freed(&points))), bits(&freed.weights()));
        }

        /// Trajectories through any cells, free, blocked or off the grid, cost what the full
        /// recomputation gives, bit for bit, also when asked again of one cache.
        #[test]
        fn cached_trajectories_equal_recomputed(
            (g, trajectories) in random_grid(0.3).prop_flat_map(|g| {
                let n = g.width() * g.height();
                (Just(g), proptest::collection::vec(random_points(n, 0..7), 1..5))
            }),
        ) {
            let stops: Vec<usize> = trajectories.iter().flatten().copied().collect();
            let cache = SoftCache::new(&g, &stops[..stops.len() / 2]);
            for _ in 0..2 {
                for t in &trajectories {
                    let (cached, full) = (cache.trajectory_cost(t), trajectory_oracle(&g, t));
                    prop_assert_eq!(cached.to_bits(), full.to_bits(), "{} ≠ {} for {:?}", cached, full, t);
                    prop_assert_eq!(g.trajectory_cost(t).to_bits(), full.to_bits());
                }
            }
        }

        /// Trajectories between free stops, where legs are remembered and searches settle
        /// several stops at once, cost what the full recomputation gives, bit for bit.
        #[test]
        fn remembered_legs_equal_recomputed(
            (g, stops, trajectories) in random_grid(0.25).prop_flat_map(|g| {
                let free: Vec<usize> = (0..g.width() * g.height()).filter(|&i| !g.blocked[i]).collect();
                let k = free.len().max(1);
                (
                    Just(g),
                    Just(free),
                    proptest::collection::vec(proptest::collection::vec(0..k, 0..8), 1..12),
                )
            }),
        ) {
            prop_assume!(!stops.is_empty());
            let cache = SoftCache::new(&g, &stops);
            for t in &trajectories {
                let points: Vec<usize> = t.iter().map(|&k| stops[k]).collect();
                let (cached, full) = (cache.trajectory_cost(&points), trajectory_oracle(&g, &points));
                prop_assert_eq!(cached.to_bits(), full.to_bits(), "{} ≠ {} for {:?}", cached, full, points);
            }
        }

        /// Every cell weighs at least 1, so the soft cost is never below the plain length of
        /// the same moves, and is finite exactly when the plain length is.
        #[test]
        fn soft_is_never_below_plain(
            (w, cells) in (2usize..12, 2usize..12).prop_flat_map(|(w, h)| {
                (Just(w), proptest::collection::vec(proptest::bool::weighted(0.3), w * h))
            }),
            a in any::<prop::sample::Index>(),
            b in any::<prop::sample::Index>(),
        ) {
            let mut g = SoftGrid::new(w, cells).unwrap();
            let n = g.width() * g.height();
            let (a, b) = (a.index(n), b.index(n));
            g.free(a);
            g.free(b);
            let (soft, plain) = (g.cost(a, b), g.plain_cost(a, b));
            prop_assert_eq!(soft.is_finite(), plain.is_finite());
            if plain.is_finite() {
                prop_assert!(soft >= plain - 1e-9, "soft {} < plain {}", soft, plain);
                prop_assert!(soft <= 1.28 * plain + 1e-9, "soft {} > 1.28 × plain {}", soft, plain);
            }
        }
    }
}
