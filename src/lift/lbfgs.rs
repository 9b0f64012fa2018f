//! Limited-memory BFGS (Nocedal & Wright, *Numerical Optimization*, 2nd ed., Algorithm 7.4 and
//! 7.5) with a backtracking Armijo line search, for the whole-sequence energy: a smooth problem
//! in ~10⁴–10⁵ unknowns whose acceleration term makes it badly conditioned (a second difference
//! along time), where a first-order method such as Adam needs a step small enough to be stable on
//! the stiffest direction and then crawls along the others.
//!
//! Plain data in, plain data out; the caller supplies the energy and its gradient.

use crate::error::Result;

/// Settings of one minimisation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lbfgs {
    /// Iterations (each one accepted step).
    pub iterations: usize,
    /// Stored (s, y) pairs.
    pub memory: usize,
    /// Stop when an iteration lowers f by less than `tolerance · max(|f|, 1)`.
    pub tolerance: f64,
}

/// What a minimisation did.
#[derive(Clone, Debug, PartialEq)]
pub struct LbfgsLog {
    pub iterations: usize,
    pub evaluations: usize,
    pub start: f64,
    pub end: f64,
}

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

/// Armijo constant and the step's shrink factor of the line search.
const C1: f64 = 1e-4;
const SHRINK: f64 = 0.5;
const MAX_BACKTRACK: usize = 30;

impl Lbfgs {
    /// Minimises `f` (returning the value and the gradient) from `x`; `x` holds the best point on
    /// return. `on_iteration` sees the iteration number and the value.
    pub fn minimise(
        &self,
        x: &mut [f64],
        mut f: impl FnMut(&[f64]) -> Result<(f64, Vec<f64>)>,
        mut on_iteration: impl FnMut(usize, f64),
    ) -> Result<LbfgsLog> {
        let n = x.len();
        let (mut fx, mut g) = f(x)?;
        let start = fx;
        let mut evaluations = 1;
        let mut hist: std::collections::VecDeque<(Vec<f64>, Vec<f64>, f64)> = Default::default();
        let mut done = 0;
        for it in 0..self.iterations {
            // Two-loop recursion: d = −H g.
            let mut q = g.clone();
            let mut alpha = Vec::with_capacity(hist.len());
            for (s, y, rho) in hist.iter().rev() {
                let a = rho * dot(s, &q);
                q.iter_mut().zip(y).for_each(|(qi, yi)| *qi -= a * yi);
                alpha.push(a);
            }
            let gamma = match hist.back() {
                Some((s, y, _)) => dot(s, y) / dot(y, y).max(1e-300),
                None => 1.0 / dot(&g, &g).sqrt().max(1e-300),
            };
            q.iter_mut().for_each(|v| *v *= gamma);
            for ((s, y, rho), a) in hist.iter().zip(alpha.iter().rev()) {
                let b = rho * dot(y, &q);
                q.iter_mut().zip(s).for_each(|(qi, si)| *qi += (a - b) * si);
            }
            let mut d: Vec<f64> = q.into_iter().map(|v| -v).collect();
            let mut slope = dot(&g, &d);
            if slope >= 0.0 || !slope.is_finite() {
                // Not a descent direction: restart from steepest descent.
                hist.clear();
                let scale = 1.0 / dot(&g, &g).sqrt().max(1e-300);
                d = g.iter().map(|v| -v * scale).collect();
                slope = dot(&g, &d);
            }
            if slope == 0.0 {
                break;
            }
            // Backtracking line search from the unit step.
            let mut step = 1.0;
            let mut accepted = None;
            for _ in 0..MAX_BACKTRACK {
                let trial: Vec<f64> = x.iter().zip(&d).map(|(xi, di)| xi + step * di).collect();
                let (ft, gt) = f(&trial)?;
                evaluations += 1;
                if ft.is_finite() && ft <= fx + C1 * step * slope {
                    accepted = Some((trial, ft, gt));
                    break;
                }
                step *= SHRINK;
            }
            let Some((xt, ft, gt)) = accepted else {
                break;
            };
            let s: Vec<f64> = xt.iter().zip(x.iter()).map(|(a, b)| a - b).collect();
            let y: Vec<f64> = gt.iter().zip(&g).map(|(a, b)| a - b).collect();
            let sy = dot(&s, &y);
            if sy > 1e-12 * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() {
                if hist.len() == self.memory {
                    hist.pop_front();
                }
                hist.push_back((s, y, 1.0 / sy));
            }
            let gain = fx - ft;
            x.copy_from_slice(&xt);
            fx = ft;
            g = gt;
            done = it + 1;
            on_iteration(it, fx);
            if gain <= self.tolerance * fx.abs().max(1.0) || n == 0 {
                break;
            }
        }
        Ok(LbfgsLog {
            iterations: done,
            evaluations,
            start,
            end: fx,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn minimises_an_ill_conditioned_rosenbrock_chain() {
        // Σ 100 (x_{k+1} − x_k²)² + (1 − x_k)², minimum at all ones.
        let n = 20;
        let mut x = vec![-1.2; n];
        let f = |x: &[f64]| -> Result<(f64, Vec<f64>)> {
            let mut v = 0.0;
            let mut g = vec![0.0; x.len()];
            for k in 0..x.len() - 1 {
                let a = x[k + 1] - x[k] * x[k];
                let b = 1.0 - x[k];
                v += 100.0 * a * a + b * b;
                g[k] += -400.0 * a * x[k] - 2.0 * b;
                g[k + 1] += 200.0 * a;
            }
            Ok((v, g))
        };
        let log = Lbfgs {
            iterations: 2000,
            memory: 10,
            tolerance: 0.0,
        }
        .minimise(&mut x, f, |_, _| {})
        .unwrap();
        assert!(log.end < 1e-10, "{log:?}");
        assert!(x.iter().all(|v| (v - 1.0).abs() < 1e-4), "{x:?}");
    }
}
