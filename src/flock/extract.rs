//! Parameter extraction from an example (Klotsman & Tal §4): per marked frame the ordering by
//! lateral position, the mean/STD of the lateral gaps, the leader, RANSAC fits per side (a line for
//! V and line shapes, a parabola for U and J shapes) with outliers, the inliers' longitudinal
//! deviations and the special roles. The result is a `herdfit.flock-shape/1` JSON file.
//!
//! Input: a `herdfit.tracks/1` file of marked birds (2D, one row per bird per marked frame), and
//! the wingspan b in the tracks' units (config key `wingspan`, or `provenance.wingspan` in the
//! tracks sidecar). Everything downstream is in wingspans in the *flock frame*: x lateral (right
//! of the flight direction), y longitudinal (forward), the leader at the origin.

use super::power;
use super::ransac::{self, Model};
use crate::data::tracks::{Tracks, Units};
use crate::error::{Error, Result};
use rand::SeedableRng;
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One example frame in the flock frame: (frame, time, [(id, position in wingspans)]).
type FramePositions = (u64, f64, Vec<(u64, [f64; 2])>);
/// Schema tag of extracted shape parameters.
pub const SHAPE_SCHEMA: &str = "herdfit.flock-shape/1";

/// The formation families of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ShapeKind {
    V,
    U,
    J,
    Line,
}

impl ShapeKind {
    /// The side model of §4 Step 2: a line for V and line shapes, a parabola for U and J.
    pub fn model(self) -> Model {
        match self {
            ShapeKind::V | ShapeKind::Line => Model::Line,
            ShapeKind::U | ShapeKind::J => Model::Parabola,
        }
    }

    /// The name as written in files and flags.
    pub fn as_str(self) -> &'static str {
        match self {
            ShapeKind::V => "v",
            ShapeKind::U => "u",
            ShapeKind::J => "j",
            ShapeKind::Line => "line",
        }
    }
}

impl std::str::FromStr for ShapeKind {
    type Err = String;
    fn from_str(s: &str) -> std::result::Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "v" => Ok(ShapeKind::V),
            "u" => Ok(ShapeKind::U),
            "j" => Ok(ShapeKind::J),
            "line" => Ok(ShapeKind::Line),
            _ => Err(format!("'{s}' is not a shape (v, u, j, line)")),
        }
    }
}

/// Settings of [`extract`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtractConfig {
    /// Wingspan b in the tracks' units; `None`: `provenance.wingspan` of the tracks sidecar.
    pub wingspan: Option<f64>,
    /// Flight direction in the tracks' coordinates (y up; pixel tracks are flipped first),
    /// degrees counter-clockwise from +x; `None`: the direction of the centroid's motion.
    pub heading_deg: Option<f64>,
    /// The example was filmed from below (mirrors left and right).
    pub from_below: bool,
    /// The formation family; `None`: classified from the fits.
    pub shape: Option<ShapeKind>,
    /// RANSAC inlier threshold on the longitudinal residual, wingspans.
    pub inlier_threshold: f64,
    /// RANSAC samples per side and frame.
    pub ransac_iterations: usize,
    /// Seed of the RANSAC samples.
    pub seed: u64,
}

impl Default for ExtractConfig {
    fn default() -> Self {
        ExtractConfig {
            wingspan: None,
            heading_deg: None,
            from_below: false,
            shape: None,
            inlier_threshold: 0.5,
            ransac_iterations: 200,
            seed: 0,
        }
    }
}

impl ExtractConfig {
    /// Checks the settings; errors name the config key.
    pub fn check(&self) -> Result<()> {
        use crate::limits::{within, MAX_COORD};
        if let Some(b) = self.wingspan {
            if !(b.is_finite() && b > 0.0) {
                return Err(Error::invalid(format!("wingspan = {b} must be > 0")));
            }
            within("wingspan", b, 0.0, MAX_COORD)?;
        }
        if let Some(h) = self.heading_deg {
            within("heading_deg", h, -360.0, 360.0)?;
        }
        within("inlier_threshold", self.inlier_threshold, 0.0, 1e3)?;
        if !(self.inlier_threshold.is_finite() && self.inlier_threshold > 0.0) {
            return Err(Error::invalid(format!(
                "inlier_threshold = {} must be > 0",
                self.inlier_threshold
            )));
        }
        if self.ransac_iterations == 0 || self.ransac_iterations > 1_000_000 {
            return Err(Error::invalid(format!(
                "ransac_iterations = {} must be in 1..=1000000",
                self.ransac_iterations
            )));
        }
        Ok(())
    }
}

/// Left or right of the leader (seen in the flight direction).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    Left,
    Right,
}

/// The fit of one side in one frame.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SideFit {
    pub model: Model,
    /// `y = Σ coef[p] u^p`, u = lateral distance from the leader (≥ 0), wingspans.
    pub coef: Vec<f64>,
    /// Ids on this side, from the leader outward.
    pub birds: Vec<u64>,
    /// Angle between the side and the flight axis, degrees: from the slope for a line, from the
    /// chord leader → farthest bird's model point for a parabola.
    pub angle_deg: f64,
}

/// One bird in one frame (flock frame, wingspans, leader at the origin).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BirdShape {
    pub id: u64,
    pub x: f64,
    pub y: f64,
    /// Longitudinal residual from its side's model (0 for the leader).
    pub dy: f64,
    pub outlier: bool,
    /// Relative power reduction ξ in this frame (None where g is singular).
    pub xi: Option<f64>,
}

/// The parameters of one marked frame (§4 Steps 1–2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameShape {
    pub frame: u64,
    pub time: f64,
    /// Ids ordered by lateral position, left to right.
    pub order: Vec<u64>,
    /// Mean μ_x and STD σ_x of the lateral gaps between neighbours, wingspans.
    pub mean_gap: f64,
    pub std_gap: f64,
    /// The front-most bird.
    pub leader: u64,
    pub left: Option<SideFit>,
    pub right: Option<SideFit>,
    /// Inliers' mean μ_y and STD σ_y of the longitudinal deviations, wingspans.
    pub mean_dev: f64,
    pub std_dev: f64,
    /// Birds, ordered by lateral position.
    pub birds: Vec<BirdShape>,
}

impl FrameShape {
    /// The fit of a side.
    pub fn side(&self, s: Side) -> Option<&SideFit> {
        match s {
            Side::Left => self.left.as_ref(),
            Side::Right => self.right.as_ref(),
        }
    }

    /// A bird by id.
    pub fn bird(&self, id: u64) -> Option<&BirdShape> {
        self.birds.iter().find(|b| b.id == id)
    }
}

/// Extracted parameters of an example (`herdfit.flock-shape/1`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ShapeParams {
    pub schema: String,
    /// The tracks file it came from.
    pub source: String,
    /// Units of the tracks (the wingspan is in them).
    pub units: Units,
    pub wingspan: f64,
    /// Flight direction used, degrees from +x in the tracks' coordinates (y up).
    pub heading_deg: f64,
    pub kind: ShapeKind,
    /// Distinct birds N̂ of the example.
    pub birds: usize,
    pub frames: Vec<FrameShape>,
    pub config: ExtractConfig,
}

impl ShapeParams {
    /// Mean side angle over the frames (degrees), per side.
    pub fn mean_angle(&self, s: Side) -> Option<f64> {
        let v: Vec<f64> = self
            .frames
            .iter()
            .filter_map(|f| f.side(s).map(|x| x.angle_deg))
            .collect();
        (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
    }
}

/// Mean and sample STD (0 for fewer than 2 values).
pub(crate) fn mean_std(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (0.0, 0.0);
    }
    let m = v.iter().sum::<f64>() / v.len() as f64;
    if v.len() < 2 {
        return (m, 0.0);
    }
    let var = v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (v.len() - 1) as f64;
    (m, var.sqrt())
}

/// Reads a tracks file and extracts its shape parameters.
pub fn extract_file(path: &Path, cfg: &ExtractConfig) -> Result<ShapeParams> {
    let tracks = Tracks::load(path)?;
    extract(&tracks, &path.display().to_string(), cfg).map_err(|e| e.in_file(path))
}

/// Extracts the shape parameters of `tracks` (§4). `source` is recorded in the result.
pub fn extract(tracks: &Tracks, source: &str, cfg: &ExtractConfig) -> Result<ShapeParams> {
    cfg.check()?;
    if tracks.meta.dimension != 2 {
        return Err(Error::invalid(format!(
            "a flock example is 2D (birds marked from above or below); dimension is {}",
            tracks.meta.dimension
        )));
    }
    let b = match cfg.wingspan {
        Some(b) => b,
        None => {
            let v = tracks.meta.provenance.get("wingspan").ok_or_else(|| {
                Error::invalid(
                    "wingspan unknown: set wingspan or provenance.wingspan in the sidecar",
                )
            })?;
            v.as_f64().ok_or_else(|| {
                Error::invalid(format!("provenance.wingspan = {v} is not a number"))
            })?
        }
    };
    if !(b.is_finite() && b > 0.0) {
        return Err(Error::invalid(format!("wingspan = {b} must be > 0")));
    }
    let flip = tracks.meta.units == Units::Pixels;
    let up = |p: [f64; 3]| [p[0], if flip { -p[1] } else { p[1] }];
    let frames = tracks.frames();
    for (f, r) in &frames {
        if r.len() < 3 {
            return Err(Error::invalid(format!(
                "frame {f} has {} bird(s); a formation needs at least 3",
                r.len()
            )));
        }
    }
    let heading = match cfg.heading_deg {
        Some(h) => h.to_radians(),
        None => heading_from_motion(tracks, &frames, b, &up)?,
    };
    let fwd = [heading.cos(), heading.sin()];
    let mirror = if cfg.from_below { -1.0 } else { 1.0 };
    let right = [fwd[1] * mirror, -fwd[0] * mirror];
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
    // Positions in the flock frame, wingspans, per frame.
    let mut per_frame: Vec<FramePositions> = Vec::new();
    for (f, r) in &frames {
        let pts: Vec<(u64, [f64; 2])> = tracks.rows[r.clone()]
            .iter()
            .map(|row| {
                let p = up(row.pos);
                (
                    row.id,
                    [
                        (p[0] * right[0] + p[1] * right[1]) / b,
                        (p[0] * fwd[0] + p[1] * fwd[1]) / b,
                    ],
                )
            })
            .collect();
        let ys: Vec<f64> = pts.iter().map(|p| p.1[1]).collect();
        let spread = ys.iter().cloned().fold(f64::NEG_INFINITY, f64::max)
            - ys.iter().cloned().fold(f64::INFINITY, f64::min);
        if spread < 0.05 {
            return Err(Error::invalid(format!(
                "frame {f}: all birds abreast (longitudinal spread {spread:.3} wingspans): a line \
                 formation needs a front-most leader"
            )));
        }
        per_frame.push((*f, tracks.rows[r.start].time, pts));
    }
    let kind = match cfg.shape {
        Some(k) => k,
        None => classify(&per_frame, cfg, &mut rng),
    };
    let model = kind.model();
    let mut shapes = Vec::with_capacity(per_frame.len());
    for (f, time, pts) in &per_frame {
        shapes.push(frame_shape(*f, *time, pts, model, cfg, &mut rng));
    }
    Ok(ShapeParams {
        schema: SHAPE_SCHEMA.into(),
        source: source.into(),
        units: tracks.meta.units,
        wingspan: b,
        heading_deg: heading.to_degrees(),
        kind,
        birds: tracks.ids().len(),
        frames: shapes,
        config: cfg.clone(),
    })
}

/// Flight direction from the centroid's displacement between the first and the last frame (over
/// the birds present in both); refused when it is under one wingspan.
fn heading_from_motion(
    tracks: &Tracks,
    frames: &[(u64, std::ops::Range<usize>)],
    b: f64,
    up: &dyn Fn([f64; 3]) -> [f64; 2],
) -> Result<f64> {
    let first = &tracks.rows[frames[0].1.clone()];
    let last = &tracks.rows[frames[frames.len() - 1].1.clone()];
    let (mut a, mut z, mut n) = ([0.0; 2], [0.0; 2], 0.0);
    for r in first {
        if let Some(s) = last.iter().find(|s| s.id == r.id) {
            let (p, q) = (up(r.pos), up(s.pos));
            a[0] += p[0];
            a[1] += p[1];
            z[0] += q[0];
            z[1] += q[1];
            n += 1.0;
        }
    }
    let d = if n > 0.0 {
        [(z[0] - a[0]) / n, (z[1] - a[1]) / n]
    } else {
        [0.0, 0.0]
    };
    let len = d[0].hypot(d[1]) / b;
    if len < 1.0 {
        return Err(Error::invalid(format!(
            "heading_deg unknown: the flock's centroid moves {len:.2} wingspans over the example \
             (under 1); give the flight direction"
        )));
    }
    Ok(d[1].atan2(d[0]))
}

/// Splits a frame into the leader and the two sides, as `(u, y)` points from the leader outward.
fn sides(pts: &[(u64, [f64; 2])]) -> (usize, Vec<usize>, Vec<usize>) {
    let leader = (0..pts.len())
        .max_by(|&a, &b| pts[a].1[1].total_cmp(&pts[b].1[1]).then(b.cmp(&a)))
        .unwrap_or(0);
    let lx = pts[leader].1[0];
    let mut left: Vec<usize> = (0..pts.len())
        .filter(|&i| i != leader && pts[i].1[0] < lx)
        .collect();
    let mut right: Vec<usize> = (0..pts.len())
        .filter(|&i| i != leader && pts[i].1[0] >= lx)
        .collect();
    left.sort_by(|&a, &b| pts[b].1[0].total_cmp(&pts[a].1[0]));
    right.sort_by(|&a, &b| pts[a].1[0].total_cmp(&pts[b].1[0]));
    (leader, left, right)
}

/// RANSAC on one side; points (u, y) relative to the leader, the leader itself included at u = 0.
fn fit_side(
    pts: &[(u64, [f64; 2])],
    leader: usize,
    idx: &[usize],
    model: Model,
    cfg: &ExtractConfig,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Option<ransac::Fit> {
    if idx.is_empty() {
        return None;
    }
    let l = pts[leader].1;
    let mut uv: Vec<(f64, f64)> = vec![(0.0, 0.0)];
    uv.extend(
        idx.iter()
            .map(|&i| ((pts[i].1[0] - l[0]).abs(), pts[i].1[1] - l[1])),
    );
    ransac::fit(model, &uv, cfg.inlier_threshold, cfg.ransac_iterations, rng)
}

fn side_angle(model: Model, coef: &[f64], umax: f64) -> f64 {
    let slope = match model {
        Model::Line => coef[1],
        Model::Parabola => {
            let u = umax.max(1e-9);
            (ransac::eval(coef, u) - ransac::eval(coef, 0.0)) / u
        }
    };
    // Angle between the side (direction (1, slope) in (u, y)) and the backward flight axis.
    1.0f64.atan2(slope.abs()).to_degrees()
}

fn frame_shape(
    frame: u64,
    time: f64,
    pts: &[(u64, [f64; 2])],
    model: Model,
    cfg: &ExtractConfig,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> FrameShape {
    let (leader, left, right) = sides(pts);
    let l = pts[leader].1;
    let mut birds: Vec<BirdShape> = pts
        .iter()
        .map(|(id, p)| BirdShape {
            id: *id,
            x: p[0] - l[0],
            y: p[1] - l[1],
            dy: 0.0,
            outlier: false,
            xi: None,
        })
        .collect();
    let mut fits = [None, None];
    let mut inlier_dev = Vec::new();
    for (k, idx) in [&left, &right].into_iter().enumerate() {
        let Some(fit) = fit_side(pts, leader, idx, model, cfg, rng) else {
            continue;
        };
        let mut umax: f64 = 0.0;
        for (m, &i) in idx.iter().enumerate() {
            let u = birds[i].x.abs();
            umax = umax.max(u);
            birds[i].dy = birds[i].y - ransac::eval(&fit.coef, u);
            birds[i].outlier = !fit.inlier[m + 1];
            if fit.inlier[m + 1] {
                inlier_dev.push(birds[i].dy);
            }
        }
        fits[k] = Some(SideFit {
            model,
            angle_deg: side_angle(model, &fit.coef, umax),
            coef: fit.coef,
            birds: idx.iter().map(|&i| pts[i].0).collect(),
        });
    }
    let pos: Vec<[f64; 2]> = birds.iter().map(|b| [b.x, b.y]).collect();
    if power::check_lateral(&pos).is_ok() {
        for (b, xi) in birds
            .iter_mut()
            .zip(power::relative(&power::savings_unchecked(&pos)))
        {
            b.xi = Some(xi);
        }
    }
    birds.sort_by(|a, b| a.x.total_cmp(&b.x).then(a.id.cmp(&b.id)));
    let gaps: Vec<f64> = birds.windows(2).map(|w| w[1].x - w[0].x).collect();
    let (mean_gap, std_gap) = mean_std(&gaps);
    let (mean_dev, std_dev) = mean_std(&inlier_dev);
    let [left, right] = fits;
    FrameShape {
        frame,
        time,
        order: birds.iter().map(|b| b.id).collect(),
        mean_gap,
        std_gap,
        leader: pts[leader].0,
        left,
        right,
        mean_dev,
        std_dev,
        birds,
    }
}

/// The formation family from the fits: two-sided (both sides with ≥ 2 birds in most frames) or
/// one-sided, straight or curved (a parabola with at least as many inliers and under 60 % of the
/// line's inlier RMS, or 5 % more inliers).
fn classify(
    per_frame: &[FramePositions],
    cfg: &ExtractConfig,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> ShapeKind {
    let mut two_sided = 0usize;
    let (mut inl, mut sse) = ([0usize; 2], [0.0f64; 2]);
    for (_, _, pts) in per_frame {
        let (leader, left, right) = sides(pts);
        if left.len().min(right.len()) >= 2 {
            two_sided += 1;
        }
        for idx in [&left, &right] {
            if idx.len() < 3 {
                continue;
            }
            for (k, model) in [Model::Line, Model::Parabola].into_iter().enumerate() {
                if let Some(fit) = fit_side(pts, leader, idx, model, cfg, rng) {
                    let l = pts[leader].1;
                    for (m, &i) in idx.iter().enumerate() {
                        if fit.inlier[m + 1] {
                            let u = (pts[i].1[0] - l[0]).abs();
                            let r = pts[i].1[1] - l[1] - ransac::eval(&fit.coef, u);
                            inl[k] += 1;
                            sse[k] += r * r;
                        }
                    }
                }
            }
        }
    }
    let rms = |k: usize| (sse[k] / inl[k].max(1) as f64).sqrt();
    let curved =
        inl[1] as f64 > 1.05 * inl[0] as f64 || (inl[1] >= inl[0] && rms(1) < 0.6 * rms(0));
    match (2 * two_sided > per_frame.len(), curved) {
        (true, false) => ShapeKind::V,
        (true, true) => ShapeKind::U,
        (false, false) => ShapeKind::Line,
        (false, true) => ShapeKind::J,
    }
}
