//! Synthetic clips with known truth: simulate the herd model with given parameters, rasterise the
//! trajectories into clip fields, keep the parameters as `truth.json`.

use crate::backend::{device, Compute, Precision};
use crate::data::agents::{push_traj_frame, AgentRow, TRAJ_HEADER};
use crate::data::atomic::AtomicDir;
use crate::data::cells::read_cells;
use crate::data::{ClipFields, Grid};
use crate::error::{Error, Result};
use crate::herd::params::Params;
use crate::herd::sim::obstacle_map;
use crate::herd::sim::{
    random_herd, theta_tensor, Decide, Guidance, HerdSpec, HerdState, Model, StepDecisions, World,
};
use crate::herd::simulate::load_params;
use crate::measure::rasterise;
use crate::progress::Progress;
use ndarray::Array2;
use rand::SeedableRng;
use std::path::PathBuf;

/// Settings of a synthetic clip.
#[derive(Clone, Debug)]
pub struct SynthConfig {
    pub params: Params,
    pub agents: usize,
    /// Number of frames (frame 0 included).
    pub frame_count: usize,
    pub fps: f64,
    pub grid: Grid,
    pub obstacles: Array2<u8>,
    pub seed: u64,
    /// Direction of travel (and of the uniform guidance), degrees from +x.
    pub heading_deg: f64,
    pub precision: Precision,
    /// Agents per BL² of the starting square.
    pub density: f64,
    /// Headings uniform on the circle and no guidance: randomly aligned agents centred on the
    /// grid (a one-frame clip of them is a still, paper §7.2.4).
    pub random_headings: bool,
}

impl SynthConfig {
    /// Checks the herd, frames, frame rate and grid; errors name the key.
    pub fn check(&self) -> Result<()> {
        if self.agents == 0 {
            return Err(Error::config("agents", "the herd is empty: must be ≥ 1"));
        }
        crate::error::check_counts(&[("frame_count", self.frame_count)])?;
        crate::limits::check_fps("fps", self.fps)?;
        crate::limits::check_count("agents", self.agents, crate::limits::MAX_AGENTS)?;
        let g = &self.grid;
        crate::limits::check_grid("grid", g.nx, g.ny)?;
        // Fields (density, 2 velocity, direction variance: 4 f32 per cell and frame) and the
        // trajectories (5 f64 and a role per agent and frame).
        let cells = (g.nx * g.ny) as f64 * self.frame_count as f64;
        let rows = self.agents as f64 * self.frame_count as f64;
        crate::limits::check_memory("frame_count", "the clip", cells * 16.0 + rows * 48.0)?;
        if g.nx == 0 || g.ny == 0 || !(g.cell_size.is_finite() && g.cell_size > 0.0) {
            return Err(Error::config(
                "grid",
                "must have ≥ 1 cell each way and a cell size > 0",
            ));
        }
        if self.obstacles.dim() != (g.ny, g.nx) {
            return Err(Error::config(
                "obstacles",
                format!(
                    "is {:?}, the grid is {}×{}",
                    self.obstacles.dim(),
                    g.ny,
                    g.nx
                ),
            ));
        }
        crate::limits::check_range("heading_deg", self.heading_deg, -360.0, 360.0, "degrees")?;
        if !(self.density.is_finite() && self.density > 0.0 && self.density <= 100.0) {
            return Err(Error::config(
                "density",
                format!("{} agents/BL² is out of range (0, 100]", self.density),
            ));
        }
        Ok(())
    }
}

/// A synthetic clip: the fields, the trajectories (one list per frame) and their CSV text.
pub struct Synth {
    pub clip: ClipFields,
    pub frames: Vec<Vec<AgentRow>>,
    pub roles: Vec<Vec<bool>>,
}

/// Runs the model with the known parameters: a herd crossing the field behind a uniform guidance
/// direction, starting upstream of the grid's centre.
pub fn synthesise(
    cfg: &SynthConfig,
    device: &burn::tensor::Device,
    progress: impl FnMut(),
) -> Result<Synth> {
    synthesise_zoned(cfg, None, device, progress)
}

/// [`synthesise`], with one parameter set per zone when `zones` is given (each agent takes its
/// zone's set every step, [`crate::herd::zoned`]; `cfg.params` gives the speed model and the
/// constants).
pub fn synthesise_zoned(
    cfg: &SynthConfig,
    zones: Option<&crate::herd::zoned::ZoneSets>,
    device: &burn::tensor::Device,
    mut progress: impl FnMut(),
) -> Result<Synth> {
    cfg.check()?;
    let g = &cfg.grid;
    let a = cfg.heading_deg.to_radians();
    let dir = [a.cos(), a.sin()];
    let size = g.size();
    let centre = [g.origin[0] + size[0] / 2.0, g.origin[1] + size[1] / 2.0];
    // Randomly aligned agents rest on the grid's centre; a travelling herd starts upstream of it.
    let upstream = if cfg.random_headings { 0.0 } else { 0.2 };
    let spec = HerdSpec {
        agents: cfg.agents,
        density: cfg.density,
        centre: [
            centre[0] - upstream * size[0] * dir[0],
            centre[1] - upstream * size[1] * dir[1],
        ],
        heading_deg: cfg.heading_deg,
        heading_spread_deg: if cfg.random_headings {
            f64::INFINITY
        } else {
            20.0
        },
    };
    let world = World {
        obstacles: Some(obstacle_map(g, &cfg.obstacles)),
        guidance: if cfg.random_headings {
            Guidance::None
        } else {
            Guidance::Uniform(dir)
        },
        fixed_speed: zones.and_then(|z| z.zones.speed_map(&z.grid)),
    };
    let mut init = random_herd(&spec, &cfg.params.speed, &world, cfg.seed)?;
    if let Some(m) = &world.fixed_speed {
        crate::herd::start::fix_speeds(&mut init, m, &cfg.params.speed);
    }
    let ids: Vec<u64> = init.iter().map(|r| r.id).collect();
    let model = Model {
        params: cfg.params.clone(),
        world,
        dt: 1.0 / cfg.fps,
        force_kernel: crate::herd::sim::ForceKernel::default(),
    };
    let theta = theta_tensor(&model.params.to_vec(), device);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x005e_ed0f_5eed);
    let mut frames = vec![init.clone()];
    let mut roles = Vec::with_capacity(cfg.frame_count);
    let decide = Decide::Live {
        rng: &mut rng,
        record: None,
    };
    let state = HerdState::from_rows(&init, device);
    let observe = |_: usize, dec: &StepDecisions, next: &HerdState| -> Result<()> {
        roles.push(dec.leader.clone());
        frames.push(next.rows(&ids)?);
        progress();
        Ok(())
    };
    let steps = cfg.frame_count - 1;
    let end = match zones {
        None => model.rollout(&theta, state, steps, decide, observe)?,
        Some(z) => {
            let guidance = vec![model.world.guidance.clone(); steps];
            let inner = crate::herd::sim::Guided {
                guidance: &guidance,
                observe,
            };
            let mut hooks = crate::herd::zoned::Zoned { inner, sets: z };
            model.run(&theta, state, steps, decide, &mut hooks)?
        }
    };
    roles.push(model.decide(&end.snapshot()?, &mut rng).leader);
    let provenance = serde_json::json!({
        "source": "synth",
        "agents": cfg.agents,
        "seed": cfg.seed,
        "heading_deg": cfg.heading_deg,
        "density": cfg.density,
        "random_headings": cfg.random_headings,
        "precision": cfg.precision,
        "truth": "truth.json",
    });
    let mut clip = rasterise(&frames, *g, cfg.fps, cfg.obstacles.clone(), provenance)?;
    if cfg.random_headings && cfg.frame_count == 1 {
        // A still of headings drawn uniformly: their spread is known, π²/3 (ClipMeta::dir_spread).
        clip.meta.dir_spread = Some(std::f64::consts::PI.powi(2) / 3.0);
    }
    Ok(Synth {
        clip,
        frames,
        roles,
    })
}

impl Synth {
    /// The trajectories as `frame,time,id,x,y,vx,vy,role` CSV.
    pub fn trajectories_csv(&self, fps: f64) -> String {
        let mut s = String::with_capacity(64 * self.frames.len() * self.frames[0].len() + 64);
        s.push_str(TRAJ_HEADER);
        s.push('\n');
        for (f, (rows, roles)) in self.frames.iter().zip(&self.roles).enumerate() {
            push_traj_frame(&mut s, f, f as f64 / fps, rows, roles);
        }
        s
    }
}

/// A synthetic clip with its files: the truth (the built-in set when absent), the herd and grid,
/// the obstacle cells, and the optional overhead video.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthJob {
    pub params: Option<PathBuf>,
    pub agents: usize,
    /// Number of frames (frame 0 included).
    pub frame_count: usize,
    pub fps: f64,
    /// Grid size in cells, (nx, ny).
    pub grid_size: (usize, usize),
    /// Cell side (BL).
    pub cell_size: f64,
    /// Obstacle cells file (`{"cells": [[ix, iy], …]}`).
    pub obstacles: Option<PathBuf>,
    /// Direction of travel of the herd and its guidance, degrees from +x.
    pub heading_deg: f64,
    pub seed: u64,
    pub precision: Precision,
    /// Where the model's tensors live (`--device`). Not written when `cpu`.
    #[serde(default, skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
    /// The clip folder written: fields.npz, clip.json, truth.json, trajectories.csv (+
    /// camera.json with a video).
    pub out: PathBuf,
    /// An overhead MJPG video of the run, and how it is rendered (`seed` is taken from the job).
    pub video: Option<(PathBuf, SynthVideo)>,
    /// A parameter-set bundle (`herdfit.param-sets/1`) whose sets' polygons are zones of the
    /// grid: each agent takes its zone's set every step (`params` still gives the speed model
    /// and the constants); written into the clip as `truth-sets.json`.
    pub zone_sets: Option<PathBuf>,
    /// Agents per BL² of the starting square.
    pub density: f64,
    /// Randomly aligned agents (uniform headings, no guidance) centred on the grid; with one
    /// frame the clip is a still (paper §7.2.4).
    pub random_headings: bool,
    /// A PNG of frame 0 as the video would show it (a still's image for `extract`), and the
    /// bare ground beside it as `<stem>-ground.png` (its background).
    pub image: Option<PathBuf>,
}

/// How `synth` renders its video.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SynthVideo {
    /// Pixels per body length.
    pub px_per_bl: f64,
    /// Body colour, RGB.
    pub body_colour: [u8; 3],
    /// Smooth pan, zoom and rotation of the camera (identity at frame 0).
    pub camera_motion: bool,
}

impl Default for SynthJob {
    fn default() -> Self {
        SynthJob {
            params: None,
            agents: 300,
            frame_count: 100,
            fps: 25.0,
            grid_size: (24, 12),
            cell_size: 2.0,
            obstacles: None,
            heading_deg: 0.0,
            seed: 0,
            precision: Precision::F32,
            device: Compute::Cpu,
            out: PathBuf::from("clip"),
            video: None,
            zone_sets: None,
            density: 0.5,
            random_headings: false,
            image: None,
        }
    }
}

impl Default for SynthVideo {
    fn default() -> Self {
        SynthVideo {
            px_per_bl: 12.0,
            body_colour: [235, 235, 225],
            camera_motion: false,
        }
    }
}

impl SynthJob {
    /// Checks the cell size (the rest is [`SynthConfig::check`]'s and the video's).
    pub fn check(&self) -> Result<()> {
        crate::error::check_positive(&[("cell_size", self.cell_size)])?;
        crate::limits::check_grid("grid_size", self.grid_size.0, self.grid_size.1)?;
        crate::limits::check_count("agents", self.agents, crate::limits::MAX_AGENTS)?;
        if let Some((_, v)) = &self.video {
            crate::limits::check_px_per_bl(v.px_per_bl)?;
        }
        let extent = self.cell_size * self.grid_size.0.max(self.grid_size.1) as f64;
        crate::limits::check_magnitude("cell_size", extent, crate::limits::MAX_COORD)
    }
}

/// Makes the synthetic clip and writes its folder (and video); returns it.
pub fn write_clip(job: &SynthJob, progress: &mut dyn Progress) -> Result<Synth> {
    let params = load_params(job.params.as_deref())?;
    job.check()?;
    let (nx, ny) = job.grid_size;
    let grid = Grid {
        origin: [0.0, 0.0],
        cell_size: job.cell_size,
        nx,
        ny,
    };
    let obstacles = match &job.obstacles {
        Some(p) => {
            let m = read_cells(p, nx, ny)?;
            if m.iter().all(|&c| c != 0) {
                return Err(Error::file(
                    p,
                    format!("every cell of the {nx}×{ny} grid is an obstacle: no room for a herd"),
                ));
            }
            m
        }
        None => Array2::zeros((ny, nx)),
    };
    if let Some(img) = &job.image {
        crate::data::atomic::check_writable(img)?;
        crate::data::atomic::check_writable(&ground_path(img))?;
    }
    AtomicDir::create(&job.out)?; // fail early on an unusable output folder
    let device = device(job.device, job.precision)?;
    let cfg = SynthConfig {
        params: params.clone(),
        agents: job.agents,
        frame_count: job.frame_count,
        fps: job.fps,
        grid,
        obstacles,
        seed: job.seed,
        heading_deg: job.heading_deg,
        precision: job.precision,
        density: job.density,
        random_headings: job.random_headings,
    };
    let zones = match &job.zone_sets {
        None => None,
        Some(p) => {
            let bundle = crate::herd::sets::ParamSets::load(p)?;
            let z = crate::herd::zoned::ZoneSets::of_bundle(&bundle, p, &grid, &cfg.obstacles)?;
            Some((z, bundle))
        }
    };
    progress.start("synth", job.frame_count.saturating_sub(1) as u64);
    let syn = synthesise_zoned(&cfg, zones.as_ref().map(|z| &z.0), &device, || {
        progress.inc(1)
    })?;
    progress.finish();
    let mut truth = params.clone();
    truth.physical = Some(params.physical_values());
    truth.provenance = Some(serde_json::json!({"source": "synth truth", "seed": job.seed}));
    let truth = serde_json::to_string_pretty(&truth)
        .map_err(|e| Error::Internal(format!("serialising truth: {e}")))?;
    let traj = syn.trajectories_csv(job.fps);
    let mut clip = syn.clip.clone();
    let mut extra = vec![
        ("truth.json", format!("{truth}\n").into_bytes()),
        ("trajectories.csv", traj.into_bytes()),
    ];
    if let Some((_, bundle)) = &zones {
        let json = serde_json::to_string_pretty(bundle)
            .map_err(|e| Error::Internal(format!("serialising the sets: {e}")))?;
        extra.push((
            "truth-sets.json",
            format!(
                "{json}
"
            )
            .into_bytes(),
        ));
    }
    let pending = match &job.video {
        None => None,
        Some((path, v)) => {
            let (cameras, pending, settings) = render::video(job, v, &syn, path, progress)?;
            let s = v.px_per_bl;
            clip.meta.body_length_px = Some(s);
            clip.meta.body_pixel_coverage =
                Some(std::f64::consts::PI * 0.5 * s * 0.5 * crate::data::clip::BODY_WIDTH_BL * s);
            if let serde_json::Value::Object(m) = &mut clip.meta.provenance {
                m.insert("video".into(), settings);
            }
            let cams = serde_json::to_string_pretty(&cameras)
                .map_err(|e| Error::Internal(format!("serialising cameras: {e}")))?;
            extra.push(("camera.json", format!("{cams}\n").into_bytes()));
            Some(pending)
        }
    };
    if let Some(img) = &job.image {
        let v = job.video.as_ref().map(|v| v.1.clone()).unwrap_or_default();
        render::image(job, &v, &syn, img)?;
    }
    clip.save(&job.out, &extra)?;
    if let Some(p) = pending {
        render::commit(p)?;
    }
    Ok(syn)
}

impl Synth {
    /// The line `herdfit synth` prints.
    pub fn summary(&self, job: &SynthJob) -> String {
        let counts: Vec<f64> = (0..self.clip.frames())
            .map(|f| self.clip.count(f))
            .collect();
        format!(
            "synth: {} agents, {} frames at {} fps on a {}×{} grid of {} BL cells; {:.0}–{:.0} agents inside the grid; wrote {}",
            job.agents,
            job.frame_count,
            job.fps,
            job.grid_size.0,
            job.grid_size.1,
            job.cell_size,
            counts.iter().cloned().fold(f64::INFINITY, f64::min),
            counts.iter().cloned().fold(0.0, f64::max),
            job.out.display()
        )
    }
}

/// Where `synth --image IMG.png` writes the bare ground: `IMG-ground.png` beside it.
pub fn ground_path(image: &std::path::Path) -> PathBuf {
    let stem = image
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_default();
    image.with_file_name(format!("{stem}-ground.png"))
}

/// Rendering the synthetic clip's video (OpenCV), or refusing to without the `video` feature.
mod render {
    use super::{Synth, SynthJob, SynthVideo};
    use crate::error::Result;
    use crate::progress::Progress;
    use std::path::Path;

    #[cfg(feature = "video")]
    pub type Pending = crate::video::PendingVideo;
    #[cfg(not(feature = "video"))]
    pub type Pending = ();

    /// Renders the video into a pending file; returns the cameras, the pending file and the
    /// settings recorded in the clip's provenance.
    #[cfg(feature = "video")]
    pub fn video(
        job: &SynthJob,
        v: &SynthVideo,
        syn: &Synth,
        path: &Path,
        progress: &mut dyn Progress,
    ) -> Result<(Vec<serde_json::Value>, Pending, serde_json::Value)> {
        crate::data::atomic::check_writable(path)?;
        let cfg = crate::video::RenderConfig {
            px_per_bl: v.px_per_bl,
            body_rgb: v.body_colour,
            camera_motion: v.camera_motion,
            seed: job.seed,
        };
        progress.start("render", syn.frames.len() as u64);
        let (cams, pending) = crate::video::render_video(
            path,
            &syn.frames,
            &syn.clip.grid(),
            &syn.clip.obstacles,
            job.fps,
            &cfg,
            || progress.inc(1),
        )?;
        progress.finish();
        let cams = cams
            .iter()
            .map(|c| serde_json::to_value(c).unwrap_or_default())
            .collect();
        let settings = serde_json::json!({
            "file": path.display().to_string(),
            "render": cfg,
            "frame_size": crate::video::render::frame_size(&syn.clip.grid(), v.px_per_bl),
        });
        Ok((cams, pending, settings))
    }

    /// The still's image of frame 0 and its bare ground beside it (`<stem>-ground.png`).
    #[cfg(feature = "video")]
    pub fn image(job: &SynthJob, v: &SynthVideo, syn: &Synth, path: &Path) -> Result<()> {
        let cfg = crate::video::RenderConfig {
            px_per_bl: v.px_per_bl,
            body_rgb: v.body_colour,
            camera_motion: false,
            seed: job.seed,
        };
        crate::video::render::render_image(
            path,
            &super::ground_path(path),
            &syn.frames[0],
            &syn.clip.grid(),
            &syn.clip.obstacles,
            &cfg,
        )
    }

    #[cfg(not(feature = "video"))]
    pub fn image(_job: &SynthJob, _v: &SynthVideo, _syn: &Synth, path: &Path) -> Result<()> {
        Err(crate::error::Error::file(
            path,
            "this herdfit was built without the `video` feature (OpenCV)",
        ))
    }

    #[cfg(not(feature = "video"))]
    pub fn video(
        _job: &SynthJob,
        _v: &SynthVideo,
        _syn: &Synth,
        path: &Path,
        _progress: &mut dyn Progress,
    ) -> Result<(Vec<serde_json::Value>, Pending, serde_json::Value)> {
        Err(crate::error::Error::file(
            path,
            "this herdfit was built without the `video` feature (OpenCV)",
        ))
    }

    #[cfg(feature = "video")]
    pub fn commit(p: Pending) -> Result<()> {
        p.commit()
    }

    #[cfg(not(feature = "video"))]
    pub fn commit(_p: Pending) -> Result<()> {
        Ok(())
    }
}
