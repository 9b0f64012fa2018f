//! Stage 5: how good a lift is, against a 3D truth seen through a (virtual) camera.
//!
//! The truth's 3D tracks are projected into 2D pixel tracks ([`super::project_tracks`]), lifted
//! back, and compared per observation with the true depth Z_c and position:
//! - depth RMSE, absolute and relative to the mean true depth;
//! - 3D position RMSE (world units; the lifted point lies on the true point's ray, so this is
//!   |Δd| · ‖ray‖);
//! - plausibility: the closest two birds of any frame, pairs nearer than d_sep / 2, and the
//!   distribution of per-frame speed changes | ‖v^f‖ − ‖v^{f−1}‖ | (eq. 3.4's quantity) against
//!   the truth's.
//!
//! Four depth estimates: (a) every bird at its frame's true mean depth (a baseline that knows
//! more than a lift may), (b) every bird at the median of [d_near, d_far] (what the bounds alone
//! give; when the bounds are estimated, at the estimate's depth guess D₀ instead, see
//! [`super::estimate`]), (c) the thesis's frame-by-frame method, (d) the whole-sequence method.
//! The whole sequence is also assessed by itself ([`super::confidence`]), so its self-assessment
//! can be checked against its error.

use super::observe::Observations;
use super::{frame, project_tracks, sequence, Checks, LiftConfig};
use crate::data::camera::Camera;
use crate::data::tracks::Tracks;
use crate::error::Result;
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

/// Schema tag of evaluation reports.
pub const EVAL_SCHEMA: &str = "herdfit.lift-eval/2";

type V3 = [f64; 3];

fn dist(a: V3, b: V3) -> f64 {
    ((a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)).sqrt()
}

/// The smallest distance between two birds of one frame over all frames (`None` when no frame
/// has two birds), and the number of (frame, pair)s closer than `below`. Every pair is checked.
pub fn closest_pairs(obs: &Observations, b: &[V3], below: f64) -> (Option<f64>, usize) {
    let mut min: Option<f64> = None;
    let mut close = 0;
    for (_, r) in &obs.frames {
        for i in r.clone() {
            for j in i + 1..r.end {
                let d = dist(b[i], b[j]);
                min = Some(min.map_or(d, |m: f64| m.min(d)));
                if d < below {
                    close += 1;
                }
            }
        }
    }
    (min, close)
}

/// Per observation with two tracked predecessors: | ‖b^f − b^{f−1}‖ − ‖b^{f−1} − b^{f−2}‖ |
/// (world units per frame).
pub fn speed_changes(obs: &Observations, b: &[V3]) -> Vec<f64> {
    (0..obs.len())
        .filter_map(|i| {
            let p = obs.prev[i]?;
            let pp = obs.prev[p]?;
            Some((dist(b[i], b[p]) - dist(b[p], b[pp])).abs())
        })
        .collect()
}

/// Mean, median and 90th percentile of a sample.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Quantiles {
    pub mean: f64,
    pub median: f64,
    pub p90: f64,
}

impl Quantiles {
    /// The quantiles of `v` (zeros when empty).
    pub fn of(v: &[f64]) -> Self {
        if v.is_empty() {
            return Quantiles::default();
        }
        let mut s = v.to_vec();
        s.sort_by(f64::total_cmp);
        let at = |q: f64| s[((s.len() - 1) as f64 * q).round() as usize];
        Quantiles {
            mean: s.iter().sum::<f64>() / s.len() as f64,
            median: at(0.5),
            p90: at(0.9),
        }
    }

    /// Ratios to `truth`, component by component.
    pub fn ratio(&self, truth: &Quantiles) -> [f64; 3] {
        [
            self.mean / truth.mean,
            self.median / truth.median,
            self.p90 / truth.p90,
        ]
    }
}

/// The scores of one depth estimate.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MethodScore {
    pub name: String,
    /// RMSE of depth (world units) and relative to the mean true depth.
    pub depth_rmse: f64,
    pub depth_rmse_relative: f64,
    /// RMSE of 3D position (world units).
    pub position_rmse: f64,
    /// The position RMSE over the flock's extent ([`TruthStats::extent`]).
    pub position_rmse_per_extent: f64,
    pub checks: Checks,
    /// Per-frame speed changes (world units per frame).
    pub speed_change: Quantiles,
    /// Their mean, median and 90th percentile over the truth's.
    pub speed_change_ratio: [f64; 3],
}

/// The truth's own plausibility figures.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TruthStats {
    pub mean_depth: f64,
    pub min_distance: Option<f64>,
    pub speed_change: Quantiles,
    /// Median speed (world units per frame).
    pub median_speed: f64,
    /// The flock's extent: the median over frames with two or more birds of the largest distance
    /// between two birds of the frame (world units).
    pub extent: f64,
    /// The same in depth alone: median over frames of the largest minus the smallest true depth.
    pub depth_extent: f64,
}

/// Median over frames with two or more birds of the frame's diameter in 3D and in depth.
fn extents(obs: &Observations, b: &[V3], depth: &[f64]) -> (f64, f64) {
    let (mut diam, mut span) = (Vec::new(), Vec::new());
    for (_, r) in &obs.frames {
        if r.len() < 2 {
            continue;
        }
        let mut m: f64 = 0.0;
        for i in r.clone() {
            for j in i + 1..r.end {
                m = m.max(dist(b[i], b[j]));
            }
        }
        diam.push(m);
        let d = &depth[r.clone()];
        let hi = d.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        let lo = d.iter().copied().fold(f64::INFINITY, f64::min);
        span.push(hi - lo);
    }
    let med = |mut v: Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v.get(v.len() / 2).copied().unwrap_or(0.0)
    };
    (med(diam), med(span))
}

/// An evaluation report (`herdfit.lift-eval/2`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub schema: String,
    pub source: serde_json::Value,
    pub camera: Camera,
    pub birds: usize,
    pub frames: usize,
    pub observations: usize,
    pub config: LiftConfig,
    pub truth: TruthStats,
    pub methods: Vec<MethodScore>,
    /// v_target and the bounds used, and how they were found.
    pub estimate: super::estimate::Estimate,
    /// The whole sequence's self-assessment.
    pub confidence: super::confidence::Confidence,
}

/// Everything an evaluation computed, for plots.
#[derive(Clone, Debug)]
pub struct Evaluation {
    pub report: EvalReport,
    pub obs: Observations,
    pub truth_depth: Vec<f64>,
    /// Depths per method, in the report's order.
    pub depths: Vec<Vec<f64>>,
}

fn score(
    name: &str,
    obs: &Observations,
    depth: &[f64],
    truth: &[f64],
    truth_changes: &Quantiles,
    extent: f64,
    d_sep: f64,
) -> MethodScore {
    let n = depth.len() as f64;
    let mean_true = truth.iter().sum::<f64>() / n;
    let depth_mse = depth
        .iter()
        .zip(truth)
        .map(|(a, b)| (a - b).powi(2))
        .sum::<f64>()
        / n;
    let b = obs.positions(depth);
    let bt = obs.positions(truth);
    let pos_mse = b
        .iter()
        .zip(&bt)
        .map(|(p, q)| dist(*p, *q).powi(2))
        .sum::<f64>()
        / n;
    let sc = Quantiles::of(&speed_changes(obs, &b));
    MethodScore {
        name: name.into(),
        depth_rmse: depth_mse.sqrt(),
        depth_rmse_relative: depth_mse.sqrt() / mean_true,
        position_rmse: pos_mse.sqrt(),
        position_rmse_per_extent: pos_mse.sqrt() / extent,
        checks: Checks::new(obs, depth, d_sep),
        speed_change: sc,
        speed_change_ratio: sc.ratio(truth_changes),
    }
}

/// Projects `truth` (3D) through `camera`, lifts it back by both methods and scores the four
/// estimates of the module docs. With `crop`, points out of view are dropped (birds leave and
/// enter); without, every point must be in view.
pub fn evaluate(
    truth: &Tracks,
    camera: &Camera,
    cfg: &LiftConfig,
    crop: bool,
    progress: &mut dyn Progress,
) -> Result<Evaluation> {
    cfg.check()?;
    let (tracks2d, truth_depth) = project_tracks(truth, camera, crop)?;
    let obs = Observations::new(&tracks2d, camera)?;
    let (cfg, est) = super::estimate::resolve(&obs, cfg)?;
    let cfg = &cfg;
    let bt = obs.positions(&truth_depth);
    let truth_changes = Quantiles::of(&speed_changes(&obs, &bt));
    let mut speeds: Vec<f64> = (0..obs.len())
        .filter_map(|i| obs.prev[i].map(|p| dist(bt[i], bt[p])))
        .collect();
    speeds.sort_by(f64::total_cmp);
    let n = obs.len();
    let (extent, depth_extent) = extents(&obs, &bt, &truth_depth);
    let mean_depth = truth_depth.iter().sum::<f64>() / n as f64;
    // (a) the true mean depth of each frame.
    let mut frame_mean = vec![0.0; n];
    for (_, r) in &obs.frames {
        let m = truth_depth[r.clone()].iter().sum::<f64>() / r.len() as f64;
        frame_mean[r.clone()].iter_mut().for_each(|d| *d = m);
    }
    // (b) the median of the bounds (of the estimate's depth guess when they are estimated).
    let constant = vec![
        match est.bounds_source {
            super::estimate::Source::Given => 0.5 * (cfg.near() + cfg.far()),
            super::estimate::Source::Estimated => est.depth_guess,
        };
        n
    ];
    // (c), (d).
    let fbf = frame::frame_by_frame(&obs, cfg, progress)?;
    let (seq, _) = sequence::whole_sequence(&obs, &fbf, cfg, progress)?;
    let confidence = super::confidence::assess(&obs, &seq, cfg, &est, progress)?;
    let named = [
        ("true_mean_depth", frame_mean),
        ("constant_median", constant),
        ("frame_by_frame", fbf),
        ("whole_sequence", seq),
    ];
    let methods = named
        .iter()
        .map(|(k, d)| score(k, &obs, d, &truth_depth, &truth_changes, extent, cfg.d_sep))
        .collect();
    let (min_distance, _) = closest_pairs(&obs, &bt, 0.0);
    let report = EvalReport {
        schema: EVAL_SCHEMA.into(),
        source: truth.meta.provenance.clone(),
        camera: camera.clone(),
        birds: obs.birds,
        frames: obs.frames.len(),
        observations: n,
        config: cfg.clone(),
        truth: TruthStats {
            mean_depth,
            min_distance,
            speed_change: truth_changes,
            median_speed: speeds.get(speeds.len() / 2).copied().unwrap_or(0.0),
            extent,
            depth_extent,
        },
        methods,
        estimate: est,
        confidence,
    };
    Ok(Evaluation {
        report,
        obs,
        truth_depth,
        depths: named.into_iter().map(|(_, d)| d).collect(),
    })
}
