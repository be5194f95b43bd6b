//! Decision latency of the exact planner (targets: ≤ 50 µs at n = 8, ≤ 100 ms at n = 16).

use criterion::{BenchmarkId, Criterion, criterion_group, criterion_main};
use ferret_plan::{TourProblem, solve_exact};

fn bench(c: &mut Criterion) {
    let mut group = c.benchmark_group("exact_planner_decision");
    for n in [4usize, 8, 12, 16, 20] {
        if n >= 16 {
            group.sample_size(10);
        }
        let p = TourProblem::random(n, n as u64);
        group.bench_with_input(BenchmarkId::from_parameter(n), &p, |b, p| {
            b.iter(|| solve_exact(p))
        });
    }
    group.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);
