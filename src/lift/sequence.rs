//! Stage 2b: the whole-sequence optimisation the thesis leaves as future work (§5: "optimize
//! globally"): every depth of every frame at once, by reverse-mode autodiff (burn) and projected
//! Adam, starting from the frame-by-frame result.
//!
//! Unknowns: u_i = ln d_i for every observation i (log-depth makes a step a relative change,
//! whatever the distance). Positions b_i = C + d_i r_i (eq. 1.1), velocities v = b^f − b^{f−1}
//! (eq. 3.3) within a bird's segment. With T observations, the energy (a whole-sequence eq. 3.1)
//! is `E = (1/T) Σ_k w_k E_k`:
//! - `accel`: Σ ‖v^{f+1} − v^f‖² / v_target² — acceleration smoothness (the thesis tried an
//!   acceleration term frame by frame, §3.1; over the whole sequence it is what removes the
//!   "sudden displacement" of §5);
//! - `speed`: Σ (‖v‖ / v_target − 1)² — v_target as the birds' speed (§3.7), over every frame
//!   rather than only the second (Algorithm 3); it sets the flock's distance, which one camera
//!   cannot see (a flock twice as far and twice as fast projects the same);
//! - `align`: Σ ‖v̂_i − v̂_j‖² over image neighbours (v̂ = v/‖v‖, the heading) — Reynolds'
//!   alignment, which the thesis drops in optimisation (§3.4); with known rays it ties
//!   neighbours' depths through their image motion. Its default weight is 0.3, not 1: real birds
//!   align less than boids (a mobbing flock's true headings cost more than a wrong lift's; the
//!   figures are in RESULTS.md §5);
//! - `cohesion`: Σ (u_i − u_j)² over image neighbours — neighbours at similar depths
//!   (scale-free, so it does not pull the flock towards the camera);
//! - `separation`: Σ max(0, 1 − ‖b_i − b_j‖ / d_sep)² over image neighbours (Algorithm 1's
//!   d_sep as a hinge);
//! - `level`: Σ (v̂·ẑ)² — birds climb and dive less than they fly level (world z is up; the
//!   camera pose makes it known).
//!
//! `align`, `level` and `cohesion` are unchanged when every depth is multiplied by one factor,
//! so they do not pull the flock towards the camera (velocity differences would: they shrink
//! with the distance); the distance is left to `speed` (and `separation`).
//!
//! Neighbours are, per frame, each bird's `neighbours` nearest birds **in the image**: two birds
//! closer than d_sep in 3D are close in the image too, so the pairs are fixed before the
//! optimisation and need no update.
//!
//! The minimiser is L-BFGS ([`super::lbfgs`]): the acceleration term is a second difference in
//! time, so the problem is badly conditioned, and a quasi-Newton method takes in a few hundred
//! steps what a first-order one (Adam: tried, it jitters the depths by its step size and ends
//! above the truth's energy from the truth itself) does not reach. Bounds (eq. 3.5) are a barrier
//! and a projection: a stiff quadratic penalty `W_BOUNDS · (max(0, ln d_near − u)² +
//! max(0, u − ln d_far)²)` outside [ln d_near, ln d_far] while minimising, then the depths are
//! clamped into the bounds.

use super::observe::Observations;
use super::LiftConfig;
use crate::backend::cpu_device;
use crate::error::{Error, Result};
use crate::progress::Progress;
use burn::tensor::{Device, Int, Tensor, TensorData};
use serde::{Deserialize, Serialize};

/// Weights and settings of the whole-sequence energy (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SequenceConfig {
    /// L-BFGS iterations per level (at most; a level stops earlier when an iteration gains less
    /// than `tolerance` relatively).
    pub iterations: usize,
    /// Stored pairs of L-BFGS.
    pub memory: usize,
    pub tolerance: f64,
    /// Knot spacings of the coarse-to-fine levels, in frames (0: one log-depth per segment; 1:
    /// every log-depth free); see [`whole_sequence`].
    pub levels: Vec<usize>,
    pub w_accel: f64,
    pub w_speed: f64,
    pub w_align: f64,
    pub w_cohesion: f64,
    pub w_separation: f64,
    pub w_level: f64,
    /// Image neighbours per bird and frame for the pair terms.
    pub neighbours: usize,
    /// Tensor precision.
    pub precision: crate::backend::Precision,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        SequenceConfig {
            iterations: 300,
            memory: 10,
            tolerance: 1e-7,
            levels: vec![0, 64, 16, 4, 1],
            w_accel: 100.0,
            w_speed: 1.0,
            w_align: 0.3,
            w_cohesion: 1.0,
            w_separation: 100.0,
            w_level: 1.0,
            neighbours: 4,
            precision: crate::backend::Precision::F32,
        }
    }
}

impl SequenceConfig {
    /// Checks ranges; errors name the key (`sequence.<key>`).
    pub fn check(&self) -> Result<()> {
        if self.iterations > 1_000_000 {
            return Err(Error::invalid(format!(
                "sequence.iterations = {} must be at most 1000000",
                self.iterations
            )));
        }
        if self.levels.is_empty() || self.levels.len() > 16 {
            return Err(Error::invalid(format!(
                "sequence.levels has {} entries: give 1 to 16 knot spacings (0 = one per segment, 1 = free)",
                self.levels.len()
            )));
        }
        if self.memory == 0 || self.memory > 100 {
            return Err(Error::invalid(format!(
                "sequence.memory = {} must be in 1..=100",
                self.memory
            )));
        }
        if !(self.tolerance.is_finite() && self.tolerance >= 0.0) {
            return Err(Error::invalid(format!(
                "sequence.tolerance = {} must be ≥ 0",
                self.tolerance
            )));
        }
        for (k, v) in self.weights() {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!("sequence.{k} = {v} must be ≥ 0")));
            }
        }
        if self.neighbours == 0 || self.neighbours > 64 {
            return Err(Error::invalid(format!(
                "sequence.neighbours = {} must be in 1..=64",
                self.neighbours
            )));
        }
        Ok(())
    }

    /// The six weights by key.
    pub fn weights(&self) -> [(&'static str, f64); 6] {
        [
            ("w_accel", self.w_accel),
            ("w_speed", self.w_speed),
            ("w_align", self.w_align),
            ("w_cohesion", self.w_cohesion),
            ("w_separation", self.w_separation),
            ("w_level", self.w_level),
        ]
    }
}

/// Index lists of the energy's terms, fixed by the tracks alone.
#[derive(Clone, Debug, Default)]
pub struct Structure {
    /// Velocities: (observation at f − 1, observation at f).
    pub vel: Vec<(usize, usize)>,
    /// Accelerations: consecutive velocities of one bird (indices into `vel`).
    pub acc: Vec<(usize, usize)>,
    /// Same-frame image-neighbour pairs (i < j).
    pub pairs: Vec<(usize, usize)>,
    /// Pairs whose two birds both have a velocity (indices into `vel`).
    pub align: Vec<(usize, usize)>,
}

impl Structure {
    /// The index lists of `obs` with `k` image neighbours per bird and frame.
    pub fn new(obs: &Observations, k: usize) -> Self {
        let n = obs.len();
        let mut vel_of = vec![usize::MAX; n];
        let mut vel = Vec::new();
        for (i, slot) in vel_of.iter_mut().enumerate() {
            if let Some(p) = obs.prev[i] {
                *slot = vel.len();
                vel.push((p, i));
            }
        }
        let acc = vel
            .iter()
            .enumerate()
            .filter(|&(_, &(p, _))| vel_of[p] != usize::MAX)
            .map(|(v, &(p, _))| (vel_of[p], v))
            .collect();
        let mut pairs = Vec::new();
        for (_, r) in &obs.frames {
            let idx: Vec<usize> = r.clone().collect();
            let mut near: Vec<(f64, usize)> = Vec::with_capacity(idx.len());
            for &i in &idx {
                near.clear();
                let p = obs.pixel[i];
                near.extend(idx.iter().filter(|&&j| j != i).map(|&j| {
                    let q = obs.pixel[j];
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2), j)
                }));
                let take = k.min(near.len());
                if take == 0 {
                    continue;
                }
                near.select_nth_unstable_by(take - 1, |a, b| {
                    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
                });
                for &(_, j) in &near[..take] {
                    pairs.push((i.min(j), i.max(j)));
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let align = pairs
            .iter()
            .filter(|&&(i, j)| vel_of[i] != usize::MAX && vel_of[j] != usize::MAX)
            .map(|&(i, j)| (vel_of[i], vel_of[j]))
            .collect();
        Structure {
            vel,
            acc,
            pairs,
            align,
        }
    }
}

/// The terms of the energy at one point (each already weighted and divided by T).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EnergyTerms {
    pub accel: f64,
    pub speed: f64,
    pub align: f64,
    pub cohesion: f64,
    pub separation: f64,
    pub level: f64,
    pub total: f64,
}

/// What the optimisation did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SequenceLog {
    /// L-BFGS iterations of each level.
    pub iterations: Vec<usize>,
    /// Energy evaluations (with gradient), line search included.
    pub evaluations: usize,
    pub start: EnergyTerms,
    pub end: EnergyTerms,
    pub pairs: usize,
}

struct Graph {
    rx: Tensor<1>,
    ry: Tensor<1>,
    rz: Tensor<1>,
    vp: Tensor<1, Int>,
    vc: Tensor<1, Int>,
    aa: Tensor<1, Int>,
    ab: Tensor<1, Int>,
    pi: Tensor<1, Int>,
    pj: Tensor<1, Int>,
    li: Tensor<1, Int>,
    lj: Tensor<1, Int>,
}

fn idx(v: impl Iterator<Item = usize>, device: &Device) -> Tensor<1, Int> {
    let v: Vec<i64> = v.map(|i| i as i64).collect();
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

fn vec1(v: Vec<f64>, device: &Device) -> Tensor<1> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

fn sum_sq(x: Tensor<1>) -> Tensor<1> {
    x.powi_scalar(2).sum()
}

impl Graph {
    fn new(obs: &Observations, s: &Structure, device: &Device) -> Self {
        let comp = |k: usize| vec1(obs.ray.iter().map(|r| r[k]).collect(), device);
        Graph {
            rx: comp(0),
            ry: comp(1),
            rz: comp(2),
            vp: idx(s.vel.iter().map(|v| v.0), device),
            vc: idx(s.vel.iter().map(|v| v.1), device),
            aa: idx(s.acc.iter().map(|a| a.0), device),
            ab: idx(s.acc.iter().map(|a| a.1), device),
            pi: idx(s.pairs.iter().map(|p| p.0), device),
            pj: idx(s.pairs.iter().map(|p| p.1), device),
            li: idx(s.align.iter().map(|p| p.0), device),
            lj: idx(s.align.iter().map(|p| p.1), device),
        }
    }

    /// The weighted terms (each a one-element tensor) at log-depths `u`.
    fn energy(
        &self,
        u: &Tensor<1>,
        s: &Structure,
        cfg: &LiftConfig,
        n: usize,
    ) -> Vec<(&'static str, Tensor<1>)> {
        let w = &cfg.sequence;
        let vt = cfg.v_target;
        let scale = 1.0 / n as f64;
        let d = u.clone().exp();
        let q = [
            d.clone() * self.rx.clone(),
            d.clone() * self.ry.clone(),
            d * self.rz.clone(),
        ];
        let g = |t: &Tensor<1>, i: &Tensor<1, Int>| t.clone().gather(0, i.clone());
        let mut out = Vec::new();
        if !s.vel.is_empty() {
            let v: Vec<Tensor<1>> = q.iter().map(|c| g(c, &self.vc) - g(c, &self.vp)).collect();
            let sp2 = v[0].clone().powi_scalar(2)
                + v[1].clone().powi_scalar(2)
                + v[2].clone().powi_scalar(2);
            let speed = (sp2 + 1e-12 * vt * vt).sqrt();
            out.push((
                "speed",
                sum_sq(speed.clone().div_scalar(vt).sub_scalar(1.0)).mul_scalar(w.w_speed * scale),
            ));
            // Unit headings (scale-free: a flock twice as far has the same headings).
            let head: Vec<Tensor<1>> = v.iter().map(|c| c.clone() / speed.clone()).collect();
            out.push((
                "level",
                sum_sq(head[2].clone()).mul_scalar(w.w_level * scale),
            ));
            if !s.acc.is_empty() {
                let a = v
                    .iter()
                    .map(|c| sum_sq(g(c, &self.ab) - g(c, &self.aa)))
                    .reduce(|x, y| x + y)
                    .expect("three components");
                out.push(("accel", a.mul_scalar(w.w_accel * scale / (vt * vt))));
            }
            if !s.align.is_empty() {
                let a = head
                    .iter()
                    .map(|c| sum_sq(g(c, &self.lj) - g(c, &self.li)))
                    .reduce(|x, y| x + y)
                    .expect("three components");
                out.push(("align", a.mul_scalar(w.w_align * scale)));
            }
        }
        if !s.pairs.is_empty() {
            out.push((
                "cohesion",
                sum_sq(g(u, &self.pj) - g(u, &self.pi)).mul_scalar(w.w_cohesion * scale),
            ));
            let d2 = q
                .iter()
                .map(|c| (g(c, &self.pj) - g(c, &self.pi)).powi_scalar(2))
                .reduce(|x, y| x + y)
                .expect("three components");
            let ds = cfg.d_sep;
            let dist = (d2 + 1e-12 * ds * ds).sqrt();
            let hinge = dist.div_scalar(-ds).add_scalar(1.0).clamp_min(0.0);
            out.push((
                "separation",
                sum_sq(hinge).mul_scalar(w.w_separation * scale),
            ));
        }
        out
    }
}

/// Reads a rank-1 tensor back as f64 values.
fn read_vec(t: &Tensor<1>) -> Result<Vec<f64>> {
    t.clone()
        .try_into_vec_as::<f64>()
        .map_err(|e| Error::Internal(format!("tensor read-back failed: {e:?}")))
}

fn read1(t: Tensor<1>) -> Result<f64> {
    Ok(read_vec(&t)?.first().copied().unwrap_or(0.0))
}

fn terms_of(parts: &[(&'static str, Tensor<1>)]) -> Result<EnergyTerms> {
    let mut e = EnergyTerms::default();
    for (k, t) in parts {
        let v = read1(t.clone().detach())?;
        match *k {
            "accel" => e.accel = v,
            "speed" => e.speed = v,
            "align" => e.align = v,
            "cohesion" => e.cohesion = v,
            "separation" => e.separation = v,
            _ => e.level = v,
        }
        e.total += v;
    }
    Ok(e)
}

/// The energy's terms at depths `depth` (no gradient).
pub fn energy_terms(obs: &Observations, depth: &[f64], cfg: &LiftConfig) -> Result<EnergyTerms> {
    let device = cpu_device(cfg.sequence.precision)?;
    let s = Structure::new(obs, cfg.sequence.neighbours);
    let g = Graph::new(obs, &s, &device);
    let u = vec1(depth.iter().map(|d| d.ln()).collect(), &device);
    terms_of(&g.energy(&u, &s, cfg, obs.len()))
}

/// Weight of the bound penalty (per observation, on log-depth).
const W_BOUNDS: f64 = 1e4;

/// Segments (a bird's run of consecutive frames): each one's observations in frame order.
pub fn segments(obs: &Observations) -> Vec<Vec<usize>> {
    (0..obs.len())
        .filter(|&i| obs.prev[i].is_none())
        .map(|start| {
            let mut run = vec![start];
            while let Some(n) = obs.next[*run.last().expect("non-empty")] {
                run.push(n);
            }
            run
        })
        .collect()
}

/// Log-depths as linear interpolation between knots along each segment: knots every `spacing`
/// frames from the segment's start and at its end (`spacing` 0: one knot per segment, a constant).
struct Knots {
    k0: Vec<usize>,
    k1: Vec<usize>,
    w1: Vec<f64>,
    /// The observation at each knot.
    at: Vec<usize>,
}

impl Knots {
    fn new(segs: &[Vec<usize>], n: usize, spacing: usize) -> Knots {
        let (mut k0, mut k1, mut w1) = (vec![0; n], vec![0; n], vec![0.0; n]);
        let mut at = Vec::new();
        for run in segs {
            let first = at.len();
            let len = run.len();
            let pos: Vec<usize> = if spacing == 0 {
                vec![0]
            } else {
                let mut p: Vec<usize> = (0..len).step_by(spacing).collect();
                if *p.last().expect("non-empty") != len - 1 {
                    p.push(len - 1);
                }
                p
            };
            at.extend(pos.iter().map(|&p| run[p]));
            let mut j = 0;
            for (k, &o) in run.iter().enumerate() {
                while j + 1 < pos.len() && pos[j + 1] <= k {
                    j += 1;
                }
                if j + 1 < pos.len() {
                    let (a, b) = (pos[j], pos[j + 1]);
                    k0[o] = first + j;
                    k1[o] = first + j + 1;
                    w1[o] = (k - a) as f64 / (b - a) as f64;
                } else {
                    k0[o] = first + j;
                    k1[o] = first + j;
                }
            }
        }
        Knots { k0, k1, w1, at }
    }
}

/// Whole-sequence depths from `init` (the frame-by-frame depths), by L-BFGS on the energy of the
/// module docs, gradients by burn's reverse-mode autodiff.
///
/// Coarse to fine (`sequence.levels`): the log-depths are first one value per segment (started at
/// the median of its initial log-depths), then linear between knots every 64, 16 and 4 frames,
/// then free. Each level starts from the previous one's result. A start whose depths jump from
/// frame to frame (as the frame-by-frame method's do) would otherwise hold the free stage in a
/// poor local minimum, and the slow modes — a segment's distance, its drift towards the camera —
/// are exactly the ones the acceleration term's stiffness makes slow for L-BFGS.
pub fn whole_sequence(
    obs: &Observations,
    init: &[f64],
    cfg: &LiftConfig,
    progress: &mut dyn Progress,
) -> Result<(Vec<f64>, SequenceLog)> {
    cfg.check()?;
    let sc = &cfg.sequence;
    let n = obs.len();
    if init.len() != n {
        return Err(Error::Internal(format!(
            "{} initial depths for {n} observations",
            init.len()
        )));
    }
    let device = cpu_device(sc.precision)?;
    let ad = device.clone().autodiff();
    let s = Structure::new(obs, sc.neighbours);
    let graph = Graph::new(obs, &s, &ad);
    let (lo, hi) = (cfg.d_near.ln(), cfg.d_far.ln());
    let mut u: Vec<f64> = init
        .iter()
        .map(|d| d.clamp(cfg.d_near, cfg.d_far).ln())
        .collect();
    let start = energy_terms(obs, init, cfg)?;
    let wb = W_BOUNDS / n as f64;
    let segs = segments(obs);
    let opt = super::lbfgs::Lbfgs {
        iterations: sc.iterations,
        memory: sc.memory,
        tolerance: sc.tolerance,
    };
    let mut per_level = Vec::with_capacity(sc.levels.len());
    let mut evaluations = 0;
    for &spacing in &sc.levels {
        let knots = (spacing != 1).then(|| Knots::new(&segs, n, spacing));
        // Unknowns x: the knots' log-depths, or every log-depth.
        let mut x: Vec<f64> = match &knots {
            None => u.clone(),
            Some(_) if spacing == 0 => segs
                .iter()
                .map(|run| {
                    let mut v: Vec<f64> = run.iter().map(|&i| u[i]).collect();
                    v.sort_by(f64::total_cmp);
                    v[v.len() / 2]
                })
                .collect(),
            Some(k) => k.at.iter().map(|&i| u[i]).collect(),
        };
        let interp = knots.as_ref().map(|k| {
            (
                idx(k.k0.iter().copied(), &ad),
                idx(k.k1.iter().copied(), &ad),
                vec1(k.w1.clone(), &ad),
                vec1(k.w1.iter().map(|w| 1.0 - w).collect(), &ad),
            )
        });
        let energy = |x: &[f64]| -> Result<(f64, Vec<f64>)> {
            let xt = vec1(x.to_vec(), &ad).require_grad();
            let ut = match &interp {
                None => xt.clone(),
                Some((k0, k1, w1, w0)) => {
                    xt.clone().gather(0, k0.clone()) * w0.clone()
                        + xt.clone().gather(0, k1.clone()) * w1.clone()
                }
            };
            let total = graph
                .energy(&ut, &s, cfg, n)
                .into_iter()
                .map(|p| p.1)
                .reduce(|a, b| a + b)
                .ok_or_else(|| Error::Internal("empty energy".into()))?;
            let value = read1(total.clone().detach())?;
            let grads = total.backward();
            let mut g = xt
                .grad(&grads)
                .map(|t| read_vec(&t))
                .transpose()?
                .unwrap_or_else(|| vec![0.0; x.len()]);
            // The bound barrier on the knots (each standing for about the frames it spans).
            let weight = wb * n as f64 / x.len() as f64;
            let mut pen = 0.0;
            for (gk, &xk) in g.iter_mut().zip(x) {
                let out = (lo - xk).max(0.0) - (xk - hi).max(0.0);
                pen += weight * out * out;
                *gk = if gk.is_finite() { *gk } else { 0.0 } - 2.0 * weight * out;
            }
            Ok((value + pen, g))
        };
        progress.start(
            &match spacing {
                0 => "lift: one depth per bird".to_string(),
                1 => "lift: every depth".to_string(),
                k => format!("lift: knots every {k} frames"),
            },
            sc.iterations as u64,
        );
        let run = opt.minimise(&mut x, energy, |_, f| {
            progress.message(&format!("E {f:.5}"));
            progress.inc(1);
        })?;
        progress.finish();
        evaluations += run.evaluations;
        per_level.push(run.iterations);
        u = match &knots {
            None => x,
            Some(k) => (0..n)
                .map(|i| (1.0 - k.w1[i]) * x[k.k0[i]] + k.w1[i] * x[k.k1[i]])
                .collect(),
        };
    }
    let depth: Vec<f64> = u
        .iter()
        .map(|x| x.exp().clamp(cfg.d_near, cfg.d_far))
        .collect();
    let end = energy_terms(obs, &depth, cfg)?;
    Ok((
        depth,
        SequenceLog {
            iterations: per_level,
            evaluations,
            start,
            end,
            pairs: s.pairs.len(),
        },
    ))
}
