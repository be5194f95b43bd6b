//! The expected-cost planner for tasks that want several targets at once, solved exactly by
//! dynamic programming over what the robot will have learnt.
//!
//! With targets `U` still wanted, each independently in candidate `a` with probability `p_t(a)`,
//! the least expected cost from standing at `l`, having searched the set `S` and found `F ⊆ U`:
//!
//! ```text
//! V(S, F, l) = min over a ∉ S of  D(l, a) + R + Σ_{G ⊆ U∖F} P(G at a) · V'(S ∪ {a}, F ∪ G, a)
//! P(G at a)  = ∏_{t ∈ G} p_t(a) · ∏_{t ∈ U∖F∖G} (1 − p_t(a))
//! V'         = D(a, g) once F ∪ G = U (the goal holds: drive to the destination g), else V
//! V(every candidate, F, l) = D(l, g)   (the candidates exhausted)
//! ```
//!
//! (`D(·, g)` is 0 without a destination.) Unlike the single-target recursion, the cost to go
//! depends on which targets were found, so the table is indexed by (searched set, found set,
//! position): 2ⁿ·2ᵐ·n entries, n candidates and m targets. One target is the Held–Karp problem
//! of [`planner`](crate::planner), which the planner solves there (its sums are the ones it has
//! always made); `any` of several targets is one target whose likelihood is 1 − ∏(1 − p_t).
//! No crate solves this recursion, hence the hand-written table.

use crate::probability::Probability;

/// Most entries a task table may hold (32 MiB of `f64`): what bounds the candidates planned
/// over exactly for a given number of targets (see [`max_candidates`]).
pub const MAX_TASK_ENTRIES: usize = 1 << 22;

/// Entries of the table of `n` candidates and `m` targets: 2ⁿ·2ᵐ·n.
pub fn table_entries(n: usize, m: usize) -> usize {
    u32::try_from(n + m)
        .ok()
        .and_then(|bits| 1usize.checked_shl(bits))
        .and_then(|sets| sets.checked_mul(n))
        .unwrap_or(usize::MAX)
}

/// The most candidates whose table for `m` targets fits in [`MAX_TASK_ENTRIES`].
pub fn max_candidates(m: usize) -> usize {
    (1..=24)
        .take_while(|&n| table_entries(n, m) <= MAX_TASK_ENTRIES)
        .last()
        .unwrap_or(1)
}

/// A task planning problem in local indices `0..n`: travel from the robot to each candidate and
/// between candidates, each wanted target's probabilities, the search cost and the destination.
#[derive(Clone, Debug)]
pub struct TaskProblem {
    /// Travel from the robot's position to candidate `i`, metres.
    pub from_robot: Vec<f64>,
    /// Travel between candidates, row-major `n × n`, metres.
    pub between: Vec<f64>,
    /// `p[t][i]`: probability that candidate `i` holds wanted target `t` (one row per target,
    /// 1 ≤ rows ≤ [`MAX_TARGETS`](crate::MAX_TARGETS)).
    pub p: Vec<Vec<Probability>>,
    /// Search cost `R` per candidate, metres.
    pub search_cost: f64,
    /// Travel from candidate `i` to the destination, metres; empty without one.
    pub to_destination: Vec<f64>,
}

impl TaskProblem {
    /// Number of candidates.
    pub fn len(&self) -> usize {
        self.from_robot.len()
    }

    /// True without candidates.
    pub fn is_empty(&self) -> bool {
        self.from_robot.is_empty()
    }

    fn d(&self, a: usize, b: usize) -> f64 {
        self.between[a * self.len() + b]
    }

    fn goal_leg(&self, x: usize) -> f64 {
        self.to_destination.get(x).copied().unwrap_or(0.0)
    }

    /// A random instance for tests and benchmarks: the robot and `n` containers in a 20 m
    /// square, straight-line travel, `m` targets with probabilities in [0, 0.5), a destination
    /// at a random point when `destination`. Deterministic per seed.
    pub fn random(n: usize, m: usize, destination: bool, seed: u64) -> TaskProblem {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let pts: Vec<(f64, f64)> = (0..=n + 1)
            .map(|_| (rng.random_range(0.0..20.0), rng.random_range(0.0..20.0)))
            .collect();
        let d = |a: (f64, f64), b: (f64, f64)| (a.0 - b.0).hypot(a.1 - b.1);
        TaskProblem {
            from_robot: (1..=n).map(|i| d(pts[0], pts[i])).collect(),
            between: (0..n * n)
                .map(|k| d(pts[1 + k / n], pts[1 + k % n]))
                .collect(),
            p: (0..m)
                .map(|_| {
                    (0..n)
                        .map(|_| Probability::clamped(rng.random_range(0.0..0.5), 0.0, 1.0))
                        .collect()
                })
                .collect(),
            search_cost: 0.0,
            to_destination: if destination {
                (1..=n).map(|i| d(pts[i], pts[n + 1])).collect()
            } else {
                Vec::new()
            },
        }
    }
}

/// The solved table of a [`TaskProblem`]: the best next candidate from any state a search of it
/// can reach.
#[derive(Clone, Debug)]
pub struct TaskSolution {
    n: usize,
    m: usize,
    /// `v[(S·2ᵐ + F)·n + l]`: least expected cost still to pay having searched `S`, found `F`
    /// (never every target), standing at `l ∈ S`; other entries are never read.
    v: Vec<f64>,
    /// The expected cost from the robot's position with nothing searched or found.
    expected_cost: f64,
}

/// Solves `problem` exactly. `None` when it has no candidate, no target, more than
/// [`MAX_TARGETS`](crate::MAX_TARGETS) targets, a row of the wrong length, or a table larger
/// than [`MAX_TASK_ENTRIES`].
pub fn solve_task(problem: &TaskProblem) -> Option<TaskSolution> {
    let (n, m) = (problem.len(), problem.p.len());
    if n == 0
        || m == 0
        || m > crate::task::MAX_TARGETS
        || problem.p.iter().any(|row| row.len() != n)
        || problem.between.len() != n * n
        || table_entries(n, m) > MAX_TASK_ENTRIES
    {
        return None;
    }
    let every_set = (1usize << n) - 1;
    let all_found = (1usize << m) - 1;
    let mut v = vec![f64::NAN; table_entries(n, m)];
    let idx = |s: usize, f: usize, l: usize| ((s << m) + f) * n + l;
    // Every candidate searched and the goal not reached: on to the destination.
    for f in 0..all_found {
        for l in 0..n {
            v[idx(every_set, f, l)] = problem.goal_leg(l);
        }
    }
    let mut after = vec![0.0; n];
    let mut expected_cost = f64::INFINITY;
    // Larger searched sets first: S ∪ {a} > S as a number.
    for s in (0..every_set).rev() {
        for f in 0..all_found {
            expected_after(problem, &v, (s, f), &mut after);
            if s == 0 {
                if f == 0 {
                    expected_cost = best(&after, s, |x| problem.from_robot[x]).0;
                }
                continue;
            }
            for l in (0..n).filter(|l| s & (1 << l) != 0) {
                v[idx(s, f, l)] = best(&after, s, |x| problem.d(l, x)).0;
            }
        }
    }
    Some(TaskSolution {
        n,
        m,
        v,
        expected_cost,
    })
}

/// For every candidate `x ∉ s`: `R + Σ_G P(G at x) · V'(s ∪ {x}, f ∪ G, x)`, into `after[x]`.
fn expected_after(problem: &TaskProblem, v: &[f64], (s, f): (usize, usize), after: &mut [f64]) {
    let (n, m) = (problem.len(), problem.p.len());
    let all_found = (1usize << m) - 1;
    let open = all_found & !f;
    for x in (0..n).filter(|x| s & (1 << x) == 0) {
        let s2 = s | (1 << x);
        let mut e = problem.search_cost;
        // Every set G of the targets still open that x may hold, the empty set included.
        let mut g = open;
        loop {
            let mut prob = 1.0;
            for (t, row) in problem.p.iter().enumerate() {
                if open & (1 << t) != 0 {
                    let p = row[x].get();
                    prob *= if g & (1 << t) != 0 { p } else { 1.0 - p };
                }
            }
            if prob > 0.0 {
                let f2 = f | g;
                let rest = if f2 == all_found {
                    problem.goal_leg(x)
                } else {
                    v[((s2 << m) + f2) * n + x]
                };
                e += prob * rest;
            }
            if g == 0 {
                break;
            }
            g = (g - 1) & open;
        }
        after[x] = e;
    }
}

/// The least `leg(x) + after[x]` over `x ∉ s` and that `x` (ties to the lower index).
fn best(after: &[f64], s: usize, leg: impl Fn(usize) -> f64) -> (f64, usize) {
    let mut out = (f64::INFINITY, usize::MAX);
    for (x, a) in after.iter().enumerate() {
        if s & (1 << x) == 0 {
            let c = leg(x) + a;
            if c < out.0 {
                out = (c, x);
            }
        }
    }
    out
}

impl TaskSolution {
    /// The expected cost of the best policy from the robot's position, metres.
    pub fn expected_cost(&self) -> f64 {
        self.expected_cost
    }

    /// The best next candidate having searched `searched` and found `found` (bit masks over
    /// candidates and targets), standing at `at` (`None`: the robot's position, with nothing
    /// searched). `None` when every candidate is searched or every target found.
    pub fn next(
        &self,
        problem: &TaskProblem,
        searched: usize,
        found: usize,
        at: Option<usize>,
    ) -> Option<usize> {
        let (n, m) = (self.n, self.m);
        let every_set = (1usize << n) - 1;
        if searched & every_set == every_set || found >= (1 << m) - 1 {
            return None;
        }
        let mut after = vec![0.0; n];
        expected_after(problem, &self.v, (searched, found), &mut after);
        let (_, x) = match at {
            None => best(&after, searched, |x| problem.from_robot[x]),
            Some(l) => best(&after, searched, |x| problem.d(l, x)),
        };
        (x < n).then_some(x)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::planner::{TourProblem, solve_exact};
    use proptest::prelude::*;

    /// The expected cost of following `solution` in `problem`, by enumerating every world: each
    /// target in each candidate or not, independently. Only for tiny problems.
    fn cost_over_worlds(
        problem: &TaskProblem,
        policy: &dyn Fn(usize, usize, Option<usize>) -> Option<usize>,
    ) -> f64 {
        let (n, m) = (problem.len(), problem.p.len());
        let cells = n * m;
        let mut total = 0.0;
        for world in 0..(1usize << cells) {
            let holds = |t: usize, x: usize| world & (1 << (t * n + x)) != 0;
            let mut prob = 1.0;
            for t in 0..m {
                for x in 0..n {
                    let p = problem.p[t][x].get();
                    prob *= if holds(t, x) { p } else { 1.0 - p };
                }
            }
            if prob == 0.0 {
                continue;
            }
            let (mut searched, mut found, mut at, mut cost) = (0usize, 0usize, None, 0.0);
            while let Some(x) = policy(searched, found, at) {
                cost += match at {
                    None => problem.from_robot[x],
                    Some(l) => problem.d(l, x),
                } + problem.search_cost;
                searched |= 1 << x;
                at = Some(x);
                for t in 0..m {
                    if holds(t, x) {
                        found |= 1 << t;
                    }
                }
                if found == (1 << m) - 1 {
                    break;
                }
            }
            if let Some(l) = at {
                cost += problem.goal_leg(l);
            }
            total += prob * cost;
        }
        total
    }

    fn small_problem() -> impl Strategy<Value = TaskProblem> {
        (
            1usize..=4,
            1usize..=3,
            any::<bool>(),
            any::<u64>(),
            prop_oneof![Just(0.0), 0.0f64..2.0],
        )
            .prop_flat_map(|(n, m, dest, seed, r)| {
                prop::collection::vec(
                    prop_oneof![6 => 0.0f64..=1.0, 1 => Just(0.0), 1 => Just(1.0)],
                    n * m,
                )
                .prop_map(move |ps| {
                    let mut pr = TaskProblem::random(n, m, dest, seed);
                    pr.search_cost = r;
                    for t in 0..m {
                        for x in 0..n {
                            pr.p[t][x] = Probability::clamped(ps[t * n + x], 0.0, 1.0);
                        }
                    }
                    pr
                })
            })
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]

        /// The table's expected cost is what following its decisions really costs, summed over
        /// every world.
        #[test]
        fn the_table_costs_what_its_policy_costs(pr in small_problem()) {
            let sol = solve_task(&pr).unwrap();
            let follow = |s, f, at| sol.next(&pr, s, f, at);
            let real = cost_over_worlds(&pr, &follow);
            prop_assert!((real - sol.expected_cost()).abs() <= 1e-9 * real.max(1.0),
                "table {} vs worlds {}", sol.expected_cost(), real);
        }

        /// No fixed order of the candidates does better (a fixed order is one policy among
        /// those the table minimises over).
        #[test]
        fn no_fixed_order_beats_the_table(pr in small_problem()) {
            let sol = solve_task(&pr).unwrap();
            let n = pr.len();
            let mut order: Vec<usize> = (0..n).collect();
            // Every permutation (n ≤ 4).
            let mut orders = Vec::new();
            permutations(&mut order, 0, &mut orders);
            for o in orders {
                let fixed = |s: usize, _f: usize, _at: Option<usize>| o.iter().copied().find(|x| s & (1 << x) == 0);
                let c = cost_over_worlds(&pr, &fixed);
                prop_assert!(sol.expected_cost() <= c + 1e-9 * c.max(1.0), "order {o:?}: {c} < {}", sol.expected_cost());
            }
        }

        /// One target is the Held–Karp problem: the same expected cost (to rounding) and, where
        /// the best first candidate is clear, the same one.
        #[test]
        fn one_target_is_the_single_target_planner(
            n in 1usize..=8,
            seed in any::<u64>(),
            dest in any::<bool>(),
        ) {
            let pr = TaskProblem::random(n, 1, dest, seed);
            let tour = TourProblem {
                from_robot: pr.from_robot.clone(),
                between: pr.between.clone(),
                p: pr.p[0].clone(),
                search_cost: 0.0,
                leg_extra: pr.to_destination.iter().zip(&pr.p[0]).map(|(g, p)| p.get() * g).collect(),
                final_leg: pr.to_destination.clone(),
            };
            let (plan, _) = solve_exact(&tour).unwrap();
            let sol = solve_task(&pr).unwrap();
            prop_assert!((plan.expected_cost - sol.expected_cost()).abs() <= 1e-9 * plan.expected_cost.max(1.0),
                "Held–Karp {} vs task table {}", plan.expected_cost, sol.expected_cost());
            prop_assert_eq!(sol.next(&pr, 0, 0, None), plan.order.first().copied());
        }
    }

    fn permutations(v: &mut Vec<usize>, k: usize, out: &mut Vec<Vec<usize>>) {
        if k == v.len() {
            out.push(v.clone());
            return;
        }
        for i in k..v.len() {
            v.swap(k, i);
            permutations(v, k + 1, out);
            v.swap(k, i);
        }
    }

    #[test]
    fn sizes_are_bounded() {
        assert_eq!(table_entries(8, 3), 256 * 8 * 8);
        assert!(max_candidates(3) >= 12, "{}", max_candidates(3));
        assert!(table_entries(max_candidates(4), 4) <= MAX_TASK_ENTRIES);
        assert!(table_entries(max_candidates(4) + 1, 4) > MAX_TASK_ENTRIES);
        let pr = TaskProblem::random(max_candidates(3) + 1, 3, false, 1);
        assert!(solve_task(&pr).is_none());
    }

    #[test]
    fn a_likely_pair_in_one_place_is_searched_first() {
        // Two targets: container 0 (8 m) likely holds both, containers 1 and 2 (3 m) each hold
        // one of them at 0.3. Going far first finds both at once most of the time.
        let pr = TaskProblem {
            from_robot: vec![8.0, 3.0, 3.0],
            between: vec![0.0, 9.0, 9.0, 9.0, 0.0, 1.0, 9.0, 1.0, 0.0],
            p: vec![
                vec![
                    Probability::clamped(0.9, 0.0, 1.0),
                    Probability::clamped(0.3, 0.0, 1.0),
                    Probability::ZERO,
                ],
                vec![
                    Probability::clamped(0.9, 0.0, 1.0),
                    Probability::ZERO,
                    Probability::clamped(0.3, 0.0, 1.0),
                ],
            ],
            search_cost: 0.0,
            to_destination: vec![],
        };
        let sol = solve_task(&pr).unwrap();
        assert_eq!(sol.next(&pr, 0, 0, None), Some(0));
        // Found the first target only there: the second is behind one of the near ones.
        assert_eq!(sol.next(&pr, 0b001, 0b01, Some(0)), Some(2));
    }
}
