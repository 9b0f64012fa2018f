//! `herdfit export-gltf TRACKS --out flock.glb`: any tracks file (2D on the ground plane, 3D as
//! is) as an animated glTF 2.0 binary, optionally with a rendered preview frame.

use crate::cli::paths::{InFile, OutFile};
use crate::data::atomic::check_writable;
use crate::data::camera::Camera;
use crate::data::gltf::{export_glb, GltfConfig};
use crate::data::jackdaw::load_tracks;
use crate::error::{Error, Result};
use clap::Args;

#[derive(Args, Debug)]
pub struct ExportGltfArgs {
    /// Tracks (herdfit.tracks/1, 2D or 3D, or a jackdaw CSV).
    #[arg(value_name = "TRACKS.csv")]
    pub tracks: InFile,
    #[arg(long, value_name = "OUT.glb")]
    pub out: OutFile,
    /// glTF metres per track unit.
    #[arg(long, value_name = "S", default_value_t = 1.0)]
    pub scale: f64,
    /// Length of the bird mesh in glTF metres (by default from the tracks' units).
    #[arg(long, value_name = "L")]
    pub body_length: Option<f64>,
    /// Empty nodes instead of the bird mesh.
    #[arg(long)]
    pub no_mesh: bool,
    /// Orientation smoothing factor (thesis §3.6).
    #[arg(long, value_name = "A", default_value_t = 0.1)]
    pub turn_rate: f64,
    /// Also render one frame of the exported file to this PNG (needs --preview-camera).
    #[arg(long, value_name = "PREVIEW.png", requires = "preview_camera")]
    pub preview: Option<OutFile>,
    /// Camera of the preview (herdfit.camera/1, in the tracks' world coordinates).
    #[arg(long, value_name = "CAMERA.json")]
    pub preview_camera: Option<InFile>,
    /// Time of the preview frame (s from the first key; the middle by default).
    #[arg(long, value_name = "T")]
    pub preview_time: Option<f64>,
}

/// Runs `herdfit export-gltf`.
pub fn run(a: ExportGltfArgs) -> Result<()> {
    let cfg = GltfConfig {
        scale: a.scale,
        body_length: a.body_length,
        mesh: !a.no_mesh,
        turn_rate: a.turn_rate,
    };
    cfg.check().map_err(|e| match e {
        Error::Invalid(m) => Error::Invalid(format!(
            "--{}: {m}",
            m.split(' ').next().unwrap_or("").replace('_', "-")
        )),
        o => o,
    })?;
    let camera = a
        .preview_camera
        .as_ref()
        .map(|p| Camera::load(p))
        .transpose()?;
    let tracks = load_tracks(&a.tracks)?;
    check_writable(&a.out)?;
    if let Some(p) = &a.preview {
        check_writable(p)?;
    }
    let s = export_glb(&tracks, &cfg, &a.out).map_err(|e| match e {
        // The tracks are fine; the scale takes them out of range.
        Error::Invalid(m) if m.starts_with("scale = ") => Error::Invalid(format!("--scale: {m}")),
        e => e.in_file(&a.tracks),
    })?;
    println!(
        "export-gltf: {} nodes, {} keyframes over {:.2} s, {} bytes; wrote {}",
        s.nodes,
        s.keyframes,
        s.duration,
        s.bytes,
        a.out.display()
    );
    if let (Some(p), Some(cam)) = (&a.preview, &camera) {
        let t = a.preview_time.unwrap_or(0.5 * s.duration);
        if !(0.0..=s.duration).contains(&t) {
            return Err(Error::invalid(format!(
                "--preview-time: {} s is outside the animation's 0..={} s",
                crate::limits::show(t),
                crate::limits::show(s.duration)
            )));
        }
        // The .glb just written waits for the end of the run in a temporary sibling.
        let glb = crate::data::atomic::plan::current(&a.out);
        let n = crate::lift::render::render_glb(&glb, t, cam, p).map_err(|e| {
            let msg = e
                .to_string()
                .replace(&glb.display().to_string(), &a.out.display().to_string());
            crate::error::Error::invalid(msg)
        })?;
        println!("  preview: {n} birds at t = {t:.2} s → {}", p.display());
    }
    Ok(())
}
