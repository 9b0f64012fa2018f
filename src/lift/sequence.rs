//! Stage 2b: the whole-sequence optimisation the thesis leaves as future work (§5: "optimize
//! globally"): every depth of every frame at once, by L-BFGS, starting from the frame-by-frame
//! result. The gradient is hand-derived (`herdfit_kernels::lift`, plain Rust over `f64` slices);
//! the same energy as burn tensor ops with reverse-mode autodiff (`super::autodiff`) is kept as
//! its reference (`sequence.gradient = "autodiff"`; checked against each other in
//! `tests/lift_gradient.rs`).
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

use super::knots::{segments, Coarse, Knots};
use super::observe::Observations;
pub use super::terms::{EnergyTerms, Structure};
use super::LiftConfig;
use crate::error::{Error, Result};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

/// Weights and settings of the whole-sequence energy (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SequenceConfig {
    /// L-BFGS iterations per level (at most; a level stops earlier when an iteration gains less
    /// than `tolerance` relatively).
    pub iterations: usize,
    /// L-BFGS iterations at most in the last level (`iterations` when smaller). The coarse levels
    /// make the progress (a segment's distance and drift, the slow modes); the last one, with
    /// every depth free, mostly polishes and costs the most per iteration: fewer is faster, at the
    /// cost measured in BENCHMARKS.md, "Lift" (the default keeps `iterations`).
    pub final_iterations: usize,
    /// Stored pairs of L-BFGS.
    pub memory: usize,
    pub tolerance: f64,
    /// Knot spacings of the coarse-to-fine levels, in frames (0: one log-depth per segment; 1:
    /// every log-depth free); see [`whole_sequence`].
    pub levels: Vec<usize>,
    /// With a value above 1, the coarse levels (knot spacing 0, or at least 4 × this) are
    /// evaluated on every `coarse_stride`-th frame only: velocities over `coarse_stride` frames,
    /// v_target × stride and w_accel / stride² (an acceleration over `stride` frames is stride²
    /// times one over one frame), each term over its own count. Each of their evaluations is then
    /// about `stride` times cheaper; the finer levels see every frame. Faster, but not the same
    /// path to the minimum: the default, 1, evaluates every level on every frame (the trade-off
    /// is measured in BENCHMARKS.md, "Lift").
    pub coarse_stride: usize,
    pub w_accel: f64,
    pub w_speed: f64,
    pub w_align: f64,
    pub w_cohesion: f64,
    /// Weight of `separation`. It is the one term that pushes a whole flock away from the camera
    /// (spreading birds in 3D): 10 since issue #50 (100 before), chosen leave-one-out on the two
    /// jackdaw flights, each of which prefers 10 (RESULTS).
    pub w_separation: f64,
    pub w_level: f64,
    /// Image neighbours per bird and frame for the pair terms.
    pub neighbours: usize,
    /// How the gradient is computed (`analytic`, the default, or `autodiff`, the reference).
    pub gradient: Gradient,
    /// Tensor precision of the `autodiff` gradient (the analytic one is always f64).
    pub precision: crate::backend::Precision,
}

impl Default for SequenceConfig {
    fn default() -> Self {
        SequenceConfig {
            iterations: 300,
            final_iterations: 300,
            memory: 10,
            tolerance: 1e-7,
            levels: vec![0, 64, 16, 4, 1],
            coarse_stride: 1,
            w_accel: 100.0,
            w_speed: 1.0,
            w_align: 0.3,
            w_cohesion: 1.0,
            w_separation: 10.0,
            w_level: 1.0,
            neighbours: 4,
            gradient: Gradient::Analytic,
            precision: crate::backend::Precision::F32,
        }
    }
}

impl SequenceConfig {
    /// Checks ranges; errors name the key (`sequence.<key>`).
    pub fn check(&self) -> Result<()> {
        for (k, v) in [
            ("iterations", self.iterations),
            ("final_iterations", self.final_iterations),
        ] {
            if v > 1_000_000 {
                return Err(Error::invalid(format!(
                    "sequence.{k} = {v} must be at most 1000000"
                )));
            }
        }
        if self.levels.is_empty() || self.levels.len() > 16 {
            return Err(Error::invalid(format!(
                "sequence.levels has {} entries: give 1 to 16 knot spacings (0 = one per segment, 1 = free)",
                self.levels.len()
            )));
        }
        if self.coarse_stride == 0 || self.coarse_stride > 64 {
            return Err(Error::invalid(format!(
                "sequence.coarse_stride = {} must be in 1..=64",
                self.coarse_stride
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

/// What the optimisation did.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SequenceLog {
    /// L-BFGS iterations of each level.
    pub iterations: Vec<usize>,
    /// The frame stride each level was evaluated on (`sequence.coarse_stride` for the coarse
    /// levels, else 1).
    #[serde(default)]
    pub strides: Vec<usize>,
    /// Energy evaluations (with gradient), line search included.
    pub evaluations: usize,
    pub start: EnergyTerms,
    pub end: EnergyTerms,
    pub pairs: usize,
}

/// How the energy's gradient is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Gradient {
    /// Hand-derived, plain Rust over `f64` slices (`herdfit_kernels::lift`).
    Analytic,
    /// burn tensor ops and reverse-mode autodiff (`super::autodiff`, at `precision`): the
    /// reference the analytic gradient is tested against; much slower (BENCHMARKS.md, "Lift").
    Autodiff,
}

fn kernel_structure<'a>(
    obs: &'a Observations,
    s: &'a Structure,
) -> herdfit_kernels::lift::SeqStructure<'a> {
    herdfit_kernels::lift::SeqStructure {
        ray: &obs.ray,
        vel: &s.vel,
        acc: &s.acc,
        pairs: &s.pairs,
        align: &s.align,
    }
}

/// One problem's energy, ready to evaluate many times.
pub struct Energy<'a> {
    s: &'a Structure,
    obs: &'a Observations,
    cfg: &'a LiftConfig,
    how: How,
}

enum How {
    Analytic(
        Box<(
            herdfit_kernels::lift::SeqPlan,
            herdfit_kernels::lift::SeqWorkspace,
        )>,
    ),
    Autodiff(Box<super::autodiff::Graph>),
}

impl<'a> Energy<'a> {
    /// The energy of `obs` with index lists `s`, by `cfg.sequence.gradient`.
    pub fn new(obs: &'a Observations, s: &'a Structure, cfg: &'a LiftConfig) -> Result<Self> {
        let how = match cfg.sequence.gradient {
            Gradient::Analytic => How::Analytic(Box::new((
                herdfit_kernels::lift::SeqPlan::new(&kernel_structure(obs, s)),
                Default::default(),
            ))),
            Gradient::Autodiff => {
                How::Autodiff(Box::new(super::autodiff::Graph::new(obs, s, cfg)?))
            }
        };
        Ok(Energy { s, obs, cfg, how })
    }

    /// Observations (log-depths) it takes.
    fn len(&self) -> usize {
        self.obs.len()
    }

    /// The terms at log-depths `u` (one per observation) and, with `grad`, ∂E/∂u written into it.
    pub fn eval(&mut self, u: &[f64], grad: Option<&mut [f64]>) -> Result<EnergyTerms> {
        let n = self.obs.len();
        if u.len() != n || grad.as_ref().is_some_and(|g| g.len() != n) {
            return Err(Error::Internal(format!(
                "{} log-depths for {n} observations",
                u.len()
            )));
        }
        let (cfg, sc, s) = (self.cfg, &self.cfg.sequence, self.s);
        match &mut self.how {
            How::Autodiff(g) => g.eval(u, cfg, grad),
            How::Analytic(pw) => {
                let (plan, ws) = &mut **pw;
                let st = kernel_structure(self.obs, s);
                let w = herdfit_kernels::lift::SeqWeights {
                    accel: sc.w_accel,
                    speed: sc.w_speed,
                    align: sc.w_align,
                    cohesion: sc.w_cohesion,
                    separation: sc.w_separation,
                    level: sc.w_level,
                    scale: 1.0 / n as f64,
                    v_target: cfg.vt(),
                    d_sep: cfg.d_sep,
                };
                let t = herdfit_kernels::lift::sequence_energy(&st, plan, &w, u, grad, ws);
                Ok(EnergyTerms {
                    accel: t.accel,
                    speed: t.speed,
                    align: t.align,
                    cohesion: t.cohesion,
                    separation: t.separation,
                    level: t.level,
                    total: t.total(),
                })
            }
        }
    }
}

/// The energy's terms at depths `depth` (no gradient), by `cfg.sequence.gradient`.
pub fn energy_terms(obs: &Observations, depth: &[f64], cfg: &LiftConfig) -> Result<EnergyTerms> {
    let cfg = super::estimate::ensure(obs, cfg)?;
    let cfg = &*cfg;
    let s = Structure::new(obs, cfg.sequence.neighbours);
    let u: Vec<f64> = depth.iter().map(|d| d.ln()).collect();
    Energy::new(obs, &s, cfg)?.eval(&u, None)
}
/// The problem on every `stride`-th frame with its index lists and settings (v_target × stride,
/// w_accel / stride²; see [`SequenceConfig::coarse_stride`]).
struct CoarseProblem {
    coarse: Coarse,
    s: Structure,
    cfg: LiftConfig,
}

impl CoarseProblem {
    fn new(obs: &Observations, segs: &[Vec<usize>], cfg: &LiftConfig, stride: usize) -> Self {
        let coarse = Coarse::new(obs, segs, stride);
        let s = Structure::new(&coarse.obs, cfg.sequence.neighbours);
        let mut cfg = cfg.clone();
        let k = stride as f64;
        cfg.v_target = Some(cfg.vt() * k);
        cfg.sequence.w_accel /= k * k;
        CoarseProblem { coarse, s, cfg }
    }
}

/// Weight of the bound penalty (per observation, on log-depth).
const W_BOUNDS: f64 = 1e4;

/// Whole-sequence depths from `init` (the frame-by-frame depths), by L-BFGS on the energy of the
/// module docs, its gradient by `sequence.gradient`.
///
/// Coarse to fine (`sequence.levels`): the log-depths are first one value per segment (started at
/// the median of its initial log-depths), then linear between knots every 64, 16 and 4 frames,
/// then free. Each level starts from the previous one's result. A start whose depths jump from
/// frame to frame (as the frame-by-frame method's do) would otherwise hold the free stage in a
/// poor local minimum, and the slow modes — a segment's distance, its drift towards the camera —
/// are exactly the ones the acceleration term's stiffness makes slow for L-BFGS. With
/// `sequence.coarse_stride` above 1 the coarse levels are evaluated on every stride-th frame
/// ([`SequenceConfig::coarse_stride`]).
pub fn whole_sequence(
    obs: &Observations,
    init: &[f64],
    cfg: &LiftConfig,
    progress: &mut dyn Progress,
) -> Result<(Vec<f64>, SequenceLog)> {
    cfg.check()?;
    let cfg = super::estimate::ensure(obs, cfg)?;
    let cfg = &*cfg;
    let sc = &cfg.sequence;
    let n = obs.len();
    if init.len() != n {
        return Err(Error::Internal(format!(
            "{} initial depths for {n} observations",
            init.len()
        )));
    }
    let s = Structure::new(obs, sc.neighbours);
    let mut energy = Energy::new(obs, &s, cfg)?;
    let (lo, hi) = (cfg.near().ln(), cfg.far().ln());
    let mut u: Vec<f64> = init
        .iter()
        .map(|d| d.clamp(cfg.near(), cfg.far()).ln())
        .collect();
    let start = energy.eval(&init.iter().map(|d| d.ln()).collect::<Vec<_>>(), None)?;
    let segs = segments(obs);
    let stride = sc.coarse_stride;
    let on_coarse = |spacing: usize| stride > 1 && (spacing == 0 || spacing >= 4 * stride);
    // The problem on every stride-th frame, built when a level is evaluated on it.
    let coarse = sc
        .levels
        .iter()
        .any(|&k| on_coarse(k))
        .then(|| CoarseProblem::new(obs, &segs, cfg, stride));
    let mut coarse_energy = match &coarse {
        Some(c) => Some(Energy::new(&c.coarse.obs, &c.s, &c.cfg)?),
        None => None,
    };
    let mut per_level = Vec::with_capacity(sc.levels.len());
    let mut strides = Vec::with_capacity(sc.levels.len());
    let mut evaluations = 0;
    let (mut ut, mut gu) = (Vec::new(), Vec::new());
    for (level, &spacing) in sc.levels.iter().enumerate() {
        let last = level + 1 == sc.levels.len();
        let opt = super::lbfgs::Lbfgs {
            iterations: if last {
                sc.iterations.min(sc.final_iterations)
            } else {
                sc.iterations
            },
            memory: sc.memory,
            tolerance: sc.tolerance,
        };
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
        // The energy this level is evaluated on, with the knots and segments seen from its
        // observations.
        let coarse_here = match (&coarse, &knots) {
            (Some(c), Some(k)) if on_coarse(spacing) => Some((c, c.coarse.knots(k))),
            _ => None,
        };
        let (en, eval_knots, eval_segs) = match (&coarse_here, coarse_energy.as_mut()) {
            (Some((c, k)), Some(e)) => (e, Some(k), &c.coarse.segs[..]),
            _ => (&mut energy, knots.as_ref(), &segs[..]),
        };
        strides.push(if coarse_here.is_some() { stride } else { 1 });
        ut.resize(en.len(), 0.0);
        gu.resize(en.len(), 0.0);
        let objective = |x: &[f64], g: &mut [f64]| -> Result<f64> {
            let value = match eval_knots {
                None => en.eval(x, Some(g))?.total,
                Some(k) => {
                    k.interpolate(x, &mut ut);
                    let e = en.eval(&ut, Some(&mut gu))?;
                    k.pull_back(eval_segs, &gu, g);
                    e.total
                }
            };
            // The bound barrier on the knots (each standing for about the frames it spans).
            let weight = W_BOUNDS / x.len() as f64;
            let mut pen = 0.0;
            for (gk, &xk) in g.iter_mut().zip(x) {
                let out = (lo - xk).max(0.0) - (xk - hi).max(0.0);
                pen += weight * out * out;
                *gk = if gk.is_finite() { *gk } else { 0.0 } - 2.0 * weight * out;
            }
            Ok(value + pen)
        };
        progress.start(
            &match spacing {
                0 => "lift: one depth per bird".to_string(),
                1 => "lift: every depth".to_string(),
                k => format!("lift: knots every {k} frames"),
            },
            opt.iterations as u64,
        );
        let run = opt.minimise(&mut x, objective, |_, f| {
            progress.message(&format!("E {f:.5}"));
            progress.inc(1);
        })?;
        progress.finish();
        evaluations += run.evaluations;
        per_level.push(run.iterations);
        u = match &knots {
            None => x,
            Some(k) => {
                let mut full = vec![0.0; n];
                k.interpolate(&x, &mut full);
                full
            }
        };
    }
    let depth: Vec<f64> = u
        .iter()
        .map(|x| x.exp().clamp(cfg.near(), cfg.far()))
        .collect();
    let end = energy.eval(&depth.iter().map(|d| d.ln()).collect::<Vec<_>>(), None)?;
    Ok((
        depth,
        SequenceLog {
            iterations: per_level,
            strides,
            evaluations,
            start,
            end,
            pairs: s.pairs.len(),
        },
    ))
}
