//! The lift section of `herdfit demo`: a synthetic boids flock seen by a ground observer, lifted
//! back to 3D by both methods, scored against its truth, drawn and exported to glTF.

use super::boids::{synth_flock, BoidsConfig};
use super::eval::{evaluate, MethodScore};
use super::render::{render_glb, views_png, Layer, COLOURS};
use super::LiftConfig;
use crate::data::gltf::{export_glb, GltfConfig};
use crate::error::{Error, Result};
use crate::progress::Progress;
use std::fmt;
use std::path::{Path, PathBuf};

/// What the demo did, printable for a newcomer.
#[derive(Clone, Debug)]
pub struct DemoSummary {
    pub birds: usize,
    pub frames: usize,
    pub observations: usize,
    pub mean_depth: f64,
    /// The flock's median diameter (m).
    pub extent: f64,
    pub scores: Vec<MethodScore>,
    pub folder: PathBuf,
    pub glb: PathBuf,
}

impl fmt::Display for DemoSummary {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        writeln!(
            f,
            "lift: {} synthetic birds × {} frames seen from the ground ({} tracked points, mean depth {:.0} m, flock {:.0} m across), lifted back to 3D:",
            self.birds, self.frames, self.observations, self.mean_depth, self.extent
        )?;
        writeln!(
            f,
            "  {:<36} {:>12} {:>14} {:>10} {:>16}",
            "depth estimate", "depth RMSE", "3D RMSE (m)", "/ extent", "closest pair (m)"
        )?;
        for s in &self.scores {
            let name = match s.name.as_str() {
                "true_mean_depth" => "(a) true mean depth of each frame",
                "constant_median" => "(b) constant, middle of the bounds",
                "frame_by_frame" => "(c) frame by frame (thesis)",
                _ => "(d) whole sequence (L-BFGS)",
            };
            writeln!(
                f,
                "  {name:<36} {:>11.1}% {:>14.2} {:>10.2} {:>16.2}",
                100.0 * s.depth_rmse_relative,
                s.position_rmse,
                s.position_rmse_per_extent,
                s.checks.min_distance.unwrap_or(f64::NAN)
            )?;
        }
        write!(
            f,
            "  wrote {}: tracks2d.csv (input), truth3d.csv, lifted3d.csv, eval.json, top.png, side.png, {} (glTF), flock_render.png",
            self.folder.display(),
            self.glb.file_name().map_or("flock.glb".into(), |f| f.to_string_lossy())
        )
    }
}

/// The settings the demo lifts with: the thesis's weights, v_target = the flock's cruise speed
/// per frame, bounds 20–400 m.
pub fn demo_config(boids: &BoidsConfig) -> LiftConfig {
    LiftConfig {
        v_target: Some(boids.cruise / boids.fps),
        d_near: Some(20.0),
        d_far: Some(400.0),
        ..LiftConfig::default()
    }
}

/// Runs the lift demo into `out` (a folder `lift/` is made there).
pub fn demo(out: &Path, progress: &mut dyn Progress) -> Result<DemoSummary> {
    let dir = out.join("lift");
    crate::data::atomic::make_dir(&dir)?;
    // Small enough for the demo's time budget (RESULTS.md §5 has the timing); the 40° view makes
    // birds leave and enter it.
    let boids = BoidsConfig::demo();
    let syn = synth_flock(&boids, progress)?;
    syn.truth.save(&dir.join("truth3d.csv"))?;
    syn.tracks.save(&dir.join("tracks2d.csv"))?;
    syn.camera.save(&dir.join("camera.json"))?;
    let cfg = demo_config(&boids);
    let ev = evaluate(&syn.truth, &syn.camera, &cfg, boids.crop, progress)?;
    let text = serde_json::to_string_pretty(&ev.report)
        .map_err(|e| Error::Internal(format!("serialising report: {e}")))?;
    crate::data::atomic::write_atomic(&dir.join("eval.json"), format!("{text}\n").as_bytes())?;
    let lifted = ev.obs.tracks_3d(
        &ev.depths[3],
        serde_json::json!({"source": "herdfit demo: whole-sequence lift of tracks2d.csv"}),
    )?;
    lifted.save(&dir.join("lifted3d.csv"))?;
    let fbf = ev.obs.tracks_3d(&ev.depths[2], serde_json::Value::Null)?;
    let seen = ev.obs.tracks_3d(&ev.truth_depth, serde_json::Value::Null)?;
    views_png(
        &dir.join("top.png"),
        &dir.join("side.png"),
        "synthetic flock",
        &[
            Layer {
                name: "truth",
                tracks: &seen,
                colour: COLOURS[0],
            },
            Layer {
                name: "frame by frame",
                tracks: &fbf,
                colour: COLOURS[2],
            },
            Layer {
                name: "whole sequence",
                tracks: &lifted,
                colour: COLOURS[1],
            },
        ],
        &syn.camera,
    )?;
    let glb = dir.join("flock.glb");
    let g = export_glb(&lifted, &GltfConfig::default(), &glb)?;
    render_glb(
        &glb,
        0.5 * g.duration,
        &syn.camera,
        &dir.join("flock_render.png"),
    )?;
    Ok(DemoSummary {
        birds: ev.report.birds,
        frames: ev.report.frames,
        observations: ev.report.observations,
        mean_depth: ev.report.truth.mean_depth,
        extent: ev.report.truth.extent,
        scores: ev.report.methods,
        folder: dir,
        glb,
    })
}
