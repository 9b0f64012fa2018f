//! `herdfit author`: flags → [`AuthorJob`] → [`run`] → one line.

use crate::cli::args::{with_flags, DeviceArg};
use crate::cli::paths::{InFile, OutDir};
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::author::job::{run, AuthorJob};
use clap::Args;

#[derive(Args, Debug)]
pub struct AuthorArgs {
    #[arg(value_name = "SCENE.json")]
    pub scene: InFile,
    /// Output folder: trajectories.csv, navigation.png, snapshots, report.json (+ herd.avi).
    #[arg(long, value_name = "DIR")]
    pub out: OutDir,
    /// Also render the herd over the scene as an MJPG AVI.
    #[arg(long)]
    pub video: bool,
    /// Video scale: pixels per body length.
    #[arg(long, value_name = "PX", default_value_t = 8.0)]
    pub px_per_bl: f64,
    #[command(flatten)]
    pub device: DeviceArg,
}

pub fn exec(a: AuthorArgs) -> Result<()> {
    let job = AuthorJob {
        scene: a.scene.into(),
        out: a.out.into(),
        video: a.video,
        px_per_bl: a.px_per_bl,
        device: a.device.device,
    };
    let summary = run(&job, &mut Bars::default()).map_err(|e| with_flags(e, &[]))?;
    println!("{summary}");
    Ok(())
}
