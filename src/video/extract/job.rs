//! An extraction as `herdfit extract` runs it: the video, the settings, the clip folder written
//! (`fields.npz`, `clip.json`, `camera.json`, `extract-report.png`: the calibration on one page)
//! and the optional preview folder.

use super::{extract, ExtractConfig, Extraction};
use crate::data::atomic::AtomicDir;
use crate::error::{Error, Result};
use crate::progress::Progress;
use std::path::{Path, PathBuf};

/// An anchor rectangle that stands for the central quarter of the first frame (the `center`
/// anchor of the command line), resolved when the video is opened.
pub const CENTRE_ANCHOR: [i32; 4] = [-1, -1, -1, -1];

/// An extraction with its files.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ExtractJob {
    pub video: PathBuf,
    /// The clip folder written.
    pub out: PathBuf,
    /// A folder for preview PNGs (density and velocity over the stabilised frame).
    pub preview: Option<PathBuf>,
    /// One preview every N frames.
    pub preview_every: usize,
    /// The settings; anchors equal to [`CENTRE_ANCHOR`] are resolved from the video's size.
    pub config: ExtractConfig,
}

impl Default for ExtractJob {
    fn default() -> Self {
        ExtractJob {
            video: PathBuf::from("herd.avi"),
            out: PathBuf::from("clip"),
            preview: None,
            preview_every: 25,
            config: ExtractConfig::default(),
        }
    }
}

impl ExtractJob {
    /// Checks the settings ([`ExtractConfig::check`]).
    pub fn check(&self) -> Result<()> {
        if self.preview.is_some() && self.preview_every == 0 {
            return Err(crate::error::Error::config(
                "preview_every",
                "0 must be ≥ 1 (one preview every N frames)",
            ));
        }
        self.config.check()
    }
}

/// `cfg` with every [`CENTRE_ANCHOR`] replaced by the central quarter of `video`'s frame.
fn resolve_centre(video: &Path, cfg: &ExtractConfig) -> Result<ExtractConfig> {
    let mut cfg = cfg.clone();
    if cfg.anchors.iter().any(|a| a[0] < 0 && a[2] < 0) {
        let probe =
            opencv::videoio::VideoCapture::from_file(video.as_os_str(), opencv::videoio::CAP_ANY)
                .ok()
                .and_then(|c| {
                    use opencv::prelude::VideoCaptureTraitConst;
                    Some((
                        c.get(opencv::videoio::CAP_PROP_FRAME_WIDTH).ok()? as i32,
                        c.get(opencv::videoio::CAP_PROP_FRAME_HEIGHT).ok()? as i32,
                    ))
                });
        let (w, h) = probe
            .filter(|p| p.0 > 0)
            .ok_or_else(|| Error::file(video, "cannot open as a video"))?;
        for r in cfg.anchors.iter_mut().filter(|r| r[0] < 0 && r[2] < 0) {
            *r = [w * 3 / 8, h * 3 / 8, w / 4, h / 4];
        }
    }
    Ok(cfg)
}

/// Runs the extraction and writes the clip folder (and the previews).
pub fn run(job: &ExtractJob, progress: &mut dyn Progress) -> Result<Extraction> {
    job.check()?;
    let cfg = resolve_centre(&job.video, &job.config)?;
    // Fail early on an unusable output folder.
    AtomicDir::create(&job.out)?;
    if let Some(d) = &job.preview {
        AtomicDir::create(d)?;
    }
    let mut stage = String::new();
    let ex = extract(
        &job.video,
        &cfg,
        job.preview.as_ref().map(|_| job.preview_every),
        |what, _done, total| {
            if what != stage {
                stage = what.to_string();
                progress.start(what, total as u64);
            }
            progress.inc(1);
        },
    )?;
    progress.finish();
    let cams =
        serde_json::to_string_pretty(&ex.camera).map_err(|e| Error::Internal(e.to_string()))?;
    let report = super::report::report_png(&ex.calibration, &ex.camera)?;
    ex.clip.save(
        &job.out,
        &[
            ("camera.json", format!("{cams}\n").into_bytes()),
            ("extract-report.png", report),
        ],
    )?;
    if let Some(d) = &job.preview {
        let dir = AtomicDir::create(d)?;
        for (name, bytes) in &ex.previews {
            dir.write(name, bytes)?;
        }
        dir.write(
            "report.json",
            b"{\"schema\": \"herdfit.preview/1\", \"source\": \"herdfit extract --preview\"}\n",
        )?;
        dir.commit()?;
    }
    Ok(ex)
}

impl Extraction {
    /// The lines `herdfit extract` prints: the calibration (each value and where it came from);
    /// frames, grid, animals per frame, mean speed.
    pub fn summary(&self, out: &Path) -> String {
        let c = &self.clip;
        let counts: Vec<f64> = (0..c.frames()).map(|f| c.count(f)).collect();
        let k = &self.calibration;
        format!(
            "calibration: body length {:.2} px ({}), {:.1} px per animal ({}), threshold {} ({}), \
             grid {} ({}), camera {}\n\
             extract: {} frames, {}×{} cells of {:.3} BL, {:.1}–{:.1} animals per frame, mean speed {:.3} BL/s; wrote {}",
            k.body_length_px,
            k.body_length_from,
            k.body_pixels,
            k.body_pixels_from,
            k.threshold,
            k.threshold_from,
            k.grid,
            k.grid_from,
            k.camera,
            c.frames(),
            c.meta.nx,
            c.meta.ny,
            c.meta.cell_size,
            counts.iter().cloned().fold(f64::INFINITY, f64::min),
            counts.iter().cloned().fold(0.0, f64::max),
            c.meta.speed.mean,
            out.display()
        )
    }
}
