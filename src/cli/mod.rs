//! The `herdfit` command line: one verb per pipeline arrow (DESIGN §1). Commands parse their flags,
//! call the library and turn its typed errors into one-line messages (in `main.rs`).

use crate::backend::{cpu_device, Precision};
use crate::bench::run_bench;
use crate::error::{Error, Result};
use crate::io::{
    check_writable, push_traj_frame, read_init_csv, write_atomic, AtomicFile, TRAJ_HEADER,
};
use crate::params::Params;
use crate::sim::{
    random_herd, theta_tensor, Decide, Guidance, HerdSpec, HerdState, Model, Recording, World,
};
use crate::train::gradcheck::{default_scenario, gradcheck, record, Scenario};
use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};
use rand::SeedableRng;
use std::path::PathBuf;

/// Learn how animal groups move from video and replay that behaviour anywhere.
#[derive(Parser, Debug)]
#[command(name = "herdfit", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Subcommand, Debug)]
pub enum Command {
    /// Simulate a herd with a parameter set and write its trajectories (CSV).
    Simulate(SimulateArgs),
    /// Check the autodiff gradient of an unrolled run against finite differences.
    Gradcheck(GradcheckArgs),
    /// Time simulation and forward+backward steps on the standard random herd.
    Bench(BenchArgs),
    /// Fit the 12 force parameters (and the speed model) to a clip's fields; export a parameter set.
    Fit(FitArgs),
    /// Extract clip fields from an overhead video (needs the `video` feature).
    Extract(ExtractArgs),
    /// Validate parameter sets on the held-out part of a clip (errors, polarization, angular
    /// momentum, aspect ratio) and write a report folder.
    Validate(ValidateArgs),
    /// Simulate a herd in an authored scene (arrows, destination, obstacles, behaviour regions).
    Author(AuthorArgs),
    /// Make a synthetic clip with known parameters (fields, truth.json, trajectories.csv).
    Synth(SynthArgs),
    /// Convert the public Herds-From-Video extractor's text files into a clip folder.
    ImportReference(ImportArgs),
    /// Summarise a clip: grid, frames, agents, speed model, polarization, angular momentum.
    FieldsInfo(FieldsInfoArgs),
    /// The built-in walk-through: a synthetic herd rendered to video, extracted, fitted on the first
    /// half from a generic start, validated on the second half; prints a summary.
    Demo(DemoArgs),
    /// 3D flocks from 2D tracks (Lin's thesis): run, synth, project, evaluate, camera.
    #[command(subcommand)]
    Lift(commands::lift::LiftCommand),
    /// Any tracks file as an animated glTF 2.0 binary (.glb) for Blender and game engines.
    ExportGltf(commands::export_gltf::ExportGltfArgs),
}

/// One file per verb of the newer systems.
pub mod commands {
    pub mod export_gltf;
    pub mod lift;
}

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Parameter set (the truth); the built-in default set when omitted.
    #[arg(long, value_name = "P.json")]
    pub params: Option<PathBuf>,
    #[arg(long, value_name = "N")]
    pub agents: usize,
    /// Number of frames (frame 0 included).
    #[arg(long, value_name = "F")]
    pub frames: usize,
    #[arg(long, value_name = "FPS", default_value_t = 25.0)]
    pub fps: f64,
    /// Grid size in cells, NXxNY.
    #[arg(long, value_name = "NXxNY", value_parser = parse_grid)]
    pub grid: (usize, usize),
    /// Cell side (BL).
    #[arg(long, value_name = "C")]
    pub cell_size: f64,
    /// Obstacle cells: {"cells": [[ix, iy], …]} (row 0 at the bottom).
    #[arg(long, value_name = "CELLS.json")]
    pub obstacles: Option<PathBuf>,
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
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    pub precision: Precision,
    /// Also render the overhead view as an MJPG AVI (needs the `video` feature).
    #[arg(long, value_name = "OUT.avi")]
    pub video: Option<PathBuf>,
    /// Video scale: pixels per body length.
    #[arg(long, value_name = "PX", default_value_t = 12.0)]
    pub px_per_bl: f64,
    /// Body colour of the rendered agents, R,G,B.
    #[arg(long, value_name = "R,G,B", default_value = "235,235,225", value_parser = parse_rgb)]
    pub body_colour: [u8; 3],
    /// Smooth pan, zoom and rotation of the camera (identity at frame 0); poses go to camera.json.
    #[arg(long)]
    pub camera_motion: bool,
    /// Output clip folder.
    #[arg(long, value_name = "CLIP/")]
    pub out: PathBuf,
}

fn parse_rgb(s: &str) -> std::result::Result<[u8; 3], String> {
    let v: Vec<&str> = s.split(',').collect();
    if v.len() != 3 {
        return Err(format!("expected R,G,B, got '{s}'"));
    }
    let mut out = [0u8; 3];
    for (o, t) in out.iter_mut().zip(v) {
        *o = t
            .trim()
            .parse()
            .map_err(|_| format!("'{t}' is not a value in 0..=255"))?;
    }
    Ok(out)
}

#[derive(Args, Debug)]
pub struct FitArgs {
    /// One clip, or several clips of the same kind of herd fitted jointly (paper §7.6).
    #[arg(value_name = "CLIP/", num_args = 1.., required = true)]
    pub clips: Vec<PathBuf>,
    /// Output parameter set (herdfit.params/1).
    #[arg(long, value_name = "PARAMS.json")]
    pub out: PathBuf,
    /// Starting parameters; a generic start (every value 0.5) when omitted.
    #[arg(long, value_name = "P.json")]
    pub init: Option<PathBuf>,
    /// Unrolled steps per update (1 = the paper's greedy per-frame scheme).
    #[arg(long, value_name = "W", default_value_t = 4)]
    pub window: usize,
    #[arg(long, value_name = "E", default_value_t = 8)]
    pub epochs: usize,
    /// β of eq. 11 (density vs velocity in the target).
    #[arg(long, value_name = "B", default_value_t = 0.7)]
    pub beta: f64,
    /// λ_var, the weight of E_var.
    #[arg(long, value_name = "L", default_value_t = 1.0)]
    pub var_weight: f64,
    #[arg(long, value_name = "X", default_value_t = 0.02)]
    pub lr: f64,
    #[arg(long, value_enum, default_value_t = crate::train::fit::Optimizer::Adam)]
    pub optimizer: crate::train::fit::Optimizer,
    /// Frames used, a..b (b exclusive); all frames when omitted.
    #[arg(long, value_name = "a..b", value_parser = parse_range)]
    pub frames: Option<(usize, usize)>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Density error above which the population is rebalanced.
    #[arg(long, value_name = "E", default_value_t = 0.3)]
    pub density_threshold: f64,
    /// Every parameter follows ∇(E_mean + λ E_var) instead of the paper's split (alignment from
    /// E_var, the others from E_mean).
    #[arg(long)]
    pub joint_gradients: bool,
    /// E_mean on each cell's mean direction instead of every follower's (spread left to E_var).
    #[arg(long)]
    pub cell_mean: bool,
    /// Objective: the paper's losses, or matching the density and momentum fields.
    #[arg(long, value_enum, default_value_t = crate::train::fit::LossKind::Paper)]
    pub loss: crate::train::fit::LossKind,
    /// Gradient checkpointing: less memory through long windows, more time (see BENCHMARKS.md).
    #[arg(long)]
    pub checkpointing: bool,
    /// Iterations settling each epoch's starting herd into the model's spacing (0: none).
    #[arg(long, value_name = "N", default_value_t = crate::train::fit::Settle::default().iterations)]
    pub settle: usize,
    /// Herds simulated side by side from the same fields (losses averaged; `--loss ensemble`
    /// compares their mean fields with the clip's).
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub replicas: usize,
    /// Runs (seeds S, S+1, …) whose density and velocity errors, with the start and the fitted
    /// parameters, are averaged into the provenance's `evaluation` (one run is mostly noise).
    #[arg(long, value_name = "K", default_value_t = 4)]
    pub eval_seeds: usize,
    /// σ (cells) of the Gaussian that smooths the clip's momentum into the leaders' guidance
    /// (0: each cell's own mean velocity; inf: the herd's mean direction everywhere).
    #[arg(long, value_name = "S", default_value_t = crate::train::fit::GUIDANCE_SCALE, allow_hyphen_values = true)]
    pub guidance_scale: f64,
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    pub precision: Precision,
    /// Write a checkpoint into DIR after every epoch.
    #[arg(long, value_name = "DIR")]
    pub checkpoint: Option<PathBuf>,
    /// Continue from DIR/checkpoint.json (same flags required).
    #[arg(long, requires = "checkpoint")]
    pub resume: bool,
    /// Training log CSV (default: next to --out, .log.csv).
    #[arg(long, value_name = "LOG.csv")]
    pub log: Option<PathBuf>,
    /// Loss-curve PNG (default: next to --out, .loss.png).
    #[arg(long, value_name = "LOSS.png")]
    pub plot: Option<PathBuf>,
}

/// Two values of type `T` from `s` cut in two by `split` (each trimmed); `form` names the
/// expected shape and `what` one value in the messages.
fn parse_two<'a, T: std::str::FromStr>(
    s: &'a str,
    split: impl Fn(&'a str) -> Option<(&'a str, &'a str)>,
    form: &str,
    what: &str,
) -> std::result::Result<(T, T), String> {
    let (a, b) = split(s).ok_or_else(|| format!("expected {form}, got '{s}'"))?;
    let p = |t: &str| {
        t.trim()
            .parse::<T>()
            .map_err(|_| format!("'{t}' is not {what}"))
    };
    Ok((p(a)?, p(b)?))
}

fn parse_range(s: &str) -> std::result::Result<(usize, usize), String> {
    parse_two(s, |s| s.split_once(".."), "a..b", "a frame index")
}

fn sibling(out: &std::path::Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "params".into());
    out.with_file_name(format!("{stem}{suffix}"))
}

#[derive(Args, Debug)]
pub struct ExtractArgs {
    #[arg(value_name = "VIDEO")]
    pub video: PathBuf,
    /// Output clip folder.
    #[arg(long, value_name = "CLIP/")]
    pub out: PathBuf,
    /// Settings file (the `settings` object a previous extraction recorded in clip.json); flags
    /// given on the command line override it.
    #[arg(long, value_name = "extract.json")]
    pub config: Option<PathBuf>,
    /// Cells along the longer side of the frame.
    #[arg(long, value_name = "N")]
    pub grid: Option<usize>,
    /// Body length in pixels.
    #[arg(long, value_name = "L")]
    pub body_length_px: Option<f64>,
    /// Body colour R,G,B (herd pixels must also be within --colour-threshold of it).
    #[arg(long, value_name = "R,G,B", value_parser = parse_rgb)]
    pub body_colour: Option<[u8; 3]>,
    #[arg(long, value_name = "T")]
    pub colour_threshold: Option<f64>,
    /// Per-channel difference to the background above which a pixel can be herd.
    #[arg(long, value_name = "T")]
    pub background_threshold: Option<f64>,
    /// Body pixels per animal (default: an ellipse of L × 0.4 L).
    #[arg(long, value_name = "NBP")]
    pub body_pixels: Option<f64>,
    /// Anchor rectangle x,y,w,h of the first frame tracked with CSRT (repeat for several;
    /// `center` for the central quarter of the frame). None: a static camera.
    #[arg(long, value_name = "x,y,w,h")]
    pub anchor: Vec<String>,
    /// `auto` (temporal median of stabilised frames) or a background image.
    #[arg(long, value_name = "auto|IMAGE")]
    pub background: Option<String>,
    /// Obstacle mask image (non-zero = obstacle), the size of the video frame.
    #[arg(long, value_name = "MASK.png")]
    pub obstacles: Option<PathBuf>,
    /// Frames used, a..b (b exclusive).
    #[arg(long, value_name = "a..b", value_parser = parse_range)]
    pub frames: Option<(usize, usize)>,
    /// Smoothing window (frames) for the camera path and velocities.
    #[arg(long, value_name = "K")]
    pub smooth: Option<usize>,
    /// Write preview PNGs (density and velocity over the stabilised frame) into DIR.
    #[arg(long, value_name = "DIR")]
    pub preview: Option<PathBuf>,
    /// One preview every N frames.
    #[arg(long, value_name = "N", default_value_t = 25)]
    pub preview_every: usize,
}

#[derive(Args, Debug)]
pub struct ValidateArgs {
    #[arg(value_name = "CLIP/")]
    pub clip: PathBuf,
    /// The parameter set to validate (e.g. the fit's output).
    #[arg(long, value_name = "P.json")]
    pub params: PathBuf,
    /// A baseline to compare with (e.g. the fit's starting parameters).
    #[arg(long, value_name = "P0.json")]
    pub baseline: Option<PathBuf>,
    /// Fraction of the clip before the held-out part.
    #[arg(long, value_name = "S", default_value_t = 0.5)]
    pub split: f64,
    /// Coarse grid (cells per side) of the density and velocity errors.
    #[arg(long, value_name = "N", default_value_t = 10)]
    pub grid: usize,
    /// Simulations per parameter set (averaged).
    #[arg(long, value_name = "K", default_value_t = 3)]
    pub seeds: usize,
    /// Iterations settling the starting herd into the model's spacing (0: none).
    #[arg(long, value_name = "N", default_value_t = crate::train::fit::Settle::default().iterations)]
    pub settle: usize,
    /// Start the herd this many frames before the held-out part (from those fields) and simulate
    /// through them unrecorded (0: start from the fields of the first held-out frame).
    #[arg(long, value_name = "F", default_value_t = 0)]
    pub warmup: usize,
    /// σ (cells) of the Gaussian that smooths the clip's momentum into the leaders' guidance
    /// (0: each cell's own mean velocity; inf: the herd's mean direction everywhere).
    #[arg(long, value_name = "S", default_value_t = crate::train::fit::GUIDANCE_SCALE, allow_hyphen_values = true)]
    pub guidance_scale: f64,
    /// Compare the seeds' mean prediction with the clip (counts, momenta and each measure
    /// averaged over the seeds frame by frame) instead of averaging each seed's own errors.
    #[arg(long)]
    pub ensemble_mean: bool,
    /// Skip the side-by-side video.
    #[arg(long)]
    pub no_video: bool,
    /// Output report folder.
    #[arg(long, value_name = "REPORT/")]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct AuthorArgs {
    #[arg(value_name = "SCENE.json")]
    pub scene: PathBuf,
    /// Output folder: trajectories.csv, navigation.png, snapshots, report.json (+ herd.avi).
    #[arg(long, value_name = "DIR")]
    pub out: PathBuf,
    /// Also render the herd over the scene as an MJPG AVI.
    #[arg(long)]
    pub video: bool,
    /// Video scale: pixels per body length.
    #[arg(long, value_name = "PX", default_value_t = 8.0)]
    pub px_per_bl: f64,
}

#[derive(Args, Debug)]
pub struct ImportArgs {
    /// Prefix of the three files: PREFIX_data_meta.txt, PREFIX_data_frame.txt, PREFIX_data_cell.txt.
    #[arg(value_name = "PREFIX")]
    pub prefix: PathBuf,
    /// Output clip folder.
    #[arg(long, value_name = "CLIP/")]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct FieldsInfoArgs {
    #[arg(value_name = "CLIP/")]
    pub clip: PathBuf,
    /// Also write the summary and per-frame measures as JSON.
    #[arg(long, value_name = "OUT.json")]
    pub json: Option<PathBuf>,
}

fn parse_grid(s: &str) -> std::result::Result<(usize, usize), String> {
    let (nx, ny): (usize, usize) =
        parse_two(s, |s| s.split_once(['x', 'X']), "NXxNY", "a cell count")?;
    if nx == 0 || ny == 0 {
        return Err("the grid needs at least one cell each way".into());
    }
    Ok((nx, ny))
}

#[derive(Args, Debug)]
pub struct DemoArgs {
    /// Output folder (created if missing).
    #[arg(long, value_name = "DIR", default_value = "out/demo")]
    pub out: PathBuf,
}

/// Where the initial herd comes from.
#[derive(Args, Debug, Clone)]
#[group(required = false, multiple = false)]
pub struct HerdSource {
    /// Initial state: CSV with columns id,x,y,vx,vy (BL, BL/s).
    #[arg(long, value_name = "INIT.csv")]
    pub init: Option<PathBuf>,
    /// A built-in random herd of N agents (one per 2 BL², heading +x ± 20°) instead of --init.
    #[arg(long, value_name = "N")]
    pub agents: Option<usize>,
}

#[derive(Args, Debug)]
pub struct SimulateArgs {
    /// Parameter set (herdfit.params/1 JSON); the built-in default set when omitted.
    #[arg(long, value_name = "P.json")]
    pub params: Option<PathBuf>,
    #[command(flatten)]
    pub herd: HerdSource,
    /// Number of steps (frames after frame 0).
    #[arg(long, value_name = "T")]
    pub steps: usize,
    /// Frames per second; Δt = 1 / fps.
    #[arg(long, value_name = "F", default_value_t = 25.0)]
    pub fps: f64,
    /// Speed noise v_σ (BL/s) of eq. 6, overriding the parameter set's speed.std; 0 makes the run
    /// deterministic.
    #[arg(long, value_name = "S")]
    pub speed_noise: Option<f64>,
    /// Uniform guidance direction DX,DY for leaders; without it leaders act as followers.
    #[arg(long, value_name = "DX,DY", value_parser = parse_pair)]
    pub guidance: Option<(f64, f64)>,
    #[arg(long, value_enum, default_value_t = Precision::F32)]
    pub precision: Precision,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Write the run's perception, roles and noise to this file (JSON).
    #[arg(long, value_name = "REC.json")]
    pub record: Option<PathBuf>,
    /// Replay the perception, roles and noise of a recorded run instead of computing them.
    #[arg(long, value_name = "REC.json", conflicts_with = "record")]
    pub replay: Option<PathBuf>,
    /// Output trajectories: frame,time,id,x,y,vx,vy,role.
    #[arg(long, value_name = "TRAJ.csv")]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct GradcheckArgs {
    /// Parameter set; the built-in default set when omitted.
    #[arg(long, value_name = "P.json")]
    pub params: Option<PathBuf>,
    #[command(flatten)]
    pub herd: HerdSource,
    /// Unrolled steps.
    #[arg(long, value_name = "T", default_value_t = 10)]
    pub steps: usize,
    #[arg(long, value_enum, default_value_t = Precision::F64)]
    pub precision: Precision,
    /// Step h of the 4-point central difference (default 1e-4 in f64, 1e-2 in f32).
    #[arg(long, value_name = "H")]
    pub fd_step: Option<f64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Save the decisions used (to replay them in another precision).
    #[arg(long, value_name = "REC.json")]
    pub record: Option<PathBuf>,
    /// Use these recorded decisions instead of recording new ones.
    #[arg(long, value_name = "REC.json", conflicts_with = "record")]
    pub replay: Option<PathBuf>,
    /// Objective: the documented herd objective, or the fit's loss on --clip.
    #[arg(long, value_enum, default_value_t = Objective::Herd)]
    pub objective: Objective,
    /// Clip for `--objective loss` (the herd starts from its first frame's fields).
    #[arg(long, value_name = "CLIP/", required_if_eq("objective", "loss"))]
    pub clip: Option<PathBuf>,
    /// Which of the fit's losses `--objective loss` checks.
    #[arg(long, value_enum, default_value_t = crate::train::fit::LossKind::Paper)]
    pub loss: crate::train::fit::LossKind,
    /// Herds for `--loss ensemble`.
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub replicas: usize,
    /// Output report (JSON).
    #[arg(long, value_name = "OUT.json")]
    pub json: PathBuf,
}

/// What `gradcheck` differentiates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Objective {
    /// Spread + mean heading of the default scenario's herd after T steps.
    Herd,
    /// The fit's loss (`--loss`: E_mean + λ E_var, eq. 7–8, or field matching, or the ensemble
    /// objective) over T steps on a clip.
    Loss,
}

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[arg(long, value_name = "N", default_value_t = 1500)]
    pub agents: usize,
    #[arg(long, value_name = "T", default_value_t = 20)]
    pub steps: usize,
    /// Skip the forward + backward measurement.
    #[arg(long)]
    pub sim_only: bool,
    /// Forward + backward repetitions (median reported).
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Recompute memory-bound activations in the backward pass (burn's balanced gradient
    /// checkpointing): less memory for long windows, more time.
    #[arg(long)]
    pub checkpointing: bool,
    /// Output report (JSON).
    #[arg(long, value_name = "OUT.json")]
    pub json: PathBuf,
}

fn parse_pair(s: &str) -> std::result::Result<(f64, f64), String> {
    let (a, b): (f64, f64) = parse_two(s, |s| s.split_once(','), "DX,DY", "a number")?;
    if !(a.is_finite() && b.is_finite()) || (a == 0.0 && b == 0.0) {
        return Err("the direction must be finite and non-zero".into());
    }
    Ok((a, b))
}

/// A progress bar on stderr (hidden when stderr is not a terminal).
pub fn progress_bar(len: u64, what: &str) -> ProgressBar {
    let pb = ProgressBar::new(len);
    if let Ok(style) =
        ProgressStyle::with_template("{msg:12} [{elapsed_precise}] {wide_bar} {pos}/{len} ({eta})")
    {
        pb.set_style(style);
    }
    pb.set_message(what.to_string());
    pb
}

fn load_params(path: &Option<PathBuf>) -> Result<Params> {
    match path {
        Some(p) => Params::load(p),
        None => Ok(Params::default()),
    }
}

fn initial_herd(
    src: &HerdSource,
    params: &Params,
    world: &World,
    seed: u64,
) -> Result<Vec<crate::io::AgentRow>> {
    match (&src.init, src.agents) {
        (Some(p), _) => read_init_csv(p),
        (None, Some(n)) => random_herd(&HerdSpec::standard(n), &params.speed, world, seed),
        (None, None) => Err(Error::invalid(
            "give the initial herd: --init INIT.csv or --agents N",
        )),
    }
}

/// Runs the parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Simulate(a) => simulate(a),
        Command::Gradcheck(a) => gradcheck_cmd(a),
        Command::Bench(a) => bench_cmd(a),
        Command::Fit(a) => fit_cmd(a),
        Command::Extract(a) => extract_cmd(a),
        Command::Validate(a) => validate_cmd(a).map(|_| ()),
        Command::Author(a) => author_cmd(a),
        Command::Synth(a) => synth_cmd(a),
        Command::ImportReference(a) => import_cmd(a),
        Command::FieldsInfo(a) => fields_info(a),
        Command::Demo(a) => demo(a),
        Command::Lift(c) => commands::lift::run(c),
        Command::ExportGltf(a) => commands::export_gltf::run(a),
    }
}

fn simulate(a: SimulateArgs) -> Result<()> {
    if a.steps == 0 {
        return Err(Error::invalid("--steps must be ≥ 1"));
    }
    if !(a.fps.is_finite() && a.fps > 0.0) {
        return Err(Error::invalid(format!("--fps {} must be > 0", a.fps)));
    }
    let mut params = load_params(&a.params)?;
    if let Some(s) = a.speed_noise {
        if !(s.is_finite() && s >= 0.0) {
            return Err(Error::invalid(format!("--speed-noise {s} must be ≥ 0")));
        }
        params.speed.std = s;
    }
    let world = World {
        obstacles: None,
        guidance: a
            .guidance
            .map_or(Guidance::None, |(x, y)| Guidance::Uniform([x, y])),
    };
    let rows = initial_herd(&a.herd, &params, &world, a.seed)?;
    let replay = a.replay.as_deref().map(Recording::load).transpose()?;
    check_writable(&a.out)?;
    if let Some(r) = &a.record {
        check_writable(r)?;
    }
    let device = cpu_device(a.precision)?;
    let model = Model {
        params,
        world,
        dt: 1.0 / a.fps,
    };
    let ids: Vec<u64> = rows.iter().map(|r| r.id).collect();
    let theta = theta_tensor(&model.params.to_vec(), &device);
    let state = HerdState::from_rows(&rows, &device);
    let mut out = AtomicFile::create(&a.out)?;
    let mut text = String::with_capacity(64 * rows.len());
    text.push_str(TRAJ_HEADER);
    text.push('\n');
    let mut prev = rows;
    let mut rec = a.record.as_ref().map(|_| Recording::new(ids.len()));
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(a.seed ^ 0x005e_ed0f_5eed);
    let pb = progress_bar(a.steps as u64, "simulate");
    let decide = match &replay {
        Some(r) => Decide::Replay(r),
        None => Decide::Live {
            rng: &mut rng,
            record: rec.as_mut(),
        },
    };
    let end = model.rollout(&theta, state, a.steps, decide, |t, dec, next| {
        push_traj_frame(&mut text, t, t as f64 * model.dt, &prev, &dec.leader);
        out.write_str(&text)?;
        text.clear();
        prev = next.rows(&ids)?;
        pb.inc(1);
        Ok(())
    })?;
    pb.finish_and_clear();
    // Roles of the last frame: the decision the next step would take.
    let last_roles = match &replay {
        Some(r) if r.steps.len() > a.steps => r.steps[a.steps].leader.clone(),
        _ => {
            let mut rng2 = rand_chacha::ChaCha8Rng::seed_from_u64(a.seed);
            model.decide(&end.snapshot()?, &mut rng2).leader
        }
    };
    push_traj_frame(
        &mut text,
        a.steps,
        a.steps as f64 * model.dt,
        &prev,
        &last_roles,
    );
    out.write_str(&text)?;
    if let (Some(path), Some(rec)) = (&a.record, &rec) {
        rec.save(path)?;
    }
    out.commit()
}

fn gradcheck_cmd(a: GradcheckArgs) -> Result<()> {
    if a.steps == 0 {
        return Err(Error::invalid("--steps must be ≥ 1"));
    }
    let params = load_params(&a.params)?;
    if a.objective == Objective::Loss {
        let path = a
            .clip
            .clone()
            .ok_or_else(|| Error::invalid("--objective loss needs --clip"))?;
        let clip = crate::fields::ClipFields::load(&path)?;
        check_writable(&a.json)?;
        let device = cpu_device(a.precision)?;
        let sc = crate::train::gradcheck::LossScenario::record(
            &clip,
            &params,
            0,
            a.steps,
            0.7,
            1.0,
            (a.loss, a.replicas),
            a.seed,
            &device,
        )
        .map_err(|e| e.in_file(&path))?;
        let h = a.fd_step.unwrap_or(match a.precision {
            Precision::F64 => 1e-4,
            Precision::F32 => 1e-2,
        });
        let pb = progress_bar(13, "gradcheck");
        let report = sc.check(a.precision, h, || pb.inc(1))?;
        pb.finish_and_clear();
        return print_grad_report(&report, &a.json);
    }
    let sc = match (&a.herd.init, a.herd.agents) {
        (Some(p), _) => {
            let base = default_scenario(params, 1, a.seed)?;
            Scenario {
                init: read_init_csv(p)?,
                ..base
            }
        }
        (None, n) => default_scenario(params, n.unwrap_or(200), a.seed)?,
    };
    check_writable(&a.json)?;
    let device = cpu_device(a.precision)?;
    let rec = match &a.replay {
        Some(p) => Recording::load(p)?,
        None => record(&sc, a.steps, a.seed, &device)?,
    };
    if let Some(p) = &a.record {
        rec.save(p)?;
    }
    let h = a.fd_step.unwrap_or(match a.precision {
        Precision::F64 => 1e-4,
        Precision::F32 => 1e-2,
    });
    let pb = progress_bar(13, "gradcheck");
    let report = gradcheck(&sc, a.steps, a.precision, h, &rec, || pb.inc(1))?;
    pb.finish_and_clear();
    print_grad_report(&report, &a.json)
}

fn print_grad_report(
    report: &crate::train::gradcheck::GradReport,
    json: &std::path::Path,
) -> Result<()> {
    println!(
        "gradcheck: {} agents, {} unrolled steps, {:?}, J = {:.6e}, h = {:e}",
        report.agents, report.steps, report.precision, report.objective, report.fd_step
    );
    println!(
        "{:<20} {:>16} {:>18} {:>10}",
        "parameter", "autodiff", "finite difference", "rel err"
    );
    for r in &report.parameters {
        println!(
            "{:<20} {:>16.9e} {:>18.9e} {:>10.2e}",
            r.name, r.autodiff, r.finite_difference, r.rel_err
        );
    }
    println!("max rel err {:.3e}", report.max_rel_err);
    let text = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::Internal(format!("serialising report: {e}")))?;
    write_atomic(json, format!("{text}\n").as_bytes())
}

fn bench_cmd(a: BenchArgs) -> Result<()> {
    if a.agents == 0 {
        return Err(Error::invalid("the herd is empty: --agents must be ≥ 1"));
    }
    check_writable(&a.json)?;
    let total = a.steps + 1 + if a.sim_only { 0 } else { a.repeats.max(1) };
    let pb = progress_bar(total as u64, "bench");
    let r = run_bench(
        a.agents,
        a.steps,
        a.sim_only,
        a.repeats,
        a.checkpointing,
        || pb.inc(1),
    )?;
    pb.finish_and_clear();
    println!(
        "bench: {} agents, {} steps: simulation {:.3} ms/step{}, peak RSS {:.1} MB (K = {}, {:.1} visible neighbours/agent)",
        r.agents,
        r.steps,
        r.sim_ms_per_step,
        r.grad_ms_per_step
            .map_or(String::new(), |g| format!(", forward+backward {g:.3} ms/step")),
        r.peak_rss_mb,
        r.k,
        r.mean_neighbours
    );
    let text = serde_json::to_string_pretty(&r)
        .map_err(|e| Error::Internal(format!("serialising report: {e}")))?;
    write_atomic(&a.json, format!("{text}\n").as_bytes())
}

fn demo(a: DemoArgs) -> Result<()> {
    use crate::train::fit::{fit, FitConfig};
    std::fs::create_dir_all(&a.out)
        .map_err(|e| Error::file(&a.out, format!("cannot create folder: {e}")))?;
    let t0 = std::time::Instant::now();
    println!("herdfit demo: synthetic herd → video → fields → fit (first half) → validation (second half)");
    let truth = Params::default();
    let truth_path = a.out.join("truth.json");
    truth.save(&truth_path)?;
    // 1. A synthetic herd with known parameters, rendered to video when OpenCV is available.
    let synth_dir = a.out.join("synthetic");
    let video = a.out.join("herd.avi");
    let with_video = cfg!(feature = "video");
    synth_cmd(SynthArgs {
        params: Some(truth_path.clone()),
        agents: 300,
        frames: 120,
        fps: 25.0,
        grid: (16, 10),
        cell_size: 3.0,
        obstacles: None,
        heading: 0.0,
        seed: 7,
        precision: Precision::F32,
        video: with_video.then(|| video.clone()),
        px_per_bl: 12.0,
        body_colour: [235, 235, 225],
        camera_motion: false,
        out: synth_dir.clone(),
    })?;
    // 2. Fields from the video (or the synthetic fields without OpenCV).
    let clip_dir = if with_video {
        let d = a.out.join("clip");
        extract_cmd(ExtractArgs {
            video: video.clone(),
            out: d.clone(),
            config: None,
            grid: Some(16),
            body_length_px: Some(12.0),
            body_colour: Some([235, 235, 225]),
            colour_threshold: None,
            background_threshold: None,
            body_pixels: None,
            anchor: vec![],
            background: None,
            obstacles: None,
            frames: None,
            smooth: None,
            preview: Some(a.out.join("preview")),
            preview_every: 60,
        })?;
        d
    } else {
        synth_dir.clone()
    };
    let clip = crate::fields::ClipFields::load(&clip_dir)?;
    // 3. Fit on the first half from a generic start.
    let half = clip.frames() / 2;
    let start = Params::neutral();
    let start_path = a.out.join("start.json");
    start.save(&start_path)?;
    // Field matching through 16-step windows: on this clip it beats the paper's losses on the
    // held-out measures (RESULTS.md §1).
    let cfg = FitConfig {
        window: 16,
        epochs: 6,
        frames: 0..half,
        seed: 1,
        loss: crate::train::fit::LossKind::Fields,
        optimizer: crate::train::fit::Optimizer::Normalized,
        ..FitConfig::default()
    };
    let pb = progress_bar((cfg.epochs * (half - 1).div_ceil(cfg.window)) as u64, "fit");
    let res = fit(&clip, &start, &cfg, None, |_, _, e, _| {
        pb.set_message(format!("E_mean {e:.3}"));
        pb.inc(1);
    })?;
    pb.finish_and_clear();
    let params_path = a.out.join("params.json");
    let mut fitted = res.params.clone();
    fitted.provenance = Some(serde_json::json!({
        "source": "demo fit",
        "clip": clip_dir.display().to_string(),
        "frames": [0, half],
        "settings": cfg,
    }));
    fitted.save(&params_path)?;
    crate::train::fit::write_log(&a.out.join("fit.log.csv"), &res.log)?;
    // 4. Validation on the second half, fitted vs the generic start.
    let report_dir = a.out.join("report");
    let report = validate_cmd(ValidateArgs {
        clip: clip_dir.clone(),
        params: params_path.clone(),
        baseline: Some(start_path),
        split: 0.5,
        grid: 10,
        seeds: 3,
        settle: crate::train::fit::Settle::default().iterations,
        warmup: 0,
        guidance_scale: crate::train::fit::GUIDANCE_SCALE,
        ensemble_mean: false,
        no_video: false,
        out: report_dir.clone(),
    })?;
    println!();
    println!(
        "{:<20} {:>8} {:>8} {:>8}",
        "parameter", "true", "start", "fitted"
    );
    for (i, n) in crate::params::param_names().iter().enumerate() {
        println!(
            "{n:<20} {:>8.3} {:>8.3} {:>8.3}",
            truth.to_vec()[i],
            start.to_vec()[i],
            res.params.to_vec()[i]
        );
    }
    let mean_abs = |v: [f64; 12]| {
        v.iter()
            .zip(truth.to_vec())
            .map(|(a, b)| (a - b).abs())
            .sum::<f64>()
            / 12.0
    };
    println!(
        "mean |θ − θ*| per parameter: start {:.3}, fitted {:.3}",
        mean_abs(start.to_vec()),
        mean_abs(res.params.to_vec())
    );
    for set in &report.sets {
        println!(
            "{:<9} density error {:.3}, velocity error {:.3}, polarization error {:.3}, angular momentum error {:.3}",
            set.name,
            set.error("density_error"),
            set.error("velocity_error"),
            set.error("polarization"),
            set.error("angular_momentum_centroid")
        );
    }
    println!(
        "report: {} (report.md opens with the comparison table); {:.0} s",
        report_dir.join("report.md").display(),
        t0.elapsed().as_secs_f64()
    );
    println!();
    println!("{}", crate::lift::demo(&a.out, &mut Bars::default())?);
    Ok(())
}

fn synth_cmd(a: SynthArgs) -> Result<()> {
    let params = load_params(&a.params)?;
    if !(a.cell_size.is_finite() && a.cell_size > 0.0) {
        return Err(Error::invalid(format!(
            "--cell-size {} must be > 0",
            a.cell_size
        )));
    }
    let (nx, ny) = a.grid;
    let grid = crate::fields::Grid {
        origin: [0.0, 0.0],
        cell_size: a.cell_size,
        nx,
        ny,
    };
    let obstacles = match &a.obstacles {
        Some(p) => crate::synth::read_cells(p, nx, ny)?,
        None => ndarray::Array2::zeros((ny, nx)),
    };
    crate::io::AtomicDir::create(&a.out)?; // fail early on an unusable --out
    let device = cpu_device(a.precision)?;
    let cfg = crate::synth::SynthConfig {
        params: params.clone(),
        agents: a.agents,
        frames: a.frames,
        fps: a.fps,
        grid,
        obstacles,
        seed: a.seed,
        heading_deg: a.heading,
        precision: a.precision,
    };
    let pb = progress_bar(a.frames.saturating_sub(1) as u64, "synth");
    let syn = crate::synth::synthesise(&cfg, &device, || pb.inc(1))?;
    pb.finish_and_clear();
    let mut truth = params.clone();
    truth.physical = Some(params.physical_values());
    truth.provenance = Some(serde_json::json!({"source": "synth truth", "seed": a.seed}));
    let truth = serde_json::to_string_pretty(&truth)
        .map_err(|e| Error::Internal(format!("serialising truth: {e}")))?;
    let traj = syn.trajectories_csv(a.fps);
    let mut clip = syn.clip.clone();
    let mut extra = vec![
        ("truth.json", format!("{truth}\n").into_bytes()),
        ("trajectories.csv", traj.into_bytes()),
    ];
    let pending = match &a.video {
        None => None,
        Some(path) => {
            let (cameras, pending, settings) = render_synth_video(&a, &syn, path)?;
            let s = a.px_per_bl;
            clip.meta.body_length_px = Some(s);
            clip.meta.body_pixel_coverage =
                Some(std::f64::consts::PI * 0.5 * s * 0.5 * crate_body_width() * s);
            if let serde_json::Value::Object(m) = &mut clip.meta.provenance {
                m.insert("video".into(), settings);
            }
            let cams = serde_json::to_string_pretty(&cameras)
                .map_err(|e| Error::Internal(format!("serialising cameras: {e}")))?;
            extra.push(("camera.json", format!("{cams}\n").into_bytes()));
            Some(pending)
        }
    };
    clip.save(&a.out, &extra)?;
    if let Some(p) = pending {
        commit_video(p)?;
    }
    let counts: Vec<f64> = (0..syn.clip.frames()).map(|f| syn.clip.count(f)).collect();
    println!(
        "synth: {} agents, {} frames at {} fps on a {nx}×{ny} grid of {} BL cells; {:.0}–{:.0} agents inside the grid; wrote {}",
        a.agents,
        a.frames,
        a.fps,
        a.cell_size,
        counts.iter().cloned().fold(f64::INFINITY, f64::min),
        counts.iter().cloned().fold(0.0, f64::max),
        a.out.display()
    );
    Ok(())
}

fn import_cmd(a: ImportArgs) -> Result<()> {
    let clip = crate::fields::import_reference(&a.prefix)?;
    clip.save(&a.out, &[])?;
    println!(
        "import-reference: {} frames, {}×{} cells of {:.4} BL, {:.3} fps; wrote {}",
        clip.frames(),
        clip.meta.nx,
        clip.meta.ny,
        clip.meta.cell_size,
        clip.meta.fps,
        a.out.display()
    );
    Ok(())
}

fn fields_info(a: FieldsInfoArgs) -> Result<()> {
    let clip = crate::fields::ClipFields::load(&a.clip)?;
    if let Some(j) = &a.json {
        check_writable(j)?;
    }
    let m = &clip.meta;
    let measures = crate::metrics::clip_measures(&clip);
    let counts: Vec<f64> = measures.iter().map(|x| x.agents).collect();
    let mean = counts.iter().sum::<f64>() / counts.len() as f64;
    let obstacles = clip.obstacles.iter().filter(|&&v| v != 0).count();
    println!("clip        {}", a.clip.display());
    println!(
        "grid        {}×{} cells of {} BL (origin {:?}), {} obstacle cells",
        m.nx, m.ny, m.cell_size, m.origin, obstacles
    );
    println!(
        "frames      {} at {} fps ({:.2} s)",
        m.frames,
        m.fps,
        m.frames as f64 / m.fps
    );
    println!(
        "agents      min {:.1}, mean {:.1}, max {:.1} per frame (Σ density × cell area)",
        counts.iter().cloned().fold(f64::INFINITY, f64::min),
        mean,
        counts.iter().cloned().fold(0.0, f64::max)
    );
    println!(
        "speed       mean {:.4} BL/s, std {:.4} BL/s, {} speed–density rows",
        m.speed.mean,
        m.speed.std,
        m.speed.density_table.len()
    );
    for r in &m.speed.density_table {
        println!(
            "              density {:.4} agents/BL² → {:.4} BL/s",
            r[0], r[1]
        );
    }
    println!(
        "{:>6} {:>10} {:>13} {:>18} {:>18}",
        "frame", "agents", "polarization", "ang.mom centroid", "ang.mom centre"
    );
    for x in &measures {
        println!(
            "{:>6} {:>10.2} {:>13.4} {:>18.4} {:>18.4}",
            x.frame,
            x.agents,
            x.polarization,
            x.angular_momentum_centroid,
            x.angular_momentum_frame_centre
        );
    }
    if let Some(j) = &a.json {
        let out = serde_json::json!({
            "clip": a.clip.display().to_string(),
            "meta": m,
            "obstacle_cells": obstacles,
            "frames": measures,
        });
        let text = serde_json::to_string_pretty(&out)
            .map_err(|e| Error::Internal(format!("serialising: {e}")))?;
        write_atomic(j, format!("{text}\n").as_bytes())?;
    }
    Ok(())
}

#[cfg(feature = "video")]
fn crate_body_width() -> f64 {
    crate::video::render::BODY_WIDTH_BL
}

#[cfg(not(feature = "video"))]
fn crate_body_width() -> f64 {
    0.4
}

#[cfg(feature = "video")]
type Pending = crate::video::PendingVideo;
#[cfg(not(feature = "video"))]
type Pending = ();

#[cfg(feature = "video")]
fn render_synth_video(
    a: &SynthArgs,
    syn: &crate::synth::Synth,
    path: &std::path::Path,
) -> Result<(Vec<serde_json::Value>, Pending, serde_json::Value)> {
    check_writable(path)?;
    let cfg = crate::video::RenderConfig {
        px_per_bl: a.px_per_bl,
        body_rgb: a.body_colour,
        camera_motion: a.camera_motion,
        seed: a.seed,
    };
    let pb = progress_bar(syn.frames.len() as u64, "render");
    let (cams, pending) = crate::video::render_video(
        path,
        &syn.frames,
        &syn.clip.grid(),
        &syn.clip.obstacles,
        a.fps,
        &cfg,
        || pb.inc(1),
    )?;
    pb.finish_and_clear();
    let cams = cams
        .iter()
        .map(|c| serde_json::to_value(c).unwrap_or_default())
        .collect();
    let settings = serde_json::json!({
        "file": path.display().to_string(),
        "render": cfg,
        "frame_size": crate::video::render::frame_size(&syn.clip.grid(), a.px_per_bl),
    });
    Ok((cams, pending, settings))
}

#[cfg(not(feature = "video"))]
fn render_synth_video(
    _a: &SynthArgs,
    _syn: &crate::synth::Synth,
    path: &std::path::Path,
) -> Result<(Vec<serde_json::Value>, Pending, serde_json::Value)> {
    Err(Error::file(
        path,
        "this herdfit was built without the `video` feature (OpenCV)",
    ))
}

#[cfg(feature = "video")]
fn commit_video(p: Pending) -> Result<()> {
    p.commit()
}

#[cfg(not(feature = "video"))]
fn commit_video(_p: Pending) -> Result<()> {
    Ok(())
}

fn fit_cmd(a: FitArgs) -> Result<()> {
    use crate::train::fit::{evaluate, fit_clips, write_log, CheckpointDir, FitConfig};
    if a.eval_seeds == 0 || a.eval_seeds > 64 {
        return Err(Error::invalid(format!(
            "--eval-seeds {} is out of range 1..=64",
            a.eval_seeds
        )));
    }
    let loaded = a
        .clips
        .iter()
        .map(|p| crate::fields::ClipFields::load(p))
        .collect::<Result<Vec<_>>>()?;
    let clips: Vec<&crate::fields::ClipFields> = loaded.iter().collect();
    let init = match &a.init {
        Some(p) => Params::load(p)?,
        None => Params::neutral(),
    };
    // All frames of the shortest clip unless --frames says otherwise.
    let shortest = clips.iter().map(|c| c.frames()).min().unwrap_or(0);
    let frames = a.frames.map_or(0..shortest, |(x, y)| x..y);
    let cfg = FitConfig {
        window: a.window,
        epochs: a.epochs,
        beta: a.beta,
        var_weight: a.var_weight,
        lr: a.lr,
        optimizer: a.optimizer,
        frames: frames.clone(),
        seed: a.seed,
        density_threshold: a.density_threshold,
        zero_grad_step: 0.02,
        precision: a.precision,
        split_gradients: !a.joint_gradients,
        cell_mean: a.cell_mean,
        loss: a.loss,
        checkpointing: a.checkpointing,
        settle: crate::train::fit::Settle::with_iterations(a.settle),
        replicas: a.replicas,
        guidance_scale: a.guidance_scale,
    };
    for (c, p) in clips.iter().zip(&a.clips) {
        cfg.check(c).map_err(|e| e.in_file(p))?;
    }
    let log_path = a.log.clone().unwrap_or_else(|| sibling(&a.out, ".log.csv"));
    let plot_path = a
        .plot
        .clone()
        .unwrap_or_else(|| sibling(&a.out, ".loss.png"));
    for p in [&a.out, &log_path, &plot_path] {
        check_writable(p)?;
    }
    let ckpt = match &a.checkpoint {
        Some(d) => {
            std::fs::create_dir_all(d)
                .map_err(|e| Error::file(d, format!("cannot create folder: {e}")))?;
            Some(CheckpointDir {
                dir: d.clone(),
                resume: a.resume,
            })
        }
        None => None,
    };
    let windows_per_epoch = (frames.end - frames.start - 1).div_ceil(a.window) * clips.len();
    let pb = progress_bar((windows_per_epoch * a.epochs) as u64, "fit");
    if let Some(c) = &ckpt {
        if c.resume {
            if let Ok(text) = std::fs::read_to_string(c.dir.join("checkpoint.json")) {
                if let Ok(k) = serde_json::from_str::<crate::train::fit::Checkpoint>(&text) {
                    pb.set_position((k.epochs_done * windows_per_epoch) as u64);
                }
            }
        }
    }
    let res = fit_clips(
        &clips,
        &init,
        &cfg,
        ckpt.as_ref(),
        |epoch, frame, e_mean, ms| {
            pb.set_message(format!(
                "epoch {epoch} frame {frame} E_mean {e_mean:.4} {ms:.1} ms/step"
            ));
            pb.inc(1);
        },
    )?;
    pb.finish_and_clear();
    let mut start_params = init.clone();
    start_params.speed = res.params.speed.clone();
    let loss_before = crate::train::fit::loss_of(&clips, &start_params, &cfg)?;
    let loss_after = crate::train::fit::loss_of(&clips, &res.params, &cfg)?;
    // Density and velocity errors, averaged over the clips (each simulated with its own speeds).
    let guidance: Vec<Vec<crate::sim::Guidance>> = clips
        .iter()
        .map(|c| crate::train::fit::guidance_fields(c, cfg.guidance_scale))
        .collect();
    let errors = |p: &Params| -> Result<(f64, f64)> {
        let (mut d, mut v) = (0.0, 0.0);
        for (c, guidance) in clips.iter().zip(&guidance) {
            let mut q = p.clone();
            q.speed = c.speed_model(&init.speed);
            for k in 0..a.eval_seeds {
                let (x, y) = evaluate(
                    c,
                    &q,
                    frames.clone(),
                    a.seed.wrapping_add(k as u64),
                    a.precision,
                    &cfg.settle,
                    guidance,
                )?;
                let w = (clips.len() * a.eval_seeds) as f64;
                d += x / w;
                v += y / w;
            }
        }
        Ok((d, v))
    };
    let before = errors(&start_params)?;
    let after = errors(&res.params)?;
    let last_epoch = res.log.last().map_or(0, |r| r.epoch);
    let last: Vec<&crate::train::fit::LogRow> =
        res.log.iter().filter(|r| r.epoch == last_epoch).collect();
    let mean = |f: &dyn Fn(&crate::train::fit::LogRow) -> f64| {
        last.iter().map(|r| f(r)).sum::<f64>() / last.len().max(1) as f64
    };
    let mut out = res.params.clone();
    out.provenance = Some(serde_json::json!({
        "source": "fit",
        "clip": a.clips[0].display().to_string(),
        "clips": a.clips.iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
        "frames": [frames.start, frames.end],
        "settings": cfg,
        "start": res.start,
        "final_losses": {
            "e_mean": mean(&|r| r.e_mean),
            "e_var": mean(&|r| r.e_var),
            "e_fields": mean(&|r| r.e_fields),
            "density_error": mean(&|r| r.density_error),
            "velocity_error": mean(&|r| r.velocity_error),
        },
        "loss": {
            "what": "mean E_mean and E_var over one epoch of the fit's schedule without updates (same herd and noise)",
            "start": {"e_mean": loss_before.0, "e_var": loss_before.1, "e_fields": loss_before.2},
            "fitted": {"e_mean": loss_after.0, "e_var": loss_after.1, "e_fields": loss_after.2},
        },
        "evaluation": {
            "what": "mean per-frame errors of runs from the first frame's fields (no population control), averaged over the seeds",
            "seeds": a.eval_seeds,
            "start": {"density_error": before.0, "velocity_error": before.1},
            "fitted": {"density_error": after.0, "velocity_error": after.1},
        },
    }));
    write_log(&log_path, &res.log)?;
    let per_epoch = |f: &dyn Fn(&crate::train::fit::LogRow) -> f64| -> Vec<(f64, f64)> {
        (0..a.epochs)
            .filter_map(|e| {
                let rows: Vec<_> = res.log.iter().filter(|r| r.epoch == e).collect();
                (!rows.is_empty()).then(|| {
                    (
                        e as f64 + 1.0,
                        rows.iter().map(|r| f(r)).sum::<f64>() / rows.len() as f64,
                    )
                })
            })
            .collect()
    };
    let series = [
        crate::plot::Series {
            name: "E_mean",
            points: per_epoch(&|r| r.e_mean),
            colour: plotters::style::RGBColor(31, 119, 180),
        },
        crate::plot::Series {
            name: "E_var",
            points: per_epoch(&|r| r.e_var),
            colour: plotters::style::RGBColor(255, 127, 14),
        },
        crate::plot::Series {
            name: "density error",
            points: per_epoch(&|r| r.density_error),
            colour: plotters::style::RGBColor(44, 160, 44),
        },
        crate::plot::Series {
            name: "velocity error",
            points: per_epoch(&|r| r.velocity_error),
            colour: plotters::style::RGBColor(214, 39, 40),
        },
    ];
    if let Err(e) = crate::plot::line_chart(
        &plot_path,
        "herdfit fit",
        "epoch",
        "mean over the epoch's windows",
        &series,
    ) {
        eprintln!("warning: no loss curve: {e}");
    }
    out.save(&a.out)?;
    println!(
        "fit: {} epochs × {} windows of {} steps on frames {}..{} of {}",
        a.epochs,
        windows_per_epoch,
        a.window,
        frames.start,
        frames.end,
        a.clips
            .iter()
            .map(|p| p.display().to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    println!("{:<20} {:>8} {:>8}", "parameter", "start", "fitted");
    for (n, (s0, s1)) in crate::params::param_names()
        .iter()
        .zip(res.start.iter().zip(res.params.to_vec()))
    {
        println!("{n:<20} {s0:>8.4} {s1:>8.4}");
    }
    println!(
        "loss E_mean {:.4} → {:.4}, E_var {:.4} → {:.4}, E_fields {:.4} → {:.4}; density error {:.4} → {:.4}, velocity error {:.4} → {:.4}",
        loss_before.0, loss_after.0, loss_before.1, loss_after.1, loss_before.2, loss_after.2, before.0, after.0, before.1, after.1
    );
    println!(
        "wrote {}, {}, {}",
        a.out.display(),
        log_path.display(),
        plot_path.display()
    );
    Ok(())
}

#[cfg(not(feature = "video"))]
fn extract_cmd(a: ExtractArgs) -> Result<()> {
    Err(Error::file(
        &a.video,
        "this herdfit was built without the `video` feature (OpenCV)",
    ))
}

#[cfg(feature = "video")]
fn extract_cmd(a: ExtractArgs) -> Result<()> {
    use crate::video::extract::{extract, ExtractConfig};
    let mut cfg = match &a.config {
        Some(p) => {
            let text = std::fs::read_to_string(p)
                .map_err(|e| Error::file(p, format!("cannot read: {e}")))?;
            serde_json::from_str::<ExtractConfig>(&text)
                .map_err(|e| Error::file(p, format!("not an extraction settings file: {e}")))?
        }
        None => ExtractConfig::default(),
    };
    if let Some(v) = a.grid {
        cfg.grid = v;
    }
    if let Some(v) = a.body_length_px {
        cfg.body_length_px = v;
    }
    if a.body_colour.is_some() {
        cfg.body_colour = a.body_colour;
    }
    if let Some(v) = a.colour_threshold {
        cfg.colour_threshold = v;
    }
    if let Some(v) = a.background_threshold {
        cfg.background_threshold = v;
    }
    if a.body_pixels.is_some() {
        cfg.body_pixels = a.body_pixels;
    }
    if let Some(v) = a.smooth {
        cfg.smooth = v;
    }
    if let Some((x, y)) = a.frames {
        cfg.frames = Some([x, y]);
    }
    if a.obstacles.is_some() {
        cfg.obstacles = a.obstacles.clone();
    }
    match a.background.as_deref() {
        None => {}
        Some("auto") => cfg.background = None,
        Some(p) => cfg.background = Some(PathBuf::from(p)),
    }
    if a.config.is_none() && a.body_length_px.is_none() {
        return Err(Error::invalid("give --body-length-px (or --config)"));
    }
    if !a.anchor.is_empty() {
        cfg.anchors.clear();
        for s in &a.anchor {
            if s == "center" || s == "centre" {
                cfg.anchors.push([-1, -1, -1, -1]);
                continue;
            }
            let v: Vec<i32> = s
                .split(',')
                .map(|t| t.trim().parse::<i32>())
                .collect::<std::result::Result<_, _>>()
                .map_err(|_| Error::invalid(format!("--anchor '{s}' is not x,y,w,h")))?;
            if v.len() != 4 {
                return Err(Error::invalid(format!("--anchor '{s}' is not x,y,w,h")));
            }
            cfg.anchors.push([v[0], v[1], v[2], v[3]]);
        }
    }
    // `center`: the central quarter of the first frame.
    if cfg.anchors.iter().any(|a| a[0] < 0 && a[2] < 0) {
        let probe =
            opencv::videoio::VideoCapture::from_file(a.video.as_os_str(), opencv::videoio::CAP_ANY)
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
            .ok_or_else(|| Error::file(&a.video, "cannot open as a video"))?;
        for r in cfg.anchors.iter_mut().filter(|r| r[0] < 0 && r[2] < 0) {
            *r = [w * 3 / 8, h * 3 / 8, w / 4, h / 4];
        }
    }
    crate::io::AtomicDir::create(&a.out)?;
    if let Some(d) = &a.preview {
        crate::io::AtomicDir::create(d)?;
    }
    let pb = progress_bar(0, "extract");
    let ex = extract(
        &a.video,
        &cfg,
        a.preview.as_ref().map(|_| a.preview_every),
        |stage, done, total| {
            if pb.length() != Some(total as u64) {
                pb.set_length(total as u64);
            }
            pb.set_message(stage.to_string());
            pb.set_position(done as u64);
        },
    )?;
    pb.finish_and_clear();
    let cams =
        serde_json::to_string_pretty(&ex.camera).map_err(|e| Error::Internal(e.to_string()))?;
    ex.clip
        .save(&a.out, &[("camera.json", format!("{cams}\n").into_bytes())])?;
    if let Some(d) = &a.preview {
        let dir = crate::io::AtomicDir::create(d)?;
        for (name, bytes) in &ex.previews {
            dir.write(name, bytes)?;
        }
        dir.write(
            "report.json",
            b"{\"source\": \"herdfit extract --preview\"}\n",
        )?;
        dir.commit()?;
    }
    let c = &ex.clip;
    let counts: Vec<f64> = (0..c.frames()).map(|f| c.count(f)).collect();
    println!(
        "extract: {} frames, {}×{} cells of {:.3} BL, {:.1}–{:.1} animals per frame, mean speed {:.3} BL/s; wrote {}",
        c.frames(),
        c.meta.nx,
        c.meta.ny,
        c.meta.cell_size,
        counts.iter().cloned().fold(f64::INFINITY, f64::min),
        counts.iter().cloned().fold(0.0, f64::max),
        c.meta.speed.mean,
        a.out.display()
    );
    Ok(())
}

/// Runs `validate` and returns the report.
fn validate_cmd(a: ValidateArgs) -> Result<crate::validate::Report> {
    use crate::validate::{markdown, validate};
    let clip = crate::fields::ClipFields::load(&a.clip)?;
    let mut sets = vec![("fitted".to_string(), Params::load(&a.params)?)];
    if let Some(b) = &a.baseline {
        sets.push(("baseline".to_string(), Params::load(b)?));
    }
    let out = crate::io::AtomicDir::create(&a.out)?;
    let pb = progress_bar((sets.len() * a.seeds) as u64, "validate");
    let (report, runs) = validate(
        &clip,
        &a.clip.display().to_string(),
        &sets,
        &crate::validate::ValidateConfig {
            split: a.split,
            grid: a.grid,
            seeds: a.seeds,
            settle: crate::train::fit::Settle::with_iterations(a.settle),
            warmup: a.warmup,
            guidance_scale: a.guidance_scale,
            ensemble_mean: a.ensemble_mean,
        },
        || pb.inc(1),
    )
    .map_err(|e| e.in_file(&a.clip))?;
    pb.finish_and_clear();
    let json = serde_json::to_string_pretty(&report).map_err(|e| Error::Internal(e.to_string()))?;
    out.write("report.json", format!("{json}\n").as_bytes())?;
    let md = markdown(&report);
    out.write("report.md", md.as_bytes())?;
    let start = report.frames[0];
    let colours = [
        plotters::style::RGBColor(31, 119, 180),
        plotters::style::RGBColor(255, 127, 14),
        plotters::style::RGBColor(44, 160, 44),
        plotters::style::RGBColor(214, 39, 40),
        plotters::style::RGBColor(148, 103, 189),
        plotters::style::RGBColor(140, 86, 75),
    ];
    let mut series = vec![crate::plot::Series {
        name: "video polarization",
        points: report
            .video_per_frame
            .iter()
            .enumerate()
            .map(|(k, v)| ((start + k) as f64, v[0]))
            .collect(),
        colour: plotters::style::RGBColor(0, 0, 0),
    }];
    let names: Vec<String> = report
        .sets
        .iter()
        .map(|s| format!("{} polarization", s.name))
        .collect();
    for (i, set) in report.sets.iter().enumerate() {
        series.push(crate::plot::Series {
            name: &names[i],
            points: set
                .per_frame
                .iter()
                .enumerate()
                .map(|(k, v)| ((start + k) as f64, v[2]))
                .collect(),
            colour: colours[i % 6],
        });
    }
    let am_names: Vec<String> = report
        .sets
        .iter()
        .map(|s| format!("{} angular momentum", s.name))
        .collect();
    series.push(crate::plot::Series {
        name: "video angular momentum",
        points: report
            .video_per_frame
            .iter()
            .enumerate()
            .map(|(k, v)| ((start + k) as f64, v[1]))
            .collect(),
        colour: plotters::style::RGBColor(120, 120, 120),
    });
    for (i, set) in report.sets.iter().enumerate() {
        series.push(crate::plot::Series {
            name: &am_names[i],
            points: set
                .per_frame
                .iter()
                .enumerate()
                .map(|(k, v)| ((start + k) as f64, v[3]))
                .collect(),
            colour: colours[(i + 2) % 6],
        });
    }
    crate::plot::line_chart(
        &out.path("metrics.png"),
        "emergent measures (held-out frames)",
        "frame",
        "value",
        &series,
    )?;
    let err_names: Vec<(String, String)> = report
        .sets
        .iter()
        .map(|s| {
            (
                format!("{} density error", s.name),
                format!("{} velocity error", s.name),
            )
        })
        .collect();
    let mut es = Vec::new();
    for (i, set) in report.sets.iter().enumerate() {
        es.push(crate::plot::Series {
            name: &err_names[i].0,
            points: set
                .per_frame
                .iter()
                .enumerate()
                .map(|(k, v)| ((start + k) as f64, v[0]))
                .collect(),
            colour: colours[(2 * i) % 6],
        });
        es.push(crate::plot::Series {
            name: &err_names[i].1,
            points: set
                .per_frame
                .iter()
                .enumerate()
                .map(|(k, v)| ((start + k) as f64, v[1]))
                .collect(),
            colour: colours[(2 * i + 1) % 6],
        });
    }
    crate::plot::line_chart(
        &out.path("errors.png"),
        "coarse-grid errors (held-out frames)",
        "frame",
        "relative error",
        &es,
    )?;
    for set in &report.sets {
        crate::plot::heat_map(
            &out.path(&format!("error-map-{}.png", set.name)),
            &format!("{}: mean |ρ' − ρ| per coarse cell (agents)", set.name),
            &set.error_map,
        )?;
    }
    #[cfg(feature = "video")]
    if !a.no_video {
        if let Some(run) = runs.first().and_then(|r| r.first()) {
            crate::video::render::render_comparison(
                &out.path("side-by-side.avi"),
                &clip,
                &run.fields,
                &run.frames,
                start,
            )?;
        }
    }
    #[cfg(not(feature = "video"))]
    let _ = (&runs, a.no_video);
    out.commit()?;
    print!("{md}");
    println!("wrote {}", a.out.display());
    Ok(report)
}

fn author_cmd(a: AuthorArgs) -> Result<()> {
    use crate::author::{run, Scene};
    let scene = Scene::load(&a.scene)?;
    let out = crate::io::AtomicDir::create(&a.out)?;
    let device = cpu_device(Precision::F32)?;
    let steps = (scene.file.duration * scene.file.fps).round() as u64;
    let pb = progress_bar(steps, "author");
    let r = run(&scene, &device, || pb.inc(1))?;
    pb.finish_and_clear();
    let fps = scene.file.fps;
    let mut csv = String::from(TRAJ_HEADER);
    csv.push('\n');
    for (f, (rows, roles)) in r.frames.iter().zip(&r.roles).enumerate() {
        push_traj_frame(&mut csv, f, f as f64 / fps, rows, roles);
    }
    out.write("trajectories.csv", csv.as_bytes())?;
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
            &format!("t = {:.1} s (colour = behaviour region)", f as f64 / fps),
            &scene.grid,
            &scene.obstacles,
            None,
            &lines,
            &agents,
        )?;
    }
    // Summary: centroid path, and polarization / aspect ratio per behaviour region.
    let centroid: Vec<[f64; 2]> = r
        .frames
        .iter()
        .map(|rows| {
            let n = rows.len().max(1) as f64;
            [
                rows.iter().map(|a| a.x).sum::<f64>() / n,
                rows.iter().map(|a| a.y).sum::<f64>() / n,
            ]
        })
        .collect();
    let sets = scene.params.len();
    let mut per_region = Vec::new();
    for g in 0..sets {
        let (mut pol, mut asp, mut frames) = (0.0, 0.0, 0usize);
        let mut agents_seen = 0usize;
        for (rows, reg) in r.frames.iter().zip(&r.regions) {
            let sel: Vec<&crate::io::AgentRow> = rows
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
            pol += crate::metrics::polarization(&vel, &w);
            asp += crate::metrics::aspect_ratio(&pos, &vel, &w).unwrap_or(f64::NAN);
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
    let report = serde_json::json!({
        "scene": a.scene.display().to_string(),
        "agents": r.frames[0].len(),
        "frames": n,
        "fps": fps,
        "centroid": centroid,
        "regions": per_region,
        "predator": r.predator,
    });
    out.write(
        "report.json",
        serde_json::to_string_pretty(&report)
            .map_err(|e| Error::Internal(e.to_string()))?
            .as_bytes(),
    )?;
    #[cfg(feature = "video")]
    if a.video {
        let cfg = crate::video::RenderConfig {
            px_per_bl: a.px_per_bl,
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
    if a.video {
        return Err(Error::invalid("--video needs the `video` feature (OpenCV)"));
    }
    out.commit()?;
    let last = centroid[n - 1];
    println!(
        "author: {} agents, {} frames ({:.1} s); centroid ({:.1}, {:.1}) → ({:.1}, {:.1}); wrote {}",
        r.frames[0].len(),
        n,
        (n - 1) as f64 / fps,
        centroid[0][0],
        centroid[0][1],
        last[0],
        last[1],
        a.out.display()
    );
    Ok(())
}

/// [`crate::progress::Progress`] as indicatif bars on stderr (hidden when stderr is not a
/// terminal), one bar per stage.
#[derive(Default)]
pub struct Bars {
    bar: Option<ProgressBar>,
}

impl crate::progress::Progress for Bars {
    fn start(&mut self, what: &str, len: u64) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
        self.bar = Some(progress_bar(len, what));
    }
    fn inc(&mut self, n: u64) {
        if let Some(b) = &self.bar {
            b.inc(n);
        }
    }
    fn message(&mut self, msg: &str) {
        if let Some(b) = &self.bar {
            b.set_message(msg.to_string());
        }
    }
    fn finish(&mut self) {
        if let Some(b) = self.bar.take() {
            b.finish_and_clear();
        }
    }
}
