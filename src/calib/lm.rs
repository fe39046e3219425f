//! Levenberg–Marquardt least squares with a numerical (central-difference) Jacobian, for the
//! calibration fits: minimise Σ r_i(p)² over the parameter vector p.
//!
//! 1. r and J = ∂r/∂p at p (J column by column, step h_j = 1e-6·max(|p_j|, 1)).
//! 2. Solve (JᵀJ + λ·diag(JᵀJ)) δ = −Jᵀr (Cholesky); try p + δ.
//! 3. Accept when the cost drops (λ /= 10), else λ *= 10 and retry; stop when the relative
//!    drop of the cost or the step is below `tol`, or after `max_iter` iterations.
//!
//! A block structure (parameters that touch only some residuals, like one view's pose) is
//! exploited by `dependents`: column j is only recomputed on the residual range it touches.

use nalgebra::{DMatrix, DVector};
use std::ops::Range;

/// Options of [`minimize`].
#[derive(Debug, Clone, Copy)]
pub struct LmOptions {
    /// Largest number of accepted or rejected steps.
    pub max_iter: usize,
    /// Relative change of cost or parameters below which the fit has converged.
    pub tol: f64,
}

impl Default for LmOptions {
    fn default() -> Self {
        Self {
            max_iter: 200,
            tol: 1e-12,
        }
    }
}

/// The result of a fit.
#[derive(Debug, Clone)]
pub struct LmResult {
    /// Final sum of squared residuals.
    pub cost: f64,
    /// Iterations used.
    pub iterations: usize,
}

/// The sparsity of a calibration problem, as [`minimize`]'s `dependents`: the first `global`
/// parameters (lens, or the pair's R and T) act on all `m` residuals; after them each view has
/// `per_view` parameters (its pose) acting only on its own `rows` residuals.
pub fn view_blocks(global: usize, per_view: usize, rows: usize, m: usize) -> impl Fn(usize) -> Range<usize> {
    move |j| {
        if j < global {
            0..m
        } else {
            let v = (j - global) / per_view;
            rows * v..rows * (v + 1)
        }
    }
}

/// Minimises Σ r² where `residuals(p, out)` fills `out` (length `m`) for parameters `p`.
/// `dependents(j)` gives the residual range parameter j influences (the whole range if unsure).
pub fn minimize(
    p: &mut [f64],
    m: usize,
    residuals: &dyn Fn(&[f64], &mut [f64]),
    dependents: &dyn Fn(usize) -> Range<usize>,
    opts: LmOptions,
) -> LmResult {
    let n = p.len();
    let mut r = vec![0.0; m];
    residuals(p, &mut r);
    let mut cost: f64 = r.iter().map(|v| v * v).sum();
    let mut lambda = 1e-3;
    let mut jac = DMatrix::<f64>::zeros(m, n);
    let mut rp = vec![0.0; m];
    let mut rm = vec![0.0; m];
    let mut q = p.to_vec();
    let mut iterations = 0;
    let mut need_jac = true;
    let (mut jtj, mut jtr) = (DMatrix::<f64>::zeros(n, n), DVector::<f64>::zeros(n));
    while iterations < opts.max_iter {
        iterations += 1;
        // 1. Jacobian by central differences, only where a parameter acts.
        if need_jac {
            jac.fill(0.0);
            for j in 0..n {
                let h = 1e-6 * p[j].abs().max(1.0);
                q.copy_from_slice(p);
                q[j] = p[j] + h;
                residuals(&q, &mut rp);
                q[j] = p[j] - h;
                residuals(&q, &mut rm);
                for i in dependents(j) {
                    jac[(i, j)] = (rp[i] - rm[i]) / (2.0 * h);
                }
            }
            jtj = jac.tr_mul(&jac);
            jtr = jac.tr_mul(&DVector::from_column_slice(&r));
            need_jac = false;
        }
        // 2. Damped normal equations.
        let mut a = jtj.clone();
        for k in 0..n {
            a[(k, k)] += lambda * jtj[(k, k)].max(1e-12);
        }
        let Some(ch) = a.cholesky() else {
            lambda *= 10.0;
            continue;
        };
        let delta = ch.solve(&(-&jtr));
        for k in 0..n {
            q[k] = p[k] + delta[k];
        }
        residuals(&q, &mut rp);
        let new_cost: f64 = rp.iter().map(|v| v * v).sum();
        // 3. Accept or reject.
        if new_cost.is_finite() && new_cost < cost {
            let drop = (cost - new_cost) / cost.max(1e-300);
            let step = delta.norm() / (p.iter().map(|v| v * v).sum::<f64>().sqrt() + 1e-12);
            p.copy_from_slice(&q);
            std::mem::swap(&mut r, &mut rp);
            cost = new_cost;
            lambda = (lambda / 10.0).max(1e-12);
            need_jac = true;
            if drop < opts.tol || step < opts.tol {
                break;
            }
        } else {
            lambda *= 10.0;
            if lambda > 1e12 {
                break;
            }
        }
    }
    LmResult { cost, iterations }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Fits y = a·exp(b·x) to exact data from a poor start.
    #[test]
    fn fits_an_exponential() {
        let xs: Vec<f64> = (0..20).map(|i| i as f64 * 0.1).collect();
        let ys: Vec<f64> = xs.iter().map(|x| 2.5 * (-1.3 * x).exp()).collect();
        let mut p = [1.0, 0.0];
        let f = |p: &[f64], out: &mut [f64]| {
            for (i, (x, y)) in xs.iter().zip(&ys).enumerate() {
                out[i] = p[0] * (p[1] * x).exp() - y;
            }
        };
        let res = minimize(&mut p, xs.len(), &f, &|_| 0..xs.len(), LmOptions::default());
        assert!((p[0] - 2.5).abs() < 1e-8 && (p[1] + 1.3).abs() < 1e-8, "{p:?} {res:?}");
    }
}
