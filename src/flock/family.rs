//! The example's shape family (Klotsman & Tal §5 Step 1: shapes that "maintain the general
//! shapes and deviations of the movie"), as a measure and as a constraint on key shapes.
//!
//! **The measure** ([`side_residuals`], [`worst_deviation`]): in one frame, in the flock frame
//! (x lateral, y forward, wingspans), the leader is the front-most bird and the others are split
//! into the two sides by their lateral position. Each side gets the curve of the example's
//! family through the leader by least squares over *all* its birds (outliers included): the
//! line t = a·u for V and line shapes, the parabola t = a·u + b·u² for U and J shapes (§4 Step 2's
//! models, here through the leader), with u ≥ 0 the lateral distance from the leader and t the
//! longitudinal offset. A bird's deviation is its longitudinal residual from its side's curve
//! (the paper's deviations are longitudinal, §4 Step 2); a frame's worst deviation is the largest
//! |residual|. The same function measures the example's frames and the animation's.
//!
//! **The constraint** ([`Family`]): Step 1's shapes are the example's frames carried to N birds
//! (its curves, its outliers' deviations, Gaussian deviations for the others), so their
//! residuals are the example's own deviation range. Each animated bird gets a band of residuals:
//! the birds that Step 1 matched to an example outlier keep their own range over the shapes
//! (joined to the inliers' band), every other bird the inliers' band (the range of all
//! non-outlier residuals over the shapes), every band within the example's own worst deviation
//! (its frames measured as above); each side's curve coefficients keep their range over
//! the shapes, widened by [`COEF_MARGIN`] of their spread. A key shape must lie inside every band
//! and range ([`Family::violation`] = 0). The residuals and the coefficients are linear in the
//! longitudinal positions for a fixed lateral layout, so a minimum-jerk blend of two key shapes on
//! proportional layouts stays inside convex bands: the steady frames between key shapes keep the
//! family too (measured, not assumed: RESULTS).

use super::extract::ShapeParams;
use super::ransac::Model;
use super::steady::InitialShapes;
use serde::Serialize;

/// Widening of each side's coefficient range over Step 1's shapes, as a fraction of its spread
/// (at least [`COEF_FLOOR`] of the coefficient's magnitude).
pub const COEF_MARGIN: f64 = 0.25;

/// Least widening of a coefficient range, as a fraction of the coefficient's magnitude.
pub const COEF_FLOOR: f64 = 0.05;

/// Least-squares curve of `model` through the origin for the points `(u, t)`: `[a]` for a line
/// t = a·u, `[a, b]` for a parabola t = a·u + b·u². A parabola with fewer than two points of
/// distinct u falls back to the line (b = 0); no point (or all at u = 0) gives zeros.
pub fn curve_through_origin(model: Model, pts: &[(f64, f64)]) -> Vec<f64> {
    let (mut s2, mut s3, mut s4, mut s1t, mut s2t) = (0.0, 0.0, 0.0, 0.0, 0.0);
    for &(u, t) in pts {
        let u2 = u * u;
        s2 += u2;
        s3 += u2 * u;
        s4 += u2 * u2;
        s1t += u * t;
        s2t += u2 * t;
    }
    let line = if s2 > 0.0 { s1t / s2 } else { 0.0 };
    match model {
        Model::Line => vec![line],
        Model::Parabola => {
            let det = s2 * s4 - s3 * s3;
            if pts.len() >= 2 && det > 1e-12 * (s2 * s4).max(f64::MIN_POSITIVE) {
                vec![(s1t * s4 - s2t * s3) / det, (s2 * s2t - s3 * s1t) / det]
            } else {
                vec![line, 0.0]
            }
        }
    }
}

fn eval(coef: &[f64], u: f64) -> f64 {
    coef[0] * u + coef.get(1).map_or(0.0, |b| b * u * u)
}

/// Residuals of an animated shape (bird 0 the leader, 1..=`nl` its left side from the leader
/// outward, the rest its right side; `x`, `y` in wingspans): per bird its longitudinal residual
/// from its side's curve through the leader (0 for the leader), and each side's coefficients.
pub fn side_residuals(model: Model, nl: usize, x: &[f64], y: &[f64]) -> (Vec<f64>, [Vec<f64>; 2]) {
    let n = x.len();
    let mut r = vec![0.0; n];
    let mut coefs = [Vec::new(), Vec::new()];
    for (s, range) in [(0usize, 1..(nl + 1).min(n)), (1, (nl + 1).min(n)..n)] {
        let pts: Vec<(f64, f64)> = range
            .clone()
            .map(|i| ((x[i] - x[0]).abs(), y[i] - y[0]))
            .collect();
        let c = curve_through_origin(model, &pts);
        for (i, &(u, t)) in range.zip(&pts) {
            r[i] = t - eval(&c, u);
        }
        coefs[s] = c;
    }
    (r, coefs)
}

/// The worst deviation of one frame of any flock (module docs): leader = the front-most bird,
/// sides by lateral position, each side's curve of `model` through the leader by least squares,
/// the largest |longitudinal residual| (wingspans). Points `[x, y]` in the flock frame; 0 for
/// fewer than two birds.
pub fn worst_deviation(model: Model, pts: &[[f64; 2]]) -> f64 {
    if pts.len() < 2 {
        return 0.0;
    }
    let lead = (0..pts.len())
        .max_by(|&a, &b| pts[a][1].total_cmp(&pts[b][1]).then(b.cmp(&a)))
        .unwrap_or(0);
    let l = pts[lead];
    let mut worst: f64 = 0.0;
    for left in [true, false] {
        let side: Vec<(f64, f64)> = (0..pts.len())
            .filter(|&i| i != lead && ((pts[i][0] < l[0]) == left))
            .map(|i| ((pts[i][0] - l[0]).abs(), pts[i][1] - l[1]))
            .collect();
        let c = curve_through_origin(model, &side);
        for &(u, t) in &side {
            worst = worst.max((t - eval(&c, u)).abs());
        }
    }
    worst
}

/// The worst deviation over an example's own frames ([`worst_deviation`] of each frame's birds).
pub fn example_worst(params: &ShapeParams) -> f64 {
    params
        .frames
        .iter()
        .map(|f| {
            let pts: Vec<[f64; 2]> = f.birds.iter().map(|b| [b.x, b.y]).collect();
            worst_deviation(params.kind.model(), &pts)
        })
        .fold(0.0, f64::max)
}

/// The shape family of an example carried to N animated birds: residual bands and coefficient
/// ranges (module docs).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Family {
    pub model: Model,
    /// Birds on the left side (bird 0 is the leader; the right side follows the left).
    pub nl: usize,
    /// Per animated bird: the band [lo, hi] of its longitudinal residual, wingspans.
    pub bands: Vec<[f64; 2]>,
    /// Per side (left, right), per coefficient: [lo, hi].
    pub coefs: [Vec<[f64; 2]>; 2],
    /// The widest lateral extent of a side over Step 1's shapes, wingspans: converts a
    /// coefficient's excess into a longitudinal distance in [`Family::violation`].
    pub reach: f64,
}

impl Family {
    /// No constraint: every band and range unbounded.
    pub fn free(model: Model, nl: usize, n: usize) -> Self {
        let inf = [f64::NEG_INFINITY, f64::INFINITY];
        Family {
            model,
            nl,
            bands: vec![inf; n],
            coefs: [vec![inf; model.params() - 1], vec![inf; model.params() - 1]],
            reach: 1.0,
        }
    }

    /// The family of Step 1's `shapes` (animated indexing), `outlier[i]` telling which animated
    /// birds Step 1 matched to an example bird that is an outlier in some frame; no band reaches
    /// beyond ±`limit` (the example's own worst deviation).
    pub fn from_shapes(
        model: Model,
        nl: usize,
        shapes: &[Vec<[f64; 2]>],
        outlier: &[bool],
        limit: f64,
    ) -> Self {
        let n = shapes.first().map_or(0, |s| s.len());
        let k = model.params() - 1;
        let mut own = vec![[f64::INFINITY, f64::NEG_INFINITY]; n];
        let mut inl = [f64::INFINITY, f64::NEG_INFINITY];
        let mut coefs = [
            vec![[f64::INFINITY, f64::NEG_INFINITY]; k],
            vec![[f64::INFINITY, f64::NEG_INFINITY]; k],
        ];
        let mut reach: f64 = 1.0;
        let widen = |b: &mut [f64; 2], v: f64| {
            b[0] = b[0].min(v);
            b[1] = b[1].max(v);
        };
        for s in shapes {
            let x: Vec<f64> = s.iter().map(|p| p[0]).collect();
            let y: Vec<f64> = s.iter().map(|p| p[1]).collect();
            reach = reach.max(x.iter().map(|v| (v - x[0]).abs()).fold(0.0, f64::max));
            let (r, c) = side_residuals(model, nl, &x, &y);
            for i in 1..n {
                widen(&mut own[i], r[i]);
                if !outlier[i] {
                    widen(&mut inl, r[i]);
                }
            }
            for side in 0..2 {
                for (b, v) in coefs[side].iter_mut().zip(&c[side]) {
                    widen(b, *v);
                }
            }
        }
        if !inl[0].is_finite() {
            inl = [0.0, 0.0];
        }
        let mut bands = vec![[0.0, 0.0]; n];
        for i in 1..n {
            let b = if outlier[i] && own[i][0].is_finite() {
                [own[i][0].min(inl[0]), own[i][1].max(inl[1])]
            } else {
                inl
            };
            bands[i] = [b[0].max(-limit).min(0.0), b[1].min(limit).max(0.0)];
        }
        for side in coefs.iter_mut() {
            for b in side.iter_mut() {
                if !b[0].is_finite() {
                    *b = [f64::NEG_INFINITY, f64::INFINITY];
                    continue;
                }
                let m = (COEF_MARGIN * (b[1] - b[0])).max(COEF_FLOOR * b[0].abs().max(b[1].abs()));
                *b = [b[0] - m, b[1] + m];
            }
        }
        Family {
            model,
            nl,
            bands,
            coefs,
            reach,
        }
    }

    /// The family of an example (`params`) carried to N birds by Step 1 (`init`): the example's
    /// side model, and as outliers the animated birds whose example bird is an outlier in some
    /// frame.
    pub fn of_example(params: &ShapeParams, init: &InitialShapes) -> Self {
        let outlier: Vec<bool> = init
            .example_bird
            .iter()
            .map(|b| {
                b.is_some_and(|id| {
                    params
                        .frames
                        .iter()
                        .any(|f| f.bird(id).is_some_and(|x| x.outlier))
                })
            })
            .collect();
        Family::from_shapes(
            params.kind.model(),
            init.nl,
            &init.shapes,
            &outlier,
            example_worst(params),
        )
    }

    /// How far the shape with lateral positions `x` and longitudinal `y` lies outside the family,
    /// wingspans: the sum over birds of the residual's distance outside its band, plus each
    /// coefficient's distance outside its range times its power of [`Family::reach`]. 0 inside.
    pub fn violation(&self, x: &[f64], y: &[f64]) -> f64 {
        let (r, c) = side_residuals(self.model, self.nl, x, y);
        let out = |v: f64, b: &[f64; 2]| (b[0] - v).max(v - b[1]).max(0.0);
        let mut total: f64 = r.iter().zip(&self.bands).map(|(v, b)| out(*v, b)).sum();
        for (cs, bs) in c.iter().zip(&self.coefs) {
            for (p, (v, b)) in cs.iter().zip(bs).enumerate() {
                total += out(*v, b) * self.reach.powi(p as i32 + 1);
            }
        }
        total
    }

    /// Longitudinal positions on the lateral layout `x1` that keep the shape (`x0`, `y0`) of the
    /// same birds: each bird keeps its residual from its side's curve, the curve evaluated at its
    /// new lateral distance from the leader (bird 0, which stays at y = `y0[0]`).
    pub fn carry(&self, x0: &[f64], y0: &[f64], x1: &[f64]) -> Vec<f64> {
        let (r, c) = side_residuals(self.model, self.nl, x0, y0);
        (0..x1.len())
            .map(|i| {
                if i == 0 {
                    return y0[0];
                }
                let side = usize::from(i > self.nl);
                y0[0] + eval(&c[side], (x1[i] - x1[0]).abs()) + r[i]
            })
            .collect()
    }

    /// The largest |band edge|: the worst deviation a key shape inside the family can have.
    pub fn widest(&self) -> f64 {
        self.bands
            .iter()
            .map(|b| b[0].abs().max(b[1].abs()))
            .fold(0.0, f64::max)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A hand-built V: leader at the origin, sides at 30° to the flight axis (t = −√3 u), one bird
    /// displaced 1.2 b backwards on the right.
    fn v_shape() -> Vec<[f64; 2]> {
        let s3 = 3f64.sqrt();
        let mut p = vec![[0.0, 0.0]];
        for k in 1..=4 {
            p.push([-(k as f64), -s3 * k as f64]);
        }
        for k in 1..=4 {
            p.push([k as f64, -s3 * k as f64]);
        }
        p[7][1] -= 1.2;
        p
    }

    #[test]
    fn line_deviation_measure_on_a_hand_built_v() {
        let p = v_shape();
        // Left side exactly on its line.
        let (x, y): (Vec<f64>, Vec<f64>) = p.iter().map(|q| (q[0], q[1])).unzip();
        let (r, c) = side_residuals(Model::Line, 4, &x, &y);
        assert!((c[0][0] + 3f64.sqrt()).abs() < 1e-12, "{c:?}");
        assert!(r[..5].iter().all(|v| v.abs() < 1e-12), "{r:?}");
        // Right side: the least-squares line through the leader, a = Σut/Σu², is pulled by
        // the displaced bird (u = 3): a = −√3 − 3·1.2/30 = −√3 − 0.12; that bird's residual
        // is −1.2 + 3·0.12 = −0.84, the outermost bird's +0.48.
        assert!((c[1][0] + 3f64.sqrt() + 0.12).abs() < 1e-12, "{c:?}");
        assert!((r[7] + 0.84).abs() < 1e-12, "{r:?}");
        assert!((r[8] - 0.48).abs() < 1e-12, "{r:?}");
        let w = worst_deviation(Model::Line, &p);
        assert!((w - 0.84).abs() < 1e-12, "{w}");
        // The measure needs no bird order, only the flock frame: shuffled, the same.
        let mut q = p.clone();
        q.reverse();
        assert!((worst_deviation(Model::Line, &q) - 0.84).abs() < 1e-12);
        // A parabola through the leader fits an exact parabola exactly.
        let par: Vec<[f64; 2]> = (-3i32..=3)
            .map(|k| {
                let u = f64::from(k.abs());
                [f64::from(k), -0.4 * u - 0.2 * u * u]
            })
            .collect();
        assert!(worst_deviation(Model::Parabola, &par) < 1e-12);
        assert!(worst_deviation(Model::Line, &par) > 0.3);
    }

    #[test]
    fn a_shape_outside_its_band_violates_the_family() {
        let p = v_shape();
        let shapes = vec![p.clone()];
        let mut outlier = vec![false; 9];
        outlier[7] = true;
        let fam = Family::from_shapes(Model::Line, 4, &shapes, &outlier, f64::INFINITY);
        let (x, y): (Vec<f64>, Vec<f64>) = p.iter().map(|q| (q[0], q[1])).unzip();
        assert_eq!(fam.violation(&x, &y), 0.0);
        // The outlier keeps its own range; an inlier that moves 2 b back leaves its band.
        assert!(fam.bands[7][0] <= -0.84 + 1e-12);
        let mut y2 = y.clone();
        y2[2] -= 2.0;
        assert!(fam.violation(&x, &y2) > 0.5);
        assert_eq!(Family::free(Model::Line, 4, 9).violation(&x, &y2), 0.0);
    }
}
