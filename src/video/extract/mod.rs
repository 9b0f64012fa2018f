//! Clip fields from an overhead video (paper §4): stabilisation by CSRT-tracked anchors and eq. 1,
//! segmentation against a temporal-median background (and the body colour), Farneback optical
//! flow, and per-cell density, mean velocity and direction variance.
//!
//! Coordinates: the global frame is the first frame's image. A pixel (u, v) of it is the world
//! point (u / L, (H − v) / L) in body lengths (L = body length in pixels, y up), so a video of
//! `herdfit synth --video` maps back onto the world of its trajectories. The grid has square cells
//! of max(W, H) / N pixels, `nx = ⌈W / cell⌉` by `ny = ⌈H / cell⌉`, origin at the bottom-left corner.
//!
//! The stages, in order: `decode` (the video and frame hand-over), `camera` (pass A, the camera
//! path), `background` (processing frame, background, grid, obstacles), `fields` (pass C:
//! segmentation, flow, per-cell sums and fields), `preview`, and `job` (the files).

mod background;
mod blobs;
mod body_size;
mod calibrate;
mod camera;
mod decode;
mod fields;
mod job;
mod preview;
mod profile;
mod register;
mod report;
mod still;

pub use calibrate::Calibration;
pub use camera::Similarity;
pub use decode::quietly;
pub use job::{run, ExtractJob, CENTRE_ANCHOR};
pub use still::is_still;

use crate::data::{ClipFields, ClipMeta, ClipSpeed, CLIP_SCHEMA};
use crate::error::{Error, Result};
use crate::measure::speed_density_table;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// An animal count the user made on one frame (`--count N@frame`): N_bp = herd pixels of that
/// frame / N.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct UserCount {
    pub animals: usize,
    /// Frame index in the video.
    pub frame: usize,
}

/// Every setting of an extraction (recorded in `clip.json`; loadable with `--config`). The
/// optional ones are estimated from the video when absent (see `calibrate`); the values used are
/// recorded in `clip.json` under `provenance.calibration`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtractConfig {
    /// Cells along the longer side of the frame; none: cells of [`AUTO_CELL_BL`] body lengths.
    pub grid: Option<usize>,
    /// Body length in pixels; none: estimated from the isolated animals.
    pub body_length_px: Option<f64>,
    /// Body colour (RGB) for the colour-distance test; none: background difference only.
    pub body_colour: Option<[u8; 3]>,
    /// Largest Euclidean RGB distance to the body colour of a herd pixel.
    pub colour_threshold: f64,
    /// Smallest per-channel difference to the background of a herd pixel; none: Otsu's threshold
    /// of the difference histogram above its noise floor.
    pub background_threshold: Option<f64>,
    /// Body pixels per animal N_bp (§4); none: from `count`, else the median area of the
    /// isolated animals.
    pub body_pixels: Option<f64>,
    /// An animal count on one frame to derive N_bp from.
    pub count: Option<UserCount>,
    /// Anchor rectangles x,y,w,h in the first frame tracked with CSRT; empty: automatic
    /// stabilisation (or a static camera without `stabilise`).
    pub anchors: Vec<[i32; 4]>,
    /// Without anchors, register every frame on the background features (eq. 1); false: the
    /// camera is static.
    pub stabilise: bool,
    /// Background image; none: per-pixel temporal median of sampled stabilised frames.
    pub background: Option<PathBuf>,
    /// Obstacle mask image (non-zero = obstacle) the size of the video frame, or a
    /// `herdfit.obstacle-polygons/1` JSON file (`data::obstacle_polygons`).
    pub obstacles: Option<PathBuf>,
    /// Frames used, start..end (end exclusive); all when absent.
    pub frames: Option<[usize; 2]>,
    /// Smoothing window (frames) of the camera path and of the velocities.
    pub smooth: usize,
    /// Processing width limit: frames are scaled down so the longer side is at most this many
    /// pixels (flow and segmentation run there).
    pub max_side: usize,
    /// A still image's direction variance (rad², paper §7.2.4): the uniform target of every
    /// occupied cell, since one image shows no motion (the paper sets it by inspection; randomly
    /// aligned animals: π²/3 ≈ 3.29). Required for a still, refused for a video.
    pub dir_variance: Option<f64>,
}

/// Largest shift (video pixels) of a frame corner, in 90 % of the frames, under a registered
/// camera that is still taken for a static camera.
pub const STILL_PX: f64 = 0.5;

/// Cell side (body lengths) of the automatic grid.
pub const AUTO_CELL_BL: f64 = 3.0;

impl Default for ExtractConfig {
    fn default() -> Self {
        ExtractConfig {
            grid: None,
            body_length_px: None,
            body_colour: None,
            colour_threshold: 60.0,
            background_threshold: None,
            body_pixels: None,
            count: None,
            anchors: Vec::new(),
            stabilise: true,
            background: None,
            obstacles: None,
            frames: None,
            smooth: 9,
            max_side: 480,
            dir_variance: None,
        }
    }
}

impl ExtractConfig {
    /// Checks the settings on their own (the frames and anchors are checked against the video
    /// when it is opened); errors name the key.
    pub fn check(&self) -> Result<()> {
        crate::error::check_counts(&[("smooth", self.smooth)])?;
        if let Some(g) = self.grid {
            crate::error::check_counts(&[("grid", g)])?;
            crate::limits::check_grid("grid", g, g)?;
        }
        // Pixels: a body within a frame of at most 65536 pixels a side (issue #47: 1e300
        // divided the density into infinities).
        if let Some(l) = self.body_length_px {
            crate::error::check_positive(&[("body_length_px", l)])?;
            crate::limits::check_magnitude("body_length_px", l, 65536.0)?;
        }
        if let Some([a, b]) = self.frames {
            if a >= b {
                return Err(Error::config("frames", format!("{a}..{b} is empty")));
            }
        }
        if let Some(n) = self.body_pixels {
            if !(n.is_finite() && n > 0.0) {
                return Err(Error::config("body_pixels", format!("{n} must be > 0")));
            }
            crate::limits::check_magnitude("body_pixels", n, 65536.0 * 65536.0)?;
        }
        if let Some(c) = &self.count {
            if c.animals == 0 {
                return Err(Error::config("count", "0 animals: must be ≥ 1"));
            }
            if let Some([a, b]) = self.frames {
                if !(a..b).contains(&c.frame) {
                    return Err(Error::config(
                        "count",
                        format!("frame {} is outside the frames {a}..{b}", c.frame),
                    ));
                }
            }
        }
        let thresholds = [
            ("colour_threshold", Some(self.colour_threshold)),
            ("background_threshold", self.background_threshold),
        ];
        for (key, v) in thresholds {
            if let Some(v) = v {
                if !(v.is_finite() && v >= 0.0) {
                    return Err(Error::config(key, format!("{v} must be ≥ 0")));
                }
                // Differences of 8-bit channels: at most √3 · 255 ≈ 441.7 between two colours.
                crate::limits::check_magnitude(key, v, 442.0)?;
            }
        }
        if let Some(v) = self.dir_variance {
            crate::data::clip::check_dir_spread("dir_variance", v)?;
        }
        if self.max_side < 16 {
            return Err(Error::config(
                "max_side",
                format!("{} must be ≥ 16 pixels", self.max_side),
            ));
        }
        Ok(())
    }
}

/// `b⁻¹ ∘ a`: the identity where the two cameras agree.
fn compose_inverse(a: &Similarity, b: &Similarity) -> Similarity {
    let inv = b.inverse();
    Similarity {
        scale: inv.scale * a.scale,
        angle: inv.angle + a.angle,
        t: inv.apply(a.t),
    }
}

/// Result of an extraction.
pub struct Extraction {
    pub clip: ClipFields,
    /// The calibration used (given or estimated).
    pub calibration: Calibration,
    /// Camera path (frame → first frame), smoothed.
    pub camera: Vec<Similarity>,
    /// Preview PNGs to write (name, bytes).
    pub previews: Vec<(String, Vec<u8>)>,
}

/// Opens the video and checks the frame range and anchors against it; the video is at the first
/// frame of the range `first..last`.
fn open_range(path: &Path, cfg: &ExtractConfig) -> Result<(decode::Video, usize, usize)> {
    cfg.check()?;
    let mut vid = decode::open(path)?;
    let (w, h) = (vid.w, vid.h);
    let (first, last) = match cfg.frames {
        Some([a, b]) => (a, b),
        None => (0, usize::MAX),
    };
    if vid.count > 0 && (first >= vid.count || (last != usize::MAX && last > vid.count)) {
        return Err(Error::config(
            "frames",
            format!(
                "{first}..{last} is out of range: the video has {} frames",
                vid.count
            ),
        ));
    }
    for (k, a) in cfg.anchors.iter().enumerate() {
        let [x, y, aw, ah] = *a;
        if x < 0 || y < 0 || aw < 4 || ah < 4 || (x + aw) as usize > w || (y + ah) as usize > h {
            return Err(Error::config(
                "anchors",
                format!("rectangle {k} ({x},{y},{aw},{ah}) is not at least 4×4 inside the {w}×{h} frame"),
            ));
        }
    }
    if !vid.skip(first)? {
        return Err(Error::config(
            "frames",
            format!("{first}..{last} starts past the end of the video"),
        ));
    }
    Ok((vid, first, last))
}

/// What pass A found: the smoothed camera path of the range, what it came from, with anchors the
/// cross-check against the registration, and the full-resolution frames it kept for the
/// background sample.
struct CameraPass {
    camera: Vec<Similarity>,
    kind: &'static str,
    cross_check: Option<serde_json::Value>,
    kept: decode::Kept,
}

/// Pass A: the camera path of the range (registered, from anchors, or static). It keeps the
/// frames the background will sample when the header's frame count is right about the range and
/// they fit in [`background::KEEP_BYTES`].
fn camera_pass(
    vid: &mut decode::Video,
    path: &Path,
    cfg: &ExtractConfig,
    (first, last): (usize, usize),
    progress: &mut impl FnMut(&str, usize, usize),
) -> Result<CameraPass> {
    let (w, h) = (vid.w, vid.h);
    let registered = cfg.anchors.is_empty() && cfg.stabilise;
    // The frames of the range the header declares.
    let declared = last.min(vid.count).saturating_sub(first);
    let extra = cfg.count.and_then(|c| c.frame.checked_sub(first));
    let (_, mut keep) = background::sample_picks(declared, extra);
    if keep.len() * w * h * 3 > background::KEEP_BYTES {
        keep.clear();
    }
    let (raw, kept) = if registered {
        register::camera_path(vid, path, cfg, (first, last), &keep, &mut *progress)?
    } else {
        camera::camera_path(vid, path, cfg, (first, last), &keep, &mut *progress)?
    };
    if cfg.frames.is_none() && vid.count > 0 && raw.len() < vid.count {
        return Err(Error::file(
            path,
            format!(
                "truncated: only {} of the {} frames its header lists could be read",
                raw.len(),
                vid.count
            ),
        ));
    }
    let frames = raw.len();
    // A truncated file: fewer frames readable than its header declares (one frame of tolerance
    // for containers whose count is estimated from the duration).
    if vid.count > 0 && frames + 1 < declared {
        return Err(Error::file(
            path,
            format!(
                "truncated or damaged: only {frames} of the {declared} frames its header declares                  in {first}..{} are readable",
                first + declared
            ),
        ));
    }
    if frames < 2 {
        return Err(Error::file(
            path,
            format!("only {frames} frame(s) readable in the range: need ≥ 2"),
        ));
    }
    let mut camera = camera::smooth_path(&raw, cfg.smooth);
    // Anchors, cross-checked against the automatic registration: the largest distance between
    // the two paths at a frame corner.
    let cross_check = if !cfg.anchors.is_empty() && cfg.stabilise {
        vid.rewind()?;
        vid.skip(first)?;
        match register::camera_path(vid, path, cfg, (first, last), &[], &mut *progress) {
            Ok((auto, _)) => {
                let auto = camera::smooth_path(&auto, cfg.smooth);
                let worst = camera
                    .iter()
                    .zip(&auto)
                    .map(|(a, b)| camera::corner_shift(&compose_inverse(a, b), w, h))
                    .fold(0.0, f64::max);
                Some(serde_json::json!(worst))
            }
            Err(e) => Some(serde_json::json!(e.to_string())),
        }
    } else {
        None
    };
    // A registered camera that moves the frame corners by less than half a pixel in 90 % of the
    // frames is a static one (the rest: the herd's pull in the first frames, see `register`):
    // the identity, no resampling of the frames.
    let mut shifts: Vec<f64> = camera
        .iter()
        .map(|c| camera::corner_shift(c, w, h))
        .collect();
    shifts.sort_by(f64::total_cmp);
    let still = shifts[(shifts.len() * 9 / 10).min(shifts.len() - 1)] < STILL_PX;
    let camera_kind = if !cfg.anchors.is_empty() {
        "anchors"
    } else if registered && !still {
        "registered"
    } else {
        if registered {
            camera.iter_mut().for_each(|c| *c = Similarity::IDENTITY);
        }
        "static"
    };
    Ok(CameraPass {
        camera,
        kind: camera_kind,
        cross_check,
        kept,
    })
}

/// Runs the extraction. `progress(stage, done, total)` after every processed frame of each pass.
pub fn extract(
    path: &Path,
    cfg: &ExtractConfig,
    preview_every: Option<usize>,
    mut progress: impl FnMut(&str, usize, usize),
) -> Result<Extraction> {
    if is_still(path) {
        return still::extract_still(path, cfg, preview_every.is_some());
    }
    if cfg.dir_variance.is_some() {
        return Err(Error::config(
            "dir_variance",
            "is for a still image (a video's direction variance comes from its optical flow)",
        ));
    }
    decode::tune_allocator();
    let (mut vid, first, last) = open_range(path, cfg)?;
    let (w, h) = (vid.w, vid.h);
    let t_start = std::time::Instant::now();
    let debug = std::env::var_os("HERDFIT_DEBUG").is_some();
    let t = profile::start();
    let CameraPass {
        camera,
        kind: camera_kind,
        cross_check,
        kept,
    } = camera_pass(&mut vid, path, cfg, (first, last), &mut progress)?;
    profile::stop("A camera pass (total)", t);
    let frames = camera.len();
    if debug {
        eprintln!("pass A (camera) done at {:?}", t_start.elapsed());
    }
    let geom = background::Geometry::new(path, w, h, cfg.max_side);
    let count_at = match &cfg.count {
        Some(c) if c.frame < first || c.frame - first >= frames => {
            return Err(Error::config(
                "count",
                format!(
                    "frame {} is outside the {frames} frames read from {first}",
                    c.frame
                ),
            ))
        }
        Some(c) => Some(c.frame - first),
        None => None,
    };
    let t = profile::start();
    let (bg, sample) = background::background(
        &mut vid,
        &geom,
        cfg,
        &camera,
        (first, frames),
        count_at,
        kept,
        &mut progress,
    )?;
    profile::stop("B background (total)", t);
    if debug {
        eprintln!("background done at {:?}", t_start.elapsed());
    }
    let t = profile::start();
    let mut calib = calibrate::calibrate(cfg, &geom, &bg, &sample, count_at)?;
    profile::stop("K calibration (total)", t);
    drop(sample);
    calib.camera = camera_kind.to_string();
    calib.registration_vs_anchors_px = cross_check;
    if debug {
        eprintln!(
            "calibration {}",
            serde_json::to_string(&calib).unwrap_or_default()
        );
    }
    let (body_len, body_px) = (calib.body_length_px, calib.body_pixels);
    let grid = background::CellGrid::new(&geom, calib.grid);
    let obstacles = background::obstacle_cells(cfg, &geom, &grid)?;
    let body_px_proc = body_px * geom.scale * geom.scale;
    let seg = calib.segmenter(&geom, &bg, cfg)?;
    let t = profile::start();
    let sums = fields::pass_c(
        &mut vid,
        &geom,
        &grid,
        &seg,
        body_len,
        &camera,
        (first, frames),
        preview_every,
        &mut progress,
    )?;
    profile::stop("C fields pass (total)", t);
    if debug {
        eprintln!("fields done at {:?}", t_start.elapsed());
    }
    let fields = sums.fields(&grid, cfg.smooth, body_len, body_px_proc);
    let (mean, std_bp) = fields.speed;
    let speed = ClipSpeed {
        mean,
        // §6.2: v_σ = v_σ^bp / √N_bp.
        std: std_bp / body_px.sqrt(),
        density_table: speed_density_table(&fields.samples),
    };
    let source = serde_json::json!({
        "video": path.display().to_string(),
        "first_frame": first,
    });
    let meta = clip_meta(
        (&grid, &geom),
        cfg,
        &calib,
        (vid.fps, frames),
        speed,
        source,
    );
    let out = finish(meta, fields, obstacles, calib, camera, sums.previews);
    profile::report(t_start.elapsed());
    out
}

/// The clip metadata of an extraction: grid and scale from the calibration, the provenance
/// (`source` — what was read — with the settings and the calibration).
fn clip_meta(
    (grid, geom): (&background::CellGrid, &background::Geometry),
    cfg: &ExtractConfig,
    calib: &Calibration,
    (fps, frames): (f64, usize),
    speed: ClipSpeed,
    source: serde_json::Value,
) -> ClipMeta {
    let mut provenance = serde_json::json!({
        "source": "extract",
        "video_size": [geom.w, geom.h],
        "processing_scale": geom.scale,
        "settings": cfg,
        "calibration": calib,
    });
    if let (Some(p), serde_json::Value::Object(src)) = (provenance.as_object_mut(), source) {
        p.extend(src);
    }
    ClipMeta {
        schema: CLIP_SCHEMA.into(),
        fps,
        cell_size: grid.cell_px / calib.body_length_px,
        nx: grid.nx,
        ny: grid.ny,
        frames,
        origin: [0.0, 0.0],
        body_length_px: Some(calib.body_length_px),
        body_pixel_coverage: Some(calib.body_pixels),
        speed,
        dir_spread: None,
        frame_measures: None,
        provenance,
    }
}

/// The extraction's clip (validated) from its metadata, fields and obstacle cells, with what it
/// came from.
fn finish(
    meta: ClipMeta,
    fields: fields::Fields,
    obstacles: ndarray::Array2<u8>,
    calibration: Calibration,
    camera: Vec<Similarity>,
    previews: Vec<(String, Vec<u8>)>,
) -> Result<Extraction> {
    let clip = ClipFields {
        meta,
        density: fields.density,
        velocity: fields.velocity,
        dir_variance: fields.dir_variance,
        obstacles,
    };
    clip.validate()?;
    Ok(Extraction {
        clip,
        calibration,
        camera,
        previews,
    })
}
