//! `herdfit simulate`: flags → [`SimulateJob`] → [`simulate`].

use crate::backend::Precision;
use crate::cli::args::{choice, parse_pair, with_flags, DeviceArg, RunArgs, PRECISIONS};
use crate::cli::paths::OutFile;
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::simulate::{simulate, SimulateConfig, SimulateJob};
use clap::Args;

#[derive(Args, Debug)]
pub struct SimulateArgs {
    #[command(flatten)]
    pub run: RunArgs,
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
    #[arg(long, value_parser = choice::<Precision>(PRECISIONS), default_value_t = Precision::F32)]
    pub precision: Precision,
    #[command(flatten)]
    pub device: DeviceArg,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output trajectories: frame,time,id,x,y,vx,vy,role.
    #[arg(long, value_name = "TRAJ.csv")]
    pub out: OutFile,
}

pub fn exec(a: SimulateArgs) -> Result<()> {
    let job = SimulateJob {
        run: a.run.files(),
        out: a.out.into(),
        config: SimulateConfig {
            steps: a.steps,
            fps: a.fps,
            speed_noise: a.speed_noise,
            guidance: a.guidance.map(|(x, y)| [x, y]),
            precision: a.precision,
            device: a.device.device,
            seed: a.seed,
        },
    };
    simulate(&job, &mut Bars::default())
        .map_err(|e| with_flags(e, &[("herd", "--init/--agents")]))?;
    Ok(())
}
