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

/// One pass over `d`: d_i = update(d_i, x_i) for every i, returning Σ_i w_i · d_i (new) grouped
/// as [`dot`] (`w` empty: 0). The two-loop recursion's axpy and the next pair's dot product in
/// one read of `d` instead of two.
fn update_dot(d: &mut [f64], x: &[f64], w: &[f64], update: impl Fn(f64, f64) -> f64 + Sync) -> f64 {
    use rayon::prelude::*;
    let one = |(ds, xs, ws): (&mut [f64], &[f64], &[f64])| -> f64 {
        if ws.is_empty() {
            ds.iter_mut().zip(xs).for_each(|(q, &v)| *q = update(*q, v));
            return 0.0;
        }
        ds.iter_mut()
            .zip(xs)
            .zip(ws)
            .map(|((q, &v), &wi)| {
                *q = update(*q, v);
                wi * *q
            })
            .sum()
    };
    if d.len() <= CHUNK {
        return one((d, x, w));
    }
    let parts: Vec<f64> = d
        .par_chunks_mut(CHUNK)
        .zip(x.par_chunks(CHUNK))
        .enumerate()
        .map(|(c, (ds, xs))| {
            let ws = w
                .get(c * CHUNK..)
                .map_or(&[][..], |w| &w[..ds.len().min(w.len())]);
            one((ds, xs, ws))
        })
        .collect();
    if w.is_empty() {
        0.0
    } else {
        parts.iter().sum()
    }
}

/// y_i = f(y_i, x_i) for every i (element-wise, in parallel chunks for long vectors).
fn zip_map(y: &mut [f64], x: &[f64], f: impl Fn(f64, f64) -> f64 + Sync) {
    update_dot(y, x, &[], f);
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

/// s = a − x and y = b − g in one pass, with sᵀy, yᵀy and sᵀs grouped as [`dot`].
fn pair_of(
    s: &mut [f64],
    y: &mut [f64],
    (a, x, b, g): (&[f64], &[f64], &[f64], &[f64]),
) -> [f64; 3] {
    use rayon::prelude::*;
    let one = |(ss, ys, c): (&mut [f64], &mut [f64], usize)| -> [f64; 3] {
        let at = c * CHUNK;
        for (k, (si, yi)) in ss.iter_mut().zip(ys.iter_mut()).enumerate() {
            *si = a[at + k] - x[at + k];
            *yi = b[at + k] - g[at + k];
        }
        // The three sums in dot's order, while the chunk is in cache.
        let sy: f64 = ss.iter().zip(ys.iter()).map(|(p, q)| p * q).sum();
        let yy: f64 = ys.iter().map(|q| q * q).sum();
        let s2: f64 = ss.iter().map(|p| p * p).sum();
        [sy, yy, s2]
    };
    let parts: Vec<[f64; 3]> = if s.len() <= CHUNK {
        vec![one((s, y, 0))]
    } else {
        s.par_chunks_mut(CHUNK)
            .zip(y.par_chunks_mut(CHUNK))
            .enumerate()
            .map(|(c, (ss, ys))| one((ss, ys, c)))
            .collect()
    };
    if parts.len() == 1 {
        return parts[0];
    }
    [0, 1, 2].map(|k| parts.iter().map(|p| p[k]).sum())
}

/// Armijo constant and the step's shrink factor of the line search.
const C1: f64 = 1e-4;
const SHRINK: f64 = 0.5;
const MAX_BACKTRACK: usize = 30;

/// One stored pair: s, y, 1 / sᵀy, and sᵀy / yᵀy (the initial Hessian scale γ it gives).
type Pair = (Vec<f64>, Vec<f64>, f64, f64);

/// The two-loop recursion (Nocedal & Wright, Algorithm 7.4): d = −H g for the history `hist`
/// (oldest first), returning the slope g · d. Each pair's axpy is fused with the next pair's dot
/// product (one pass over d per pair and loop instead of two), and the initial scale, the final
/// negation and the slope likewise; every sum is grouped as [`dot`] groups it, so the bytes are
/// those of the textbook loops (`the_fused_two_loop_recursion_gives_the_textbook_bytes`).
fn direction(
    hist: &std::collections::VecDeque<Pair>,
    g: &[f64],
    d: &mut [f64],
    alpha: &mut [f64],
) -> f64 {
    let m = hist.len();
    // s of pair i, or nothing.
    let s_at = |i: Option<usize>| i.map_or(&[][..], |i| &hist[i].0[..]);
    // d = g, with s_newest · d.
    let mut next = update_dot(d, g, s_at(m.checked_sub(1)), |_, gi| gi);
    for i in (0..m).rev() {
        let a = hist[i].2 * next;
        alpha[i] = a;
        next = update_dot(d, &hist[i].1, s_at(i.checked_sub(1)), |qi, yi| qi - a * yi);
    }
    if m == 0 {
        let gamma = 1.0 / dot(g, g).sqrt().max(1e-300);
        zip_map(d, g, |qi, _| qi * gamma);
        return update_dot(d, g, g, |qi, _| -qi);
    }
    // d = γ d (γ = sᵀy / yᵀy of the newest pair), with y_oldest · d.
    let gamma = hist[m - 1].3;
    next = update_dot(d, g, &hist[0].1, |qi, _| qi * gamma);
    for i in 0..m {
        let (a, b) = (alpha[i], hist[i].2 * next);
        if i + 1 < m {
            next = update_dot(d, &hist[i].0, &hist[i + 1].1, |qi, si| qi + (a - b) * si);
        } else {
            // The last pair, the negation and the slope g · d in one pass.
            return update_dot(d, &hist[i].0, g, |qi, si| -(qi + (a - b) * si));
        }
    }
    unreachable!("m > 0")
}

impl Lbfgs {
    /// Minimises `f` from `x`: `f(x, g)` returns the value at `x` and writes the gradient into `g`.
    /// `x` holds the best point on return. `on_iteration` sees the iteration number and the value.
    /// Every vector is allocated once per call (the history's pairs are recycled), and each
    /// iteration makes about half the passes over its vectors of the textbook form (`direction`,
    /// `pair_of`) with the same bytes.
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
        // Oldest first.
        let mut hist: std::collections::VecDeque<Pair> = Default::default();
        let (mut d, mut trial, mut gt) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mut xv = x.to_vec();
        let mut alpha = vec![0.0; self.memory];
        let mut spare: Option<(Vec<f64>, Vec<f64>)> = None;
        let mut done = 0;
        for it in 0..self.iterations {
            // Two-loop recursion: d = −H g.
            let mut slope = direction(&hist, &g, &mut d, &mut alpha);
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
                zip_into(&mut trial, &xv, &d, |xi, di| xi + step * di);
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
            let [sy, yy, ss] = pair_of(&mut s, &mut y, (&trial, &xv, &gt, &g));
            if sy > 1e-12 * yy.sqrt() * ss.sqrt() {
                if hist.len() == self.memory {
                    spare = hist.pop_front().map(|(s, y, _, _)| (s, y));
                }
                hist.push_back((s, y, 1.0 / sy, sy / yy.max(1e-300)));
            } else {
                spare = Some((s, y));
            }
            let gain = fx - ft;
            std::mem::swap(&mut xv, &mut trial);
            fx = ft;
            std::mem::swap(&mut g, &mut gt);
            done = it + 1;
            on_iteration(it, fx);
            if gain <= self.tolerance * fx.abs().max(1.0) || n == 0 {
                break;
            }
        }
        x.copy_from_slice(&xv);
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

    /// The textbook two-loop recursion with separate dot and axpy passes (the code before the
    /// fusion), for the bytes the fused one must give.
    fn textbook(hist: &std::collections::VecDeque<Pair>, g: &[f64], d: &mut [f64]) -> f64 {
        d.copy_from_slice(g);
        let mut alpha = Vec::new();
        for (s, y, rho, _) in hist.iter().rev() {
            let a = rho * dot(s, d);
            zip_map(d, y, |qi, yi| qi - a * yi);
            alpha.push(a);
        }
        let gamma = match hist.back() {
            Some((s, y, _, _)) => dot(s, y) / dot(y, y).max(1e-300),
            None => 1.0 / dot(g, g).sqrt().max(1e-300),
        };
        zip_map(d, g, |qi, _| qi * gamma);
        for ((s, y, rho, _), a) in hist.iter().zip(alpha.iter().rev()) {
            let b = rho * dot(y, d);
            zip_map(d, s, |qi, si| qi + (a - b) * si);
        }
        zip_map(d, g, |qi, _| -qi);
        dot(g, d)
    }

    #[test]
    fn the_fused_two_loop_recursion_gives_the_textbook_bytes() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        // One chunk and several (with a short last one).
        for n in [1000, 3 * CHUNK + 123] {
            let mut v =
                |k: f64| -> Vec<f64> { (0..n).map(|_| k * rng.gen_range(-1.0..1.0)).collect() };
            let g = v(1.0);
            let mut hist: std::collections::VecDeque<Pair> = Default::default();
            for m in 0..=4 {
                let (mut d1, mut d2) = (vec![0.0; n], vec![0.0; n]);
                let mut alpha = vec![0.0; 4];
                let fused = direction(&hist, &g, &mut d1, &mut alpha);
                let plain = textbook(&hist, &g, &mut d2);
                assert_eq!(fused.to_bits(), plain.to_bits(), "n {n}, m {m}");
                assert!(
                    d1.iter().zip(&d2).all(|(a, b)| a.to_bits() == b.to_bits()),
                    "n {n}, m {m}"
                );
                // A new pair (y ≈ s: positive curvature), with pair_of's sums.
                let (x, trial, gt) = (v(1.0), v(1.0), v(0.1));
                let (mut s, mut y) = (vec![0.0; n], vec![0.0; n]);
                let gy: Vec<f64> = (0..n).map(|i| gt[i] - (trial[i] - x[i])).collect();
                let [sy, yy, ss] = pair_of(&mut s, &mut y, (&trial, &x, &g, &gy));
                assert_eq!(
                    [sy, yy, ss].map(f64::to_bits),
                    [dot(&s, &y), dot(&y, &y), dot(&s, &s)].map(f64::to_bits)
                );
                hist.push_back((s, y, 1.0 / sy, sy / yy.max(1e-300)));
            }
        }
    }

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
