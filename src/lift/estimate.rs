//! v_target, d_near and d_far from the 2D tracks and the camera, for a user who does not know
//! the birds' speed per frame in world units (issue #50).
//!
//! One camera cannot see a flock's distance: a flock twice as far and twice as fast projects the
//! same (a scale about the camera centre leaves every image and every direction unchanged). So
//! the speed, which sets the lift's distance (`sequence`'s `speed` term), can only come from what
//! birds do, not from geometry. What the image does show, whatever the scale, is how sharply the
//! birds turn: the turning rate Ω of an image track (rad/s, from its velocity and acceleration
//! over `estimate.lag_s`). Birds that turn sharply fly slowly (a bird's lateral acceleration v·Ω
//! is limited); on the two shipped jackdaw flights the speed of 2 s windows falls with their
//! image turning rate in both flights, and a power law v = `coef` · Ω^(−`exponent`) (m/s, Ω in
//! rad/s) fitted to one flight's windows predicts the other's median speed to 11–17 %
//! (RESULTS, leave one out). The defaults are that law fitted to both flights. It is a prior
//! about jackdaw-like birds: for other species give `v_target`, or refit the law.
//!
//! The depth bounds, when absent, bracket the depth at which that speed gives the tracks' median
//! angular speed: D₀ = v / ω, d_near = D₀ / `bounds_factor`, d_far = D₀ · `bounds_factor`.
//!
//! Lengths are metres: the prior is a speed in m/s, so a camera in other units needs
//! `v_target` (and the bounds) given.

use super::observe::Observations;
use super::LiftConfig;
use crate::data::tracks::Units;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::borrow::Cow;

/// Settings of the estimate (`estimate.<key>`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EstimateConfig {
    /// Half the time span of the velocity and acceleration differences, seconds.
    pub lag_s: f64,
    /// The speed law v = coef · Ω^(−exponent), m/s with Ω in rad/s.
    pub coef: f64,
    pub exponent: f64,
    /// The image turning rates the law was fitted on, rad/s: outside, the report says the speed
    /// is extrapolated.
    pub calibrated: [f64; 2],
    /// d_near = D₀ / bounds_factor, d_far = D₀ · bounds_factor.
    pub bounds_factor: f64,
}

impl Default for EstimateConfig {
    fn default() -> Self {
        EstimateConfig {
            lag_s: 0.1,
            coef: 4.948,
            exponent: 0.339,
            calibrated: [0.06, 0.6],
            bounds_factor: 5.0,
        }
    }
}

impl EstimateConfig {
    /// Checks ranges; errors name the key (`estimate.<key>`).
    pub fn check(&self) -> Result<()> {
        for (k, v) in [
            ("lag_s", self.lag_s),
            ("coef", self.coef),
            ("bounds_factor", self.bounds_factor - 1.0),
        ] {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!(
                    "estimate.{k} = {} must be > {}",
                    if k == "bounds_factor" { v + 1.0 } else { v },
                    if k == "bounds_factor" { 1 } else { 0 }
                )));
            }
        }
        if !(self.exponent.is_finite() && (0.0..=3.0).contains(&self.exponent)) {
            return Err(Error::invalid(format!(
                "estimate.exponent = {} must be in [0, 3]",
                self.exponent
            )));
        }
        let c = self.calibrated;
        if !(c[0].is_finite() && c[1].is_finite() && 0.0 < c[0] && c[0] < c[1]) {
            return Err(Error::invalid(format!(
                "estimate.calibrated = [{}, {}] must be 0 < low < high",
                c[0], c[1]
            )));
        }
        Ok(())
    }
}

/// Where a value of the lift came from.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Source {
    Given,
    Estimated,
}

/// What the estimate found (recorded in the lift report).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Estimate {
    /// Median image turning rate Ω of the tracks, rad/s, and the samples it is the median of.
    pub turn_rate: f64,
    pub samples: usize,
    /// Median angular speed of the tracks (rad/s, on the unit sphere of view directions).
    pub angular_speed: f64,
    /// The speed law's value at Ω, m/s (also when v_target was given).
    pub speed_mps: f64,
    /// Whether Ω lies outside `estimate.calibrated` (the speed is then extrapolated).
    pub extrapolated: bool,
    /// Median turning rate of the tracks laid on a horizontal plane ([`plane_turning`]), rad/s;
    /// None when too few rays leave the horizon.
    #[serde(default)]
    pub plane_turn_rate: Option<f64>,
    /// `turn_rate` / `plane_turn_rate`: how much more sharply the image tracks turn than their
    /// paths on the horizontal plane. Well above 1, the image turns are foreshortening of birds
    /// flying along the line of sight, not turns the speed prior knows.
    #[serde(default)]
    pub foreshortening: Option<f64>,
    /// D₀ = speed / angular speed, world units.
    pub depth_guess: f64,
    /// The values the lift used, world units (per frame for v_target), and where they came from.
    pub v_target: f64,
    pub v_target_source: Source,
    pub d_near: f64,
    pub d_far: f64,
    pub bounds_source: Source,
}

/// The observation `k` steps after (k > 0) or before (k < 0) `i` along its bird's segment.
fn step(obs: &Observations, mut i: usize, k: i64) -> Option<usize> {
    for _ in 0..k.unsigned_abs() {
        i = if k > 0 { obs.next[i]? } else { obs.prev[i]? };
    }
    Some(i)
}

fn unit(r: [f64; 3]) -> [f64; 3] {
    let l = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
    [r[0] / l, r[1] / l, r[2] / l]
}

fn median(mut v: Vec<f64>) -> Option<f64> {
    v.sort_by(f64::total_cmp);
    (!v.is_empty()).then(|| v[v.len() / 2])
}

/// |v × a| / |v|² of the 2D points `p(j)` at observation `i` (v, a the central differences over
/// `lag` frames, 2·lag/fps apart); None without a whole ±2·lag window, a point `p` refuses, or
/// motion.
fn turn_at(
    obs: &Observations,
    i: usize,
    lag: i64,
    p: &dyn Fn(usize) -> Option<[f64; 2]>,
) -> Option<f64> {
    let dt = 2.0 * lag as f64 / obs.fps;
    let [a, b, c, e] = [-2, -1, 1, 2].map(|k| step(obs, i, k * lag));
    let [a, b, c, e, m] = [a?, b?, c?, e?, i].map(p);
    let [a, b, c, e, m] = [a?, b?, c?, e?, m?];
    let v = [(c[0] - b[0]) / dt, (c[1] - b[1]) / dt];
    let acc = [
        (e[0] - 2.0 * m[0] + a[0]) / (dt * dt),
        (e[1] - 2.0 * m[1] + a[1]) / (dt * dt),
    ];
    let s = v[0] * v[0] + v[1] * v[1];
    (s > 0.0).then(|| (v[0] * acc[1] - v[1] * acc[0]).abs() / s)
}

/// The frame count of `lag_s` at the tracks' rate (at least 1).
fn lag_frames(obs: &Observations, lag_s: f64) -> i64 {
    ((lag_s * obs.fps).round() as i64).max(1)
}

/// Median image turning rate (rad/s) and angular speed (rad/s) of the tracks, and the number of
/// observations with a whole ±2·lag window. Turning rate of a track at i: |v × a| / |v|² with
/// v, a the central differences over `lag` frames of its pixel positions.
pub fn turning(obs: &Observations, lag_s: f64) -> (Option<f64>, Option<f64>, usize) {
    let lag = lag_frames(obs, lag_s);
    let dt = 2.0 * lag as f64 / obs.fps;
    let pixel = |j: usize| Some(obs.pixel[j]);
    let (mut om, mut w) = (Vec::new(), Vec::new());
    for i in 0..obs.len() {
        let (Some(b), Some(c)) = (step(obs, i, -lag), step(obs, i, lag)) else {
            continue;
        };
        if step(obs, i, -2 * lag).is_none() || step(obs, i, 2 * lag).is_none() {
            continue;
        }
        om.extend(turn_at(obs, i, lag, &pixel));
        let (rb, rc) = (unit(obs.ray[b]), unit(obs.ray[c]));
        let d = [rc[0] - rb[0], rc[1] - rb[1], rc[2] - rb[2]];
        w.push((d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() / dt);
    }
    let n = om.len();
    (median(om), median(w), n)
}

/// Smallest |sine| of a ray's elevation that [`plane_turning`] lays on the horizontal plane.
const MIN_PLANE_ELEVATION: f64 = 0.02;

/// Median turning rate (rad/s) of the tracks laid on a horizontal plane (world z up, the camera
/// convention): each viewing ray r meets the plane one unit above (or below) the camera at
/// (r_x / r_z, r_y / r_z), whatever the plane's height, so the rate does not depend on the
/// flock's distance. A flock that turns in the horizontal plane turns there as it does in the
/// world; foreshortening does not bend it. Rays within `MIN_PLANE_ELEVATION` (0.02 rad) of the horizon
/// are left out. None with fewer than [`MIN_SAMPLES`] rates.
pub fn plane_turning(obs: &Observations, lag_s: f64) -> Option<f64> {
    let lag = lag_frames(obs, lag_s);
    let plane = |j: usize| {
        let r = obs.ray[j];
        let l = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
        (r[2].abs() > MIN_PLANE_ELEVATION * l).then(|| [r[0] / r[2], r[1] / r[2]])
    };
    let om: Vec<f64> = (0..obs.len())
        .filter_map(|i| turn_at(obs, i, lag, &plane))
        .collect();
    (om.len() >= MIN_SAMPLES).then(|| median(om)).flatten()
}

/// `cfg` itself when v_target and both bounds are set, else `cfg` resolved ([`resolve`]): what
/// the library's entry points call first.
pub fn ensure<'a>(obs: &Observations, cfg: &'a LiftConfig) -> Result<Cow<'a, LiftConfig>> {
    Ok(if cfg.resolved() {
        Cow::Borrowed(cfg)
    } else {
        Cow::Owned(resolve(obs, cfg)?.0)
    })
}

/// Fewest turning-rate samples the estimate accepts.
pub const MIN_SAMPLES: usize = 20;

/// `cfg` with v_target and the bounds filled in where absent (module docs), and what was found.
/// Errors, naming the key to give, when a value is absent and cannot be estimated.
pub fn resolve(obs: &Observations, cfg: &LiftConfig) -> Result<(LiftConfig, Estimate)> {
    let e = &cfg.estimate;
    e.check()?;
    let (turn, ang, samples) = turning(obs, e.lag_s);
    let plane = plane_turning(obs, e.lag_s).filter(|p| *p > 0.0);
    let need_speed = cfg.v_target.is_none();
    let need_bounds = cfg.d_near.is_none() || cfg.d_far.is_none();
    let fail = |why: String| -> Error {
        let key = if need_speed {
            "v_target"
        } else {
            "d_near/d_far"
        };
        Error::invalid(format!("{key} not given and {why}: give {key}"))
    };
    if (need_speed || need_bounds) && obs.camera.units != Units::Metres {
        return Err(fail(format!(
            "the camera is in '{}' (the speed prior is in m/s)",
            obs.camera.units.as_str()
        )));
    }
    let turn = match turn {
        Some(t) if samples >= MIN_SAMPLES && t > 0.0 => t,
        _ if !(need_speed || need_bounds) => f64::NAN,
        _ => {
            return Err(fail(format!(
                "only {samples} track points have {:.2} s of track on both sides (at least \
                 {MIN_SAMPLES} needed to measure how the birds turn)",
                2.0 * e.lag_s
            )))
        }
    };
    let clamped = turn.clamp(0.5 * e.calibrated[0], 2.0 * e.calibrated[1]);
    let speed_mps = e.coef * clamped.powf(-e.exponent);
    let v_target = cfg.v_target.unwrap_or(speed_mps / obs.fps);
    let ang = ang.unwrap_or(f64::NAN);
    let depth_guess = v_target * obs.fps / ang;
    let mut out = cfg.clone();
    out.v_target = Some(v_target);
    if need_bounds {
        if !(depth_guess.is_finite() && depth_guess > 0.0) {
            return Err(fail("the tracks do not move in the image".into()));
        }
        let k = e.bounds_factor;
        out.d_near = Some(cfg.d_near.unwrap_or(depth_guess / k));
        out.d_far = Some(cfg.d_far.unwrap_or(depth_guess * k));
        if out.near() >= out.far() {
            return Err(Error::invalid(format!(
                "d_near = {} must be below d_far = {} (one of them estimated: give both)",
                out.near(),
                out.far()
            )));
        }
    }
    out.check()?;
    let est = Estimate {
        turn_rate: turn,
        samples,
        angular_speed: ang,
        speed_mps,
        extrapolated: !(e.calibrated[0]..=e.calibrated[1]).contains(&turn),
        plane_turn_rate: plane,
        foreshortening: plane.map(|p| turn / p).filter(|f| f.is_finite()),
        depth_guess,
        v_target,
        v_target_source: if need_speed {
            Source::Estimated
        } else {
            Source::Given
        },
        d_near: out.near(),
        d_far: out.far(),
        bounds_source: if need_bounds {
            Source::Estimated
        } else {
            Source::Given
        },
    };
    Ok((out, est))
}
