//! Stage 4: synthetic ground truth (thesis §4.1) — a 3D boids flock (Reynolds' separation,
//! alignment and cohesion) with homing on a moving target, seen by a ground observer's camera:
//! 2D pixel tracks to lift, with the true 3D tracks and the camera beside them.
//!
//! One step of bird i (Δt = 1/fps), neighbours j within `r_neighbour`:
//! `a = k_sep Σ_{d_ij < r_sep} (b_i − b_j)/d_ij² + k_align (v̄ − v_i) + k_cohesion (b̄ − b_i) +
//! k_home (cruise · unit(target − b_i) − v_i)`, |a| ≤ `a_max`, then
//! `v ← v + a Δt` with the speed kept in [0.6, 1.4] · cruise, `b ← b + v Δt`. The target circles
//! the origin at `altitude` (radius `orbit_radius`, one turn per `orbit_period` s) and bobs up
//! and down by a fifth of the radius, so the flock turns, climbs and dives.

use super::observe::project_tracks;
use crate::data::camera::Camera;
use crate::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
use crate::error::{Error, Result};
use crate::progress::Progress;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

/// Settings of the synthetic flock and of its observer (metres, seconds).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BoidsConfig {
    pub birds: usize,
    pub frames: usize,
    pub fps: f64,
    pub seed: u64,
    /// Cruise speed (m/s).
    pub cruise: f64,
    pub r_sep: f64,
    pub r_neighbour: f64,
    pub k_sep: f64,
    pub k_align: f64,
    pub k_cohesion: f64,
    pub k_home: f64,
    /// Largest acceleration (m/s²).
    pub a_max: f64,
    pub orbit_radius: f64,
    pub orbit_period: f64,
    pub altitude: f64,
    /// The observer: horizontal distance from the orbit's centre (on −y), eye height, image
    /// size and horizontal field of view (degrees); it looks at the orbit's centre.
    pub observer_distance: f64,
    pub observer_height: f64,
    pub width: u32,
    pub height: u32,
    pub hfov: f64,
    /// Drop points outside the image (birds then leave and enter the view); off: every point
    /// must be in view.
    pub crop: bool,
}

impl Default for BoidsConfig {
    fn default() -> Self {
        BoidsConfig {
            birds: 30,
            frames: 600,
            fps: 30.0,
            seed: 1,
            cruise: 10.0,
            r_sep: 2.0,
            r_neighbour: 10.0,
            k_sep: 20.0,
            k_align: 1.5,
            k_cohesion: 0.3,
            k_home: 0.4,
            a_max: 15.0,
            orbit_radius: 40.0,
            orbit_period: 30.0,
            altitude: 40.0,
            observer_distance: 120.0,
            observer_height: 1.7,
            width: 1280,
            height: 720,
            hfov: 60.0,
            crop: true,
        }
    }
}

impl BoidsConfig {
    /// The flock of `herdfit demo`, RESULTS.md §5 and the tests: 12 birds over 150 frames seen
    /// through a 40° view, so that birds leave and enter it.
    pub fn demo() -> Self {
        BoidsConfig {
            birds: 12,
            frames: 150,
            hfov: 40.0,
            ..BoidsConfig::default()
        }
    }

    /// Checks ranges; errors name the key.
    pub fn check(&self) -> Result<()> {
        if self.birds < 2 || self.birds > 100_000 {
            return Err(Error::invalid(format!(
                "birds = {} must be in 2..=100000",
                self.birds
            )));
        }
        if self.frames < 3 || self.frames > 10_000_000 {
            return Err(Error::invalid(format!(
                "frames = {} must be in 3..=10000000",
                self.frames
            )));
        }
        // Physical ranges (issue #47): metres, seconds and gains within the coordinate limit,
        // every value finite (the one wording of crate::limits).
        use crate::limits::{within, FPS_RANGE, MAX_COORD};
        within("fps", self.fps, FPS_RANGE.0, FPS_RANGE.1)?;
        for (k, v) in [
            ("cruise", self.cruise),
            ("r_sep", self.r_sep),
            ("r_neighbour", self.r_neighbour),
            ("a_max", self.a_max),
            ("orbit_period", self.orbit_period),
            ("observer_distance", self.observer_distance),
        ] {
            within(k, v, 0.0, MAX_COORD)?;
            if v <= 0.0 {
                return Err(Error::invalid(format!("{k} = {v} must be > 0")));
            }
        }
        for (k, v) in [
            ("k_sep", self.k_sep),
            ("k_align", self.k_align),
            ("k_cohesion", self.k_cohesion),
            ("k_home", self.k_home),
            ("orbit_radius", self.orbit_radius),
        ] {
            within(k, v, 0.0, MAX_COORD)?;
        }
        for (k, v) in [
            ("altitude", self.altitude),
            ("observer_height", self.observer_height),
        ] {
            within(k, v, -MAX_COORD, MAX_COORD)?;
        }
        // Every bird in every frame is kept (3D truth, 2D tracks): ~200 bytes a point.
        crate::limits::check_memory(
            "frames",
            "the flock's tracks",
            self.birds as f64 * self.frames as f64 * 200.0,
        )
        .map_err(|e| Error::invalid(e.to_string().replacen(": ", " = ", 1)))?;
        Ok(())
    }

    /// The observer's camera: at (0, −observer_distance, observer_height), looking at
    /// (0, 0, altitude), world z up.
    pub fn camera(&self) -> Result<Camera> {
        let mut c = Camera::look_at(
            Units::Metres,
            self.width,
            self.height,
            self.hfov,
            [0.0, -self.observer_distance, self.observer_height],
            [0.0, 0.0, self.altitude],
            [0.0, 0.0, 1.0],
        )?;
        c.provenance = serde_json::json!({"source": "herdfit lift synth: ground observer"});
        Ok(c)
    }

    /// The homing target at time t (s).
    pub fn target(&self, t: f64) -> [f64; 3] {
        let w = std::f64::consts::TAU / self.orbit_period;
        [
            self.orbit_radius * (w * t).cos(),
            self.orbit_radius * (w * t).sin(),
            self.altitude + 0.2 * self.orbit_radius * (1.7 * w * t).sin(),
        ]
    }
}

/// A synthetic flock: the truth, what the camera sees, and the camera.
#[derive(Clone, Debug)]
pub struct Synthetic {
    /// True 3D tracks (metres, z up).
    pub truth: Tracks,
    /// The 2D pixel tracks of the points in view.
    pub tracks: Tracks,
    /// True depth of each row of `tracks`.
    pub depth: Vec<f64>,
    pub camera: Camera,
}

type V3 = [f64; 3];

fn clamp_norm(a: V3, max: f64) -> V3 {
    let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
    if n > max {
        a.map(|c| c * max / n)
    } else {
        a
    }
}

/// One boids step for every bird (see the module docs).
fn step(cfg: &BoidsConfig, b: &mut [V3], v: &mut [V3], target: V3, dt: f64) {
    let n = b.len();
    let acc: Vec<V3> = (0..n)
        .map(|i| {
            let (mut sep, mut vbar, mut bbar) = ([0.0; 3], [0.0; 3], [0.0; 3]);
            let mut k = 0.0;
            for j in 0..n {
                if j == i {
                    continue;
                }
                let off = [0, 1, 2].map(|c| b[i][c] - b[j][c]);
                let d2 = off.iter().map(|x| x * x).sum::<f64>().max(1e-6);
                if d2 < cfg.r_sep * cfg.r_sep {
                    (0..3).for_each(|c| sep[c] += off[c] / d2);
                }
                if d2 < cfg.r_neighbour * cfg.r_neighbour {
                    k += 1.0;
                    (0..3).for_each(|c| {
                        vbar[c] += v[j][c];
                        bbar[c] += b[j][c];
                    });
                }
            }
            let to = [0, 1, 2].map(|c| target[c] - b[i][c]);
            let tn = to.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-9);
            let a = [0, 1, 2].map(|c| {
                let flock = if k > 0.0 {
                    cfg.k_align * (vbar[c] / k - v[i][c]) + cfg.k_cohesion * (bbar[c] / k - b[i][c])
                } else {
                    0.0
                };
                cfg.k_sep * sep[c] + flock + cfg.k_home * (cfg.cruise * to[c] / tn - v[i][c])
            });
            clamp_norm(a, cfg.a_max)
        })
        .collect();
    for i in 0..n {
        let mut vi = [0, 1, 2].map(|c| v[i][c] + acc[i][c] * dt);
        let s = vi.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-9);
        let want = s.clamp(0.6 * cfg.cruise, 1.4 * cfg.cruise);
        vi = vi.map(|c| c * want / s);
        v[i] = vi;
        b[i] = [0, 1, 2].map(|c| b[i][c] + vi[c] * dt);
    }
}

/// Simulates the flock of `cfg` and projects it through its observer's camera.
pub fn synth_flock(cfg: &BoidsConfig, progress: &mut dyn Progress) -> Result<Synthetic> {
    cfg.check()?;
    let camera = cfg.camera()?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed);
    let dt = 1.0 / cfg.fps;
    // Start: a loose ball near the target, heading along the orbit.
    let t0 = cfg.target(0.0);
    let spread = (cfg.birds as f64).cbrt() * cfg.r_sep * 1.5;
    let mut b: Vec<V3> = (0..cfg.birds)
        .map(|_| {
            [0, 1, 2]
                .map(|c| t0[c] + rng.gen_range(-spread..spread) - if c == 1 { 10.0 } else { 0.0 })
        })
        .collect();
    let mut v: Vec<V3> = (0..cfg.birds)
        .map(|_| {
            [
                rng.gen_range(-1.0..1.0),
                cfg.cruise + rng.gen_range(-1.0..1.0),
                rng.gen_range(-0.5..0.5),
            ]
        })
        .collect();
    let mut rows = Vec::with_capacity(cfg.birds * cfg.frames);
    progress.start("boids", cfg.frames as u64);
    for f in 0..cfg.frames {
        let t = f as f64 * dt;
        if f > 0 {
            step(cfg, &mut b, &mut v, cfg.target(t), dt);
        }
        for i in 0..cfg.birds {
            rows.push(TrackRow {
                frame: f as u64,
                time: t,
                id: i as u64,
                pos: b[i],
                vel: Some(v[i]),
                role: None,
            });
        }
        progress.inc(1);
    }
    progress.finish();
    let mut meta = TracksMeta::new(Units::Metres, cfg.fps, 3);
    meta.provenance =
        serde_json::json!({"source": "herdfit lift synth (boids with homing)", "settings": cfg});
    let truth = Tracks::new(meta, rows)?;
    let (tracks, depth) = project_tracks(&truth, &camera, cfg.crop)?;
    Ok(Synthetic {
        truth,
        tracks,
        depth,
        camera,
    })
}
