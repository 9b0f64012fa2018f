//! Key shapes of the steady flight (Klotsman & Tal §5 Step 3, eq. 2–4) whose drawn relative
//! savings ξ̂ are reproduced exactly by the positions that solve eq. 4.
//!
//! Eq. 4 has N − 1 unknowns (the longitudinal positions y relative to the leader; the lateral
//! layout is fixed, "the x-distance is constant") and N equations, one of them redundant by
//! Munk's theorem (Σ e does not depend on y, eq. 3). So the ξ that positions can give on a
//! layout form a bounded (N − 1)-dimensional region R of the simplex Σ ξ = 1 (g saturates as
//! |y| → ∞). Eq. 2 draws every ξ̂_i independently in its box; most such draws lie outside R
//! (RESULTS.md §3: the rejection rate of plain eq. 2 draws). A key shape therefore draws ξ̂ from
//! eq. 2's distribution *restricted to R*: uniform on R ∩ Box, sampled by a Metropolis chain over
//! the positions y, whose density is the volume element √det(JᵀJ) of y ↦ ξ (J = ∂ξ/∂y), so that
//! the draws are uniform in ξ as eq. 2's are, with the box as a hard constraint. Levenberg–
//! Marquardt then solves eq. 4 for that ξ̂ from the previous key shape's positions (never from the
//! chain's); where it does not reproduce the draw to `solve_tol`, or reproduces it with positions
//! outside the example's shape family, the chain's own positions are the key shape (they solve
//! eq. 4 for the draw exactly, by construction).
//!
//! The chain's region is also restricted to the example's shape family ([`Family`]: every bird
//! within its band of longitudinal deviations from its side's curve, the curves' coefficients
//! within the example's range), so that the key shapes keep the example's look (§5 Step 1:
//! "the general shapes and deviations of the movie") while their ξ̂ stay in eq. 2's box.

use super::family::Family;
use super::pairs::Pairs;
use super::power;
use super::solve::{self, PositionProblem};
use super::steady::{KeyShape, SteadyConfig};
use nalgebra::{DMatrix, DVector};
use rand::Rng;
use rand_distr::{Distribution, StandardNormal};

/// Eq. 2's box for every bird: [(1 − ε) p_i, (1 + ε) P_i] ∩ [C₁ ξ̂_{k−1}, C₂ ξ̂_{k−1}] (the
/// previous value alone where the two do not meet).
pub fn eq2_box(prev: &[f64], range: &[[f64; 2]], cfg: &SteadyConfig) -> Vec<[f64; 2]> {
    prev.iter()
        .zip(range)
        .map(|(&p, r)| {
            let lo = ((1.0 - cfg.epsilon) * r[0]).max(cfg.c1 * p);
            let hi = ((1.0 + cfg.epsilon) * r[1]).min(cfg.c2 * p);
            if lo <= hi {
                [lo, hi]
            } else {
                [p, p]
            }
        })
        .collect()
}

/// Uniform lateral layout with gap `gap`: leader at 0, left birds at −k·gap, right at k·gap.
pub fn layout(nl: usize, nr: usize, gap: f64) -> Vec<f64> {
    let mut x = vec![0.0];
    x.extend((1..=nl).map(|k| -(k as f64) * gap));
    x.extend((1..=nr).map(|k| k as f64 * gap));
    x
}

/// ξ (eq. 1 and §5 Step 3's ξ_i = e_i / E) on the layout of `pairs` with E = `total` (eq. 3),
/// keeping the pairs' ∂g/∂t in `dg` for [`jacobian`].
fn xi_of(pairs: &Pairs, y: &[f64], total: f64, dg: &mut Vec<f64>) -> Vec<f64> {
    let mut xi = vec![0.0; pairs.len()];
    pairs.eval(y, &mut xi, dg);
    xi.iter_mut().for_each(|v| *v /= total);
    xi
}

/// ∂ξ/∂y (the leader's y held), N × (N − 1), from [`xi_of`]'s `dg`.
fn jacobian(pairs: &Pairs, dg: &[f64], total: f64) -> DMatrix<f64> {
    pairs.jacobian(dg, &vec![1.0 / total; pairs.len()], 0)
}

/// Relative violation of the box: Σ max(0, lo − ξ, ξ − hi) / hi.
fn violation(xi: &[f64], bx: &[[f64; 2]]) -> f64 {
    xi.iter()
        .zip(bx)
        .map(|(v, b)| (b[0] - v).max(v - b[1]).max(0.0) / b[1].max(f64::MIN_POSITIVE))
        .sum()
}

/// ½ ln det(JᵀJ): the log volume element of y ↦ ξ (−∞ where J loses rank).
fn log_volume(j: &DMatrix<f64>) -> f64 {
    match j.tr_mul(j).cholesky() {
        Some(c) => c.l_dirty().diagonal().iter().map(|d| d.ln()).sum(),
        None => f64::NEG_INFINITY,
    }
}

/// State and tallies of the Metropolis chain of one key shape.
#[derive(Clone, Debug)]
struct Chain {
    y: Vec<f64>,
    xi: Vec<f64>,
    viol: f64,
    logv: f64,
    scale: f64,
    proposed: usize,
    accepted: usize,
}

/// What a chain must stay inside: eq. 2's box and the example's shape family on layout `x`.
struct Region<'a> {
    bx: &'a [[f64; 2]],
    family: &'a Family,
    x: &'a [f64],
}

impl Region<'_> {
    /// The box's relative violation plus the family's (wingspans); 0 inside both.
    fn violation(&self, xi: &[f64], y: &[f64]) -> f64 {
        violation(xi, self.bx) + self.family.violation(self.x, y)
    }
}

impl Chain {
    fn new(pairs: &Pairs, y: Vec<f64>, total: f64, region: &Region) -> Self {
        let mut dg = Vec::new();
        let xi = xi_of(pairs, &y, total, &mut dg);
        Chain {
            viol: region.violation(&xi, &y),
            logv: log_volume(&jacobian(pairs, &dg, total)),
            y,
            xi,
            scale: 0.05,
            proposed: 0,
            accepted: 0,
        }
    }

    /// `steps` Metropolis steps: isotropic Gaussian moves of the N − 1 free birds, accepted with
    /// probability min(1, vol(y′)/vol(y)) inside the region (box and family), never outside it.
    /// A chain that starts outside (the previous key's ξ just off a box face by solver rounding,
    /// or a new lateral layout that moved birds off their bands) first accepts any move that does
    /// not increase the violation. The proposal scale adapts towards 30 % acceptance with a
    /// decaying gain.
    fn run(
        &mut self,
        pairs: &Pairs,
        total: f64,
        region: &Region,
        steps: usize,
        rng: &mut impl Rng,
    ) {
        let m = (pairs.len() - 1) as f64;
        let mut dg = Vec::new();
        for s in 0..steps {
            let mut y = self.y.clone();
            for v in y.iter_mut().skip(1) {
                let z: f64 = StandardNormal.sample(rng);
                *v += self.scale / m.sqrt() * z;
            }
            let xi = xi_of(pairs, &y, total, &mut dg);
            let viol = region.violation(&xi, &y);
            self.proposed += 1;
            // The proposal's log volume, once: the Metropolis test needs it inside the box, and
            // an accepted move keeps it.
            let mut logv = None;
            let ok = if self.viol > 0.0 {
                viol <= self.viol
            } else if viol > 0.0 {
                false
            } else {
                let l = log_volume(&jacobian(pairs, &dg, total));
                logv = Some(l);
                let u: f64 = rng.gen();
                l.is_finite() && u.ln() < l - self.logv
            };
            let gain = 1.0 / (1.0 + s as f64).sqrt();
            if ok {
                self.logv = logv.unwrap_or_else(|| log_volume(&jacobian(pairs, &dg, total)));
                self.y = y;
                self.xi = xi;
                self.viol = viol;
                self.accepted += 1;
                self.scale *= (0.7 * gain).exp();
            } else {
                self.scale *= (-0.3 * gain).exp();
            }
        }
    }
}

/// A continuation step's solver run is abandoned once an iterate moves a bird this many times
/// `max_key_step` from the step's start: its end point could be accepted only if the run came
/// back within `max_key_step` (RESULTS.md §3: no accepted step did so in the sweep).
const LEASH: f64 = 10.0;

/// The continuation sizes each step so that the tangent predicts a largest move of this fraction
/// of `max_key_step` (the path bends, so a step sized for the whole of it fails about half the
/// time: RESULTS.md §3).
const PREDICTED_MOVE: f64 = 0.7;

/// The smallest continuation step in t; a failed step of this size ends the continuation.
const MIN_STEP: f64 = 1.0 / 256.0;

/// The problem of eq. 4 at t of the straight line from (x0, ξ0) to (x1, ξ1).
fn on_line(line: [&[f64]; 4], t: f64, y: Vec<f64>) -> PositionProblem {
    let lerp = |a: &[f64], b: &[f64]| -> Vec<f64> {
        a.iter().zip(b).map(|(p, q)| p + t * (q - p)).collect()
    };
    PositionProblem::new(lerp(line[0], line[1]), lerp(line[2], line[3]), 0, y)
}

/// The tangent dy/dt of the solution path of eq. 4 along `line` at a solved point (t, y): the
/// least-squares solution of J ẏ = −∂r/∂t (J = ∂r/∂y with the leader held, from the normal
/// equations; ∂r/∂t by a forward difference of 1e-6 in t). None where JᵀJ is singular.
fn tangent(line: [&[f64]; 4], t: f64, y: &[f64]) -> Option<Vec<f64>> {
    let h = 1e-6;
    let p = on_line(line, t, y.to_vec());
    let q = on_line(line, t + h, y.to_vec());
    let rt = DVector::from_iterator(
        y.len(),
        q.residual_vec()
            .iter()
            .zip(p.residual_vec())
            .map(|(a, b)| (a - b) / h),
    );
    let j = p.jacobian_matrix();
    let d = j.tr_mul(&j).cholesky()?.solve(&-(j.tr_mul(&rt)));
    let mut v = vec![0.0; y.len()];
    v[1..].copy_from_slice(d.as_slice());
    v.iter().all(|a| a.is_finite()).then_some(v)
}

/// Continuation of eq. 4 from (x0, ξ0), solved by y0, to (x1, ξ1): both interpolated linearly
/// in t, an Euler–Newton predictor–corrector. From each solved point the tangent
/// (`tangent`) sizes the next step (its largest predicted move `PREDICTED_MOVE` ×
/// `max_key_step`, at most twice the last step, at least `MIN_STEP`) and predicts the start of
/// Levenberg–Marquardt there; a step whose solve misses `solve_tol` or moves a bird more than
/// `max_key_step` from the last point is halved, and one of `MIN_STEP` that fails ends the
/// continuation. Returns how far it got, its y and error, solver runs and evaluations.
pub fn continuation(
    x0: &[f64],
    x1: &[f64],
    xi0: &[f64],
    xi1: &[f64],
    y0: Vec<f64>,
    cfg: &SteadyConfig,
) -> (f64, Vec<f64>, f64, usize, usize) {
    let line = [x0, x1, xi0, xi1];
    let (mut t, mut dt) = (0.0f64, 1.0f64);
    let mut y = y0;
    let (mut solves, mut evals) = (0, 0);
    let mut err = on_line(line, 0.0, y.clone()).max_relative_error();
    let mut tan = tangent(line, t, &y);
    let mut fresh = true;
    while t < 1.0 {
        if fresh {
            if let Some(v) = &tan {
                let fastest = v.iter().map(|a| a.abs()).fold(0.0, f64::max);
                dt = (PREDICTED_MOVE * cfg.max_key_step / fastest).min(2.0 * dt);
            }
            dt = dt.clamp(MIN_STEP, 1.0);
        }
        let tn = (t + dt).min(1.0);
        let start = match &tan {
            Some(v) => y.iter().zip(v).map(|(a, b)| a + (tn - t) * b).collect(),
            None => y.clone(),
        };
        let s = solve::solve(
            on_line(line, tn, start).with_leash_around(y.clone(), LEASH * cfg.max_key_step),
            cfg.solve_evaluations,
        );
        solves += 1;
        evals += s.evaluations;
        let step =
            s.y.iter()
                .zip(&y)
                .map(|(a, b)| (a - b).abs())
                .fold(0.0, f64::max);
        if s.max_relative_error <= cfg.solve_tol && step <= cfg.max_key_step {
            t = tn;
            y = s.y;
            err = s.max_relative_error;
            tan = tangent(line, t, &y);
            fresh = true;
        } else if dt <= MIN_STEP {
            break;
        } else {
            dt = (0.5 * dt).max(MIN_STEP);
            fresh = false;
        }
    }
    (t, y, err, solves, evals)
}

/// Step 3 for one key shape. (1) A uniform lateral gap is drawn in `gap_range` (the paper's
/// constant x-distance from the range of the example's mean gaps) and the previous key's ξ̂ is
/// carried onto that layout by [`continuation`] (as far as it goes: the layout then stops part
/// way). (2) ξ̂ is drawn from eq. 2's box restricted to the reachable set and to the example's
/// shape family `family` by the Metropolis chain (`draw_steps` × (N − 1) steps from the previous
/// key's positions); where the carried-over shape has left the family and the chain cannot bring
/// it back within one draw's steps, the previous key's layout is kept (its positions lie inside
/// both). (3) Levenberg–Marquardt solves eq. 4 for that ξ̂ from the previous positions; a
/// solution that misses `solve_tol` or leaves the family is replaced by the chain's positions,
/// which solve eq. 4 for ξ̂ exactly. A chain that never gets inside the region draws again, up to
/// `draw_retries` times; if it never does, the key shape repeats the previous positions
/// (`reproduced` false).
#[allow(clippy::too_many_arguments)]
pub fn next_key<R: Rng>(
    prev: &KeyShape,
    nl: usize,
    nr: usize,
    range: &[[f64; 2]],
    gap_range: [f64; 2],
    family: &Family,
    cfg: &SteadyConfig,
    rng: &mut R,
) -> KeyShape {
    let bx = eq2_box(&prev.xi_target, range, cfg);
    let gap = if gap_range[1] > gap_range[0] {
        rng.gen_range(gap_range[0]..=gap_range[1])
    } else {
        gap_range[0]
    }
    .max(cfg.min_gap);
    let x0: Vec<f64> = prev.pos.iter().map(|p| p[0] - prev.pos[0][0]).collect();
    let y0: Vec<f64> = prev.pos.iter().map(|p| p[1] - prev.pos[0][1]).collect();
    let x1 = layout(nl, nr, gap);
    let (mut solves, mut evals) = (0, 0);
    let steps = cfg.draw_steps * (x0.len() - 1);
    // A layout between the previous one and the drawn uniform one (all the way first, then a
    // half, a quarter, an eighth) with the previous shape carried over: each bird keeps its
    // residual from its side's curve, now evaluated at its new lateral distance. The chain must
    // bring it into the region within one draw's steps; else the previous layout is kept (its
    // positions lie in the region).
    let attempt = |t: f64, rng: &mut R| {
        let x: Vec<f64> = x0.iter().zip(&x1).map(|(a, b)| a + t * (b - a)).collect();
        let pairs = Pairs::new(&x);
        let total = power::total_abreast(&x);
        let ya = if t > 0.0 {
            family.carry(&x0, &y0, &x)
        } else {
            y0.clone()
        };
        let region = Region {
            bx: &bx,
            family,
            x: &x,
        };
        let mut chain = Chain::new(&pairs, ya, total, &region);
        if chain.viol > 0.0 && t > 0.0 {
            chain.run(&pairs, total, &region, steps, rng);
        }
        (chain.viol == 0.0 || t == 0.0).then(|| {
            let ya = chain.y.clone();
            (t, x, pairs, total, chain, ya)
        })
    };
    let (ta, x, pairs, total, mut chain, ya) = [1.0, 0.5, 0.25, 0.125, 0.0]
        .into_iter()
        .find_map(|t| attempt(t, rng))
        .expect("the previous layout is always accepted");
    let region = Region {
        bx: &bx,
        family,
        x: &x,
    };
    let mut rejected = 0;
    for _ in 0..=cfg.draw_retries {
        chain.run(&pairs, total, &region, steps, rng);
        if chain.viol > 0.0 {
            rejected += 1;
            continue;
        }
        let draw = chain.xi.clone();
        let s = solve::solve(
            PositionProblem::new(x.clone(), draw.clone(), 0, ya.clone()),
            cfg.solve_evaluations,
        );
        solves += 1;
        evals += s.evaluations;
        let y = if s.max_relative_error <= cfg.solve_tol && family.violation(&x, &s.y) == 0.0 {
            s.y
        } else {
            chain.y.clone()
        };
        let err = on_line([&x, &x, &draw, &draw], 0.0, y.clone()).max_relative_error();
        return finish(
            x,
            y,
            draw.clone(),
            draw,
            err,
            gap_of(prev, ta, gap),
            (rejected, &chain, solves, evals),
        );
    }
    let mut k = finish(
        x0,
        y0,
        prev.xi_target.clone(),
        chain.xi.clone(),
        prev.max_relative_error,
        prev.gap,
        (rejected, &chain, solves, evals),
    );
    k.reproduced = false;
    k
}

/// The first key shape brought into the example's shape family: `key` (Step 1's first shape)
/// itself when it lies in the family and in Step 2's ranges [(1 − ε) p_i, (1 + ε) P_i], else the
/// Metropolis chain's point after it got inside (moves that do not increase the violation, then
/// ordinary steps inside; up to `draw_retries` + 1 runs of `draw_steps` × (N − 1) steps). The
/// chain's positions give their own ξ exactly. Unchanged if the chain never gets inside.
pub fn settle<R: Rng>(
    key: KeyShape,
    range: &[[f64; 2]],
    family: &Family,
    cfg: &SteadyConfig,
    rng: &mut R,
) -> KeyShape {
    let bx: Vec<[f64; 2]> = range
        .iter()
        .map(|r| [(1.0 - cfg.epsilon) * r[0], (1.0 + cfg.epsilon) * r[1]])
        .collect();
    let x: Vec<f64> = key.pos.iter().map(|p| p[0] - key.pos[0][0]).collect();
    let y: Vec<f64> = key.pos.iter().map(|p| p[1] - key.pos[0][1]).collect();
    let pairs = Pairs::new(&x);
    let total = power::total_abreast(&x);
    let region = Region {
        bx: &bx,
        family,
        x: &x,
    };
    let mut chain = Chain::new(&pairs, y, total, &region);
    if chain.viol == 0.0 {
        return key;
    }
    let steps = cfg.draw_steps * (x.len() - 1);
    for _ in 0..=cfg.draw_retries {
        chain.run(&pairs, total, &region, steps, rng);
        if chain.viol == 0.0 {
            let xi = chain.xi.clone();
            let err = on_line([&x, &x, &xi, &xi], 0.0, chain.y.clone()).max_relative_error();
            let gap = key.gap;
            return finish(
                x,
                chain.y.clone(),
                xi.clone(),
                xi,
                err,
                gap,
                (0, &chain, 0, 0),
            );
        }
    }
    key
}

fn gap_of(prev: &KeyShape, t: f64, gap: f64) -> f64 {
    prev.gap + t * (gap - prev.gap)
}

fn finish(
    x: Vec<f64>,
    y: Vec<f64>,
    xi_target: Vec<f64>,
    xi_draw: Vec<f64>,
    err: f64,
    gap: f64,
    (rejected, chain, solves, evaluations): (usize, &Chain, usize, usize),
) -> KeyShape {
    let pos: Vec<[f64; 2]> = x.iter().zip(&y).map(|(&a, &b)| [a, b]).collect();
    let xi = power::relative(&power::savings_unchecked(&pos));
    KeyShape {
        pos,
        xi_target,
        xi_draw,
        xi,
        max_relative_error: err,
        gap,
        reproduced: true,
        draws_rejected: rejected,
        chain_acceptance: chain.accepted as f64 / chain.proposed.max(1) as f64,
        solves,
        evaluations,
    }
}
