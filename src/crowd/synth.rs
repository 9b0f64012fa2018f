//! A small rule-based source crowd for the demo and for users without tracked data: pedestrians
//! walking to goals with a social-force rule (relaxation to a desired velocity plus exponential
//! repulsion from the others, after Helbing et al. 2001 cited in §2). It plays the part of the
//! video in §3: the crowd model learns from its tracks without knowing the rule.

use super::features::V2;
use crate::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
use crate::error::{Error, Result};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Settings of the synthetic corridor crowd.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthConfig {
    /// Corridor length and width (m); walkers enter at x = 0 or x = length.
    pub length: f64,
    pub width: f64,
    /// Walkers entering per second (both directions together).
    pub rate: f64,
    /// Seconds simulated and frames per second.
    pub duration: f64,
    pub fps: f64,
    /// Desired speed mean and spread (m/s).
    pub speed: f64,
    pub speed_sd: f64,
    /// Repulsion strength (m/s²) and range (m).
    pub repulsion: f64,
    pub range: f64,
    /// Relaxation time (s).
    pub tau: f64,
    pub seed: u64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            length: 20.0,
            width: 6.0,
            rate: 1.2,
            duration: 90.0,
            fps: 5.0,
            speed: 1.3,
            speed_sd: 0.2,
            repulsion: 2.0,
            range: 0.5,
            tau: 0.5,
            seed: 0,
        }
    }
}

impl SynthConfig {
    pub fn check(&self) -> Result<()> {
        for (v, k) in [
            (self.length, "length"),
            (self.width, "width"),
            (self.rate, "rate"),
            (self.duration, "duration"),
            (self.fps, "fps"),
            (self.speed, "speed"),
            (self.range, "range"),
            (self.tau, "tau"),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!("synth.{k} = {v} must be > 0")));
            }
        }
        // Physical ranges (issue #47): metres, seconds, walkers per second.
        use crate::limits::{within, FPS_RANGE, MAX_COORD, MAX_SECONDS, MAX_SPEED};
        within("synth.length", self.length, 0.0, MAX_COORD)?;
        within("synth.width", self.width, 0.0, MAX_COORD)?;
        within("synth.rate", self.rate, 0.0, 1e3)?;
        within("synth.duration", self.duration, 0.0, MAX_SECONDS)?;
        within("synth.fps", self.fps, FPS_RANGE.0, FPS_RANGE.1)?;
        within("synth.speed", self.speed, 0.0, MAX_SPEED)?;
        within("synth.range", self.range, 0.0, MAX_COORD)?;
        within("synth.tau", self.tau, 0.0, MAX_SECONDS)?;
        crate::limits::check_memory(
            "synth.duration",
            "the synthetic crowd",
            // rows ≈ frames × walkers in the corridor at once (rate × crossing time)
            self.duration
                * self.fps
                * (self.rate * self.length / self.speed.max(0.1) + 1.0)
                    .min(self.rate * self.duration + 1.0)
                * 64.0,
        )?;
        if !(self.speed_sd >= 0.0 && self.repulsion >= 0.0) {
            return Err(Error::invalid(
                "synth.speed_sd and synth.repulsion must be ≥ 0",
            ));
        }
        Ok(())
    }
}

struct Walker {
    id: u64,
    p: V2,
    v: V2,
    goal_x: f64,
    speed: f64,
}

/// Simulates the corridor and returns its tracks (metres, `fps`).
pub fn corridor(cfg: &SynthConfig) -> Result<Tracks> {
    cfg.check()?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let dt = 1.0 / cfg.fps;
    let sub = 4;
    let h = dt / sub as f64;
    let steps = (cfg.duration * cfg.fps).round() as usize;
    let mut walkers: Vec<Walker> = Vec::new();
    let mut rows = Vec::new();
    let mut next_id = 0u64;
    let mut due = 0.0;
    for t in 0..steps {
        due += cfg.rate * dt;
        while due >= 1.0 {
            due -= 1.0;
            let right = rng.gen_bool(0.5);
            let y = rng.gen_range(0.4..cfg.width - 0.4);
            let speed = (cfg.speed + cfg.speed_sd * (rng.gen::<f64>() * 2.0 - 1.0) * 1.7).max(0.3);
            let (x, gx) = if right {
                (0.0, cfg.length)
            } else {
                (cfg.length, 0.0)
            };
            walkers.push(Walker {
                id: next_id,
                p: [x, y],
                v: [(gx - x).signum() * speed, 0.0],
                goal_x: gx,
                speed,
            });
            next_id += 1;
        }
        for w in &walkers {
            rows.push(TrackRow {
                frame: t as u64,
                time: t as f64 * dt,
                id: w.id,
                pos: [w.p[0], w.p[1], 0.0],
                vel: Some([w.v[0], w.v[1], 0.0]),
                role: None,
            });
        }
        for _ in 0..sub {
            let pos: Vec<V2> = walkers.iter().map(|w| w.p).collect();
            for (i, w) in walkers.iter_mut().enumerate() {
                let dir = [(w.goal_x - w.p[0]).signum(), 0.0];
                let mut a = [
                    (dir[0] * w.speed - w.v[0]) / cfg.tau,
                    (dir[1] * w.speed - w.v[1]) / cfg.tau,
                ];
                for (j, q) in pos.iter().enumerate() {
                    if j == i {
                        continue;
                    }
                    let d = [w.p[0] - q[0], w.p[1] - q[1]];
                    let r = d[0].hypot(d[1]).max(1e-6);
                    if r < 3.0 {
                        let f = cfg.repulsion * (-(r - 0.4) / cfg.range).exp();
                        a[0] += f * d[0] / r;
                        a[1] += f * d[1] / r;
                    }
                }
                // The walls of the corridor push back within 0.5 m.
                for (yw, s) in [(0.0, 1.0), (cfg.width, -1.0)] {
                    let r = (w.p[1] - yw).abs().max(1e-3);
                    a[1] += s * cfg.repulsion * (-(r - 0.2) / cfg.range).exp();
                }
                w.v[0] += a[0] * h;
                w.v[1] += a[1] * h;
                let s = w.v[0].hypot(w.v[1]);
                if s > 1.5 * w.speed {
                    w.v = [w.v[0] * 1.5 * w.speed / s, w.v[1] * 1.5 * w.speed / s];
                }
                w.p[0] += w.v[0] * h;
                w.p[1] = (w.p[1] + w.v[1] * h).clamp(0.05, cfg.width - 0.05);
            }
        }
        walkers.retain(|w| (w.goal_x - w.p[0]) * (w.goal_x - cfg.length / 2.0) > 0.0);
    }
    let mut meta = TracksMeta::new(Units::Metres, cfg.fps, 2);
    meta.provenance =
        serde_json::json!({"source": "herdfit crowd synth (social-force corridor)", "config": cfg});
    Tracks::new(meta, rows)
}
