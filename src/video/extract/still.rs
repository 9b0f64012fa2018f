//! A still image (`.png`, `.jpg`, …) → a one-frame clip (paper §7.2.4): density from the
//! segmented herd pixels exactly as a video's frame (the same calibration: threshold, body length
//! and pixels per animal from the isolated animals, or given), no velocity, and the user's
//! uniform direction variance (`dir_variance`, set by inspection as the paper does) in every
//! occupied cell. `herdfit fit` fits such a clip as a stationary target
//! ([`crate::herd::fit::still`]).
//!
//! The background is `background` when given (best: the bare ground), else the image's median
//! over a window of an eighth of its longer side, which removes animals that cover less than half
//! of any such window (for denser herds give the background).

use super::background::{obstacle_cells, CellGrid, Geometry, Sample};
use super::calibrate::calibrate;
use super::camera::Similarity;
use super::decode::cv;
use super::fields::Sums;
use super::preview::preview_png;
use super::{ExtractConfig, Extraction};
use crate::data::ClipSpeed;
use crate::error::{Error, Result};
use opencv::core::Mat;
use opencv::prelude::*;
use opencv::{imgcodecs, imgproc};
use std::path::Path;

/// Image extensions read as a still rather than a video.
const STILL_EXTENSIONS: [&str; 7] = ["png", "jpg", "jpeg", "bmp", "tif", "tiff", "webp"];

/// Whether `path` names a still image (by its extension).
pub fn is_still(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| STILL_EXTENSIONS.iter().any(|s| e.eq_ignore_ascii_case(s)))
}

/// The settings a still cannot use, named with their keys.
fn check_still(cfg: &ExtractConfig) -> Result<()> {
    cfg.check()?;
    if !cfg.anchors.is_empty() {
        return Err(Error::config(
            "anchors",
            "a still image has no camera motion to track",
        ));
    }
    if cfg.frames.is_some_and(|f| f != [0, 1]) {
        return Err(Error::config("frames", "a still image has one frame, 0..1"));
    }
    if let Some(c) = cfg.count.filter(|c| c.frame != 0) {
        return Err(Error::config(
            "count",
            format!("frame {}: a still image has only frame 0", c.frame),
        ));
    }
    Ok(())
}

/// The still's direction variance, which the user must give.
fn dir_variance(path: &Path, cfg: &ExtractConfig) -> Result<f64> {
    cfg.dir_variance.ok_or_else(|| {
        Error::file(
            path,
            "a still image shows no motion: give its direction variance with --dir-variance V \
             (rad², set by inspection; randomly aligned animals: π²/3 ≈ 3.29, aligned: 0)",
        )
    })
}

/// Shortest body (processing pixels) taken for an animal when the body length is estimated:
/// shorter isolated components are the ground's texture or noise (an image without animals).
pub const MIN_STILL_BODY_PX: f64 = 6.0;

/// The image's own background: its per-channel median over a window of an eighth of the
/// processing frame's longer side.
fn median_background(img: &Mat, geom: &Geometry) -> Result<Vec<u8>> {
    let k = ((geom.pw.max(geom.ph) / 8) | 1).max(3) as i32;
    let mut bg = Mat::default();
    imgproc::median_blur(img, &mut bg, k).map_err(cv(geom.path))?;
    Ok(bg.data_bytes().map_err(cv(geom.path))?.to_vec())
}

/// Extracts the one-frame clip of the still at `path`; with `preview`, one preview PNG.
pub(super) fn extract_still(path: &Path, cfg: &ExtractConfig, preview: bool) -> Result<Extraction> {
    check_still(cfg)?;
    crate::data::atomic::note_input(path);
    if !path.is_file() {
        return Err(Error::file(path, "no such image file"));
    }
    let img =
        super::decode::quietly(|| imgcodecs::imread(path.as_os_str(), imgcodecs::IMREAD_COLOR))
            .map_err(cv(path))?;
    if img.empty() {
        return Err(Error::file(path, "cannot read as an image"));
    }
    let dir_variance = dir_variance(path, cfg)?;
    let (w, h) = (img.cols() as usize, img.rows() as usize);
    let geom = Geometry::new(path, w, h, cfg.max_side);
    let mut small = Mat::default();
    geom.warp(&img, &Similarity::IDENTITY, &mut small, imgproc::INTER_AREA)?;
    let px = small.data_bytes().map_err(cv(path))?.to_vec();
    let vm = vec![255u8; geom.pw * geom.ph];
    let bg = match &cfg.background {
        Some(b) => {
            let bimg = geom.image(b, imgcodecs::IMREAD_COLOR)?;
            let mut out = Mat::default();
            geom.warp(&bimg, &Similarity::IDENTITY, &mut out, imgproc::INTER_AREA)?;
            out.data_bytes().map_err(cv(b))?.to_vec()
        }
        None => median_background(&small, &geom)?,
    };
    let sample = Sample {
        frames: vec![(0, px.clone(), vm.clone())],
    };
    let mut calib = calibrate(cfg, &geom, &bg, &sample, cfg.count.map(|_| 0))?;
    calib.camera = "still".to_string();
    let body_proc = calib.body_length_px * geom.scale;
    if cfg.body_length_px.is_none() && body_proc < MIN_STILL_BODY_PX {
        return Err(Error::file(
            path,
            format!(
                "no animals found: the isolated components are {body_proc:.1} pixels long at the \
                 processing scale (< {MIN_STILL_BODY_PX}: the ground's texture or noise); give \
                 --body-length-px or --background if the animals are that small"
            ),
        ));
    }
    let grid = CellGrid::new(&geom, calib.grid);
    let obstacles = obstacle_cells(cfg, &geom, &grid)?;
    let seg = calib.segmenter(&geom, &bg, cfg)?;
    let herd = seg.mask(&px, &vm)?;
    let count = grid.herd_pixels(&herd);
    if count.iter().all(|&n| n == 0.0) {
        return Err(Error::file(
            path,
            format!(
                "no animals found: no pixel stands out of the background by more than {:.0} grey \
                 levels in components of ≥ {} pixels",
                calib.threshold, calib.min_component_px
            ),
        ));
    }
    let body_len = calib.body_length_px;
    let body_px_proc = calib.body_pixels * geom.scale * geom.scale;
    let sums = Sums::still(count, dir_variance, body_px_proc);
    let previews = match preview {
        false => Vec::new(),
        true => vec![(
            "preview-00000.png".to_string(),
            preview_png(&small, &herd, &sums.count[0], &sums.fsum[0], &grid, &geom)?,
        )],
    };
    let fields = sums.fields(&grid, 1, body_len, body_px_proc);
    // No motion is seen: the fit takes the start set's speed model. A still has no frame rate of
    // its own: the fit steps it at the usual 25 fps.
    let speed = ClipSpeed {
        mean: 0.0,
        std: 0.0,
        density_table: Vec::new(),
    };
    let source = serde_json::json!({"still": path.display().to_string()});
    let mut meta = super::clip_meta((&grid, &geom), cfg, &calib, (25.0, 1), speed, source);
    meta.dir_spread = Some(dir_variance);
    super::finish(
        meta,
        fields,
        obstacles,
        calib,
        vec![Similarity::IDENTITY],
        previews,
    )
}
