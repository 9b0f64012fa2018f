//! `herdfit synth`: flags → [`SynthJob`] → [`write_clip`] → one line.

use crate::backend::Precision;
use crate::cli::args::{choice, parse_grid, parse_rgb, with_flags, DeviceArg, PRECISIONS};
use crate::cli::paths::{InFile, OutDir, OutFile};
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::synth::{write_clip, SynthJob, SynthVideo};
use clap::Args;

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Parameter set (the truth); the built-in default set when omitted.
    #[arg(long, value_name = "P.json")]
    pub params: Option<InFile>,
    #[arg(long, value_name = "N")]
    pub agents: usize,
    /// Number of frames (frame 0 included).
    #[arg(long, alias = "frames", value_name = "F")]
    pub frame_count: usize,
    #[arg(long, value_name = "FPS", default_value_t = 25.0)]
    pub fps: f64,
    /// Grid size in cells, NXxNY.
    #[arg(long, alias = "grid", value_name = "NXxNY", value_parser = parse_grid)]
    pub grid_size: (usize, usize),
    /// Cell side (BL).
    #[arg(long, value_name = "C")]
    pub cell_size: f64,
    /// Obstacle cells: {"cells": [[ix, iy], …]} (row 0 at the bottom).
    #[arg(long, value_name = "CELLS.json")]
    pub obstacles: Option<InFile>,
    /// Direction of travel of the herd and its guidance, degrees from +x.
    #[arg(
        long,
        value_name = "DEG",
        default_value_t = 0.0,
        allow_hyphen_values = true
    )]
    pub heading: f64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    #[arg(long, value_parser = choice::<Precision>(PRECISIONS), default_value_t = Precision::F32)]
    pub precision: Precision,
    #[command(flatten)]
    pub device: DeviceArg,
    /// Also render the overhead view as an MJPG AVI (needs the `video` feature).
    #[arg(long, alias = "video", value_name = "OUT.avi")]
    pub video_file: Option<OutFile>,
    /// Video scale: pixels per body length.
    #[arg(long, value_name = "PX", default_value_t = 12.0)]
    pub px_per_bl: f64,
    /// Body colour of the rendered agents, R,G,B.
    #[arg(long, value_name = "R,G,B", default_value = "235,235,225", value_parser = parse_rgb)]
    pub body_colour: [u8; 3],
    /// Smooth pan, zoom and rotation of the camera (identity at frame 0); poses go to camera.json.
    #[arg(long)]
    pub camera_motion: bool,
    /// One parameter set per zone: a parameter-set bundle (herdfit.param-sets/1) whose sets'
    /// polygons cover the grid; each agent takes its zone's set every step.
    #[arg(long, value_name = "SETS.json")]
    pub zone_sets: Option<InFile>,
    /// Agents per BL² of the herd's starting square.
    #[arg(long, value_name = "D", default_value_t = 0.5)]
    pub density: f64,
    /// Randomly aligned agents: headings uniform on the circle, no guidance, the herd centred on
    /// the grid. With --frames 1 the clip is a still (a one-frame clip, paper §7.2.4).
    #[arg(long)]
    pub random_headings: bool,
    /// Also render frame 0 as a PNG (a still's image for `extract`), and the bare ground as
    /// IMG-ground.png beside it (needs the `video` feature).
    #[arg(long, value_name = "IMG.png")]
    pub image: Option<OutFile>,
    /// Output clip folder.
    #[arg(long, value_name = "CLIP/")]
    pub out: OutDir,
}

pub fn exec(a: SynthArgs) -> Result<()> {
    let video = SynthVideo {
        px_per_bl: a.px_per_bl,
        body_colour: a.body_colour,
        camera_motion: a.camera_motion,
    };
    let job = SynthJob {
        params: a.params.map(Into::into),
        agents: a.agents,
        frame_count: a.frame_count,
        fps: a.fps,
        grid_size: a.grid_size,
        cell_size: a.cell_size,
        obstacles: a.obstacles.map(Into::into),
        heading_deg: a.heading,
        seed: a.seed,
        precision: a.precision,
        device: a.device.device,
        out: a.out.into(),
        video: a.video_file.map(|p| (p.into(), video)),
        zone_sets: a.zone_sets.map(Into::into),
        density: a.density,
        random_headings: a.random_headings,
        image: a.image.map(Into::into),
    };
    let renamed = [
        ("heading_deg", "--heading"),
        ("grid", "--grid-size"),
        ("density", "--density"),
    ];
    // The scale is judged whether or not a video or image is asked for (issue #47).
    crate::limits::check_px_per_bl(a.px_per_bl).map_err(|e| with_flags(e, &renamed))?;
    let syn = write_clip(&job, &mut Bars::default()).map_err(|e| with_flags(e, &renamed))?;
    println!("{}", syn.summary(&job));
    Ok(())
}
