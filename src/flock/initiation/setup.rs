//! The initiation's settings, bird state, random starts and target shape (Klotsman & Tal §6).

use super::super::extract::Side;
use crate::error::{Error, Result};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// Settings of the initiation.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct InitiationConfig {
    /// Decisions (and output frames) per second.
    pub fps: f64,
    /// Cruise speed, wingspans/s.
    pub speed: f64,
    /// Visual volume per eye, degrees either side of the heading (the paper: 90°).
    pub eye_field_deg: f64,
    /// A bird keeps its reference while it sees it within the visual volume widened by this
    /// (degrees per eye; hysteresis of the chain rules, `ARCHITECTURE.md`).
    pub keep_margin_deg: f64,
    /// Reference-bird volume per eye, degrees (the paper: 0.35π = 63°).
    pub reference_field_deg: f64,
    /// Margin of the HPR flipping sphere beyond the farthest bird, wingspans (the paper's R =
    /// b/2).
    pub hpr_pad: f64,
    /// |K| of eq. 5 (the paper: 0.06).
    pub k: f64,
    /// α of eq. 6 (the paper: 0.2).
    pub alpha: f64,
    /// Separation threshold, wingspans (the paper: 10 b).
    pub separation_distance: f64,
    /// Eq. 6's max(r, 1) is capped at this (wingspans): a bird farther from its target turns as
    /// fast as one at this distance. Without the cap a bird that overshoots turns ever more
    /// slowly as it recedes and never comes back (RESULTS.md §3).
    pub turn_distance: f64,
    /// Steering aims this far (wingspans) ahead of the target position along the reference's
    /// direction (eq. 6's Δd only; eq. 5's r and the sign of K use the target itself): a bird
    /// that overshoots its place slows down instead of turning back. 0: the paper's rule.
    pub look_ahead: f64,
    /// Cap on speed changes, wingspans/s².
    pub max_speed_change: f64,
    /// Cap on turns, degrees/s.
    pub max_turn_deg: f64,
    /// Speed limits as fractions of the cruise speed.
    pub min_speed: f64,
    pub max_speed: f64,
    /// Converged: mean distance to the target positions at most this (wingspans) ...
    pub converge_distance: f64,
    /// ... for this long (seconds).
    pub hold: f64,
    /// Give up after this long (seconds).
    pub max_time: f64,
    /// Random starts: birds uniform in a square of side `start_spread · √N` wingspans ...
    pub start_spread: f64,
    /// ... heading within ± this of the migration direction (degrees), speed 0.8–1.2 × cruise.
    pub start_heading_deg: f64,
}

impl Default for InitiationConfig {
    fn default() -> Self {
        InitiationConfig {
            fps: 25.0,
            speed: 10.0,
            eye_field_deg: 90.0,
            keep_margin_deg: 90.0,
            reference_field_deg: 63.0,
            hpr_pad: 0.5,
            k: 0.06,
            alpha: 0.2,
            separation_distance: 10.0,
            turn_distance: 5.0,
            look_ahead: 3.0,
            max_speed_change: 4.0,
            max_turn_deg: 90.0,
            min_speed: 0.6,
            max_speed: 1.6,
            converge_distance: 0.5,
            hold: 2.0,
            max_time: 60.0,
            start_spread: 3.0,
            start_heading_deg: 60.0,
        }
    }
}

impl InitiationConfig {
    /// Checks the settings; errors name the config key.
    pub fn check(&self) -> Result<()> {
        let positive = [
            ("fps", self.fps),
            ("speed", self.speed),
            ("eye_field_deg", self.eye_field_deg),
            ("reference_field_deg", self.reference_field_deg),
            ("hpr_pad", self.hpr_pad),
            ("alpha", self.alpha),
            ("separation_distance", self.separation_distance),
            ("turn_distance", self.turn_distance),
            ("max_speed_change", self.max_speed_change),
            ("max_turn_deg", self.max_turn_deg),
            ("min_speed", self.min_speed),
            ("converge_distance", self.converge_distance),
            ("max_time", self.max_time),
            ("start_spread", self.start_spread),
        ];
        for (k, v) in positive {
            if !(v.is_finite() && v > 0.0) {
                return Err(Error::invalid(format!("{k} = {v} must be > 0")));
            }
            // Wingspans, seconds, degrees and their rates: beyond a million none is physical.
            crate::limits::within(k, v, 0.0, 1e6)?;
        }
        if !(self.k.is_finite() && self.k >= 0.0) {
            return Err(Error::invalid(format!("k = {} must be ≥ 0", self.k)));
        }
        if !(self.look_ahead.is_finite() && self.look_ahead >= 0.0) {
            return Err(Error::invalid(format!(
                "look_ahead = {} must be ≥ 0",
                self.look_ahead
            )));
        }
        if !(self.keep_margin_deg.is_finite() && self.keep_margin_deg >= 0.0) {
            return Err(Error::invalid(format!(
                "keep_margin_deg = {} must be ≥ 0",
                self.keep_margin_deg
            )));
        }
        if !(self.hold.is_finite() && self.hold >= 0.0) {
            return Err(Error::invalid(format!("hold = {} must be ≥ 0", self.hold)));
        }
        if !(self.max_speed.is_finite() && self.max_speed > self.min_speed) {
            return Err(Error::invalid(format!(
                "max_speed = {} must exceed min_speed = {}",
                self.max_speed, self.min_speed
            )));
        }
        if self.eye_field_deg > 180.0 || self.reference_field_deg > self.eye_field_deg {
            return Err(Error::invalid(format!(
                "reference_field_deg = {} must be within eye_field_deg = {} ≤ 180",
                self.reference_field_deg, self.eye_field_deg
            )));
        }
        if !(0.0..=180.0).contains(&self.start_heading_deg) {
            return Err(Error::invalid(format!(
                "start_heading_deg = {} must be in [0, 180]",
                self.start_heading_deg
            )));
        }
        Ok(())
    }
}

/// One bird's state.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Bird {
    /// Position, wingspans.
    pub pos: [f64; 2],
    /// Direction angle θ (d = (sin θ, cos θ)).
    pub theta: f64,
    /// Speed, wingspans per step.
    pub v: f64,
}

impl Bird {
    /// Unit direction.
    pub fn dir(&self) -> [f64; 2] {
        [self.theta.sin(), self.theta.cos()]
    }
}

/// Seeded random start (see [`InitiationConfig::start_spread`]).
pub fn random_start(n: usize, cfg: &InitiationConfig, rng: &mut impl Rng) -> Vec<Bird> {
    let side = cfg.start_spread * (n as f64).sqrt();
    let v = cfg.speed / cfg.fps;
    let h = cfg.start_heading_deg.to_radians();
    (0..n)
        .map(|_| Bird {
            pos: [
                rng.gen_range(-0.5..0.5) * side,
                rng.gen_range(-0.5..0.5) * side,
            ],
            theta: if h > 0.0 { rng.gen_range(-h..=h) } else { 0.0 },
            v: v * rng.gen_range(0.8..1.2),
        })
        .collect()
}

/// The target shape's chains: slot 0 the leader, `nl` left slots from the leader outward, then
/// `nr` right slots.
#[derive(Clone, Debug)]
pub struct Target {
    pub pos: Vec<[f64; 2]>,
    pub nl: usize,
    pub nr: usize,
}

impl Target {
    /// The slot after `t` on side `s` (None beyond the end of the chain).
    pub fn next(&self, t: usize, s: Side) -> Option<usize> {
        let (start, len) = match s {
            Side::Left => (1, self.nl),
            Side::Right => (1 + self.nl, self.nr),
        };
        if t == 0 {
            return (len > 0).then_some(start);
        }
        let rank = t.checked_sub(start).filter(|&r| r < len)?;
        (rank + 1 < len).then_some(t + 1)
    }

    /// The target distance from slot `t` to the bird after it on side `s`; beyond the end of a
    /// chain, the chain's last gap again.
    pub fn delta(&self, t: Option<usize>, next: Option<usize>, s: Side) -> [f64; 2] {
        match (t, next) {
            (Some(a), Some(b)) => [
                self.pos[b][0] - self.pos[a][0],
                self.pos[b][1] - self.pos[a][1],
            ],
            _ => {
                let (start, len) = match s {
                    Side::Left => (1, self.nl),
                    Side::Right => (1 + self.nl, self.nr),
                };
                let sign = if s == Side::Left { -1.0 } else { 1.0 };
                if len == 0 {
                    return [sign, -1.0];
                }
                let end = start + len - 1;
                let prev = if len > 1 { end - 1 } else { 0 };
                let d = [
                    self.pos[end][0] - self.pos[prev][0],
                    self.pos[end][1] - self.pos[prev][1],
                ];
                [sign * d[0].abs(), d[1]]
            }
        }
    }
}
