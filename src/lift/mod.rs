//! LIFT — 3D flocks from 2D tracks (Che-An Lin, "Predicting 3D Bird Flock Motion From 2D
//! Projection", master's thesis, University of Tokyo, 2019; `papers/bird-flock-3d-from-2d.md`).
//!
//! From 2D tracks of birds seen by one static pinhole camera, find every bird's depth d_n^f in
//! every frame; each 3D position `b = C + d · ray` (eq. 1.1) projects exactly onto its track.
//! Stages, one file each:
//! 1. [`observe`] — tracks + camera → observations (rays, segments, frames); the virtual camera
//!    that projects 3D tracks into 2D ones.
//! 2. [`frame`] — the thesis's frame-by-frame optimisation (§3.3–3.5, Algorithms 1–3).
//! 3. [`sequence`] — the whole-sequence optimisation (§5's future work) by L-BFGS with a
//!    hand-derived gradient (burn autodiff as its reference, `autodiff`), started from the
//!    frame-by-frame depths.
//! 4. [`boids`] — a synthetic 3D boids flock with homing (§4.1) seen by a ground observer: 2D
//!    tracks with known 3D truth.
//! 5. [`eval`] — depth and position errors against a truth, plausibility checks, baselines.
//! 6. [`render`] — top and side views (PNG, AVI) and a rendered frame of an exported glTF.
//!
//! The thesis's five user parameters (§3.7) keep its names and its Table 4.1 values as defaults
//! (results 1 and 2): λ_t 0.3, λ_f 1.0, w_sep 2, d_sep 0.9; v_target and the depth bounds, when
//! not given, are estimated from the tracks and the camera ([`estimate`]). Lengths are in the
//! camera's world unit; v_target is per frame (the position-based velocity of eq. 3.3).
//!
//! A lift says how far it can be trusted ([`confidence`]): the whole sequence is run again from a
//! second start and the two results compared.

mod autodiff;
pub mod boids;
pub mod confidence;
mod demo;
pub mod estimate;
pub mod eval;
pub mod frame;
mod knots;
pub mod lbfgs;
pub mod observe;
pub mod render;
pub mod sequence;
pub mod terms;

pub use demo::{demo, demo_config, DemoSummary};
pub use observe::{project_tracks, Observations};
pub use sequence::SequenceConfig;

use crate::data::camera::Camera;
use crate::data::tracks::Tracks;
use crate::error::{Error, Result};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

/// Schema tag of lifting reports.
pub const LIFT_REPORT_SCHEMA: &str = "herdfit.lift-report/2";

/// How the depths are found.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Method {
    /// The thesis's frame-by-frame optimisation (§3.5).
    Frame,
    /// Frame by frame, then the whole-sequence optimisation from that start.
    Sequence,
}

/// Settings of a lift. Keys are the thesis's symbols; lengths in the camera's world unit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LiftConfig {
    pub method: Method,
    /// v_target: the birds' speed, world units per frame (eq. 3.3; Algorithm 3); estimated from
    /// the tracks and the camera when absent ([`estimate`]).
    pub v_target: Option<f64>,
    /// λ_t: weight of trajectory smoothness (eq. 3.2, 3.4).
    pub lambda_t: f64,
    /// λ_f: weight of flock-behaviour similarity (eq. 3.2).
    pub lambda_f: f64,
    /// d_sep: the separation neighbourhood (Algorithm 1).
    pub d_sep: f64,
    /// w_sep: separation vs cohesion in the flock target (Algorithm 3).
    pub w_sep: f64,
    /// Depth bounds d_near < d < d_far (eq. 3.5); estimated when absent ([`estimate`]).
    pub d_near: Option<f64>,
    pub d_far: Option<f64>,
    /// Least distance between birds scattered in the first frame (§3.5); d_sep when absent.
    pub min_spacing: Option<f64>,
    /// Seed of the first frame's scatter.
    pub seed: u64,
    /// The whole-sequence stage.
    pub sequence: SequenceConfig,
    /// How v_target and the bounds are estimated when absent.
    pub estimate: estimate::EstimateConfig,
    /// How the lift judges itself (method `sequence`).
    pub confidence: confidence::ConfidenceConfig,
}

impl Default for LiftConfig {
    fn default() -> Self {
        LiftConfig {
            method: Method::Sequence,
            v_target: None,
            lambda_t: 0.3,
            lambda_f: 1.0,
            d_sep: 0.9,
            w_sep: 2.0,
            d_near: None,
            d_far: None,
            min_spacing: None,
            seed: 0,
            sequence: SequenceConfig::default(),
            estimate: estimate::EstimateConfig::default(),
            confidence: confidence::ConfidenceConfig::default(),
        }
    }
}

impl LiftConfig {
    /// Checks every value; errors name the key.
    pub fn check(&self) -> Result<()> {
        for (k, v) in [
            ("v_target", self.v_target),
            ("d_sep", Some(self.d_sep)),
            ("d_near", self.d_near),
            ("d_far", self.d_far),
        ] {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    return Err(Error::invalid(format!("{k} = {v} must be > 0")));
                }
            }
        }
        for (k, v) in [("lambda_t", self.lambda_t), ("lambda_f", self.lambda_f)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!("{k} = {v} must be ≥ 0")));
            }
        }
        if !self.w_sep.is_finite() {
            return Err(Error::invalid(format!(
                "w_sep = {} must be finite",
                self.w_sep
            )));
        }
        // Distances within the coordinate limit; weights within ±1e6 (issue #47: --v-target
        // 1e300 was accepted).
        use crate::limits::{within, MAX_COORD};
        for (k, v) in [
            ("v_target", self.v_target),
            ("d_sep", Some(self.d_sep)),
            ("d_near", self.d_near),
            ("d_far", self.d_far),
        ] {
            if let Some(v) = v {
                within(k, v, 0.0, MAX_COORD)?;
            }
        }
        for (k, v) in [("lambda_t", self.lambda_t), ("lambda_f", self.lambda_f)] {
            within(k, v, 0.0, 1e6)?;
        }
        within("w_sep", self.w_sep, -1e6, 1e6)?;
        if let (Some(a), Some(b)) = (self.d_near, self.d_far) {
            if a >= b {
                return Err(Error::invalid(format!(
                    "d_near = {a} must be below d_far = {b}"
                )));
            }
        }
        if let Some(m) = self.min_spacing {
            if !(m.is_finite() && m >= 0.0) {
                return Err(Error::invalid(format!("min_spacing = {m} must be ≥ 0")));
            }
        }
        self.sequence.check()?;
        self.estimate.check()?;
        self.confidence.check()
    }

    /// v_target, world units per frame, once resolved ([`estimate::resolve`], which every entry
    /// point calls first); NaN before.
    pub fn vt(&self) -> f64 {
        self.v_target.unwrap_or(f64::NAN)
    }

    /// d_near once resolved; NaN before.
    pub fn near(&self) -> f64 {
        self.d_near.unwrap_or(f64::NAN)
    }

    /// d_far once resolved; NaN before.
    pub fn far(&self) -> f64 {
        self.d_far.unwrap_or(f64::NAN)
    }

    /// Whether v_target and both bounds are set.
    pub fn resolved(&self) -> bool {
        self.v_target.is_some() && self.d_near.is_some() && self.d_far.is_some()
    }

    /// The first frame's least spacing.
    pub fn spacing(&self) -> f64 {
        self.min_spacing.unwrap_or(self.d_sep)
    }

    /// Reads a config JSON (every key optional, unknown keys rejected) and checks it.
    pub fn load(path: &std::path::Path) -> Result<Self> {
        crate::data::atomic::note_input(path);
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let c: LiftConfig = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a lift config: {e}")))?;
        c.check().map_err(|e| e.in_file(path))?;
        Ok(c)
    }
}

/// Checks a lift of `obs` at depths `depth` can rely on: plausibility and reprojection.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Checks {
    /// Largest distance (px) between a 3D point's projection and its track.
    pub reprojection_max_px: f64,
    /// Smallest distance between two birds of one frame (world units; `null` with one bird per
    /// frame throughout).
    pub min_distance: Option<f64>,
    /// Bird pairs closer than d_sep / 2 in some frame.
    pub pairs_below_half_d_sep: usize,
    /// Depths: smallest, median, largest.
    pub depth_range: [f64; 3],
}

impl Checks {
    /// The checks of depths `depth` for `obs` with separation distance `d_sep`.
    pub fn new(obs: &Observations, depth: &[f64], d_sep: f64) -> Self {
        let b = obs.positions(depth);
        let (min, close) = eval::closest_pairs(obs, &b, 0.5 * d_sep);
        let mut sorted = depth.to_vec();
        sorted.sort_by(f64::total_cmp);
        Checks {
            reprojection_max_px: obs.reprojection_error(&b),
            min_distance: min,
            pairs_below_half_d_sep: close,
            depth_range: [
                sorted[0],
                sorted[sorted.len() / 2],
                sorted[sorted.len() - 1],
            ],
        }
    }
}

/// The report written beside lifted tracks.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LiftReport {
    pub schema: String,
    pub birds: usize,
    pub frames: usize,
    pub observations: usize,
    pub config: LiftConfig,
    /// The frame-by-frame result's checks.
    pub frame_by_frame: Checks,
    /// The whole-sequence result's checks and energy (method `sequence`).
    pub whole_sequence: Option<Checks>,
    pub sequence_log: Option<sequence::SequenceLog>,
    /// v_target and the bounds used, and how they were found.
    pub estimate: estimate::Estimate,
    /// How far the whole-sequence result can be trusted (method `sequence`).
    pub confidence: Option<confidence::Confidence>,
}

/// A lift's result: the 3D tracks (the chosen method's), every depth and the report.
#[derive(Clone, Debug)]
pub struct Lifted {
    pub tracks: Tracks,
    pub depth: Vec<f64>,
    /// The frame-by-frame depths (the start of the whole-sequence stage).
    pub frame_depth: Vec<f64>,
    pub report: LiftReport,
}

/// Lifts 2D pixel tracks seen by `camera` to 3D (see the module docs).
pub fn lift(
    tracks: &Tracks,
    camera: &Camera,
    cfg: &LiftConfig,
    progress: &mut dyn Progress,
) -> Result<Lifted> {
    cfg.check()?;
    let obs = Observations::new(tracks, camera)?;
    let (cfg, est) = estimate::resolve(&obs, cfg)?;
    let cfg = &cfg;
    let frame_depth = frame::frame_by_frame(&obs, cfg, progress)?;
    let (depth, seq) = match cfg.method {
        Method::Frame => (frame_depth.clone(), None),
        Method::Sequence => {
            let (d, log) = sequence::whole_sequence(&obs, &frame_depth, cfg, progress)?;
            (d, Some(log))
        }
    };
    let confidence = match cfg.method {
        Method::Frame => None,
        Method::Sequence => Some(confidence::assess(&obs, &depth, cfg, &est, progress)?),
    };
    let report = LiftReport {
        schema: LIFT_REPORT_SCHEMA.into(),
        birds: obs.birds,
        frames: obs.frames.len(),
        observations: obs.len(),
        config: cfg.clone(),
        frame_by_frame: Checks::new(&obs, &frame_depth, cfg.d_sep),
        whole_sequence: seq.as_ref().map(|_| Checks::new(&obs, &depth, cfg.d_sep)),
        sequence_log: seq,
        estimate: est,
        confidence,
    };
    let out = obs.tracks_3d(
        &depth,
        serde_json::json!({
            "lifted_from": tracks.meta.provenance,
            "camera": camera,
            "method": cfg.method,
        }),
    )?;
    Ok(Lifted {
        tracks: out,
        depth,
        frame_depth,
        report,
    })
}
