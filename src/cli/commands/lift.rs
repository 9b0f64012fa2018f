//! `herdfit lift …`: 3D flocks from 2D tracks (Lin's thesis). Each verb parses its flags into the
//! library's config, makes one library call and prints.

use super::lift_print;
use crate::cli::paths::{InFile, OutDir, OutFile, OutFilesIn, OutTracks};
use crate::cli::Bars;
use crate::data::atomic::{check_writable, write_atomic, AtomicDir};
use crate::data::camera::Camera;
use crate::data::jackdaw::load_tracks;
use crate::data::tracks::{Tracks, Units};
use crate::error::{Error, Result};
use crate::lift::boids::{synth_flock, BoidsConfig};
use crate::lift::eval::evaluate;
use crate::lift::render::{views_png, Layer, COLOURS};
use crate::lift::{lift, project_tracks, LiftConfig, Method};
use clap::{Args, Subcommand};

#[derive(Subcommand, Debug)]
pub enum LiftCommand {
    /// Lift 2D pixel tracks seen by one camera to 3D tracks (frame by frame, then the whole
    /// sequence); writes the 3D tracks, a report and optionally views and a video.
    Run(RunArgs),
    /// A synthetic boids flock with homing seen by a ground observer: 2D tracks, 3D truth, camera.
    Synth(SynthArgs),
    /// Project 3D tracks through a camera into 2D pixel tracks.
    Project(ProjectArgs),
    /// Score both lifting methods and two baselines against 3D tracks seen by a camera.
    Evaluate(EvaluateArgs),
    /// Write a camera file looking from a position at a target.
    Camera(CameraArgs),
}

/// The thesis's parameters and the bounds, as flags over an optional config file.
#[derive(Args, Debug, Default)]
pub struct LiftFlags {
    /// Lift settings (herdfit lift config JSON; flags override its values).
    #[arg(long, value_name = "LIFT.json")]
    pub config: Option<InFile>,
    /// frame: the thesis's frame-by-frame method; sequence: then the whole-sequence optimisation.
    #[arg(long, value_parser = ["frame", "sequence"])]
    pub method: Option<String>,
    /// v_target, the birds' speed in world units per frame (estimated from the tracks and the
    /// camera when absent: the report says how).
    #[arg(long, value_name = "V")]
    pub v_target: Option<f64>,
    /// λ_t, weight of trajectory smoothness.
    #[arg(long, value_name = "L")]
    pub lambda_t: Option<f64>,
    /// λ_f, weight of flock-behaviour similarity.
    #[arg(long, value_name = "L")]
    pub lambda_f: Option<f64>,
    /// d_sep, the separation distance.
    #[arg(long, value_name = "D")]
    pub d_sep: Option<f64>,
    /// w_sep, separation against cohesion.
    #[arg(long, value_name = "W", allow_hyphen_values = true)]
    pub w_sep: Option<f64>,
    /// Nearest allowed depth (estimated when absent).
    #[arg(long, value_name = "D")]
    pub d_near: Option<f64>,
    /// Farthest allowed depth (estimated when absent).
    #[arg(long, value_name = "D")]
    pub d_far: Option<f64>,
    /// Iterations of the whole-sequence optimisation.
    #[arg(long, value_name = "N")]
    pub iterations: Option<usize>,
    #[arg(long)]
    pub seed: Option<u64>,
}

const FLAG_KEYS: [(&str, &str); 9] = [
    ("v_target", "--v-target"),
    ("lambda_t", "--lambda-t"),
    ("lambda_f", "--lambda-f"),
    ("d_sep", "--d-sep"),
    ("w_sep", "--w-sep"),
    ("d_near", "--d-near"),
    ("d_far", "--d-far"),
    ("sequence.iterations", "--iterations"),
    ("min_spacing", "--config"),
];

impl LiftFlags {
    /// The config: the file's (or the defaults), flags on top, checked.
    pub fn config(&self) -> Result<LiftConfig> {
        let mut c = match &self.config {
            Some(p) => LiftConfig::load(p)?,
            None => LiftConfig::default(),
        };
        if let Some(m) = &self.method {
            c.method = if m == "frame" {
                Method::Frame
            } else {
                Method::Sequence
            };
        }
        let set = |dst: &mut f64, v: Option<f64>| {
            if let Some(v) = v {
                *dst = v;
            }
        };
        if self.v_target.is_some() {
            c.v_target = self.v_target;
        }
        if self.d_near.is_some() {
            c.d_near = self.d_near;
        }
        if self.d_far.is_some() {
            c.d_far = self.d_far;
        }
        set(&mut c.lambda_t, self.lambda_t);
        set(&mut c.lambda_f, self.lambda_f);
        set(&mut c.d_sep, self.d_sep);
        set(&mut c.w_sep, self.w_sep);
        if let Some(n) = self.iterations {
            c.sequence.iterations = n;
        }
        if let Some(s) = self.seed {
            c.seed = s;
        }
        c.check().map_err(with_flag)?;
        Ok(c)
    }
}

/// Prefixes a setting's error with the flag that sets it.
fn with_flag(e: Error) -> Error {
    flagged(e, &FLAG_KEYS)
}

/// Prefixes an error about config key `k` (a message starting "k = …") with its flag.
fn flagged(e: Error, keys: &[(&str, &str)]) -> Error {
    match e {
        Error::Invalid(msg) => {
            let flag = keys
                .iter()
                .find(|(k, _)| msg.starts_with(&format!("{k} =")))
                .map(|(_, f)| *f);
            Error::Invalid(match flag {
                Some(f) => format!("{f}: {msg}"),
                None => msg,
            })
        }
        other => other,
    }
}

#[derive(Args, Debug)]
pub struct RunArgs {
    /// 2D tracks in pixels (herdfit.tracks/1, units px).
    #[arg(value_name = "TRACKS.csv")]
    pub tracks: InFile,
    #[arg(long, value_name = "CAMERA.json")]
    pub camera: InFile,
    /// Output 3D tracks (herdfit.tracks/1 CSV; its sidecar beside it).
    #[arg(long, value_name = "OUT.csv")]
    pub out: OutTracks,
    /// Report (herdfit.lift-report/2); OUT.report.json when omitted.
    #[arg(long, value_name = "REPORT.json")]
    pub report: Option<OutFile>,
    /// Folder for top.png and side.png.
    #[arg(long, value_name = "DIR")]
    pub plots: Option<OutFilesIn>,
    /// Top and side views animated (MJPG AVI; feature `video`).
    #[arg(long, value_name = "OUT.avi")]
    pub video: Option<OutFile>,
    #[command(flatten)]
    pub lift: LiftFlags,
}

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Output folder: tracks2d.csv, truth3d.csv, camera.json, report.json.
    #[arg(long, value_name = "DIR")]
    pub out: OutDir,
    /// Flock settings (JSON; flags override).
    #[arg(long, value_name = "BOIDS.json")]
    pub config: Option<InFile>,
    #[arg(long, value_name = "N")]
    pub birds: Option<usize>,
    #[arg(long, value_name = "F")]
    pub frames: Option<usize>,
    #[arg(long, value_name = "FPS")]
    pub fps: Option<f64>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Keep every point, in view or not (an error if one is not); by default points out of view
    /// are dropped.
    #[arg(long)]
    pub no_crop: bool,
}

#[derive(Args, Debug)]
pub struct ProjectArgs {
    /// 3D tracks (herdfit.tracks/1 or a jackdaw CSV).
    #[arg(value_name = "TRACKS3D.csv")]
    pub tracks: InFile,
    #[arg(long, value_name = "CAMERA.json")]
    pub camera: InFile,
    #[arg(long, value_name = "OUT.csv")]
    pub out: OutTracks,
    /// Drop points outside the image instead of failing.
    #[arg(long)]
    pub crop: bool,
}

#[derive(Args, Debug)]
pub struct EvaluateArgs {
    /// True 3D tracks (herdfit.tracks/1 or a jackdaw CSV).
    #[arg(value_name = "TRUTH3D.csv")]
    pub truth: InFile,
    #[arg(long, value_name = "CAMERA.json")]
    pub camera: InFile,
    /// Output folder: report.json, tracks2d.csv, the lifted tracks, top.png, side.png.
    #[arg(long, value_name = "DIR")]
    pub out: OutDir,
    /// Drop points out of view (birds leave and enter) instead of failing.
    #[arg(long)]
    pub crop: bool,
    #[command(flatten)]
    pub lift: LiftFlags,
}

#[derive(Args, Debug)]
pub struct CameraArgs {
    #[arg(long, value_name = "CAMERA.json")]
    pub out: OutFile,
    /// Camera centre, world coordinates.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_v3, allow_hyphen_values = true)]
    pub position: [f64; 3],
    /// The point on the optical axis.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_v3, allow_hyphen_values = true)]
    pub look_at: [f64; 3],
    /// World direction that appears up in the image.
    #[arg(long, value_name = "X,Y,Z", value_parser = parse_v3, default_value = "0,0,1", allow_hyphen_values = true)]
    pub up: [f64; 3],
    /// Image size.
    #[arg(long, value_name = "WxH", value_parser = parse_size, default_value = "1920x1080")]
    pub size: (u32, u32),
    /// Horizontal field of view (degrees).
    #[arg(long, value_name = "DEG", default_value_t = 60.0)]
    pub hfov: f64,
    /// World unit: m or BL.
    #[arg(long, value_parser = ["m", "BL"], default_value = "m")]
    pub units: String,
}

fn parse_v3(s: &str) -> std::result::Result<[f64; 3], String> {
    let v: Vec<&str> = s.split(',').collect();
    if v.len() != 3 {
        return Err(format!("expected X,Y,Z, got '{s}'"));
    }
    let mut out = [0.0; 3];
    for (o, t) in out.iter_mut().zip(v) {
        *o = t
            .trim()
            .parse::<f64>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| format!("'{t}' is not a finite number"))?;
        if o.abs() > crate::limits::MAX_COORD {
            return Err(crate::limits::beyond(*o, crate::limits::MAX_COORD));
        }
    }
    Ok(out)
}

fn parse_size(s: &str) -> std::result::Result<(u32, u32), String> {
    let (a, b) = s
        .split_once('x')
        .ok_or_else(|| format!("expected WxH, got '{s}'"))?;
    let p = |t: &str| {
        t.parse::<u32>()
            .ok()
            .filter(|v| *v > 0)
            .ok_or_else(|| format!("'{t}' is not a positive integer"))
    };
    Ok((p(a)?, p(b)?))
}

/// Runs a `herdfit lift` verb.
pub fn run(cmd: LiftCommand) -> Result<()> {
    match cmd {
        LiftCommand::Run(a) => run_cmd(a),
        LiftCommand::Synth(a) => synth_cmd(a),
        LiftCommand::Project(a) => project_cmd(a),
        LiftCommand::Evaluate(a) => evaluate_cmd(a),
        LiftCommand::Camera(a) => camera_cmd(a),
    }
}

fn json<T: serde::Serialize>(v: &T) -> Result<Vec<u8>> {
    serde_json::to_string_pretty(v)
        .map(|s| format!("{s}\n").into_bytes())
        .map_err(|e| Error::Internal(format!("serialising: {e}")))
}

fn run_cmd(a: RunArgs) -> Result<()> {
    let cfg = a.lift.config()?;
    let camera = Camera::load(&a.camera)?;
    let tracks = Tracks::load(&a.tracks)?;
    let report_path = a
        .report
        .as_ref()
        .map_or_else(|| a.out.with_extension("report.json"), |r| r.path());
    // The default report beside --out is this verb's own output: declared here, before writing.
    check_writable(&report_path)?;
    #[cfg(not(feature = "video"))]
    if a.video.is_some() {
        return Err(Error::invalid(
            "--video needs herdfit built with the `video` feature",
        ));
    }
    let t0 = std::time::Instant::now();
    let out =
        lift(&tracks, &camera, &cfg, &mut Bars::default()).map_err(|e| e.in_file(&a.tracks))?;
    let secs = t0.elapsed().as_secs_f64();
    if let Some(dir) = &a.plots {
        crate::data::atomic::make_dir(dir)?;
        views_png(
            &dir.join("top.png"),
            &dir.join("side.png"),
            "lifted flock",
            &[Layer {
                name: "lifted",
                tracks: &out.tracks,
                colour: COLOURS[1],
            }],
            &camera,
        )?;
    }
    #[cfg(feature = "video")]
    if let Some(v) = &a.video {
        crate::lift::render::views_avi(
            v,
            &[Layer {
                name: "lifted",
                tracks: &out.tracks,
                colour: COLOURS[1],
            }],
            &camera,
            tracks.meta.fps,
        )?;
    }
    out.tracks.save(&a.out)?;
    write_atomic(&report_path, &json(&out.report)?)?;
    let r = &out.report;
    let c = r.whole_sequence.as_ref().unwrap_or(&r.frame_by_frame);
    println!(
        "lift: {} birds, {} frames, {} points → {} in {secs:.2} s",
        r.birds,
        r.frames,
        r.observations,
        a.out.display()
    );
    println!(
        "  depth {:.3}–{:.3} (median {:.3}) {}; reprojection ≤ {:.2e} px; closest pair {}",
        c.depth_range[0],
        c.depth_range[2],
        c.depth_range[1],
        camera.units.as_str(),
        c.reprojection_max_px,
        c.min_distance.map_or("–".into(), |d| format!(
            "{d:.3} {}",
            camera.units.as_str()
        ))
    );
    lift_print::print_estimate(&r.estimate, camera.units.as_str());
    if let Some(c) = &r.confidence {
        lift_print::print_confidence(c);
    }
    println!("  report: {}", report_path.display());
    Ok(())
}

fn synth_cmd(a: SynthArgs) -> Result<()> {
    let mut cfg = match &a.config {
        Some(p) => {
            crate::data::atomic::note_input(p);
            let text = std::fs::read_to_string(p)
                .map_err(|e| Error::file(p, format!("cannot read: {e}")))?;
            let c: BoidsConfig = serde_json::from_str(&text)
                .map_err(|e| Error::file(p, format!("not a boids config: {e}")))?;
            c.check().map_err(|e| e.in_file(p))?;
            c
        }
        None => BoidsConfig::default(),
    };
    if let Some(v) = a.birds {
        cfg.birds = v;
    }
    if let Some(v) = a.frames {
        cfg.frames = v;
    }
    if let Some(v) = a.fps {
        cfg.fps = v;
    }
    if let Some(v) = a.seed {
        cfg.seed = v;
    }
    if a.no_crop {
        cfg.crop = false;
    }
    cfg.check().map_err(|e| {
        flagged(
            e,
            &[
                ("birds", "--birds"),
                ("frames", "--frames"),
                ("fps", "--fps"),
            ],
        )
    })?;
    let dir = AtomicDir::create(&a.out)?;
    let s = synth_flock(&cfg, &mut Bars::default())?;
    s.truth.save(&dir.path("truth3d.csv"))?;
    s.tracks.save(&dir.path("tracks2d.csv"))?;
    s.camera.save(&dir.path("camera.json"))?;
    let report = serde_json::json!({
        "schema": "herdfit.lift-synth/1",
        "settings": cfg,
        "true_points": s.truth.rows.len(),
        "points_in_view": s.tracks.rows.len(),
        "v_target_per_frame": cfg.cruise / cfg.fps,
    });
    dir.write("report.json", &json(&report)?)?;
    dir.commit()?;
    let d: Vec<f64> = {
        let mut d = s.depth.clone();
        d.sort_by(f64::total_cmp);
        d
    };
    println!(
        "lift synth: {} birds × {} frames; {} of {} points in view, depth {:.1}–{:.1} m (median {:.1}); wrote {}",
        cfg.birds,
        cfg.frames,
        s.tracks.rows.len(),
        s.truth.rows.len(),
        d[0],
        d[d.len() - 1],
        d[d.len() / 2],
        a.out.display()
    );
    Ok(())
}

fn project_cmd(a: ProjectArgs) -> Result<()> {
    let camera = Camera::load(&a.camera)?;
    let tracks = load_tracks(&a.tracks)?;
    check_writable(&a.out)?;
    let (t2, depth) = project_tracks(&tracks, &camera, a.crop).map_err(|e| e.in_file(&a.tracks))?;
    t2.save(&a.out)?;
    let (lo, hi) = depth
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), d| {
            (a.min(*d), b.max(*d))
        });
    println!(
        "lift project: {} of {} points in view, depth {lo:.2}–{hi:.2} {}; wrote {}",
        t2.rows.len(),
        tracks.rows.len(),
        camera.units.as_str(),
        a.out.display()
    );
    Ok(())
}

fn evaluate_cmd(a: EvaluateArgs) -> Result<()> {
    let cfg = a.lift.config()?;
    let camera = Camera::load(&a.camera)?;
    let truth = load_tracks(&a.truth)?;
    let dir = AtomicDir::create(&a.out)?;
    let t0 = std::time::Instant::now();
    let ev = evaluate(&truth, &camera, &cfg, a.crop, &mut Bars::default())
        .map_err(|e| e.in_file(&a.truth))?;
    let secs = t0.elapsed().as_secs_f64();
    dir.write("report.json", &json(&ev.report)?)?;
    let names = ["frame_by_frame", "whole_sequence"];
    let mut lifted = Vec::new();
    for (k, name) in names.iter().enumerate() {
        let t = ev
            .obs
            .tracks_3d(&ev.depths[2 + k], serde_json::json!({"method": name}))?;
        t.save(&dir.path(&format!("{name}.csv")))?;
        lifted.push(t);
    }
    let seen = ev
        .obs
        .tracks_3d(&ev.truth_depth, truth.meta.provenance.clone())?;
    views_png(
        &dir.path("top.png"),
        &dir.path("side.png"),
        &a.truth
            .file_name()
            .map_or("flock".into(), |f| f.to_string_lossy().into_owned()),
        &[
            Layer {
                name: "truth",
                tracks: &seen,
                colour: COLOURS[0],
            },
            Layer {
                name: "frame by frame",
                tracks: &lifted[0],
                colour: COLOURS[2],
            },
            Layer {
                name: "whole sequence",
                tracks: &lifted[1],
                colour: COLOURS[1],
            },
        ],
        &camera,
    )?;
    dir.commit()?;
    lift_print::print_eval(&ev.report, &a.out, secs);
    Ok(())
}

fn camera_cmd(a: CameraArgs) -> Result<()> {
    let units = if a.units == "m" {
        Units::Metres
    } else {
        Units::BodyLengths
    };
    let mut cam = Camera::look_at(
        units, a.size.0, a.size.1, a.hfov, a.position, a.look_at, a.up,
    )
    .map_err(|e| match e {
        Error::Invalid(m) if m.starts_with("hfov") => Error::Invalid(format!("--hfov: {m}")),
        o => o,
    })?;
    cam.provenance = serde_json::json!({
        "source": "herdfit lift camera",
        "position": a.position,
        "look_at": a.look_at,
        "up": a.up,
        "hfov_deg": a.hfov,
    });
    cam.save(&a.out)?;
    println!(
        "lift camera: {}×{} px, f = {:.1} px, at ({}, {}, {}) looking at ({}, {}, {}); wrote {}",
        cam.width,
        cam.height,
        cam.fx,
        a.position[0],
        a.position[1],
        a.position[2],
        a.look_at[0],
        a.look_at[1],
        a.look_at[2],
        a.out.display()
    );
    Ok(())
}
