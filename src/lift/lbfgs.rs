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

/// Elements per chunk of the vector algebra: fixed, so sums (added chunk by chunk in order) give
/// the same bytes for any thread count; vectors of one chunk or less run on the calling thread.
const CHUNK: usize = 16_384;

/// a · b, in chunks of [`CHUNK`] added in order.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    use rayon::prelude::*;
    let one = |(a, b): (&[f64], &[f64])| -> f64 { a.iter().zip(b).map(|(x, y)| x * y).sum() };
    if a.len() <= CHUNK {
        return one((a, b));
    }
    let parts: Vec<f64> = a
        .par_chunks(CHUNK)
        .zip(b.par_chunks(CHUNK))
        .map(one)
        .collect();
    parts.iter().sum()
}

/// y_i = f(y_i, x_i) for every i (element-wise, in parallel chunks for long vectors).
fn zip_map(y: &mut [f64], x: &[f64], f: impl Fn(f64, f64) -> f64 + Sync) {
    use rayon::prelude::*;
    if y.len() <= CHUNK {
        y.iter_mut().zip(x).for_each(|(a, &b)| *a = f(*a, b));
        return;
    }
    y.par_chunks_mut(CHUNK)
        .zip(x.par_chunks(CHUNK))
        .for_each(|(ys, xs)| ys.iter_mut().zip(xs).for_each(|(a, &b)| *a = f(*a, b)));
}

/// out_i = f(a_i, b_i) for every i (element-wise, in parallel chunks for long vectors).
fn zip_into(out: &mut [f64], a: &[f64], b: &[f64], f: impl Fn(f64, f64) -> f64 + Sync) {
    use rayon::prelude::*;
    if out.len() <= CHUNK {
        out.iter_mut()
            .zip(a.iter().zip(b))
            .for_each(|(o, (&x, &y))| *o = f(x, y));
        return;
    }
    out.par_chunks_mut(CHUNK)
        .zip(a.par_chunks(CHUNK).zip(b.par_chunks(CHUNK)))
        .for_each(|(os, (xs, ys))| {
            os.iter_mut()
                .zip(xs.iter().zip(ys))
                .for_each(|(o, (&x, &y))| *o = f(x, y))
        });
}

/// Armijo constant and the step's shrink factor of the line search.
const C1: f64 = 1e-4;
const SHRINK: f64 = 0.5;
const MAX_BACKTRACK: usize = 30;

impl Lbfgs {
    /// Minimises `f` from `x`: `f(x, g)` returns the value at `x` and writes the gradient into `g`.
    /// `x` holds the best point on return. `on_iteration` sees the iteration number and the value.
    /// Every vector is allocated once per call (the history's pairs are recycled).
    pub fn minimise(
        &self,
        x: &mut [f64],
        mut f: impl FnMut(&[f64], &mut [f64]) -> Result<f64>,
        mut on_iteration: impl FnMut(usize, f64),
    ) -> Result<LbfgsLog> {
        let n = x.len();
        let mut g = vec![0.0; n];
        let mut fx = f(x, &mut g)?;
        let start = fx;
        let mut evaluations = 1;
        // (s, y, 1 / sᵀy), oldest first.
        let mut hist: std::collections::VecDeque<(Vec<f64>, Vec<f64>, f64)> = Default::default();
        let (mut d, mut trial, mut gt) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut alpha = Vec::with_capacity(self.memory);
        let mut spare: Option<(Vec<f64>, Vec<f64>)> = None;
        let mut done = 0;
        for it in 0..self.iterations {
            // Two-loop recursion: d = −H g.
            d.copy_from_slice(&g);
            alpha.clear();
            for (s, y, rho) in hist.iter().rev() {
                let a = rho * dot(s, &d);
                zip_map(&mut d, y, |qi, yi| qi - a * yi);
                alpha.push(a);
            }
            let gamma = match hist.back() {
                Some((s, y, _)) => dot(s, y) / dot(y, y).max(1e-300),
                None => 1.0 / dot(&g, &g).sqrt().max(1e-300),
            };
            zip_map(&mut d, &g, |qi, _| qi * gamma);
            for ((s, y, rho), a) in hist.iter().zip(alpha.iter().rev()) {
                let b = rho * dot(y, &d);
                zip_map(&mut d, s, |qi, si| qi + (a - b) * si);
            }
            zip_map(&mut d, &g, |qi, _| -qi);
            let mut slope = dot(&g, &d);
            if slope >= 0.0 || !slope.is_finite() {
                // Not a descent direction: restart from steepest descent.
                hist.clear();
                let scale = 1.0 / dot(&g, &g).sqrt().max(1e-300);
                zip_into(&mut d, &g, &g, |v, _| -v * scale);
                slope = dot(&g, &d);
            }
            if slope == 0.0 {
                break;
            }
            // Backtracking line search from the unit step.
            let mut step = 1.0;
            let mut accepted = None;
            for _ in 0..MAX_BACKTRACK {
                zip_into(&mut trial, x, &d, |xi, di| xi + step * di);
                let ft = f(&trial, &mut gt)?;
                evaluations += 1;
                if ft.is_finite() && ft <= fx + C1 * step * slope {
                    accepted = Some(ft);
                    break;
                }
                step *= SHRINK;
            }
            let Some(ft) = accepted else {
                break;
            };
            // s = trial − x and y = gt − g, in recycled storage (the pair the memory last dropped).
            let (mut s, mut y) = spare.take().unwrap_or_else(|| (vec![0.0; n], vec![0.0; n]));
            zip_into(&mut s, &trial, x, |a, b| a - b);
            zip_into(&mut y, &gt, &g, |a, b| a - b);
            let sy = dot(&s, &y);
            if sy > 1e-12 * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() {
                if hist.len() == self.memory {
                    spare = hist.pop_front().map(|(s, y, _)| (s, y));
                }
                hist.push_back((s, y, 1.0 / sy));
            } else {
                spare = Some((s, y));
            }
            let gain = fx - ft;
            x.copy_from_slice(&trial);
            fx = ft;
            std::mem::swap(&mut g, &mut gt);
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
        let f = |x: &[f64], g: &mut [f64]| -> Result<f64> {
            let mut v = 0.0;
            g.iter_mut().for_each(|gk| *gk = 0.0);
            for k in 0..x.len() - 1 {
                let a = x[k + 1] - x[k] * x[k];
                let b = 1.0 - x[k];
                v += 100.0 * a * a + b * b;
                g[k] += -400.0 * a * x[k] - 2.0 * b;
                g[k + 1] += 200.0 * a;
            }
            Ok(v)
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
