//! Steady flight (Klotsman & Tal §5, Algorithm 1): initial shapes of N birds from the example's
//! parameters (Step 1, with the correspondence of animated to example birds), their relative
//! savings ξ and per-bird ranges [p_i, P_i] (Step 2), key shapes whose ξ̂ are drawn by eq. 2 and
//! whose positions solve eq. 4 (Step 3), and their interpolation (Step 4, [`Timeline`]).
//!
//! Animated birds are indexed 0 = leader, 1..=nl left side from the leader outward, then the right
//! side likewise. Positions are `[x, y]` in wingspans in the flock frame (x right, y forward).

use super::extract::{mean_std, FrameShape, ShapeParams, Side};
pub use super::keys::{layout, next_key, settle};
use super::power;
use super::ransac;
use crate::error::{Error, Result};
use rand::Rng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};

/// Settings of the steady flight.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SteadyConfig {
    /// ε of the feasible range [(1 − ε) p_i, (1 + ε) P_i] (eq. 2; the paper: 0 ≤ ε ≤ 0.2).
    pub epsilon: f64,
    /// C₁, C₂ of eq. 2 (the paper: 0.75 ≤ C₁ ≤ 0.9, 1.1 ≤ C₂ ≤ 1.25).
    pub c1: f64,
    pub c2: f64,
    /// Shortest time between key shapes, seconds.
    pub key_interval: f64,
    /// Bound on every bird's acceleration relative to the flock frame, wingspans/s²: key shapes
    /// further apart get longer transitions (minimum-jerk interpolation).
    pub max_accel: f64,
    /// Smallest lateral gap between neighbours in constructed shapes, wingspans (> π/4: keeps
    /// every pair off the singular set of g and out of the neighbour's vortex core).
    pub min_gap: f64,
    /// Swap the sides of the example (the paper's Fig. 4).
    pub mirror: bool,
    /// Largest |ξ − ξ̂|/ξ̂ accepted from the solver.
    pub solve_tol: f64,
    /// Residual evaluations after which one Levenberg–Marquardt run of eq. 4 gives up (a run
    /// that reproduces its target from a warm start needs far fewer: RESULTS.md §3).
    pub solve_evaluations: usize,
    /// Largest longitudinal move of a bird in one continuation step of the solver, wingspans.
    pub max_key_step: f64,
    /// Metropolis steps per free bird for one draw of ξ̂ restricted to the reachable set.
    pub draw_steps: usize,
    /// Draws rejected (eq. 4 not solved to `solve_tol`) before a key shape gives up.
    pub draw_retries: usize,
    /// Smallest distance between two birds of Step 1's shapes, wingspans: 1 b (the initiation's
    /// bound between converged birds) plus a margin, because converged birds sit up to a few
    /// hundredths of a wingspan off their places (RESULTS.md §3).
    pub min_pair: f64,
}

impl Default for SteadyConfig {
    fn default() -> Self {
        SteadyConfig {
            epsilon: 0.1,
            c1: 0.85,
            c2: 1.15,
            key_interval: 3.0,
            max_accel: 0.5,
            min_gap: power::VORTEX_SPAN + 0.05,
            mirror: false,
            solve_tol: 1e-9,
            solve_evaluations: 40,
            max_key_step: 3.0,
            draw_steps: 8,
            draw_retries: 4,
            min_pair: 1.05,
        }
    }
}

impl SteadyConfig {
    /// Checks the settings; errors name the config key.
    pub fn check(&self) -> Result<()> {
        let bad = |k: &str, v: f64, why: &str| Err(Error::invalid(format!("{k} = {v} {why}")));
        if !(0.0..=1.0).contains(&self.epsilon) {
            return bad("epsilon", self.epsilon, "must be in [0, 1]");
        }
        if !(self.c1 > 0.0 && self.c1 <= 1.0) {
            return bad("c1", self.c1, "must be in (0, 1]");
        }
        if !(self.c2 >= 1.0 && self.c2.is_finite()) {
            return bad("c2", self.c2, "must be ≥ 1");
        }
        if !(self.key_interval.is_finite() && self.key_interval > 0.0) {
            return bad("key_interval", self.key_interval, "must be > 0");
        }
        if !(self.max_accel.is_finite() && self.max_accel > 0.0) {
            return bad("max_accel", self.max_accel, "must be > 0");
        }
        if !(self.min_gap.is_finite() && self.min_gap > power::VORTEX_SPAN) {
            return bad("min_gap", self.min_gap, "must exceed π/4 wingspans");
        }
        if !(self.solve_tol > 0.0 && self.solve_tol < 1e-3) {
            return bad("solve_tol", self.solve_tol, "must be in (0, 1e-3)");
        }
        if !(self.max_key_step.is_finite() && self.max_key_step > 0.0) {
            return bad("max_key_step", self.max_key_step, "must be > 0");
        }
        if self.solve_evaluations == 0 {
            return bad("solve_evaluations", 0.0, "must be ≥ 1");
        }
        if self.draw_steps == 0 {
            return bad("draw_steps", 0.0, "must be ≥ 1");
        }
        if !(self.min_pair.is_finite() && (0.0..=3.0).contains(&self.min_pair)) {
            return bad("min_pair", self.min_pair, "must be in [0, 3] wingspans");
        }
        Ok(())
    }
}

/// Step 1's correspondence and initial shapes.
#[derive(Clone, Debug, Serialize)]
pub struct InitialShapes {
    /// Birds on the left and right side of the leader.
    pub nl: usize,
    pub nr: usize,
    /// Per animated bird: the example bird it corresponds to (None: an added bird).
    pub example_bird: Vec<Option<u64>>,
    /// One shape per example frame.
    pub shapes: Vec<Vec<[f64; 2]>>,
}

/// Animated side `s` (0 left, 1 right) → example side, honouring `mirror`.
fn example_side(s: usize, mirror: bool) -> Side {
    match (s == 0) != mirror {
        true => Side::Left,
        false => Side::Right,
    }
}

/// Matches `n` animated slots of a side (leader outward) to the example's side birds `ids` with
/// outlier flags: nearest and farthest first, then the outliers, then the inliers; each takes the
/// free slot nearest its relative rank. Unmatched slots are added birds.
pub fn match_side(n: usize, ids: &[(u64, bool)]) -> Vec<Option<u64>> {
    let mut slots = vec![None; n];
    let m = ids.len();
    if n == 0 || m == 0 {
        return slots;
    }
    let mut order: Vec<usize> = vec![0];
    if m > 1 {
        order.push(m - 1);
    }
    order.extend((1..m.saturating_sub(1)).filter(|&k| ids[k].1));
    order.extend((1..m.saturating_sub(1)).filter(|&k| !ids[k].1));
    let rank = |k: usize, len: usize| {
        if len > 1 {
            k as f64 / (len - 1) as f64
        } else {
            0.0
        }
    };
    for k in order {
        let v = rank(k, m);
        let best = (0..n)
            .filter(|&a| slots[a].is_none())
            .min_by(|&a, &b| (rank(a, n) - v).abs().total_cmp(&(rank(b, n) - v).abs()));
        match best {
            Some(a) => slots[a] = Some(ids[k].0),
            None => break,
        }
    }
    slots
}

/// Lateral gaps from N(mean, std) truncated below at `min_gap` (redrawn, then clamped).
fn draw_gap(rng: &mut impl Rng, mean: f64, std: f64, min_gap: f64) -> f64 {
    let d = Normal::new(mean, std.max(0.0)).unwrap_or_else(|_| Normal::new(mean, 0.0).unwrap());
    for _ in 0..20 {
        let g = d.sample(rng);
        if g >= min_gap {
            return g;
        }
    }
    mean.max(min_gap)
}

/// The side model of frame `f` for example side `s`, falling back to the other side's.
fn side_model(f: &FrameShape, s: Side) -> Result<&[f64]> {
    let other = match s {
        Side::Left => Side::Right,
        Side::Right => Side::Left,
    };
    f.side(s)
        .or_else(|| f.side(other))
        .map(|m| m.coef.as_slice())
        .ok_or_else(|| Error::invalid(format!("frame {}: no side fit", f.frame)))
}

/// Step 1: the correspondence (from the first frame) and one N-bird shape per example frame.
/// Each bird sits on the frame's side curve at lateral distances drawn from the frame's gap
/// statistics, displaced longitudinally by its example bird's deviation where that bird is an
/// outlier in the frame, else by a draw from the frame's N(μ_y, σ_y) kept within the range of
/// the example's inlier deviations over all its frames.
pub fn initial_shapes(
    params: &ShapeParams,
    birds: usize,
    cfg: &SteadyConfig,
    rng: &mut impl Rng,
) -> Result<InitialShapes> {
    if birds < 3 {
        return Err(Error::invalid(format!(
            "birds = {birds}: a formation needs at least 3"
        )));
    }
    let f0 = &params.frames[0];
    let side_ids = |s: Side| -> Vec<(u64, bool)> {
        f0.side(s).map_or(vec![], |fit| {
            fit.birds
                .iter()
                .map(|&id| (id, f0.bird(id).is_some_and(|b| b.outlier)))
                .collect()
        })
    };
    let ex = [
        side_ids(example_side(0, cfg.mirror)),
        side_ids(example_side(1, cfg.mirror)),
    ];
    let total = (ex[0].len() + ex[1].len()).max(1);
    let nr = ((birds - 1) as f64 * ex[1].len() as f64 / total as f64).round() as usize;
    let nl = birds - 1 - nr;
    let mut example_bird = vec![Some(f0.leader)];
    example_bird.extend(match_side(nl, &ex[0]));
    example_bird.extend(match_side(nr, &ex[1]));
    // The inliers' deviations over the whole example: Step 1's Gaussian deviations are kept in
    // it, so that N birds drawn from a 9-bird example do not stray further than its own inliers.
    let inlier_dev = params
        .frames
        .iter()
        .flat_map(|f| f.birds.iter().filter(|b| !b.outlier).map(|b| b.dy))
        .fold([f64::INFINITY, f64::NEG_INFINITY], |r, v| {
            [r[0].min(v), r[1].max(v)]
        });
    let mut shapes = Vec::with_capacity(params.frames.len());
    for f in &params.frames {
        let mut pos = vec![[0.0, 0.0]];
        let dev = Normal::new(f.mean_dev, f.std_dev.max(0.0))
            .map_err(|e| Error::invalid(format!("frame {}: deviations: {e}", f.frame)))?;
        for (s, n) in [(0usize, nl), (1, nr)] {
            let coef = side_model(f, example_side(s, cfg.mirror))?;
            let sign = if s == 0 { -1.0 } else { 1.0 };
            let mut u = 0.0;
            for k in 0..n {
                u += draw_gap(rng, f.mean_gap, f.std_gap, cfg.min_gap);
                let idx = 1 + if s == 0 { k } else { nl + k };
                let out = example_bird[idx]
                    .and_then(|id| f.bird(id))
                    .filter(|b| b.outlier)
                    .map(|b| b.dy);
                let dy = match out {
                    Some(d) => d,
                    None => dev.sample(rng).clamp(inlier_dev[0], inlier_dev[1]),
                };
                // Keep every pair at least `min_pair` apart: widen this bird's lateral gap
                // (deterministically, no extra draw) while it sits too close to a placed bird.
                let mut p = [sign * u, ransac::eval(coef, u) + dy];
                for _ in 0..200 {
                    let d = pos
                        .iter()
                        .map(|q: &[f64; 2]| (q[0] - p[0]).hypot(q[1] - p[1]))
                        .fold(f64::INFINITY, f64::min);
                    if d >= cfg.min_pair {
                        break;
                    }
                    u += (cfg.min_pair - d).max(1e-3);
                    p = [sign * u, ransac::eval(coef, u) + dy];
                }
                pos.push(p);
            }
        }
        shapes.push(pos);
    }
    Ok(InitialShapes {
        nl,
        nr,
        example_bird,
        shapes,
    })
}

/// ξ of each shape, and each bird's [p_i, P_i] (Algorithm 1 Step 2).
pub type Ranges = (Vec<Vec<f64>>, Vec<[f64; 2]>);

/// Step 2: ξ of each shape and the per-bird range [p_i, P_i] over the shapes.
pub fn ranges(shapes: &[Vec<[f64; 2]>]) -> Result<Ranges> {
    let mut xis = Vec::with_capacity(shapes.len());
    for s in shapes {
        xis.push(power::relative(&power::savings(s)?));
    }
    let n = shapes[0].len();
    let r = (0..n)
        .map(|i| {
            let v: Vec<f64> = xis.iter().map(|x| x[i]).collect();
            [
                v.iter().cloned().fold(f64::INFINITY, f64::min),
                v.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
            ]
        })
        .collect();
    Ok((xis, r))
}

/// Eq. 2: a draw in [(1 − ε) p_i, (1 + ε) P_i] ∩ [C₁ ξ̂_{k−1}, C₂ ξ̂_{k−1}], then the nearest
/// point of that box on the simplex Σ ξ̂ = 1 (a common shift, clamped to the box, found by
/// bisection). Returns the draw and the box.
pub fn draw_xi(
    prev: &[f64],
    range: &[[f64; 2]],
    cfg: &SteadyConfig,
    rng: &mut impl Rng,
) -> (Vec<f64>, Vec<[f64; 2]>) {
    let bx = super::keys::eq2_box(prev, range, cfg);
    let u: Vec<f64> = bx
        .iter()
        .map(|b| {
            if b[1] > b[0] {
                rng.gen_range(b[0]..=b[1])
            } else {
                b[0]
            }
        })
        .collect();
    let sum = |l: f64| -> f64 {
        u.iter()
            .zip(&bx)
            .map(|(v, b)| (v + l).clamp(b[0], b[1]))
            .sum()
    };
    let (mut a, mut z) = (-1.0, 1.0);
    for _ in 0..200 {
        let m = 0.5 * (a + z);
        if sum(m) < 1.0 {
            a = m;
        } else {
            z = m;
        }
    }
    let l = 0.5 * (a + z);
    let mut xi: Vec<f64> = u
        .iter()
        .zip(&bx)
        .map(|(v, b)| (v + l).clamp(b[0], b[1]))
        .collect();
    // Remove the bisection's last rounding so the targets sum to 1 as eq. 3 assumes.
    let s: f64 = xi.iter().sum();
    for v in &mut xi {
        *v /= s;
    }
    (xi, bx)
}

/// One solved key shape.
#[derive(Clone, Debug, Serialize)]
pub struct KeyShape {
    /// Positions, wingspans (flock frame).
    pub pos: Vec<[f64; 2]>,
    /// The relative savings eq. 4 was solved for: the draw itself when `reproduced`.
    pub xi_target: Vec<f64>,
    /// The drawn ξ̂ (eq. 2 restricted to the reachable set, [`super::keys`]).
    pub xi_draw: Vec<f64>,
    /// ξ of the solved positions.
    pub xi: Vec<f64>,
    /// Largest |ξ − ξ̂|/ξ̂ (ξ̂ = `xi_target`).
    pub max_relative_error: f64,
    /// The lateral gap of this key shape's layout, wingspans.
    pub gap: f64,
    /// Whether Levenberg–Marquardt reproduced the draw to `solve_tol`.
    pub reproduced: bool,
    /// Draws rejected before this one because eq. 4 could not be solved for them.
    pub draws_rejected: usize,
    /// Acceptance rate of the Metropolis chain that drew ξ̂.
    pub chain_acceptance: f64,
    /// Solver runs and residual evaluations.
    pub solves: usize,
    pub evaluations: usize,
}

/// The first key shape: Step 1's shape of the example's first frame, as it is (its ξ is its own
/// target, exactly).
pub fn first_key(shape: &[[f64; 2]]) -> Result<KeyShape> {
    let xi = power::relative(&power::savings(shape)?);
    let gaps: Vec<f64> = {
        let mut x: Vec<f64> = shape.iter().map(|p| p[0]).collect();
        x.sort_by(f64::total_cmp);
        x.windows(2).map(|w| w[1] - w[0]).collect()
    };
    Ok(KeyShape {
        pos: shape.to_vec(),
        xi_target: xi.clone(),
        xi_draw: xi.clone(),
        xi,
        max_relative_error: 0.0,
        gap: mean_std(&gaps).0,
        reproduced: true,
        draws_rejected: 0,
        chain_acceptance: 0.0,
        solves: 0,
        evaluations: 0,
    })
}

/// Minimum-jerk blend s(τ) = 10τ³ − 15τ⁴ + 6τ⁵ and its derivatives; max |s''| = 10/√3.
pub fn min_jerk(tau: f64) -> (f64, f64, f64) {
    let t = tau.clamp(0.0, 1.0);
    let (t2, t3) = (t * t, t * t * t);
    (
        t3 * (10.0 - 15.0 * t + 6.0 * t2),
        30.0 * t2 * (1.0 - t) * (1.0 - t),
        60.0 * t * (1.0 - t) * (1.0 - 2.0 * t),
    )
}

/// Peak |s''| of [`min_jerk`].
pub const MIN_JERK_PEAK: f64 = 5.773_502_691_896_258;

/// Step 4: key shapes joined by minimum-jerk segments (zero relative velocity and acceleration at
/// every key shape), each lasting at least `key_interval` and long enough that no bird's relative
/// acceleration exceeds `max_accel`: T ≥ √(10/√3 · D / a_max), D the largest move of a bird.
#[derive(Clone, Debug, Serialize)]
pub struct Timeline {
    /// Key shapes, centred on the first one's centroid.
    pub keys: Vec<Vec<[f64; 2]>>,
    /// Start time of each key shape, seconds (`keys[0]` at 0).
    pub times: Vec<f64>,
}

impl Timeline {
    /// Centres `keys` on the first one's centroid and times the segments.
    pub fn new(keys: Vec<Vec<[f64; 2]>>, key_interval: f64, max_accel: f64) -> Self {
        let centroid = |k: &[[f64; 2]]| {
            let n = k.len() as f64;
            [
                k.iter().map(|p| p[0]).sum::<f64>() / n,
                k.iter().map(|p| p[1]).sum::<f64>() / n,
            ]
        };
        let c0 = centroid(&keys[0]);
        let keys: Vec<Vec<[f64; 2]>> = keys
            .into_iter()
            .map(|k| {
                let c = centroid(&k);
                k.iter()
                    .map(|p| [p[0] - c[0] + c0[0], p[1] - c[1] + c0[1]])
                    .collect()
            })
            .collect();
        let mut times = vec![0.0];
        for w in keys.windows(2) {
            let d = w[0]
                .iter()
                .zip(&w[1])
                .map(|(a, b)| (a[0] - b[0]).hypot(a[1] - b[1]))
                .fold(0.0, f64::max);
            let t = key_interval.max((MIN_JERK_PEAK * d / max_accel).sqrt());
            times.push(times.last().copied().unwrap_or(0.0) + t);
        }
        Timeline { keys, times }
    }

    /// Total duration, seconds.
    pub fn duration(&self) -> f64 {
        *self.times.last().unwrap_or(&0.0)
    }

    /// Positions and velocities (wingspans, wingspans/s, flock frame) at time `t`.
    pub fn at(&self, t: f64) -> (Vec<[f64; 2]>, Vec<[f64; 2]>) {
        let k = self
            .times
            .windows(2)
            .position(|w| t < w[1])
            .unwrap_or(self.times.len().saturating_sub(2));
        if self.keys.len() == 1 {
            return (self.keys[0].clone(), vec![[0.0, 0.0]; self.keys[0].len()]);
        }
        let (t0, t1) = (self.times[k], self.times[k + 1]);
        let (s, ds, _) = min_jerk((t - t0) / (t1 - t0));
        let (a, b) = (&self.keys[k], &self.keys[k + 1]);
        let v = ds / (t1 - t0);
        let pos = a
            .iter()
            .zip(b)
            .map(|(p, q)| [p[0] + s * (q[0] - p[0]), p[1] + s * (q[1] - p[1])])
            .collect();
        let vel = a
            .iter()
            .zip(b)
            .map(|(p, q)| [v * (q[0] - p[0]), v * (q[1] - p[1])])
            .collect();
        (pos, vel)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn side_matching_keeps_extremes_and_outliers() {
        // 4 example birds (the third an outlier) on 7 animated slots.
        let ids = [(10, false), (11, false), (12, true), (13, false)];
        let m = match_side(7, &ids);
        assert_eq!(m[0], Some(10));
        assert_eq!(m[6], Some(13));
        assert_eq!(m.iter().filter(|s| s.is_some()).count(), 4);
        assert!(m.contains(&Some(12)));
        // Fewer slots than example birds: extremes, then the outlier.
        let m = match_side(3, &ids);
        assert_eq!(m, vec![Some(10), Some(12), Some(13)]);
    }

    #[test]
    fn drawn_targets_lie_in_the_box_and_sum_to_one() {
        use rand::SeedableRng;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        let prev = vec![0.1, 0.2, 0.3, 0.4];
        let range = vec![[0.08, 0.12], [0.15, 0.25], [0.2, 0.35], [0.35, 0.5]];
        let cfg = SteadyConfig::default();
        for _ in 0..100 {
            let (xi, bx) = draw_xi(&prev, &range, &cfg, &mut rng);
            assert!((xi.iter().sum::<f64>() - 1.0).abs() < 1e-12);
            for (v, b) in xi.iter().zip(&bx) {
                assert!(*v >= b[0] - 1e-12 && *v <= b[1] + 1e-12);
            }
        }
    }

    #[test]
    fn timeline_respects_the_acceleration_bound() {
        let a = vec![[0.0, 0.0], [1.0, -1.0], [-1.0, -1.0]];
        let b = vec![[0.0, 0.0], [1.2, -3.0], [-1.0, -1.5]];
        let tl = Timeline::new(vec![a, b], 1.0, 0.5);
        let dt = 1e-3;
        let mut peak: f64 = 0.0;
        let mut t = dt;
        while t < tl.duration() - dt {
            let (p0, _) = tl.at(t - dt);
            let (p1, _) = tl.at(t);
            let (p2, _) = tl.at(t + dt);
            for i in 0..3 {
                let ax = (p2[i][0] - 2.0 * p1[i][0] + p0[i][0]) / (dt * dt);
                let ay = (p2[i][1] - 2.0 * p1[i][1] + p0[i][1]) / (dt * dt);
                peak = peak.max(ax.hypot(ay));
            }
            t += dt;
        }
        assert!(peak <= 0.5 * (1.0 + 1e-3), "{peak}");
        assert!(peak > 0.45, "the bound is tight: {peak}");
    }
}
