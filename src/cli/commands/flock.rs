//! `herdfit flock …`: line-formation flocks (Klotsman & Tal). Each verb parses its flags into the
//! library's config, makes one library call and prints.

use crate::error::{Error, Result};
use crate::flock::{animate, extract, synth};
use clap::{Args, Subcommand};
use std::path::PathBuf;

/// The flock verbs.
#[derive(Subcommand, Debug)]
pub enum FlockCommand {
    /// Write a synthetic marked example (tracks CSV + sidecar with the wingspan), or with
    /// --examples the shipped V, U, J and line examples.
    Synth(SynthArgs),
    /// Extract shape parameters (§4) from a marked example: ordering, gaps, leader, RANSAC side
    /// fits, outliers, deviations.
    Extract(ExtractArgs),
    /// Animate a flock of any size from extracted shape parameters: initiation (§6), then
    /// steady flight (§5): 3D tracks, per-bird savings, plots, video.
    Animate(AnimateArgs),
}

#[derive(Args, Debug)]
pub struct SynthArgs {
    /// Formation: v, u, j or line.
    #[arg(long, default_value = "v")]
    pub shape: extract::ShapeKind,
    #[arg(long, value_name = "N", default_value_t = 9)]
    pub birds: usize,
    /// Marked frames.
    #[arg(long, value_name = "F", default_value_t = 16)]
    pub frames: usize,
    /// Fraction of birds displaced off their side.
    #[arg(long, value_name = "FRAC", default_value_t = 0.2)]
    pub outliers: f64,
    /// Position noise STD, wingspans.
    #[arg(long, value_name = "B", default_value_t = 0.1)]
    pub noise: f64,
    /// Side angle to the flight axis (V, line), degrees.
    #[arg(long, value_name = "DEG", default_value_t = 30.0)]
    pub half_angle: f64,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// All settings as JSON (keys of SynthConfig); flags override nothing in it.
    #[arg(long, value_name = "CFG.json", conflicts_with_all = ["shape", "birds", "frames", "outliers", "noise", "half_angle", "seed"])]
    pub config: Option<PathBuf>,
    /// Write the shipped examples into this folder instead.
    #[arg(long, value_name = "DIR", conflicts_with_all = ["out", "config"])]
    pub examples: Option<PathBuf>,
    /// Output tracks CSV (its sidecar gets the same stem).
    #[arg(long, value_name = "OUT.csv", required_unless_present = "examples")]
    pub out: Option<PathBuf>,
}

#[derive(Args, Debug)]
pub struct ExtractArgs {
    /// Marked example, herdfit.tracks/1 (2D).
    #[arg(value_name = "TRACKS.csv")]
    pub tracks: PathBuf,
    /// Wingspan in the tracks' units (default: provenance.wingspan of the sidecar).
    #[arg(long, value_name = "B", allow_hyphen_values = true)]
    pub wingspan: Option<f64>,
    /// Flight direction, degrees counter-clockwise from +x (default: the centroid's motion).
    #[arg(long, value_name = "DEG", allow_hyphen_values = true)]
    pub heading: Option<f64>,
    /// Formation: v, u, j or line (default: classified).
    #[arg(long)]
    pub shape: Option<extract::ShapeKind>,
    /// The example was filmed from below.
    #[arg(long)]
    pub from_below: bool,
    /// RANSAC inlier threshold on the longitudinal residual, wingspans.
    #[arg(long, value_name = "B")]
    pub inlier_threshold: Option<f64>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Output shape parameters (herdfit.flock-shape/1 JSON).
    #[arg(long, value_name = "SHAPE.json")]
    pub out: PathBuf,
}

#[derive(Args, Debug)]
pub struct AnimateArgs {
    /// Shape parameters from `herdfit flock extract`.
    #[arg(value_name = "SHAPE.json")]
    pub shape: PathBuf,
    /// Birds N (default: as many as the example).
    #[arg(long, value_name = "N")]
    pub birds: Option<usize>,
    /// Steady-flight frames F (after the hand-over from the initiation).
    #[arg(long, value_name = "F")]
    pub frames: Option<usize>,
    #[arg(long)]
    pub seed: Option<u64>,
    /// Start on the first key shape (no initiation).
    #[arg(long)]
    pub no_initiation: bool,
    /// Skip the AVI.
    #[arg(long)]
    pub no_video: bool,
    /// Settings as JSON (keys of AnimateConfig: steady.*, init.*, …); flags override it.
    #[arg(long, value_name = "CFG.json")]
    pub config: Option<PathBuf>,
    /// Output folder.
    #[arg(long, value_name = "DIR/")]
    pub out: PathBuf,
}

fn read_json<T: serde::de::DeserializeOwned>(p: &PathBuf) -> Result<T> {
    crate::data::atomic::note_input(p);
    let s = std::fs::read_to_string(p).map_err(|e| Error::file(p, format!("cannot read: {e}")))?;
    serde_json::from_str(&s).map_err(|e| Error::file(p, format!("bad settings: {e}")))
}

/// Runs a flock verb.
pub fn run(cmd: FlockCommand) -> Result<()> {
    match cmd {
        FlockCommand::Synth(a) => synth_cmd(a),
        FlockCommand::Extract(a) => extract_cmd(a),
        FlockCommand::Animate(a) => animate_cmd(a),
    }
}

fn synth_cmd(a: SynthArgs) -> Result<()> {
    if let Some(dir) = a.examples {
        for p in synth::write_examples(&dir)? {
            println!("wrote {}", p.display());
        }
        return Ok(());
    }
    let cfg = match &a.config {
        Some(p) => read_json(p)?,
        None => synth::SynthConfig {
            shape: a.shape,
            birds: a.birds,
            frames: a.frames,
            outlier_fraction: a.outliers,
            noise: a.noise,
            half_angle_deg: a.half_angle,
            seed: a.seed,
            ..synth::SynthConfig::default()
        },
    };
    let out = a.out.expect("clap requires --out");
    let t = synth::synth(&cfg).map_err(|e| match &a.config {
        Some(p) => e.in_file(p),
        None => flagged(e),
    })?;
    t.save(&out)?;
    println!(
        "flock synth: {} {}-bird example, {} marked frames → {}",
        cfg.shape.as_str(),
        cfg.birds,
        cfg.frames,
        out.display()
    );
    Ok(())
}

/// Names the flag for a config key in a library error.
fn flagged(e: Error) -> Error {
    match e {
        Error::Invalid(m) => {
            let flag = [
                ("outlier_fraction", "--outliers"),
                ("half_angle_deg", "--half-angle"),
                ("birds", "--birds"),
                ("frames", "--frames"),
                ("noise", "--noise"),
                ("wingspan", "--wingspan"),
                ("heading_deg", "--heading"),
                ("inlier_threshold", "--inlier-threshold"),
            ]
            .iter()
            .find(|(k, _)| m.starts_with(&format!("{k} ")));
            match flag {
                Some((_, f)) => Error::Invalid(format!("{f}: {m}")),
                None => Error::Invalid(m),
            }
        }
        other => other,
    }
}

fn extract_cmd(a: ExtractArgs) -> Result<()> {
    let d = extract::ExtractConfig::default();
    let cfg = extract::ExtractConfig {
        wingspan: a.wingspan,
        heading_deg: a.heading,
        from_below: a.from_below,
        shape: a.shape,
        inlier_threshold: a.inlier_threshold.unwrap_or(d.inlier_threshold),
        seed: a.seed.unwrap_or(d.seed),
        ..d
    };
    cfg.check().map_err(flagged)?;
    let p = extract::extract_file(&a.tracks, &cfg)?;
    p.save(&a.out)?;
    let outliers: usize = p
        .frames
        .iter()
        .map(|f| f.birds.iter().filter(|b| b.outlier).count())
        .sum();
    let ang = |s| {
        p.mean_angle(s)
            .map_or("-".into(), |v: f64| format!("{v:.1}°"))
    };
    println!(
        "flock extract: {} birds, {} frames, shape {}, side angles {} (left) / {} (right), \
         {outliers} outlier marks → {}",
        p.birds,
        p.frames.len(),
        p.kind.as_str(),
        ang(extract::Side::Left),
        ang(extract::Side::Right),
        a.out.display()
    );
    Ok(())
}

fn animate_cmd(a: AnimateArgs) -> Result<()> {
    let mut cfg: animate::AnimateConfig = match &a.config {
        Some(p) => {
            let c: animate::AnimateConfig = read_json(p)?;
            c.check().map_err(|e| e.in_file(p))?;
            c
        }
        None => animate::AnimateConfig::default(),
    };
    if a.birds.is_some() {
        cfg.birds = a.birds;
    }
    if let Some(f) = a.frames {
        cfg.frames = f;
    }
    if let Some(s) = a.seed {
        cfg.seed = s;
    }
    if a.no_initiation {
        cfg.initiation = false;
    }
    if a.no_video {
        cfg.video = false;
    }
    cfg.check().map_err(flagged)?;
    let mut bars = crate::cli::Bars::default();
    let r = animate::animate_file(&a.shape, &a.out, &cfg, &mut bars)?;
    let init = match &r.initiation {
        Some(i) => match i.converged_after {
            Some(t) => format!("initiation converged in {t:.1} s, "),
            None => "initiation did not converge, ".into(),
        },
        None => String::new(),
    };
    let worst = r
        .keys
        .iter()
        .map(|k| k.max_relative_error)
        .fold(0.0, f64::max);
    println!(
        "flock animate: {} birds, {}{} key shapes (worst |ξ − ξ̂|/ξ̂ {worst:.1e}), {} frames \
         ({} initiation, {} hand-over, {} steady) → {}",
        r.birds,
        init,
        r.keys.len(),
        r.initiation_frames + r.hand_over_frames + r.steady_frames,
        r.initiation_frames,
        r.hand_over_frames,
        r.steady_frames,
        a.out.display()
    );
    let f = &r.shape_family;
    println!(
        "  shape: worst bird {:.2} b from its side's {} over the steady frames ({:.2}× the \
         example's own {:.2} b); ξ in its Step 2 range in {:.1} % of bird-frames",
        f.steady_worst,
        match f.model {
            crate::flock::ransac::Model::Line => "line",
            crate::flock::ransac::Model::Parabola => "parabola",
        },
        f.ratio,
        f.example_worst,
        100.0 * r.xi_in_range_steady
    );
    println!(
        "  acceleration: hand-over {:.3}, steady {:.3} b/s² (bound {:.3})",
        r.max_accel_hand_over, r.max_accel_steady, r.accel_bound
    );
    println!(
        "  energy: the flock saves {:.1} % of its induced power on average (per bird {:.1}–{:.1} %) \
         at a mean wing-tip spacing of {:+.2} b; field studies of goose skeins report 14–36 % of \
         induced power (savings.json says where from)",
        100.0 * r.flock_mean_saving,
        100.0 * r.mean_saving.iter().cloned().fold(f64::INFINITY, f64::min),
        100.0 * r.mean_saving.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
        r.mean_wing_tip_spacing
    );
    Ok(())
}
