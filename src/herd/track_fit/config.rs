//! The settings of a track fit ([`TrackFitConfig`]) and the two rollouts ([`Rollout`]).

use crate::backend::Precision;
use crate::error::{check_counts, Error, Result};
use crate::herd::guidance::check_guidance_scale;
use crate::herd::sim::ForceKernel;
use crate::optim::Optimizer;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// How the animals of a window are rolled out.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Rollout {
    /// Each animal is stepped by the model among its neighbours replayed from their tracks (the
    /// calibration of pedestrian studies, Johansson, Helbing & Shukla 2007): its error is its own
    /// response to where the others really were. Not a forecast: the neighbours' positions are
    /// the future's.
    #[default]
    Conditioned,
    /// Every animal present at the window's start is stepped jointly by the model, neighbours
    /// included: a forecast from the start.
    Free,
}

enum_names!(Rollout { Conditioned = "conditioned", Free = "free" });

/// Whether the tracked animals of a window may lead (§5.1).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Leaders {
    /// No animal leads: every animal turns by eq. 2 under the forces of eq. 3–5, so θ steers
    /// them all. Tracked groups are sparse beside a filmed herd: with the §5.1 rule nearly every
    /// tracked fish and pedestrian has no one in its front cone, leads, and no set differs from
    /// another (measured in docs/notes/2026-12-07-track-rollout-leaders.md).
    #[default]
    Off,
    /// The §5.1 rule as a fit from fields runs it: an animal with at most
    /// `leader_max_neighbours` visible neighbours in its front cone takes the clip's guidance
    /// direction (its cell's mean velocity, of frames no later than the window's start) and is
    /// not scored in training; a clip's synthetic herd (`synth`) is made this way.
    Field,
}

enum_names!(Leaders { Off = "off", Field = "field" });

/// Where a rolled-out animal's speed comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Speeds {
    /// Each animal moves at its tracked speed into every frame (eq. 6 where it is not tracked):
    /// the position error is then the direction's alone, what θ steers.
    Tracks,
    /// Eq. 6 without its noise (ξ = 0): each animal at its expected speed, so the objective's
    /// minimum does not favour sets that damp the noise's spread
    /// (E|X(θ) − x|² = |E X(θ) − x|² + Var X(θ)).
    #[default]
    Expected,
    /// Eq. 6 with its noise ξ, as a simulation runs.
    Noisy,
}

enum_names!(Speeds { Tracks = "tracks", Expected = "expected", Noisy = "noisy" });

/// Settings of a track fit (recorded as `settings` in the fitted set's provenance).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackFitConfig {
    /// How a window's animals are rolled out.
    pub rollout: Rollout,
    /// Window length (s): every window starts from the tracked animals and is scored at each of
    /// its steps; the steps are `round(horizon · fps)`, at least 1.
    pub horizon: f64,
    /// Seconds between the starts of consecutive windows (windows overlap when it is below the
    /// horizon; 0: a window from every frame).
    pub stride: f64,
    /// Weight (BL²) of the heading error |d − d̂|² beside the squared position error (BL²).
    pub heading_weight: f64,
    /// A tracked heading is scored only where the animal moves faster than this (BL/s).
    pub min_speed: f64,
    /// Weight of the spacing term ([`super::spacing`]: mean squared difference, BL², of the
    /// sorted nearest-neighbour distances, simulated against tracked) beside the position
    /// error; 0: off.
    pub spacing_weight: f64,
    pub epochs: usize,
    pub lr: f64,
    pub optimizer: Optimizer,
    /// Frames of each clip learnt from, `start..end` (end exclusive); `0..0`: all.
    pub frames: Range<usize>,
    pub seed: u64,
    pub precision: Precision,
    /// σ (cells) of the smoothing of the clip's momentum into the leaders' guidance
    /// ([`crate::herd::guidance::guidance_field`]).
    pub guidance_scale: f64,
    /// Parameters held at their start value, by name.
    pub frozen: Vec<String>,
    pub force_kernel: ForceKernel,
    /// Size of the random step taken where the gradient vanishes.
    pub zero_grad_step: f64,
    /// The animals' speeds in the training windows (eq. 6's speeds carry no gradient: θ steers
    /// only the directions).
    pub speeds: Speeds,
    /// Learn eq. 6's speed model from the tracks ([`super::speed`]); off: the start set's.
    pub learn_speed: bool,
    /// Whether tracked animals may lead (§5.1), following the clip's guidance.
    pub leaders: Leaders,
    /// Global phase ([`super::global`]): candidate starts (the given one, then a Latin hypercube
    /// over the box), each refined by `start_epochs` epochs; the lowest objective starts the
    /// full fit. 1: the plain fit. The default was chosen on the synthetic recovery clip
    /// (docs/notes/2026-12-07-track-rollout-leaders.md).
    pub starts: usize,
    /// Epochs of each candidate's short fit.
    pub start_epochs: usize,
}

impl Default for TrackFitConfig {
    fn default() -> Self {
        TrackFitConfig {
            rollout: Rollout::Conditioned,
            horizon: 1.0,
            stride: 0.25,
            heading_weight: 1.0,
            min_speed: 0.1,
            spacing_weight: 0.0,
            epochs: 8,
            lr: 0.02,
            optimizer: Optimizer::Adam,
            frames: 0..0,
            seed: 0,
            precision: Precision::F32,
            guidance_scale: crate::herd::guidance::GUIDANCE_SCALE,
            frozen: Vec::new(),
            force_kernel: ForceKernel::Fused,
            zero_grad_step: 0.02,
            speeds: Speeds::Expected,
            learn_speed: true,
            leaders: Leaders::Off,
            starts: 4,
            start_epochs: 2,
        }
    }
}

impl TrackFitConfig {
    /// Checks the settings; errors name the key.
    pub fn check(&self) -> Result<()> {
        check_counts(&[("epochs", self.epochs), ("start_epochs", self.start_epochs)])?;
        if !(1..=64).contains(&self.starts) {
            return Err(Error::config(
                "starts",
                format!("{} is out of range 1..=64", self.starts),
            ));
        }
        check_guidance_scale(self.guidance_scale)?;
        for (key, v, lo, hi) in [
            ("horizon", self.horizon, 1e-9, 3600.0),
            ("stride", self.stride, 0.0, 3600.0),
            ("heading_weight", self.heading_weight, 0.0, 1e6),
            ("spacing_weight", self.spacing_weight, 0.0, 1e6),
            ("min_speed", self.min_speed, 0.0, crate::limits::MAX_SPEED),
            ("lr", self.lr, 1e-12, 1.0),
            ("zero_grad_step", self.zero_grad_step, 0.0, 1.0),
        ] {
            if !(v.is_finite() && v >= lo && v <= hi) {
                return Err(Error::config(key, format!("{v} is out of range")));
            }
        }
        if self.frames.end != 0 && self.frames.end < self.frames.start + 3 {
            return Err(Error::config(
                "frames",
                format!(
                    "{}..{} must span at least 3 frames (a window starts from two)",
                    self.frames.start, self.frames.end
                ),
            ));
        }
        self.frozen_indices().map(|_| ())
    }

    /// The indices of the `frozen` parameters; an unknown name is an error naming `frozen`.
    pub fn frozen_indices(&self) -> Result<Vec<usize>> {
        crate::herd::params::indices_of(&self.frozen, "frozen")
    }

    /// The window's steps at `fps` frames per second.
    pub fn steps(&self, fps: f64) -> usize {
        steps_of(self.horizon, fps)
    }

    /// How a training window is rolled out and scored.
    pub fn scoring(&self) -> Scoring {
        Scoring {
            rollout: self.rollout,
            speeds: self.speeds,
            heading_weight: self.heading_weight,
            min_speed: self.min_speed,
            spacing_weight: self.spacing_weight,
        }
    }

    /// Frames between window starts at `fps` frames per second (at least 1).
    pub fn stride_frames(&self, fps: f64) -> usize {
        ((self.stride * fps).round() as usize).max(1)
    }
}

/// `round(seconds · fps)`, at least 1.
pub fn steps_of(seconds: f64, fps: f64) -> usize {
    ((seconds * fps).round() as usize).max(1)
}

/// How a training window is rolled out and scored.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Scoring {
    pub rollout: Rollout,
    pub speeds: Speeds,
    /// Weight (BL²) of the mean squared heading error.
    pub heading_weight: f64,
    /// Headings are scored where the animal moves faster than this (BL/s).
    pub min_speed: f64,
    /// Weight of the spacing term ([`super::spacing`]); 0: off.
    pub spacing_weight: f64,
}
