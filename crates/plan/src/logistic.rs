//! Small logistic regressions: the prior's Platt scaling (two weights) and the fusion of the prior
//! with another source (five weights), fitted by Newton's method.
//!
//! Written out rather than taken from a crate: a handful of parameters need an N×N solve, and the
//! crates that fit logistic regressions bring a linear-algebra stack for it.

/// Probabilities are kept this far from 0 and 1 before their logit is taken (a source that says
/// 0.01 and one that says 1e-9 mean the same to a planner; the logit of the second would swamp
/// a fit).
pub const LOGIT_EPS: f64 = 1e-4;

/// The ridge penalty on penalised weights: enough to keep Newton's method finite on data the
/// inputs separate perfectly (tiny test sets), far too small to matter on real training sets.
pub const RIDGE: f64 = 1e-3;

/// `ln(p / (1 − p))` with `p` kept in [[`LOGIT_EPS`], 1 − [`LOGIT_EPS`]].
pub fn logit(p: f64) -> f64 {
    let p = p.clamp(LOGIT_EPS, 1.0 - LOGIT_EPS);
    (p / (1.0 - p)).ln()
}

/// The logistic function, without overflow for large |z|.
pub fn sigmoid(z: f64) -> f64 {
    if z >= 0.0 {
        1.0 / (1.0 + (-z).exp())
    } else {
        let e = z.exp();
        e / (1.0 + e)
    }
}

/// Fits `P(y) = sigmoid(w · x)` to `rows` by maximum likelihood with a ridge penalty
/// `RIDGE · (w − start)²` on the weights where `penalised` is true (the penalty pulls toward the
/// starting weights, so an input that carries no information keeps its neutral weight). `None`
/// without both classes, or when the fit does not settle.
pub fn fit<const N: usize>(
    rows: &[([f64; N], bool)],
    start: [f64; N],
    penalised: [bool; N],
) -> Option<[f64; N]> {
    let counted: Vec<([f64; N], f64, f64)> = rows
        .iter()
        .map(|(x, y)| (*x, f64::from(u8::from(*y)), 1.0))
        .collect();
    fit_counts(&counted, start, penalised)
}

/// [`fit`] over grouped rows: each row's inputs with how many of its `total` cases were
/// positive. Many questions share their inputs (every house asks the same target about the same
/// kind of container), and one row per group is what keeps a fit over hundreds of thousands of
/// questions quick.
#[allow(clippy::needless_range_loop)] // gradient and Hessian by index, as written on paper
pub fn fit_counts<const N: usize>(
    rows: &[([f64; N], f64, f64)],
    start: [f64; N],
    penalised: [bool; N],
) -> Option<[f64; N]> {
    let positives: f64 = rows.iter().map(|r| r.1).sum();
    let total: f64 = rows.iter().map(|r| r.2).sum();
    if positives <= 0.0 || positives >= total {
        return None;
    }
    let mut w = start;
    for _ in 0..100 {
        let mut grad = [0.0; N];
        let mut hess = [[0.0; N]; N];
        for i in 0..N {
            if penalised[i] {
                grad[i] = -RIDGE * (w[i] - start[i]);
                hess[i][i] = RIDGE;
            }
        }
        for (x, k, n) in rows {
            let z: f64 = (0..N).map(|i| x[i] * w[i]).sum();
            let p = sigmoid(z);
            let weight = n * p * (1.0 - p);
            for i in 0..N {
                grad[i] += (k - n * p) * x[i];
                for j in 0..N {
                    hess[i][j] += weight * x[i] * x[j];
                }
            }
        }
        let mut step = solve(hess, grad)?;
        // Newton's full step settles a well-started fit; from a poor start (inputs with a wide
        // range, like a network's logits) it can overshoot into a worse fit and diverge, so a
        // step that raises the loss clearly is halved until it does not.
        let before = loss(rows, &w, &start, &penalised);
        for _ in 0..40 {
            let tried: [f64; N] = std::array::from_fn(|i| w[i] + step[i]);
            let after = loss(rows, &tried, &start, &penalised);
            if after.is_finite() && after <= before + 1e-6 * (1.0 + before.abs()) {
                break;
            }
            step.iter_mut().for_each(|s| *s *= 0.5);
        }
        for i in 0..N {
            w[i] += step[i];
        }
        if !w.iter().all(|v| v.is_finite()) {
            return None;
        }
        if step.iter().map(|s| s.abs()).fold(0.0, f64::max) < 1e-10 {
            break;
        }
    }
    Some(w)
}

/// The penalised negative log-likelihood [`fit_counts`] minimises.
fn loss<const N: usize>(
    rows: &[([f64; N], f64, f64)],
    w: &[f64; N],
    start: &[f64; N],
    penalised: &[bool; N],
) -> f64 {
    let softplus = |z: f64| {
        if z > 0.0 {
            z + (-z).exp().ln_1p()
        } else {
            z.exp().ln_1p()
        }
    };
    let mut total = 0.0;
    for (x, k, n) in rows {
        let z: f64 = (0..N).map(|i| x[i] * w[i]).sum();
        total += k * softplus(-z) + (n - k) * softplus(z);
    }
    for i in 0..N {
        if penalised[i] {
            total += 0.5 * RIDGE * (w[i] - start[i]).powi(2);
        }
    }
    total
}

/// Solves `m · x = v` by Gaussian elimination with partial pivoting; `None` when singular.
// Indices read as the textbook algorithm does; iterators over rows and columns would not.
#[allow(clippy::needless_range_loop)]
fn solve<const N: usize>(mut m: [[f64; N]; N], mut v: [f64; N]) -> Option<[f64; N]> {
    for col in 0..N {
        let pivot = (col..N).max_by(|&a, &b| m[a][col].abs().total_cmp(&m[b][col].abs()))?;
        if m[pivot][col].abs() < 1e-12 {
            return None;
        }
        m.swap(col, pivot);
        v.swap(col, pivot);
        for row in col + 1..N {
            let f = m[row][col] / m[col][col];
            for k in col..N {
                m[row][k] -= f * m[col][k];
            }
            v[row] -= f * v[col];
        }
    }
    let mut x = [0.0; N];
    for row in (0..N).rev() {
        let rest: f64 = (row + 1..N).map(|k| m[row][k] * x[k]).sum();
        x[row] = (v[row] - rest) / m[row][row];
    }
    Some(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn the_solver_inverts_a_known_system() {
        let m = [[4.0, 1.0, 0.0], [1.0, 3.0, 1.0], [0.0, 1.0, 2.0]];
        let x = [1.0, -2.0, 3.0];
        let v = [
            4.0 * x[0] + x[1],
            x[0] + 3.0 * x[1] + x[2],
            x[1] + 2.0 * x[2],
        ];
        let got = solve(m, v).unwrap();
        for i in 0..3 {
            assert!((got[i] - x[i]).abs() < 1e-12, "{got:?}");
        }
        assert_eq!(solve([[1.0, 2.0], [2.0, 4.0]], [1.0, 2.0]), None);
    }

    #[test]
    fn a_two_weight_fit_recovers_the_model_that_made_the_data() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(11);
        let (a, c) = (1.3, 0.8);
        let rows: Vec<([f64; 2], bool)> = (0..20_000)
            .map(|_| {
                let p: f64 = rng.random_range(0.01..0.5);
                let y = rng.random::<f64>() < sigmoid(a * logit(p) + c);
                ([logit(p), 1.0], y)
            })
            .collect();
        let w = fit(&rows, [1.0, 0.0], [true, false]).unwrap();
        assert!((w[0] - a).abs() < 0.08 && (w[1] - c).abs() < 0.15, "{w:?}");
    }
}
