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
mod camera;
mod decode;
mod fields;
mod job;
mod preview;

pub use camera::Similarity;
pub use decode::quietly;
pub use job::{run, ExtractJob, CENTRE_ANCHOR};

use crate::data::clip::BODY_WIDTH_BL;
use crate::data::{ClipFields, ClipMeta, ClipSpeed, CLIP_SCHEMA};
use crate::error::{Error, Result};
use crate::measure::speed_density_table;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Every setting of an extraction (recorded in `clip.json`; loadable with `--config`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtractConfig {
    /// Cells along the longer side of the frame.
    pub grid: usize,
    /// Body length in pixels.
    pub body_length_px: f64,
    /// Body colour (RGB) for the colour-distance test; none: background difference only.
    pub body_colour: Option<[u8; 3]>,
    /// Largest Euclidean RGB distance to the body colour of a herd pixel.
    pub colour_threshold: f64,
    /// Smallest per-channel difference to the background of a herd pixel.
    pub background_threshold: f64,
    /// Body pixels per animal; estimated as an ellipse of L × [`BODY_WIDTH_BL`]·L when absent.
    pub body_pixels: Option<f64>,
    /// Anchor rectangles x,y,w,h in the first frame; empty: static camera.
    pub anchors: Vec<[i32; 4]>,
    /// Background image; none: per-pixel temporal median of sampled stabilised frames.
    pub background: Option<PathBuf>,
    /// Obstacle mask (non-zero = obstacle), the size of the video frame.
    pub obstacles: Option<PathBuf>,
    /// Frames used, start..end (end exclusive); all when absent.
    pub frames: Option<[usize; 2]>,
    /// Smoothing window (frames) of the camera path and of the velocities.
    pub smooth: usize,
    /// Processing width limit: frames are scaled down so the longer side is at most this many
    /// pixels (flow and segmentation run there).
    pub max_side: usize,
}

impl Default for ExtractConfig {
    fn default() -> Self {
        ExtractConfig {
            grid: 20,
            body_length_px: 10.0,
            body_colour: None,
            colour_threshold: 60.0,
            background_threshold: 30.0,
            body_pixels: None,
            anchors: Vec::new(),
            background: None,
            obstacles: None,
            frames: None,
            smooth: 9,
            max_side: 480,
        }
    }
}

impl ExtractConfig {
    /// Checks the settings on their own (the frames and anchors are checked against the video
    /// when it is opened); errors name the key.
    pub fn check(&self) -> Result<()> {
        crate::error::check_counts(&[("grid", self.grid), ("smooth", self.smooth)])?;
        crate::limits::check_grid("grid", self.grid, self.grid)?;
        crate::error::check_positive(&[("body_length_px", self.body_length_px)])?;
        if let Some([a, b]) = self.frames {
            if a >= b {
                return Err(Error::config("frames", format!("{a}..{b} is empty")));
            }
        }
        if let Some(n) = self.body_pixels {
            if !(n.is_finite() && n > 0.0) {
                return Err(Error::config("body_pixels", format!("{n} must be > 0")));
            }
        }
        for (key, v) in [
            ("colour_threshold", self.colour_threshold),
            ("background_threshold", self.background_threshold),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::config(key, format!("{v} must be ≥ 0")));
            }
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

/// Result of an extraction.
pub struct Extraction {
    pub clip: ClipFields,
    /// Camera path (frame → first frame), smoothed.
    pub camera: Vec<Similarity>,
    /// Preview PNGs to write (name, bytes).
    pub previews: Vec<(String, Vec<u8>)>,
}

/// Runs the extraction. `progress(stage, done, total)` after every processed frame of each pass.
pub fn extract(
    path: &Path,
    cfg: &ExtractConfig,
    preview_every: Option<usize>,
    mut progress: impl FnMut(&str, usize, usize),
) -> Result<Extraction> {
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
    let t_start = std::time::Instant::now();
    let debug = std::env::var_os("HERDFIT_DEBUG").is_some();
    let raw = camera::camera_path(&mut vid, path, cfg, (first, last), &mut progress)?;
    let frames = raw.len();
    // A truncated file: fewer frames readable than its header declares (one frame of tolerance
    // for containers whose count is estimated from the duration).
    let declared = last.min(vid.count).saturating_sub(first);
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
    if debug {
        eprintln!("pass A (camera) done at {:?}", t_start.elapsed());
    }
    let camera = camera::smooth_path(&raw, cfg.smooth);
    let geom = background::Geometry::new(path, w, h, cfg.max_side);
    let bg = background::background(
        &mut vid,
        &geom,
        cfg,
        &camera,
        (first, frames),
        &mut progress,
    )?;
    if debug {
        eprintln!("background done at {:?}", t_start.elapsed());
    }
    let grid = background::CellGrid::new(&geom, cfg.grid);
    let obstacles = background::obstacle_cells(cfg, &geom, &grid)?;
    let body_px = cfg.body_pixels.unwrap_or(
        std::f64::consts::PI / 4.0 * cfg.body_length_px * BODY_WIDTH_BL * cfg.body_length_px,
    );
    if !(body_px.is_finite() && body_px > 0.0) {
        return Err(Error::config(
            "body_pixels",
            format!("{body_px} must be > 0"),
        ));
    }
    let body_px_proc = body_px * geom.scale * geom.scale;
    let sums = fields::pass_c(
        &mut vid,
        &geom,
        &grid,
        cfg,
        &camera,
        &bg,
        (first, frames),
        preview_every,
        &mut progress,
    )?;
    if debug {
        eprintln!("fields done at {:?}", t_start.elapsed());
    }
    let fields = sums.fields(&grid, cfg, body_px_proc);
    let (mean, std_bp) = fields.speed;
    let clip = ClipFields {
        meta: ClipMeta {
            schema: CLIP_SCHEMA.into(),
            fps: vid.fps,
            cell_size: grid.cell_px / cfg.body_length_px,
            nx: grid.nx,
            ny: grid.ny,
            frames,
            origin: [0.0, 0.0],
            body_length_px: Some(cfg.body_length_px),
            body_pixel_coverage: Some(body_px),
            speed: ClipSpeed {
                mean,
                // §6.2: v_σ = v_σ^bp / √N_bp.
                std: std_bp / body_px.sqrt(),
                density_table: speed_density_table(&fields.samples),
            },
            provenance: serde_json::json!({
                "source": "extract",
                "video": path.display().to_string(),
                "video_size": [w, h],
                "first_frame": first,
                "processing_scale": geom.scale,
                "settings": cfg,
            }),
        },
        density: fields.density,
        velocity: fields.velocity,
        dir_variance: fields.dir_variance,
        obstacles,
    };
    clip.validate()?;
    Ok(Extraction {
        clip,
        camera,
        previews: sums.previews,
    })
}
