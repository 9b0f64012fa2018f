//! Stage 2a: Lin's frame-by-frame optimisation (thesis §3.3–3.5, Algorithms 1–3).
//!
//! Frame by frame (eq. 3.8), each bird's depth d_n^f minimises its error e(n, f) (eq. 3.2) within
//! the bounds d_near < d < d_far (eq. 3.5, 3.7):
//! - a bird's **first** frame: the first frame of the sequence scatters the birds uniformly in
//!   [d_near, d_far] with at least `min_spacing` between them (§3.5); a bird that enters later
//!   (the thesis assumes none do, §5) starts at the median depth of the birds tracked in the
//!   previous frame, moved by steps of `min_spacing` until it keeps that spacing;
//! - its **second** frame: | ‖b^f − b^{f−1}‖ − v_target | (Algorithm 3, "initial speed");
//! - **later** frames: λ_t · | ‖b^f − b^{f−1}‖ − ‖b^{f−1} − b^{f−2}‖ | (eq. 3.4) +
//!   λ_f · ‖b^f − target‖, target = b^{f−1} + w_sep·s + (1 − w_sep)·c, with the separation s of
//!   Algorithm 1 (mean unit vector away from the birds within d_sep) and the cohesion c of
//!   Algorithm 2 (mean offset to every other bird), both computed on frame f − 1.
//!
//! **The bounded method, and why.** Because s and c are the boids steering of the previous
//! frame's state (the target is "calculated first", §3.4), eq. 3.6 separates into one problem per
//! bird in a single unknown, d ∈ [d_near, d_far], and b(d) = C + d·r is linear in d. Each term is
//! then |‖a + d r‖ − s| (s = 0 for the flock term), monotone between the points where ‖a + d r‖
//! is smallest or equals s — points known in closed form. We cut [d_near, d_far] at them and run
//! golden-section search on each piece, keeping the best end or interior point: a bounded method
//! that searches the whole interval, where COBYLA (the thesis's choice, via NLopt) is a local
//! method for general constraints and an N-dimensional one where one dimension per bird
//! suffices.

use super::observe::Observations;
use super::LiftConfig;
use crate::error::Result;
use crate::progress::Progress;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

type V3 = [f64; 3];

fn sub(a: V3, b: V3) -> V3 {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn dot(a: V3, b: V3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn norm(a: V3) -> f64 {
    dot(a, a).sqrt()
}

/// One term `w · |‖a + d r‖ − s|` of a bird's error along its ray (`s = 0`: a plain distance).
#[derive(Clone, Copy, Debug)]
pub struct Term {
    pub w: f64,
    pub a: V3,
    pub s: f64,
}

fn eval(terms: &[Term], r: V3, d: f64) -> f64 {
    terms
        .iter()
        .map(|t| {
            let p = [t.a[0] + d * r[0], t.a[1] + d * r[1], t.a[2] + d * r[2]];
            t.w * (norm(p) - t.s).abs()
        })
        .sum()
}

/// Golden-section iterations per piece: the piece shrinks to 0.618^40 ≈ 4e-9 of its length.
const GOLDEN_STEPS: usize = 40;

/// The d in [lo, hi] minimising Σ terms along ray r: the interval is cut where a term has its
/// vertex or changes sign, and each piece is searched by golden section (see the module docs).
pub fn minimise_on_ray(terms: &[Term], r: V3, lo: f64, hi: f64) -> f64 {
    let rr = dot(r, r);
    let mut cuts = vec![lo, hi];
    for t in terms {
        let ar = dot(t.a, r);
        let vertex = -ar / rr;
        cuts.push(vertex);
        if t.s > 0.0 {
            // ‖a + d r‖² = s²  ⇔  rr d² + 2 ar d + (aa − s²) = 0.
            let disc = ar * ar - rr * (dot(t.a, t.a) - t.s * t.s);
            if disc >= 0.0 {
                let q = disc.sqrt();
                cuts.push((-ar - q) / rr);
                cuts.push((-ar + q) / rr);
            }
        }
    }
    cuts.retain(|c| c.is_finite() && *c >= lo && *c <= hi);
    cuts.sort_by(f64::total_cmp);
    cuts.dedup();
    let mut best = (eval(terms, r, lo), lo);
    let g = 0.5 * (5f64.sqrt() - 1.0);
    for w in cuts.windows(2) {
        let (mut a, mut b) = (w[0], w[1]);
        let fb = eval(terms, r, b);
        if fb < best.0 {
            best = (fb, b);
        }
        if b - a <= 0.0 {
            continue;
        }
        let mut x1 = b - g * (b - a);
        let mut x2 = a + g * (b - a);
        let (mut f1, mut f2) = (eval(terms, r, x1), eval(terms, r, x2));
        for _ in 0..GOLDEN_STEPS {
            if f1 <= f2 {
                b = x2;
                x2 = x1;
                f2 = f1;
                x1 = b - g * (b - a);
                f1 = eval(terms, r, x1);
            } else {
                a = x1;
                x1 = x2;
                f1 = f2;
                x2 = a + g * (b - a);
                f2 = eval(terms, r, x2);
            }
        }
        let (f, x) = if f1 <= f2 { (f1, x1) } else { (f2, x2) };
        if f < best.0 {
            best = (f, x);
        }
    }
    best.1
}

/// Separation s (Algorithm 1) and cohesion c (Algorithm 2) of bird `me` among `flock` (positions
/// of one frame; `me` indexes into it).
pub fn steering(flock: &[V3], me: usize, d_sep: f64) -> (V3, V3) {
    let b = flock[me];
    let (mut s, mut c) = ([0.0; 3], [0.0; 3]);
    let mut neighbours = 0usize;
    for (i, &q) in flock.iter().enumerate() {
        if i == me {
            continue;
        }
        let off = sub(b, q);
        let dist = norm(off);
        if dist <= d_sep && dist > 0.0 {
            neighbours += 1;
            for k in 0..3 {
                s[k] += off[k] / dist;
            }
        }
        for k in 0..3 {
            c[k] -= off[k];
        }
    }
    if neighbours > 0 {
        s = s.map(|v| v / neighbours as f64);
    }
    if flock.len() > 1 {
        c = c.map(|v| v / (flock.len() - 1) as f64);
    }
    (s, c)
}

/// Depths of every observation by the thesis's frame-by-frame method (see the module docs).
pub fn frame_by_frame(
    obs: &Observations,
    cfg: &LiftConfig,
    progress: &mut dyn Progress,
) -> Result<Vec<f64>> {
    cfg.check()?;
    let cfg = super::estimate::ensure(obs, cfg)?;
    let cfg = &*cfg;
    let n = obs.len();
    let mut depth = vec![f64::NAN; n];
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let (lo, hi) = (cfg.near(), cfg.far());
    progress.start("lift frame by frame", obs.frames.len() as u64);
    let mut prev_range: Option<std::ops::Range<usize>> = None;
    for (fi, (_, range)) in obs.frames.iter().enumerate() {
        // Positions of the previous frame, and each of its birds' index into that list.
        let prev_pos: Vec<V3> = match &prev_range {
            Some(pr) if obs.frame[pr.start] + 1 == obs.frame[range.start] => {
                pr.clone().map(|j| obs.position(j, depth[j])).collect()
            }
            _ => Vec::new(),
        };
        let prev_start = prev_range.as_ref().map_or(0, |r| r.start);
        let solved: Vec<Option<f64>> = range
            .clone()
            .into_par_iter()
            .map(|i| {
                let p = obs.prev[i]?;
                let bp = obs.position(p, depth[p]);
                let c = obs.camera.position;
                let a0 = sub(c, bp);
                let terms = match obs.prev[p] {
                    None => vec![Term {
                        w: 1.0,
                        a: a0,
                        s: cfg.vt(),
                    }],
                    Some(pp) => {
                        let v_last = norm(sub(bp, obs.position(pp, depth[pp])));
                        let (s, coh) = steering(&prev_pos, p - prev_start, cfg.d_sep);
                        let target = [0, 1, 2]
                            .map(|k| bp[k] + cfg.w_sep * s[k] + (1.0 - cfg.w_sep) * coh[k]);
                        vec![
                            Term {
                                w: cfg.lambda_t,
                                a: a0,
                                s: v_last,
                            },
                            Term {
                                w: cfg.lambda_f,
                                a: sub(c, target),
                                s: 0.0,
                            },
                        ]
                    }
                };
                Some(minimise_on_ray(&terms, obs.ray[i], lo, hi))
            })
            .collect();
        let mut placed: Vec<V3> = Vec::new();
        for (i, d) in range.clone().zip(&solved) {
            if let Some(d) = d {
                depth[i] = *d;
                placed.push(obs.position(i, *d));
            }
        }
        // Birds without a past in this frame: scattered (first frame) or joined to the flock.
        let median = median_depth(&prev_range, &depth);
        for i in range.clone() {
            if solved[i - range.start].is_some() {
                continue;
            }
            let d = match (fi, median) {
                (0, _) | (_, None) => scatter(obs, i, &placed, cfg, &mut rng),
                (_, Some(m)) => join(obs, i, &placed, m, cfg),
            };
            depth[i] = d;
            placed.push(obs.position(i, d));
        }
        prev_range = Some(range.clone());
        progress.inc(1);
    }
    progress.finish();
    Ok(depth)
}

fn median_depth(range: &Option<std::ops::Range<usize>>, depth: &[f64]) -> Option<f64> {
    let r = range.as_ref()?;
    let mut v: Vec<f64> = depth[r.clone()].to_vec();
    v.sort_by(f64::total_cmp);
    (!v.is_empty()).then(|| v[v.len() / 2])
}

fn spaced(p: V3, placed: &[V3], min: f64) -> bool {
    placed.iter().all(|q| norm(sub(p, *q)) >= min)
}

/// Attempts at a random depth that keeps the spacing before the most distant of them is taken.
const SCATTER_TRIES: usize = 64;

/// A uniform random depth in the bounds at least `min_spacing` from the birds placed so far (the
/// best-spaced of [`SCATTER_TRIES`] draws when none is).
fn scatter(
    obs: &Observations,
    i: usize,
    placed: &[V3],
    cfg: &LiftConfig,
    rng: &mut ChaCha8Rng,
) -> f64 {
    let mut best = (f64::NEG_INFINITY, cfg.near());
    for _ in 0..SCATTER_TRIES {
        let d = rng.gen_range(cfg.near()..=cfg.far());
        let p = obs.position(i, d);
        let gap = placed
            .iter()
            .map(|q| norm(sub(p, *q)))
            .fold(f64::INFINITY, f64::min);
        if gap >= cfg.spacing() {
            return d;
        }
        if gap > best.0 {
            best = (gap, d);
        }
    }
    best.1
}

/// The flock's median depth, or the nearest depth k·min_spacing from it (k = ±1, ±2, …) that
/// keeps the spacing.
fn join(obs: &Observations, i: usize, placed: &[V3], median: f64, cfg: &LiftConfig) -> f64 {
    let step = cfg.spacing().max(1e-9);
    for k in 0..200 {
        let off = (k as f64 / 2.0).ceil() * if k % 2 == 1 { 1.0 } else { -1.0 };
        let d = (median + off * step).clamp(cfg.near(), cfg.far());
        if spaced(obs.position(i, d), placed, cfg.spacing()) {
            return d;
        }
    }
    median.clamp(cfg.near(), cfg.far())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ray_minimiser_finds_the_global_minimum_on_a_dense_grid() {
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        for _ in 0..200 {
            let r = [rng.gen_range(-0.3..0.3), rng.gen_range(-0.3..0.3), 1.0];
            let terms: Vec<Term> = (0..2)
                .map(|k| Term {
                    w: rng.gen_range(0.1..1.0),
                    a: [
                        rng.gen_range(-5.0..5.0),
                        rng.gen_range(-5.0..5.0),
                        rng.gen_range(-30.0..-5.0),
                    ],
                    s: if k == 0 { rng.gen_range(0.0..3.0) } else { 0.0 },
                })
                .collect();
            let (lo, hi) = (1.0, 40.0);
            let d = minimise_on_ray(&terms, r, lo, hi);
            assert!((lo..=hi).contains(&d));
            let grid = (0..=20000)
                .map(|k| lo + (hi - lo) * k as f64 / 20000.0)
                .map(|x| eval(&terms, r, x))
                .fold(f64::INFINITY, f64::min);
            assert!(
                eval(&terms, r, d) <= grid + 1e-9,
                "{} > {grid}",
                eval(&terms, r, d)
            );
        }
    }

    #[test]
    fn steering_follows_algorithms_1_and_2() {
        let flock = [[0.0, 0.0, 0.0], [0.5, 0.0, 0.0], [0.0, 3.0, 0.0]];
        let (s, c) = steering(&flock, 0, 0.9);
        // One neighbour within d_sep, at +x: s is the unit vector away from it.
        assert_eq!(s, [-1.0, 0.0, 0.0]);
        // Cohesion: the mean offset to the two others.
        assert_eq!(c, [0.25, 1.5, 0.0]);
        let (s, _) = steering(&flock, 2, 0.9);
        assert_eq!(s, [0.0, 0.0, 0.0], "no neighbour: no separation");
    }
}
