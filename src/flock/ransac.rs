//! RANSAC (Fischler & Bolles 1981) fits of one side of a formation (Klotsman & Tal §4 Step 2): a
//! line for V and line shapes, a parabola for U and J shapes, with outliers.
//!
//! A side is a set of points `(u, t)`: `u ≥ 0` the lateral distance from the leader, `t` the
//! longitudinal offset from it (negative behind), both in wingspans. The model is `t = f(u)`,
//! a polynomial of degree 1 or 2; the residual is longitudinal, as the paper's deviations are.

use rand::seq::index::sample;
use rand::Rng;
use serde::{Deserialize, Serialize};

/// The model fitted to a side.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Model {
    /// `t = a + b u` (V, line).
    Line,
    /// `t = a + b u + c u²` (U, J).
    Parabola,
}

impl Model {
    /// Number of coefficients (and of points in a minimal sample).
    pub fn params(self) -> usize {
        match self {
            Model::Line => 2,
            Model::Parabola => 3,
        }
    }
}

/// Evaluates the polynomial `coef` (ascending powers) at `u`.
pub fn eval(coef: &[f64], u: f64) -> f64 {
    coef.iter().rev().fold(0.0, |acc, c| acc * u + c)
}

/// A fitted side.
#[derive(Clone, Debug, PartialEq)]
pub struct Fit {
    pub model: Model,
    /// Coefficients, ascending powers of u.
    pub coef: Vec<f64>,
    /// Per point: within the threshold of the final model.
    pub inlier: Vec<bool>,
}

/// Least-squares polynomial of `model`'s degree through the points `idx` (normal equations with
/// u scaled to [0, 1] for conditioning). `None` when the points do not determine it.
pub fn least_squares(model: Model, pts: &[(f64, f64)], idx: &[usize]) -> Option<Vec<f64>> {
    let k = model.params();
    if idx.len() < k {
        return None;
    }
    let scale = idx
        .iter()
        .map(|&i| pts[i].0.abs())
        .fold(0.0f64, f64::max)
        .max(1e-12);
    let mut ata = [[0.0f64; 3]; 3];
    let mut atb = [0.0f64; 3];
    for &i in idx {
        let (u, t) = (pts[i].0 / scale, pts[i].1);
        let row = [1.0, u, u * u];
        for r in 0..k {
            atb[r] += row[r] * t;
            for c in 0..k {
                ata[r][c] += row[r] * row[c];
            }
        }
    }
    let sol = solve_small(&mut ata, &mut atb, k)?;
    // Undo the scaling: coefficient of u^p divides by scale^p.
    Some(
        (0..k)
            .map(|p| sol[p] / scale.powi(p as i32))
            .collect::<Vec<f64>>(),
    )
}

/// Gaussian elimination with partial pivoting on a k×k system (k ≤ 3).
#[allow(clippy::needless_range_loop)]
fn solve_small(a: &mut [[f64; 3]; 3], b: &mut [f64; 3], k: usize) -> Option<[f64; 3]> {
    let norm = (0..k)
        .flat_map(|r| (0..k).map(move |c| (r, c)))
        .map(|(r, c)| a[r][c].abs())
        .fold(0.0f64, f64::max);
    for col in 0..k {
        let piv = (col..k).max_by(|&x, &y| a[x][col].abs().total_cmp(&a[y][col].abs()))?;
        if a[piv][col].abs() <= 1e-12 * norm.max(1e-300) {
            return None;
        }
        a.swap(col, piv);
        b.swap(col, piv);
        for r in col + 1..k {
            let f = a[r][col] / a[col][col];
            for c in col..k {
                a[r][c] -= f * a[col][c];
            }
            b[r] -= f * b[col];
        }
    }
    let mut x = [0.0f64; 3];
    for r in (0..k).rev() {
        let s: f64 = (r + 1..k).map(|c| a[r][c] * x[c]).sum();
        x[r] = (b[r] - s) / a[r][r];
    }
    x.iter().all(|v| v.is_finite()).then_some(x)
}

fn inliers(coef: &[f64], pts: &[(f64, f64)], threshold: f64) -> (Vec<bool>, f64) {
    let mut sse = 0.0;
    let flags = pts
        .iter()
        .map(|&(u, t)| {
            let r = (t - eval(coef, u)).abs();
            let ok = r <= threshold;
            if ok {
                sse += r * r;
            }
            ok
        })
        .collect();
    (flags, sse)
}

/// RANSAC: `iterations` minimal samples, the model with most inliers (ties: smaller squared
/// residual) is refitted by least squares on its inliers until the inlier set stops changing.
/// Fewer points than a minimal sample + 1 leave no redundancy: they are all inliers of the
/// least-squares fit (or of a lower-degree model when even that is undetermined).
pub fn fit(
    model: Model,
    pts: &[(f64, f64)],
    threshold: f64,
    iterations: usize,
    rng: &mut impl Rng,
) -> Option<Fit> {
    let k = model.params();
    let all: Vec<usize> = (0..pts.len()).collect();
    if pts.len() <= k {
        let m = if pts.len() >= k { model } else { Model::Line };
        let coef = least_squares(m, pts, &all).or_else(|| {
            // One point (or coincident u): a constant.
            let mean = pts.iter().map(|p| p.1).sum::<f64>() / pts.len().max(1) as f64;
            (!pts.is_empty()).then(|| vec![mean, 0.0])
        })?;
        let mut coef = coef;
        coef.resize(k, 0.0);
        return Some(Fit {
            model,
            coef,
            inlier: vec![true; pts.len()],
        });
    }
    let mut best: Option<(usize, f64, Vec<f64>)> = None;
    for _ in 0..iterations {
        let idx = sample(rng, pts.len(), k).into_vec();
        let Some(coef) = least_squares(model, pts, &idx) else {
            continue;
        };
        let (flags, sse) = inliers(&coef, pts, threshold);
        let n = flags.iter().filter(|&&f| f).count();
        let better = match &best {
            None => true,
            Some((bn, bs, _)) => n > *bn || (n == *bn && sse < *bs),
        };
        if better {
            best = Some((n, sse, coef));
        }
    }
    let (_, _, mut coef) = best?;
    let (mut flags, _) = inliers(&coef, pts, threshold);
    for _ in 0..10 {
        let idx: Vec<usize> = (0..pts.len()).filter(|&i| flags[i]).collect();
        let Some(c) = least_squares(model, pts, &idx) else {
            break;
        };
        let (f2, _) = inliers(&c, pts, threshold);
        coef = c;
        if f2 == flags {
            break;
        }
        flags = f2;
    }
    Some(Fit {
        model,
        coef,
        inlier: flags,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    #[test]
    fn line_and_parabola_are_recovered_with_outliers() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut pts: Vec<(f64, f64)> = (0..12)
            .map(|i| (i as f64, 0.5 - 1.7 * i as f64 + 0.01 * ((i * 7) % 5) as f64))
            .collect();
        pts[4].1 += 2.0;
        pts[9].1 -= 1.5;
        let f = fit(Model::Line, &pts, 0.3, 100, &mut rng).unwrap();
        assert!((f.coef[1] + 1.7).abs() < 0.01, "{:?}", f.coef);
        let out: Vec<usize> = (0..12).filter(|&i| !f.inlier[i]).collect();
        assert_eq!(out, vec![4, 9]);
        let pts: Vec<(f64, f64)> = (0..10)
            .map(|i| (i as f64, -0.3 * (i * i) as f64 + 0.2 * i as f64))
            .collect();
        let f = fit(Model::Parabola, &pts, 0.1, 100, &mut rng).unwrap();
        assert!((f.coef[2] + 0.3).abs() < 1e-9 && (f.coef[1] - 0.2).abs() < 1e-9);
        assert!(f.inlier.iter().all(|&b| b));
        // Two points cannot fix a parabola: the line through them, all inliers.
        let f = fit(Model::Parabola, &pts[..2], 0.1, 10, &mut rng).unwrap();
        assert_eq!(f.coef.len(), 3);
        assert!((eval(&f.coef, 1.0) - pts[1].1).abs() < 1e-12);
    }
}
