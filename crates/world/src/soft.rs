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
//! the reference's formulas); [`Distances::travel_cost`](crate::Distances::travel_cost) applies
//! it to a house's occupancy grid.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

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
    /// 0). `f64::INFINITY` when a leg cannot be travelled.
    pub fn trajectory_cost(&self, points: &[usize]) -> f64 {
        let mut g = self.clone();
        for &p in points {
            g.free(p);
        }
        let weights = g.weights();
        points
            .windows(2)
            .map(|leg| g.dijkstra(&weights, leg[0], leg[1]))
            .sum()
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

    proptest! {
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
