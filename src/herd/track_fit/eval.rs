//! Scores of parameter sets on held-out tracks: displacement errors of rollouts from the tracked
//! animals (ADE/FDE at each horizon, either rollout), constant velocity on the same windows, and
//! the motion distributions of free runs against the tracks'.
//!
//! A window starts at every `stride` frames f₀ of the scored frames. It scores an animal at
//! horizon H (steps) when the animal is tracked in the `observe` frames up to f₀ (f₀ − 1 at
//! least: its velocity) and in every frame f₀ + 1 … f₀ + H, so the animals and windows scored
//! are the same for every set, seed and rollout (and for constant velocity: p̂(f₀) + k Δt v(f₀)
//! with v(f₀) the velocity into f₀). ADE averages |p − p̂| over the H steps, FDE takes step H.
//! A seed fixes each window's noise ξ (eq. 6) for every set: seed s of two sets is a pair with
//! common random numbers.

use super::config::{steps_of, Leaders, Rollout, Speeds};
use super::rollout::{roll, TrackClip, Window};
use crate::backend::{cpu_device, Precision};
use crate::error::{Error, Result};
use crate::herd::params::Params;
use crate::herd::sim::{theta_tensor, Decide, ForceTensors, HerdState};
use crate::measure::distribution::MotionSamples;
use burn::tensor::Device;
use herdfit_kernels::P2;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Settings of a track evaluation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackEvalConfig {
    /// Horizons (s); each becomes `round(h · fps)` steps.
    pub horizons: Vec<f64>,
    pub rollouts: Vec<Rollout>,
    /// Seeds per set (each fixes every window's speed noise).
    pub seeds: usize,
    /// Seconds between window starts (0: every frame).
    pub stride: f64,
    /// Frames an animal must be tracked up to a window's start to be scored (≥ 2).
    pub observe: usize,
    /// Blocks of consecutive windows for the verdicts over time.
    pub blocks: usize,
    /// Length (s) of the free runs whose distributions are compared with the tracks' (0: none).
    pub free_run: f64,
    /// Speed (BL/s) below which a step does not count as moving (turning rate, polarization).
    pub still: f64,
    /// σ (cells) of the leaders' guidance smoothing; ∞ is written as "inf", not null.
    #[serde(with = "crate::limits::infinite_ok")]
    pub guidance_scale: f64,
    /// Whether tracked animals may lead (§5.1): the same for every set scored.
    pub leaders: Leaders,
    /// The displacement errors' speeds: eq. 6 with its noise (one sample per seed) or without
    /// it (the expected speeds: a point forecast); never the tracks' own (the future).
    pub speeds: Speeds,
    pub precision: Precision,
}

impl Default for TrackEvalConfig {
    fn default() -> Self {
        TrackEvalConfig {
            horizons: vec![1.0, 2.0],
            rollouts: vec![Rollout::Conditioned, Rollout::Free],
            seeds: 16,
            stride: 0.5,
            observe: 2,
            blocks: 10,
            free_run: 10.0,
            still: 0.1,
            guidance_scale: crate::herd::guidance::GUIDANCE_SCALE,
            leaders: Leaders::Off,
            speeds: Speeds::Noisy,
            precision: Precision::F32,
        }
    }
}

impl TrackEvalConfig {
    /// Checks the settings; errors name the key.
    pub fn check(&self) -> Result<()> {
        let bad = |k: &str, m: String| Err(Error::config(k, m));
        if self.horizons.is_empty()
            || self
                .horizons
                .iter()
                .any(|h| !(h.is_finite() && *h > 0.0 && *h <= 3600.0))
        {
            return bad(
                "horizons",
                "give one or more horizons in (0, 3600] s".into(),
            );
        }
        if self.speeds == Speeds::Tracks {
            return bad(
                "speeds",
                "tracks would move each animal at its future tracked speed: give noisy or expected"
                    .into(),
            );
        }
        if self.rollouts.is_empty() {
            return bad("rollouts", "give conditioned, free or both".into());
        }
        if self.seeds == 0 || self.seeds > 1024 {
            return bad("seeds", format!("{} is out of range 1..=1024", self.seeds));
        }
        if self.observe < 2 {
            return bad("observe", "must be ≥ 2 (a start needs its velocity)".into());
        }
        if !(2..=10_000).contains(&self.blocks) {
            return bad(
                "blocks",
                format!("{} is out of range 2..=10000", self.blocks),
            );
        }
        for (k, v) in [
            ("stride", self.stride),
            ("free_run", self.free_run),
            ("still", self.still),
        ] {
            if !(v.is_finite() && (0.0..=3600.0).contains(&v)) {
                return bad(k, format!("{v} is out of range 0..=3600 s"));
            }
        }
        crate::herd::guidance::check_guidance_scale(self.guidance_scale)
    }
}

/// Sums of displacement errors per horizon and block.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sums {
    /// `[horizon][block]`: (Σ ADE, Σ FDE, samples).
    pub cells: Vec<Vec<(f64, f64, usize)>>,
}

impl Sums {
    fn new(horizons: usize, blocks: usize) -> Self {
        Sums {
            cells: vec![vec![(0.0, 0.0, 0); blocks]; horizons],
        }
    }

    /// (ADE, FDE, samples) of horizon `h` over every block.
    pub fn total(&self, h: usize) -> (f64, f64, usize) {
        let (a, f, n) = self.cells[h]
            .iter()
            .fold((0.0, 0.0, 0), |s, c| (s.0 + c.0, s.1 + c.1, s.2 + c.2));
        (a / n.max(1) as f64, f / n.max(1) as f64, n)
    }

    /// (ADE, FDE) of horizon `h` per block holding samples (`None` for an empty block).
    pub fn per_block(&self, h: usize) -> Vec<Option<(f64, f64)>> {
        self.cells[h]
            .iter()
            .map(|c| (c.2 > 0).then(|| (c.0 / c.2 as f64, c.1 / c.2 as f64)))
            .collect()
    }
}

/// The windows of a clip's scored frames: every `stride` frames from the first frame with a
/// frame before it; each rolled out for the longest horizon that fits.
fn windows(clip: &TrackClip, index: usize, steps: &[usize], stride: usize) -> Vec<Window> {
    let (a, b) = (
        clip.frames.start.max(1),
        clip.frames.end.min(clip.tracks.len()),
    );
    let longest = steps.iter().copied().max().unwrap_or(1);
    (a..b)
        .step_by(stride.max(1))
        .filter(|&f0| f0 < b - 1)
        .map(|f0| Window {
            clip: index,
            start: f0,
            steps: longest.min(b - 1 - f0),
        })
        .collect()
}

/// Whether `id` is tracked in every frame of `range`.
fn tracked(clip: &TrackClip, id: u64, range: std::ops::Range<usize>) -> bool {
    range.into_iter().all(|f| clip.tracks.pos(f, id).is_some())
}

/// A window's block among `blocks` over the clip's scored frames.
fn block(clip: &TrackClip, f0: usize, blocks: usize) -> usize {
    let span = clip.frames.end.saturating_sub(clip.frames.start).max(1);
    ((f0.saturating_sub(clip.frames.start)) * blocks / span).min(blocks - 1)
}

/// Adds a window's errors to `sums`: `at(k, i)` is animal i's predicted position after k steps.
fn add_window(
    sums: &mut Sums,
    clip: &TrackClip,
    w: &Window,
    ids: &[u64],
    steps: &[usize],
    cfg: &TrackEvalConfig,
    at: &dyn Fn(usize, usize) -> P2,
) {
    let b = block(clip, w.start, cfg.blocks);
    let seen = (w.start + 1).saturating_sub(cfg.observe)..w.start + 1;
    for (i, &id) in ids.iter().enumerate() {
        if !tracked(clip, id, seen.clone()) {
            continue;
        }
        let mut ade = 0.0;
        for k in 1..=w.steps {
            let Some(t) = clip.tracks.pos(w.start + k, id) else {
                break;
            };
            let p = at(k, i);
            let e = (p[0] - t[0]).hypot(p[1] - t[1]);
            ade += e;
            for (h, &hs) in steps.iter().enumerate() {
                if hs == k {
                    let c = &mut sums.cells[h][b];
                    c.0 += ade / k as f64;
                    c.1 += e;
                    c.2 += 1;
                }
            }
        }
    }
}

/// The noise of window `w` under seed `seed`: the same for every set.
fn window_rng(seed: u64, w: &Window) -> ChaCha8Rng {
    let key = (seed.wrapping_mul(0x9E37_79B9_7F4A_7C15))
        ^ ((w.clip as u64) << 48)
        ^ (w.start as u64).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    ChaCha8Rng::seed_from_u64(key)
}

/// The displacement errors of `params` with `rollout` and seed `seed` over every clip.
pub fn score(
    clips: &[TrackClip],
    params: &Params,
    rollout: Rollout,
    seed: u64,
    cfg: &TrackEvalConfig,
    device: &Device,
) -> Result<Sums> {
    let mut sums = Sums::new(cfg.horizons.len(), cfg.blocks);
    let theta = theta_tensor(&params.to_vec(), device);
    let forces = ForceTensors::new(&theta, &params.constants);
    for (ci, clip) in clips.iter().enumerate() {
        let mut clip = clip.clone();
        clip.model.params = params.clone();
        let fps = clip.tracks.fps;
        let steps: Vec<usize> = cfg.horizons.iter().map(|&h| steps_of(h, fps)).collect();
        let stride = (cfg.stride * fps).round() as usize;
        for w in windows(&clip, ci, &steps, stride) {
            let mut rng = window_rng(seed, &w);
            let mut path: Vec<Vec<P2>> = Vec::with_capacity(w.steps);
            let decide = Decide::Live {
                rng: &mut rng,
                record: None,
            };
            let ids = roll(
                &clip,
                &w,
                rollout,
                cfg.speeds,
                &forces,
                device,
                decide,
                |_, s, _| {
                    path.push(s.snapshot()?.pos);
                    Ok(())
                },
            )?;
            if let Some(ids) = ids {
                add_window(&mut sums, &clip, &w, &ids, &steps, cfg, &|k, i| {
                    path[k - 1][i]
                });
            }
        }
    }
    Ok(sums)
}

/// The displacement errors of constant velocity (the velocity into the window's start) on the
/// windows of [`score`].
pub fn constant_velocity(clips: &[TrackClip], cfg: &TrackEvalConfig) -> Sums {
    let mut sums = Sums::new(cfg.horizons.len(), cfg.blocks);
    for (ci, clip) in clips.iter().enumerate() {
        let fps = clip.tracks.fps;
        let steps: Vec<usize> = cfg.horizons.iter().map(|&h| steps_of(h, fps)).collect();
        let stride = (cfg.stride * fps).round() as usize;
        for w in windows(clip, ci, &steps, stride) {
            let rows = clip.starters(w.start);
            let ids: Vec<u64> = rows.iter().map(|r| r.id).collect();
            add_window(&mut sums, clip, &w, &ids, &steps, cfg, &|k, i| {
                let (r, t) = (&rows[i], k as f64 / fps);
                [r.x + r.vx * t, r.y + r.vy * t]
            });
        }
    }
    sums
}

/// The motion samples of free runs of `params` (each `cfg.free_run` long, restarted from the
/// tracked animals) and of the tracks over the same animals and frames: at every simulated frame
/// the animals of the run that are still tracked in it.
pub fn free_run_samples(
    clips: &[TrackClip],
    params: &Params,
    seed: u64,
    cfg: &TrackEvalConfig,
    device: &Device,
) -> Result<(MotionSamples, MotionSamples)> {
    let (mut sim, mut obs) = (MotionSamples::default(), MotionSamples::default());
    let theta = theta_tensor(&params.to_vec(), device);
    let forces = ForceTensors::new(&theta, &params.constants);
    for (ci, clip) in clips.iter().enumerate() {
        let mut clip = clip.clone();
        clip.model.params = params.clone();
        let (fps, t) = (clip.tracks.fps, &clip.tracks);
        let dt = 1.0 / fps;
        let len = steps_of(cfg.free_run, fps);
        let (a, b) = (clip.frames.start.max(1), clip.frames.end.min(t.len()));
        let mut f0 = a;
        while f0 + 1 < b {
            let w = Window {
                clip: ci,
                start: f0,
                steps: len.min(b - 1 - f0),
            };
            let mut rng = window_rng(seed ^ 0xD157, &w);
            let decide = Decide::Live {
                rng: &mut rng,
                record: None,
            };
            let start: Vec<P2> = clip.starters(f0).iter().map(|r| [r.x, r.y]).collect();
            let ids: Vec<u64> = clip.starters(f0).iter().map(|r| r.id).collect();
            let mut last = start.clone();
            let mut last_step: Vec<Option<P2>> = ids
                .iter()
                .map(|&id| t.back_vel(f0, id).map(|v| [v[0] * dt, v[1] * dt]))
                .collect();
            roll(
                &clip,
                &w,
                Rollout::Free,
                Speeds::Noisy,
                &forces,
                device,
                decide,
                |k, s: &HerdState, _| {
                    let f = f0 + k;
                    let pos = s.snapshot()?.pos;
                    let keep: Vec<usize> = (0..ids.len())
                        .filter(|&i| t.pos(f, ids[i]).is_some())
                        .collect();
                    let d = |a: P2, b: P2| Some([a[0] - b[0], a[1] - b[1]]);
                    let step: Vec<Option<P2>> =
                        (0..ids.len()).map(|i| d(pos[i], last[i])).collect();
                    sim.add_frame(
                        &keep.iter().map(|&i| pos[i]).collect::<Vec<_>>(),
                        &keep.iter().map(|&i| step[i]).collect::<Vec<_>>(),
                        &keep.iter().map(|&i| last_step[i]).collect::<Vec<_>>(),
                        dt,
                        cfg.still,
                    );
                    let tstep =
                        |g: usize, id: u64| t.back_vel(g, id).map(|v| [v[0] * dt, v[1] * dt]);
                    obs.add_frame(
                        &keep
                            .iter()
                            .filter_map(|&i| t.pos(f, ids[i]))
                            .collect::<Vec<_>>(),
                        &keep.iter().map(|&i| tstep(f, ids[i])).collect::<Vec<_>>(),
                        &keep
                            .iter()
                            .map(|&i| tstep(f - 1, ids[i]))
                            .collect::<Vec<_>>(),
                        dt,
                        cfg.still,
                    );
                    last = pos;
                    last_step = step;
                    Ok(())
                },
            )?;
            f0 += len;
        }
    }
    Ok((sim, obs))
}

/// The device a track evaluation runs on (no autodiff).
pub fn device(cfg: &TrackEvalConfig) -> Result<Device> {
    cpu_device(cfg.precision)
}
