//! An authored scene as `herdfit author` writes it: `trajectories.csv`, `navigation.png`, three
//! snapshots, `report.json` (centroid path and the measures of each behaviour region) and
//! optionally `herd.avi`.

use super::{run as simulate_scene, AuthorRun, Scene};
use crate::backend::{device, Compute, Precision};
use crate::data::agents::{push_traj_frame, AgentRow, TRAJ_HEADER};
use crate::data::atomic::AtomicDir;
use crate::error::{Error, Result};
use crate::measure::{aspect_ratio, polarization};
use crate::progress::Progress;
use std::path::PathBuf;

type P2 = [f64; 2];

/// Schema tag of an authored scene's `report.json`.
pub const AUTHORING_SCHEMA: &str = "herdfit.authoring/1";

/// A scene with its outputs.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AuthorJob {
    pub scene: PathBuf,
    /// The output folder.
    pub out: PathBuf,
    /// Also render the herd over the scene as an MJPG AVI (feature `video`).
    pub video: bool,
    /// Video scale: pixels per body length.
    pub px_per_bl: f64,
    /// Where the model's tensors live (`--device`). Not written when `cpu`.
    #[serde(default, skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
}

impl Default for AuthorJob {
    fn default() -> Self {
        AuthorJob {
            scene: PathBuf::from("scene.json"),
            out: PathBuf::from("author"),
            video: false,
            px_per_bl: 8.0,
            device: Compute::Cpu,
        }
    }
}

impl AuthorJob {
    /// Checks the video scale when a video is asked for (at least 2 pixels per body length).
    pub fn check(&self) -> Result<()> {
        crate::limits::check_px_per_bl(self.px_per_bl)
    }
}

/// What `herdfit author` prints: the herd, the run's length and where its centroid went.
#[derive(Clone, Debug, PartialEq)]
pub struct AuthorSummary {
    pub agents: usize,
    pub frames: usize,
    pub fps: f64,
    pub centroid: Vec<P2>,
    pub out: PathBuf,
}

/// The herd's centroid in every frame.
pub fn centroids(frames: &[Vec<AgentRow>]) -> Vec<P2> {
    frames
        .iter()
        .map(|rows| {
            let n = rows.len().max(1) as f64;
            [
                rows.iter().map(|a| a.x).sum::<f64>() / n,
                rows.iter().map(|a| a.y).sum::<f64>() / n,
            ]
        })
        .collect()
}

/// Per behaviour set (0 = default, k = region k − 1): the frames in which at least 5 agents use
/// it, their mean number, and the mean polarization (eq. 12) and aspect ratio of those agents.
pub fn region_measures(r: &AuthorRun, sets: usize) -> Vec<serde_json::Value> {
    let mut per_region = Vec::new();
    for g in 0..sets {
        let (mut pol, mut asp, mut frames) = (0.0, 0.0, 0usize);
        let mut agents_seen = 0usize;
        for (rows, reg) in r.frames.iter().zip(&r.regions) {
            let sel: Vec<&AgentRow> = rows
                .iter()
                .zip(reg)
                .filter(|(_, &x)| x == g)
                .map(|(a, _)| a)
                .collect();
            if sel.len() < 5 {
                continue;
            }
            let pos: Vec<[f64; 2]> = sel.iter().map(|a| [a.x, a.y]).collect();
            let vel: Vec<[f64; 2]> = sel.iter().map(|a| [a.vx, a.vy]).collect();
            let w = vec![1.0; sel.len()];
            pol += polarization(&vel, &w);
            asp += aspect_ratio(&pos, &vel, &w).unwrap_or(f64::NAN);
            frames += 1;
            agents_seen += sel.len();
        }
        per_region.push(serde_json::json!({
            "set": g,
            "frames": frames,
            "mean_agents": if frames > 0 { agents_seen as f64 / frames as f64 } else { 0.0 },
            "polarization": if frames > 0 { pol / frames as f64 } else { f64::NAN },
            "aspect_ratio": if frames > 0 { asp / frames as f64 } else { f64::NAN },
        }));
    }
    per_region
}

/// Simulates the scene and writes the output folder.
pub fn run(job: &AuthorJob, progress: &mut dyn Progress) -> Result<AuthorSummary> {
    job.check()?;
    let scene = Scene::load(&job.scene)?;
    let out = AtomicDir::create(&job.out)?;
    let device = device(job.device, Precision::F32)?;
    let steps = (scene.file.duration * scene.file.fps).round() as u64;
    progress.start("author", steps);
    let r = simulate_scene(&scene, &device, || progress.inc(1))?;
    progress.finish();
    let fps = scene.file.fps;
    let mut csv = String::from(TRAJ_HEADER);
    csv.push('\n');
    for (f, (rows, roles)) in r.frames.iter().zip(&r.roles).enumerate() {
        push_traj_frame(&mut csv, f, f as f64 / fps, rows, roles);
    }
    out.write("trajectories.csv", csv.as_bytes())?;
    plots(&scene, &r, &out)?;
    let centroid = centroids(&r.frames);
    let mut report = serde_json::json!({
        "schema": AUTHORING_SCHEMA,
        "scene": job.scene.display().to_string(),
        "agents": r.frames[0].len(),
        "frames": r.frames.len(),
        "fps": fps,
        "centroid": centroid,
        "regions": region_measures(&r, scene.params.len()),
        "predator": r.predator,
    });
    if !job.device.is_cpu() {
        report["device"] = serde_json::json!(job.device);
    }
    // Through the scene's sources and sinks: what entered, what left (left, right, bottom,
    // top) and the count in the world frame by frame.
    if let Some(c) = &r.crossings {
        let in_world = |rows: &Vec<AgentRow>| {
            rows.iter()
                .filter(|a| scene.grid.cell_of([a.x, a.y]).is_some())
                .count()
        };
        report["boundary"] = serde_json::json!({
            "entered": c.entered,
            "left": c.left,
            "count": r.frames.iter().map(in_world).collect::<Vec<_>>(),
        });
    }
    out.write(
        "report.json",
        serde_json::to_string_pretty(&report)
            .map_err(|e| Error::Internal(e.to_string()))?
            .as_bytes(),
    )?;
    #[cfg(feature = "video")]
    if job.video {
        let cfg = crate::video::RenderConfig {
            px_per_bl: job.px_per_bl,
            body_rgb: [235, 235, 225],
            camera_motion: false,
            seed: scene.file.seed,
        };
        let (_, pending) = crate::video::render_video(
            &out.path("herd.avi"),
            &r.frames,
            &scene.grid,
            &scene.obstacles,
            fps,
            &cfg,
            || {},
        )?;
        pending.commit()?;
    }
    #[cfg(not(feature = "video"))]
    if job.video {
        return Err(Error::config("video", "needs the `video` feature (OpenCV)"));
    }
    out.commit()?;
    Ok(AuthorSummary {
        agents: r.frames[0].len(),
        frames: r.frames.len(),
        fps,
        centroid,
        out: job.out.clone(),
    })
}

/// `navigation.png` (the field, obstacles, arrows and the predator's path) and three snapshots
/// coloured by behaviour region (first, middle and last frame).
fn plots(scene: &Scene, r: &AuthorRun, out: &AtomicDir) -> Result<()> {
    let mut lines = scene.file.arrows.clone();
    if let Some(p) = &scene.file.predator {
        lines.push(p.path.clone());
    }
    crate::plot::scene_plot(
        &out.path("navigation.png"),
        "navigation field",
        &scene.grid,
        &scene.obstacles,
        Some(&r.navigation),
        &lines,
        &[],
    )?;
    let n = r.frames.len();
    for (k, f) in [0, n / 2, n - 1].into_iter().enumerate() {
        let agents: Vec<([f64; 2], usize)> = r.frames[f]
            .iter()
            .zip(&r.regions[f])
            .map(|(a, &g)| ([a.x, a.y], g))
            .collect();
        crate::plot::scene_plot(
            &out.path(&format!("snapshot-{k}.png")),
            &format!(
                "t = {:.1} s (colour = behaviour region)",
                f as f64 / scene.file.fps
            ),
            &scene.grid,
            &scene.obstacles,
            None,
            &lines,
            &agents,
        )?;
    }
    Ok(())
}

impl std::fmt::Display for AuthorSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let (first, last) = (self.centroid[0], self.centroid[self.frames - 1]);
        write!(
            f,
            "author: {} agents, {} frames ({:.1} s); centroid ({:.1}, {:.1}) → ({:.1}, {:.1}); wrote {}",
            self.agents,
            self.frames,
            (self.frames - 1) as f64 / self.fps,
            first[0],
            first[1],
            last[0],
            last[1],
            self.out.display()
        )
    }
}
