//! The expected-cost planner (paper eq. 3), solved exactly by dynamic programming.
//!
//! Searching container `a` from where the robot stands costs the travel `D` plus the search cost
//! `R`; with probability `p_a` the target is found there, otherwise search goes on. For an
//! ordering `s1..sn`:
//!
//! ```text
//! E = D(r,s1)+R + (1-p1)·[ D(s1,s2)+R + (1-p2)·[ ... ] ]
//! ```
//!
//! The weight in front of each leg is the product of `(1-p)` over the containers already searched,
//! which depends on the SET searched, not on its order. So the cost-to-go from "searched set `S`,
//! standing at `l`" obeys a Held–Karp recursion over (set, last container): O(2ⁿ·n²) time and
//! O(2ⁿ·n) memory instead of n! orderings. No crate implements this weighted variant, hence the
//! hand-written table.

use crate::probability::Probability;

/// A small planning problem in local indices `0..n`: travel from the robot to each candidate, between
/// candidates, their probabilities and the search cost.
#[derive(Clone, Debug)]
pub struct TourProblem {
    /// Travel from the robot's position to candidate `i`, metres.
    pub from_robot: Vec<f64>,
    /// Travel between candidates, row-major `n × n`, metres.
    pub between: Vec<f64>,
    /// Probability that candidate `i` holds the target.
    pub p: Vec<Probability>,
    /// Search cost `R` added to every leg, metres.
    pub search_cost: f64,
    /// A cost added to every leg that ends at candidate `i`, weighted like the leg; empty for
    /// eq. 3. [`CostModel::Authors`](crate::CostModel::Authors) puts `p_i · D(robot, i)` here.
    /// Because it depends only on the leg's end, the Held–Karp recursion stays exact. A
    /// destination puts `p_i · D(i, destination)` here: the drive there once found at `i`.
    pub leg_extra: Vec<f64>,
    /// The cost of ending the search at candidate `i` without the target, weighted by the
    /// chance that no candidate held it: the drive from `i` to a destination; empty for none
    /// (eq. 3: leftover probability costs nothing).
    pub final_leg: Vec<f64>,
}

impl TourProblem {
    /// Number of candidates.
    pub fn len(&self) -> usize {
        self.p.len()
    }

    /// True for a problem without candidates.
    pub fn is_empty(&self) -> bool {
        self.p.is_empty()
    }

    fn d(&self, a: usize, b: usize) -> f64 {
        self.between[a * self.len() + b]
    }

    fn extra(&self, x: usize) -> f64 {
        self.leg_extra.get(x).copied().unwrap_or(0.0)
    }

    fn final_at(&self, x: usize) -> f64 {
        self.final_leg.get(x).copied().unwrap_or(0.0)
    }

    /// The expected cost of searching in `order` (local indices) from the robot's position, paper
    /// eq. 3. Leftover probability after the last container costs nothing.
    pub fn expected_cost(&self, order: &[usize]) -> f64 {
        let mut weight = 1.0;
        let mut total = 0.0;
        let mut at: Option<usize> = None;
        for &x in order {
            let leg = match at {
                None => self.from_robot[x],
                Some(l) => self.d(l, x),
            };
            total += weight * (leg + self.search_cost + self.extra(x));
            weight *= 1.0 - self.p[x].get();
            at = Some(x);
        }
        if let Some(l) = at.filter(|_| !self.final_leg.is_empty()) {
            total += weight * self.final_at(l);
        }
        total
    }
}

impl TourProblem {
    /// A random instance for benchmarks: the robot and `n` containers scattered in a 20 m square,
    /// straight-line travel, probabilities in [0.01, 0.5), no search cost. Deterministic per seed.
    pub fn random(n: usize, seed: u64) -> TourProblem {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let pts: Vec<(f64, f64)> = (0..=n)
            .map(|_| (rng.random_range(0.0..20.0), rng.random_range(0.0..20.0)))
            .collect();
        let d = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
        TourProblem {
            from_robot: (1..=n).map(|i| d(pts[0], pts[i])).collect(),
            between: (0..n * n)
                .map(|k| d(pts[1 + k / n], pts[1 + k % n]))
                .collect(),
            p: (0..n)
                .map(|_| Probability::clamped(rng.random_range(0.01..0.5), 0.0, 1.0))
                .collect(),
            search_cost: 0.0,
            leg_extra: Vec::new(),
            final_leg: Vec::new(),
        }
    }
}

/// The best ordering found and its expected cost.
#[derive(Clone, Debug, PartialEq)]
pub struct Plan {
    /// Candidates in search order (local indices); empty for an empty problem.
    pub order: Vec<usize>,
    /// Expected cost of `order`, metres.
    pub expected_cost: f64,
}

/// Largest problem [`solve_exact`] accepts: its table holds 2²²·24 f64 entries (0.8 GB).
pub const MAX_EXACT: usize = 22;

/// Largest problem whose table a thread keeps for its next solve (2¹⁸·20 entries, 42 MB): the
/// exact planner solves problems of the same size decision after decision and trial after
/// trial, and a fresh table of that size costs more in page faults than a tenth of the
/// recursion. Larger tables are rare and would pin too much memory per thread.
const POOLED_MAX: usize = 18;

/// The cost-to-go table of one problem, reusable for every later decision of the same trial:
/// after searching some candidates without finding the target, the best continuation is a lookup.
#[derive(Clone, Debug)]
pub struct Solution {
    n: usize,
    /// Row length of `h`: `n` rounded up to a multiple of 4, so that a row is a fixed-size array
    /// the compiler keeps in vector registers.
    stride: usize,
    /// `h[U·stride + l]`: least expected cost still to pay (weighted by the absolute weight of
    /// the searched set, the complement of `U`) while the candidates `U` remain unsearched and the
    /// robot stands at `l ∉ U`; entries with `l ∈ U` or `l ≥ n` are never read, nor is the row
    /// of `U` = everything (nothing searched: the robot stands at no candidate). Indexed by the
    /// remaining set because the recursion needs smaller remaining sets first, so rows are
    /// appended in order.
    h: Vec<f64>,
    /// Product of `(1 - p)` over each searched set.
    weight: Vec<f64>,
}

thread_local! {
    /// The buffers of this thread's last dropped [`Solution`], for its next solve.
    static SPARE: std::cell::RefCell<(Vec<f64>, Vec<f64>)> =
        const { std::cell::RefCell::new((Vec::new(), Vec::new())) };
}

impl Drop for Solution {
    fn drop(&mut self) {
        if self.n > POOLED_MAX {
            return;
        }
        let h = std::mem::take(&mut self.h);
        let weight = std::mem::take(&mut self.weight);
        // During thread teardown the pool may be gone already; the buffers are then just freed.
        let _ = SPARE.try_with(|spare| {
            if let Ok(mut spare) = spare.try_borrow_mut()
                && h.capacity() > spare.0.capacity()
            {
                *spare = (h, weight);
            }
        });
    }
}

/// This thread's spare buffers, emptied (new ones when there are none).
fn spare_buffers() -> (Vec<f64>, Vec<f64>) {
    let (mut h, mut weight) = SPARE
        .try_with(|spare| {
            spare
                .try_borrow_mut()
                .map(|mut s| std::mem::take(&mut *s))
                .unwrap_or_default()
        })
        .unwrap_or_default();
    h.clear();
    weight.clear();
    (h, weight)
}

/// Solves `problem` exactly by Held–Karp dynamic programming.
///
/// Returns `None` when the problem has more than [`MAX_EXACT`] candidates.
pub fn solve_exact(problem: &TourProblem) -> Option<(Plan, Solution)> {
    let n = problem.len();
    if n > MAX_EXACT {
        return None;
    }
    let (mut h, mut weight) = spare_buffers();
    let stride = n.next_multiple_of(4).max(4);
    if n == 0 {
        h.resize(stride, 0.0);
        weight.push(1.0);
        let solution = Solution {
            n,
            stride,
            h,
            weight,
        };
        let plan = Plan {
            order: vec![],
            expected_cost: 0.0,
        };
        return Some((plan, solution));
    }
    let full = (1usize << n) - 1;
    weight.reserve_exact(full + 1);
    weight.push(1.0);
    for s in 1..=full {
        let low = s.trailing_zeros() as usize;
        let w = weight[s & (s - 1)] * (1.0 - problem.p[low].get());
        weight.push(w);
    }
    h.reserve_exact((full + 1) * stride);
    fill_table(problem, &weight, &mut h, stride);
    let solution = Solution {
        n,
        stride,
        h,
        weight,
    };
    let order = solution.best_order(problem, 0, None);
    let expected_cost = problem.expected_cost(&order);
    Some((
        Plan {
            order,
            expected_cost,
        },
        solution,
    ))
}

/// Appends every row of the table to the empty `h`, on the widest vector unit the processor has.
fn fill_table(problem: &TourProblem, weight: &[f64], h: &mut Vec<f64>, stride: usize) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the processor has AVX2, checked just above.
        unsafe { fill_table_avx2(problem, weight, h, stride) };
        return;
    }
    fill_table_any(problem, weight, h, stride);
}

/// The same instructions as [`fill_table_any`] on 4 lanes instead of 2: only additions,
/// multiplications and comparisons, each rounded exactly as the scalar one (no fused
/// multiply-add), so the table is identical bit for bit.
///
/// # Safety
/// The processor must support AVX2.
#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn fill_table_avx2(problem: &TourProblem, weight: &[f64], h: &mut Vec<f64>, stride: usize) {
    match stride {
        4 => fill_rows::<4>(problem, weight, h),
        8 => fill_rows::<8>(problem, weight, h),
        12 => fill_rows::<12>(problem, weight, h),
        16 => fill_rows::<16>(problem, weight, h),
        20 => fill_rows::<20>(problem, weight, h),
        _ => fill_rows::<24>(problem, weight, h),
    }
}

fn fill_table_any(problem: &TourProblem, weight: &[f64], h: &mut Vec<f64>, stride: usize) {
    match stride {
        4 => fill_rows::<4>(problem, weight, h),
        8 => fill_rows::<8>(problem, weight, h),
        12 => fill_rows::<12>(problem, weight, h),
        16 => fill_rows::<16>(problem, weight, h),
        20 => fill_rows::<20>(problem, weight, h),
        _ => fill_rows::<24>(problem, weight, h),
    }
}

/// The Held–Karp recursion over remaining sets, `W` = row length (≥ n, at most 24).
#[inline(always)]
fn fill_rows<const W: usize>(problem: &TourProblem, weight: &[f64], h: &mut Vec<f64>) {
    let n = problem.len().min(W);
    let full = (1usize << n) - 1;
    // Leg costs by destination: `leg_to[x][l]` is the cost of the leg l → x before its weight,
    // summed in the order `expected_cost` and `next` sum it, so that every entry is bit for bit
    // what the recursion written out per (set, position, next container) gives and ties break
    // as they did. Lanes l ≥ n are padding.
    let mut leg_to = vec![[0.0f64; W]; n];
    for (x, row) in leg_to.iter_mut().enumerate() {
        let extra = problem.extra(x);
        for (l, leg) in row.iter_mut().enumerate().take(n) {
            *leg = problem.d(l, x) + problem.search_cost + extra;
        }
    }
    let weight_of = |u: usize| weight[full ^ u];
    // Nothing left: nothing more to pay but the drive to a destination, if there is one.
    let mut last = [0.0; W];
    if !problem.final_leg.is_empty() {
        for (l, e) in last.iter_mut().enumerate().take(n) {
            *e = weight[full] * problem.final_at(l);
        }
    }
    h.extend_from_slice(&last);
    // Remaining sets 1, 2, 3 (only containers 0 and 1) one by one.
    for u in 1..=full.min(3) {
        let w = weight_of(u);
        let mut best = [f64::INFINITY; W];
        let mut left = u;
        while left != 0 {
            let x = left.trailing_zeros() as usize;
            left &= left - 1;
            relax(&mut best, w, &leg_to[x], h[(u ^ (1 << x)) * W + x]);
        }
        h.extend_from_slice(&best);
    }
    // Then four rows at a time: a remaining set U without containers 0 and 1, then U with 0,
    // with 1, with both. Every next container but 0 and 1 is shared, so one pass over them
    // loads each leg row once, reads four adjacent rows per lookup (one stretch of memory, where
    // scattered lookups were what the recursion waited on) and keeps four independent chains of
    // minima in flight. The last group ends with U = everything, a row nothing reads.
    for u in (4..=full).step_by(4) {
        let rows = [u, u | 1, u | 2, u | 3];
        let w = rows.map(weight_of);
        let mut best = [[f64::INFINITY; W]; 4];
        prefetch_far_lookups::<W>(h, u + 4 * PREFETCH_GROUPS_AHEAD, full);
        let mut left = u;
        while left != 0 {
            let x = left.trailing_zeros() as usize;
            left &= left - 1;
            // The rows of U − {x} with 0 and 1 added or not are adjacent, in the same order.
            let after = (u ^ (1 << x)) * W + x;
            for k in 0..4 {
                relax(&mut best[k], w[k], &leg_to[x], h[after + k * W]);
            }
        }
        // Containers 0 and 1 next, from rows of this group: U + {0} leaves U, U + {1} leaves U,
        // U + {0, 1} leaves U + {1} or U + {0}.
        let [b, b0, b1, b01] = &mut best;
        relax(b0, w[1], &leg_to[0], b[0]);
        relax(b1, w[2], &leg_to[1], b[1]);
        relax(b01, w[3], &leg_to[0], b1[0]);
        relax(b01, w[3], &leg_to[1], b0[1]);
        for row in &best {
            h.extend_from_slice(row);
        }
    }
}

/// How many groups ahead [`prefetch_far_lookups`] asks for: far enough for a line from the
/// shared cache to arrive before the group reads it, near enough that it is still in the core's
/// cache when it does.
const PREFETCH_GROUPS_AHEAD: usize = 2;

/// Lookups of container `x` go back 2ˣ rows: from x = 11 on (256 KiB back at 16 lanes) they
/// leave the core's own caches, so these are the ones worth asking for early.
const FAR_LOOKUP: usize = 11;

/// Asks the processor for the entries the group of `u` will read for its far next containers,
/// those from [`FAR_LOOKUP`] on: the hardware prefetchers follow a few streams, not the dozen a
/// group reads at once. It changes no entry, only when its line arrives. Entries not yet written
/// (past the end of the table) are skipped.
#[inline(always)]
fn prefetch_far_lookups<const W: usize>(h: &[f64], u: usize, full: usize) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let mut far = u & full & !((1usize << FAR_LOOKUP) - 1);
        while far != 0 {
            let x = far.trailing_zeros() as usize;
            far &= far - 1;
            let after = (u ^ (1 << x)) * W + x;
            for k in 0..4 {
                if let Some(entry) = h.get(after + k * W) {
                    // SAFETY: SSE is part of x86_64; a prefetch reads nothing the program sees
                    // and the address is that of a live entry.
                    unsafe { _mm_prefetch::<_MM_HINT_T0>(std::ptr::from_ref(entry).cast()) };
                }
            }
        }
    }
    #[cfg(not(target_arch = "x86_64"))]
    let _ = (h, u, full);
}

/// `best[l] = min(best[l], w · leg[l] + after)` for every lane: for each next container one
/// lookup serves every position, branch-free on vector registers (lanes of positions still to
/// search are computed and never read). `v < best` as in [`Solution::next`]: a NaN (0 · ∞ after
/// a certain container) is never chosen.
#[inline(always)]
fn relax<const W: usize>(best: &mut [f64; W], w: f64, leg: &[f64; W], after: f64) {
    for (b, &leg) in best.iter_mut().zip(leg) {
        let v = w * leg + after;
        *b = if v < *b { v } else { *b };
    }
}

/// The best first candidate of `problem` given its table's first steps (see
/// [`Solution::first_steps`]): what [`Solution::next`] gives with nothing searched and the robot
/// where `problem` has it, computed the same way.
pub(crate) fn first_from_steps(problem: &TourProblem, steps: &[f64]) -> Option<usize> {
    // The weight of nothing searched, as the table has it.
    let options = steps.iter().enumerate().take(problem.len());
    best_next(
        problem,
        1.0,
        options.map(|(x, &after)| (x, problem.from_robot[x], after)),
    )
}

/// The option `(x, leg, after)` with the least `weight · (leg + R + extra) + after`, ties to the
/// first: the one rule of a table's decisions and of the memo's.
fn best_next(
    problem: &TourProblem,
    weight: f64,
    options: impl Iterator<Item = (usize, f64, f64)>,
) -> Option<usize> {
    let mut best: Option<(f64, usize)> = None;
    for (x, leg, after) in options {
        let v = weight * (leg + problem.search_cost + problem.extra(x)) + after;
        if best.is_none_or(|(b, _)| v < b) {
            best = Some((v, x));
        }
    }
    best.map(|(_, x)| x)
}

impl Solution {
    /// The entries a first decision reads: for each candidate, the expected cost after it
    /// when it is searched first.
    pub(crate) fn first_steps(&self) -> Vec<f64> {
        let full = (1usize << self.n) - 1;
        (0..self.n)
            .map(|x| self.h[(full & !(1 << x)) * self.stride + x])
            .collect()
    }

    /// The best next candidate after searching set `searched` (bit mask over local indices),
    /// standing at `at` (`None` = the robot's original position, only valid with nothing searched).
    /// Ties go to the lower index.
    pub fn next(&self, problem: &TourProblem, searched: usize, at: Option<usize>) -> Option<usize> {
        let full = (1usize << self.n) - 1;
        let options = (0..self.n).filter(|x| searched & (1 << x) == 0).map(|x| {
            let leg = match at {
                None => problem.from_robot[x],
                Some(l) => problem.d(l, x),
            };
            let remaining = full & !(searched | (1 << x));
            (x, leg, self.h[remaining * self.stride + x])
        });
        best_next(problem, self.weight[searched], options)
    }

    fn best_order(
        &self,
        problem: &TourProblem,
        mut searched: usize,
        mut at: Option<usize>,
    ) -> Vec<usize> {
        let mut order = Vec::with_capacity(self.n);
        while let Some(x) = self.next(problem, searched, at) {
            order.push(x);
            searched |= 1 << x;
            at = Some(x);
        }
        order
    }
}

/// The best ordering by enumerating all n! orderings (Heap's algorithm); for tests and tiny
/// problems only. Ties keep the lexicographically first ordering found.
pub fn solve_brute_force(problem: &TourProblem) -> Plan {
    let n = problem.len();
    let mut perm: Vec<usize> = (0..n).collect();
    let mut best = Plan {
        expected_cost: problem.expected_cost(&perm),
        order: perm.clone(),
    };
    let mut c = vec![0usize; n];
    let mut i = 0;
    while i < n {
        if c[i] < i {
            if i % 2 == 0 {
                perm.swap(0, i);
            } else {
                perm.swap(c[i], i);
            }
            let cost = problem.expected_cost(&perm);
            if cost < best.expected_cost {
                best = Plan {
                    expected_cost: cost,
                    order: perm.clone(),
                };
            }
            c[i] += 1;
            i = 0;
        } else {
            c[i] = 0;
            i += 1;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn problem(n: usize, coords: &[(f64, f64)], p: &[f64], r: f64) -> TourProblem {
        let d = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
        let robot = (0.0, 0.0);
        TourProblem {
            from_robot: (0..n).map(|i| d(robot, coords[i])).collect(),
            between: (0..n * n)
                .map(|k| d(coords[k / n], coords[k % n]))
                .collect(),
            p: p.iter()
                .map(|&x| Probability::clamped(x, 0.0, 1.0))
                .collect(),
            search_cost: r,
            leg_extra: Vec::new(),
            final_leg: Vec::new(),
        }
    }

    #[test]
    fn likely_far_container_beats_unlikely_near_one() {
        // Near container (1 m) almost surely empty; far one (5 m) almost surely holds the target.
        let pr = problem(2, &[(1.0, 0.0), (-5.0, 0.0)], &[0.01, 0.99], 0.0);
        let (plan, _) = solve_exact(&pr).unwrap();
        assert_eq!(plan.order, vec![1, 0]);
        // 5 + 0.01·6 = 5.06, versus 1 + 0.99·6 = 6.94 the other way.
        assert!((plan.expected_cost - 5.06).abs() < 1e-12);
    }

    #[test]
    fn authors_cost_sometimes_chooses_differently_from_eq_3() {
        // Random instances of 6 containers: the extra p·D(robot, a) penalises likely far
        // containers, so the first choice changes on some instances but not on most.
        let mut differ = 0;
        for seed in 0..200 {
            let eq3 = TourProblem::random(6, seed);
            let mut authors = eq3.clone();
            authors.leg_extra = (0..6).map(|i| eq3.p[i].get() * eq3.from_robot[i]).collect();
            let a = solve_exact(&eq3).unwrap().0.order[0];
            let b = solve_exact(&authors).unwrap().0.order[0];
            differ += usize::from(a != b);
        }
        assert!(
            (1..100).contains(&differ),
            "{differ} of 200 first choices differ"
        );
    }

    #[test]
    fn too_large_problems_are_refused() {
        let n = MAX_EXACT + 1;
        let pr = TourProblem {
            from_robot: vec![1.0; n],
            between: vec![1.0; n * n],
            p: vec![Probability::ONE; n],
            search_cost: 0.0,
            leg_extra: Vec::new(),
            final_leg: Vec::new(),
        };
        assert!(solve_exact(&pr).is_none());
    }

    /// The recursion as first written, indexed by the searched set, one lookup per (set, position,
    /// next container): the reference the faster table must equal bit for bit.
    fn reference_table(problem: &TourProblem) -> Vec<f64> {
        let n = problem.len();
        let full = (1usize << n) - 1;
        let mut weight = vec![1.0f64; 1 << n];
        for s in 1..=full {
            let low = s.trailing_zeros() as usize;
            weight[s] = weight[s & (s - 1)] * (1.0 - problem.p[low].get());
        }
        let mut h = vec![f64::INFINITY; (1 << n) * n];
        for l in 0..n {
            h[full * n + l] = if problem.final_leg.is_empty() {
                0.0
            } else {
                weight[full] * problem.final_at(l)
            };
        }
        for s in (1..full).rev() {
            for l in (0..n).filter(|l| s & (1 << l) != 0) {
                let mut best = f64::INFINITY;
                for x in (0..n).filter(|x| s & (1 << x) == 0) {
                    let v = weight[s] * (problem.d(l, x) + problem.search_cost + problem.extra(x))
                        + h[(s | (1 << x)) * n + x];
                    if v < best {
                        best = v;
                    }
                }
                h[s * n + l] = best;
            }
        }
        h
    }

    fn assert_table_is_reference(problem: &TourProblem) -> Result<(), TestCaseError> {
        let n = problem.len();
        let full = (1usize << n) - 1;
        let reference = reference_table(problem);
        let (_, solution) = solve_exact(problem).unwrap();
        // The portable kernel too, where the vector one is what `solve_exact` ran.
        let mut portable = Vec::new();
        fill_table_any(problem, &solution.weight, &mut portable, solution.stride);
        prop_assert!(
            portable
                .iter()
                .zip(&solution.h)
                .all(|(a, b)| a.to_bits() == b.to_bits())
        );
        prop_assert_eq!(portable.len(), solution.h.len());
        for s in 1..=full {
            for l in (0..n).filter(|l| s & (1 << l) != 0) {
                let new = solution.h[(full ^ s) * solution.stride + l];
                let old = reference[s * n + l];
                prop_assert!(
                    new.to_bits() == old.to_bits(),
                    "set {s:b}, at {l}: {new} vs {old}"
                );
            }
        }
        Ok(())
    }

    /// Rows of any width give the same entries, so the widths real problems never reach in
    /// tests (20, 24) are checked on small ones.
    fn assert_every_width_is_reference(problem: &TourProblem) -> Result<(), TestCaseError> {
        let n = problem.len();
        let full = (1usize << n) - 1;
        let reference = reference_table(problem);
        let (_, solution) = solve_exact(problem).unwrap();
        for stride in [4, 8, 12, 16, 20, 24].into_iter().filter(|&w| w >= n) {
            let mut h = Vec::new();
            fill_table_any(problem, &solution.weight, &mut h, stride);
            prop_assert_eq!(h.len(), (full + 1) * stride);
            for s in 1..=full {
                for l in (0..n).filter(|l| s & (1 << l) != 0) {
                    prop_assert_eq!(
                        h[(full ^ s) * stride + l].to_bits(),
                        reference[s * n + l].to_bits()
                    );
                }
            }
        }
        Ok(())
    }

    #[test]
    fn larger_tables_equal_reference_bit_for_bit() {
        for (n, seed) in [(13, 1), (16, 2), (17, 3)] {
            let mut pr = TourProblem::random(n, seed);
            pr.search_cost = 0.25;
            assert_table_is_reference(&pr).unwrap();
        }
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(200))]

        #[test]
        fn table_equals_reference_bit_for_bit(
            n in 1usize..=9,
            raw in prop::collection::vec(prop_oneof![9 => 0.0f64..20.0, 1 => Just(f64::INFINITY)], 90),
            ps in prop::collection::vec(prop_oneof![8 => 0.0f64..=1.0, 1 => Just(1.0), 1 => Just(0.0)], 9),
            r in prop_oneof![Just(0.0), 0.0f64..3.0],
            authors in any::<bool>(),
        ) {
            // Unreachable legs and certain containers included: 0 · ∞ is NaN, skipped by both.
            let mut pr = TourProblem {
                from_robot: raw[..n].to_vec(),
                between: raw[9..9 + n * n].to_vec(),
                p: ps[..n].iter().map(|&x| Probability::clamped(x, 0.0, 1.0)).collect(),
                search_cost: r,
                leg_extra: Vec::new(),
                final_leg: Vec::new(),
            };
            if authors {
                pr.leg_extra = (0..n).map(|i| pr.p[i].get() * pr.from_robot[i]).collect();
            }
            assert_table_is_reference(&pr)?;
            assert_every_width_is_reference(&pr)?;
        }

        #[test]
        fn dp_equals_brute_force(
            pts in prop::collection::vec((-10.0f64..10.0, -10.0f64..10.0), 1..=7),
            ps in prop::collection::vec(0.0f64..=1.0, 7),
            r in prop_oneof![Just(0.0), 0.0f64..3.0],
        ) {
            let n = pts.len();
            let pr = problem(n, &pts, &ps[..n], r);
            let (dp, solution) = solve_exact(&pr).unwrap();
            let bf = solve_brute_force(&pr);
            prop_assert!((dp.expected_cost - bf.expected_cost).abs() <= 1e-9 * bf.expected_cost.max(1.0),
                "dp {} vs brute force {}", dp.expected_cost, bf.expected_cost);
            // The DP's own ordering really has the cost it claims.
            prop_assert!((pr.expected_cost(&dp.order) - dp.expected_cost).abs() < 1e-9);
            let mut sorted = dp.order.clone();
            sorted.sort_unstable();
            prop_assert_eq!(sorted, (0..n).collect::<Vec<_>>());
            // Bellman: after following the plan's first step, the continuation is the plan's tail.
            if n >= 2 {
                let first = dp.order[0];
                prop_assert_eq!(solution.next(&pr, 1 << first, Some(first)), Some(dp.order[1]));
            }
        }

        /// After each empty search the table of the first solve answers what a fresh solve of
        /// what remains, from where the robot stands, answers: the reuse a trial relies on.
        /// The fresh problem's weights start at 1 instead of the searched containers' `1 - p`,
        /// so its sums round differently; orders whose costs differ by less than that rounding
        /// could be told apart differently, which random coordinates do not produce.
        #[test]
        fn one_solution_serves_every_later_decision(
            pts in prop::collection::vec((-10.0f64..10.0, -10.0f64..10.0), 2..=8),
            ps in prop::collection::vec(0.01f64..0.99, 8),
            r in prop_oneof![Just(0.0), 0.0f64..3.0],
        ) {
            let n = pts.len();
            let pr = problem(n, &pts, &ps[..n], r);
            let (plan, solution) = solve_exact(&pr).unwrap();
            let mut searched = 0usize;
            for (step, &c) in plan.order.iter().enumerate().take(n - 1) {
                searched |= 1 << c;
                let reused = solution.next(&pr, searched, Some(c)).unwrap();
                let left: Vec<usize> = (0..n).filter(|&x| searched & (1 << x) == 0).collect();
                let sub = TourProblem {
                    from_robot: left.iter().map(|&x| pr.d(c, x)).collect(),
                    between: left.iter().flat_map(|&a| left.iter().map(move |&b| (a, b)))
                        .map(|(a, b)| pr.d(a, b)).collect(),
                    p: left.iter().map(|&x| pr.p[x]).collect(),
                    search_cost: r,
                    leg_extra: Vec::new(),
                    final_leg: Vec::new(),
                };
                let fresh = left[solve_exact(&sub).unwrap().0.order[0]];
                prop_assert_eq!(reused, fresh, "step {}", step);
                prop_assert_eq!(reused, plan.order[step + 1]);
            }
        }

        #[test]
        fn dp_equals_brute_force_on_asymmetric_costs(
            n in 1usize..=6,
            raw in prop::collection::vec(0.0f64..20.0, 42),
            ps in prop::collection::vec(0.0f64..=1.0, 6),
        ) {
            // Not a metric: the DP must still be exact.
            let pr = TourProblem {
                from_robot: raw[..n].to_vec(),
                between: raw[6..6 + n * n].to_vec(),
                p: ps[..n].iter().map(|&x| Probability::clamped(x, 0.0, 1.0)).collect(),
                search_cost: 0.5,
                leg_extra: Vec::new(),
                final_leg: Vec::new(),
            };
            let (dp, _) = solve_exact(&pr).unwrap();
            let bf = solve_brute_force(&pr);
            prop_assert!((dp.expected_cost - bf.expected_cost).abs() <= 1e-9 * bf.expected_cost.max(1.0));
        }

        /// The reference code's objective (an extra p·D(robot, a) on every leg ending at a) is
        /// solved exactly too: the DP equals brute force of that objective.
        #[test]
        fn authors_cost_dp_equals_its_own_brute_force(
            pts in prop::collection::vec((-10.0f64..10.0, -10.0f64..10.0), 1..=7),
            ps in prop::collection::vec(0.0f64..=1.0, 7),
        ) {
            let n = pts.len();
            let mut pr = problem(n, &pts, &ps[..n], 0.0);
            pr.leg_extra = (0..n).map(|i| pr.p[i].get() * pr.from_robot[i]).collect();
            let (dp, _) = solve_exact(&pr).unwrap();
            let bf = solve_brute_force(&pr);
            prop_assert!((dp.expected_cost - bf.expected_cost).abs() <= 1e-9 * bf.expected_cost.max(1.0),
                "dp {} vs brute force {}", dp.expected_cost, bf.expected_cost);
            // The objective really is eq. 3 plus Σ weight · p_a · D(robot, a).
            let eq3 = TourProblem { leg_extra: Vec::new(), ..pr.clone() };
            let mut w = 1.0;
            let mut extra = 0.0;
            for &a in &dp.order {
                extra += w * pr.p[a].get() * pr.from_robot[a];
                w *= 1.0 - pr.p[a].get();
            }
            prop_assert!((pr.expected_cost(&dp.order) - eq3.expected_cost(&dp.order) - extra).abs() < 1e-9);
        }
    }
}
