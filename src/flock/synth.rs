//! Synthetic examples of marked formations with known truth: V, U, J and line (echelon) shapes
//! with noise and outliers, written as `herdfit.tracks/1` (metres, 2D, y up) with the wingspan in
//! the sidecar's `provenance.wingspan`. The `role` column carries the truth (`leader`, `inlier`,
//! `outlier`); extraction does not read it.
//!
//! Geometry per marked frame, in the flock frame (wingspans, leader at the origin): each side's
//! birds sit at lateral distances u_k = Σ gaps (gaps ~ N(gap, gap_std), drawn once per bird plus a
//! small per-frame jitter), at y = −u / tan(half_angle) (V, line) or y = −curvature · u² (U, J);
//! outliers are displaced longitudinally by a signed offset of |offset| ∈ [outlier_min,
//! outlier_max]; every coordinate gets N(0, noise) per frame. The flock flies along
//! `heading_deg` at `speed`.

use super::extract::ShapeKind;
use crate::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
use crate::error::{Error, Result};
use rand::{Rng, SeedableRng};
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Settings of [`synth`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthConfig {
    pub shape: ShapeKind,
    pub birds: usize,
    /// Marked frames.
    pub frames: usize,
    /// Marked frames per second.
    pub fps: f64,
    /// Wingspan, metres.
    pub wingspan: f64,
    /// Angle between each side and the flight axis (V, line), degrees.
    pub half_angle_deg: f64,
    /// y = −curvature · u² (U, J), per wingspan.
    pub curvature: f64,
    /// Mean lateral gap between neighbours, wingspans.
    pub gap: f64,
    /// STD of the per-bird gaps, wingspans.
    pub gap_std: f64,
    /// Fraction of non-leader birds displaced off their side.
    pub outlier_fraction: f64,
    /// Range of the outliers' longitudinal offset, wingspans.
    pub outlier_min: f64,
    pub outlier_max: f64,
    /// STD of the position noise per coordinate, wingspans.
    pub noise: f64,
    /// Ground speed, m/s.
    pub speed: f64,
    /// Flight direction, degrees counter-clockwise from +x.
    pub heading_deg: f64,
    pub seed: u64,
}

impl Default for SynthConfig {
    fn default() -> Self {
        SynthConfig {
            shape: ShapeKind::V,
            birds: 9,
            frames: 16,
            fps: 2.0,
            wingspan: 1.5,
            half_angle_deg: 30.0,
            curvature: 0.15,
            gap: 1.0,
            gap_std: 0.08,
            outlier_fraction: 0.2,
            outlier_min: 1.2,
            outlier_max: 2.5,
            noise: 0.1,
            speed: 15.0,
            heading_deg: 90.0,
            seed: 0,
        }
    }
}

impl SynthConfig {
    /// Checks the settings; errors name the config key.
    pub fn check(&self) -> Result<()> {
        let pos = |v: f64, k: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(format!("{k} = {v} must be > 0")))
            }
        };
        let nonneg = |v: f64, k: &str| {
            if v.is_finite() && v >= 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(format!("{k} = {v} must be ≥ 0")))
            }
        };
        if !(3..=1000).contains(&self.birds) {
            return Err(Error::invalid(format!(
                "birds = {} must be in 3..=1000",
                self.birds
            )));
        }
        if !(1..=100_000).contains(&self.frames) {
            return Err(Error::invalid(format!(
                "frames = {} must be in 1..=100000",
                self.frames
            )));
        }
        pos(self.fps, "fps")?;
        pos(self.wingspan, "wingspan")?;
        pos(self.gap, "gap")?;
        pos(self.curvature, "curvature")?;
        nonneg(self.gap_std, "gap_std")?;
        nonneg(self.noise, "noise")?;
        nonneg(self.speed, "speed")?;
        nonneg(self.outlier_min, "outlier_min")?;
        if !(self.half_angle_deg > 1.0 && self.half_angle_deg < 89.0) {
            return Err(Error::invalid(format!(
                "half_angle_deg = {} must be in (1, 89)",
                self.half_angle_deg
            )));
        }
        if !(0.0..=0.9).contains(&self.outlier_fraction) {
            return Err(Error::invalid(format!(
                "outlier_fraction = {} must be in [0, 0.9]",
                self.outlier_fraction
            )));
        }
        if !(self.outlier_max.is_finite() && self.outlier_max >= self.outlier_min) {
            return Err(Error::invalid(format!(
                "outlier_max = {} must be ≥ outlier_min = {}",
                self.outlier_max, self.outlier_min
            )));
        }
        if !self.heading_deg.is_finite() {
            return Err(Error::invalid("heading_deg must be finite"));
        }
        Ok(())
    }
}

/// Birds per side (left, right) for a shape: V and U split evenly, J keeps one bird on its short
/// (left) side, a line has every bird on the right.
pub fn side_counts(shape: ShapeKind, birds: usize) -> (usize, usize) {
    let rest = birds - 1;
    match shape {
        ShapeKind::V | ShapeKind::U => (rest / 2, rest - rest / 2),
        ShapeKind::J => (1, rest - 1),
        ShapeKind::Line => (0, rest),
    }
}

/// Makes a synthetic example (see the module docs).
pub fn synth(cfg: &SynthConfig) -> Result<Tracks> {
    cfg.check()?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
    let (nl, nr) = side_counts(cfg.shape, cfg.birds);
    let gap = Normal::new(cfg.gap, cfg.gap_std).map_err(|e| Error::invalid(format!("gap: {e}")))?;
    let noise = Normal::new(0.0, cfg.noise).map_err(|e| Error::invalid(format!("noise: {e}")))?;
    let jitter = Normal::new(0.0, 0.02).map_err(|e| Error::Internal(e.to_string()))?;
    // Per bird: side sign, gap to the previous bird on the side, outlier offset.
    struct Bird {
        side: f64,
        rank: usize,
        gap: f64,
        offset: Option<f64>,
    }
    let mut birds = vec![Bird {
        side: 0.0,
        rank: 0,
        gap: 0.0,
        offset: None,
    }];
    for (side, n) in [(-1.0, nl), (1.0, nr)] {
        for k in 1..=n {
            birds.push(Bird {
                side,
                rank: k,
                gap: gap.sample(&mut rng).max(0.5 * cfg.gap),
                offset: None,
            });
        }
    }
    let n_out = (cfg.outlier_fraction * (cfg.birds - 1) as f64).round() as usize;
    for i in rand::seq::index::sample(&mut rng, cfg.birds - 1, n_out).into_vec() {
        let mag = rng.gen_range(cfg.outlier_min..=cfg.outlier_max);
        let sign = if rng.gen_bool(0.5) { 1.0 } else { -1.0 };
        birds[i + 1].offset = Some(sign * mag);
    }
    let tan = cfg.half_angle_deg.to_radians().tan();
    let h = cfg.heading_deg.to_radians();
    let (fwd, right) = ([h.cos(), h.sin()], [h.sin(), -h.cos()]);
    let b = cfg.wingspan;
    let mut rows = Vec::with_capacity(cfg.birds * cfg.frames);
    for f in 0..cfg.frames {
        let t = f as f64 / cfg.fps;
        let centre = [fwd[0] * cfg.speed * t, fwd[1] * cfg.speed * t];
        let mut u_side = [0.0f64; 2];
        for (id, bird) in birds.iter().enumerate() {
            let s = usize::from(bird.side > 0.0);
            let (x, y) = if bird.rank == 0 {
                (0.0, 0.0)
            } else {
                u_side[s] += bird.gap + jitter.sample(&mut rng);
                let u = u_side[s];
                let y = match cfg.shape {
                    ShapeKind::V | ShapeKind::Line => -u / tan,
                    ShapeKind::U | ShapeKind::J => -cfg.curvature * u * u,
                };
                let off = bird
                    .offset
                    .map_or(0.0, |o| o + 0.1 * jitter.sample(&mut rng));
                (bird.side * u, y + off)
            };
            let (x, y) = (x + noise.sample(&mut rng), y + noise.sample(&mut rng));
            let pos = [
                centre[0] + b * (x * right[0] + y * fwd[0]),
                centre[1] + b * (x * right[1] + y * fwd[1]),
                0.0,
            ];
            let role = match (bird.rank, bird.offset) {
                (0, _) => "leader",
                (_, Some(_)) => "outlier",
                _ => "inlier",
            };
            rows.push(TrackRow {
                frame: f as u64,
                time: t,
                id: id as u64,
                pos,
                vel: None,
                role: Some(role.into()),
            });
        }
    }
    let mut meta = TracksMeta::new(Units::Metres, cfg.fps, 2);
    meta.provenance = serde_json::json!({
        "generator": "herdfit flock synth",
        "wingspan": cfg.wingspan,
        "heading_deg": cfg.heading_deg,
        "truth": "role column: leader, inlier, outlier",
        "config": cfg,
    });
    Tracks::new(meta, rows)
}

/// The steady-flight set-up of a key-shape case: the synthetic example `ex` extracted (§4),
/// Step 1's initial shapes for `n` birds, Step 2's ranges [p_i, P_i], the range of the
/// example's per-frame mean lateral gaps (the gaps key shapes draw from) and the example's shape
/// family carried to `n` birds.
#[allow(clippy::type_complexity)]
pub fn key_shape_setup(
    ex: &SynthConfig,
    n: usize,
    cfg: &super::steady::SteadyConfig,
    rng: &mut impl Rng,
) -> Result<(
    super::steady::InitialShapes,
    Vec<[f64; 2]>,
    [f64; 2],
    super::family::Family,
)> {
    let t = synth(ex)?;
    let p = super::extract::extract(&t, "synthetic", &super::extract::ExtractConfig::default())?;
    let init = super::steady::initial_shapes(&p, n, cfg, rng)?;
    let (_, range) = super::steady::ranges(&init.shapes)?;
    let means: Vec<f64> = p.frames.iter().map(|f| f.mean_gap).collect();
    let gaps = [
        means.iter().cloned().fold(f64::INFINITY, f64::min),
        means.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
    ];
    let family = super::family::Family::of_example(&p, &init);
    Ok((init, range, gaps, family))
}

/// The examples shipped in `examples/flocks/` (file stem, settings). `herdfit flock synth
/// --examples DIR` writes exactly these.
/// The examples and flock sizes of the key-shape checks (eq. 4 solved by Levenberg–Marquardt):
/// a 9-bird V at N = 9 and 14, a 16-bird U at N = 16 and 28, a 41-bird V at N = 41.
pub fn key_shape_cases() -> Vec<(SynthConfig, usize)> {
    let v9 = SynthConfig {
        seed: 1,
        ..SynthConfig::default()
    };
    let u16 = SynthConfig {
        shape: ShapeKind::U,
        birds: 16,
        curvature: 0.12,
        seed: 2,
        ..SynthConfig::default()
    };
    let v41 = SynthConfig {
        birds: 41,
        seed: 3,
        ..SynthConfig::default()
    };
    vec![
        (v9.clone(), 9),
        (v9, 14),
        (u16.clone(), 16),
        (u16, 28),
        (v41, 41),
    ]
}

pub fn shipped_examples() -> Vec<(&'static str, SynthConfig)> {
    let base = SynthConfig::default();
    vec![
        (
            "v",
            SynthConfig {
                seed: 1,
                ..base.clone()
            },
        ),
        (
            "u",
            SynthConfig {
                shape: ShapeKind::U,
                birds: 16,
                curvature: 0.12,
                seed: 2,
                ..base.clone()
            },
        ),
        (
            "j",
            SynthConfig {
                shape: ShapeKind::J,
                birds: 12,
                curvature: 0.1,
                seed: 3,
                ..base.clone()
            },
        ),
        (
            "line",
            SynthConfig {
                shape: ShapeKind::Line,
                birds: 8,
                half_angle_deg: 45.0,
                seed: 4,
                ..base
            },
        ),
    ]
}

/// Writes the shipped examples into `dir` (`<stem>.csv` + `<stem>.json` each); returns the CSV
/// paths.
pub fn write_examples(dir: &Path) -> Result<Vec<std::path::PathBuf>> {
    std::fs::create_dir_all(dir)
        .map_err(|e| Error::file(dir, format!("cannot create folder: {e}")))?;
    let mut out = Vec::new();
    for (stem, cfg) in shipped_examples() {
        let p = dir.join(format!("{stem}.csv"));
        synth(&cfg)?.save(&p)?;
        out.push(p);
    }
    Ok(out)
}
