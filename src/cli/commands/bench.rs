//! `herdfit bench`: flags → [`BenchConfig`] → [`run`] → one line.

use crate::cli::args::{with_flags, DeviceArg};
use crate::cli::paths::OutFile;
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::bench::{run, BenchConfig};
use crate::herd::sim::ForceKernel;
use clap::Args;

#[derive(Args, Debug)]
pub struct BenchArgs {
    #[arg(long, value_name = "N", default_value_t = 1500)]
    pub agents: usize,
    #[arg(long, value_name = "T", default_value_t = 20)]
    pub steps: usize,
    /// Skip the forward + backward measurement.
    #[arg(long)]
    pub sim_only: bool,
    /// Forward + backward repetitions of each kind, live and replayed (median reported).
    #[arg(long, default_value_t = 3)]
    pub repeats: usize,
    /// Recompute memory-bound activations in the backward pass (burn's balanced gradient
    /// checkpointing): less memory for long windows, more time.
    #[arg(long)]
    pub checkpointing: bool,
    /// Compute the forces with the tensor-op reference implementation instead of the fused op
    /// (the same values to round-off; slower).
    #[arg(long)]
    pub reference_forces: bool,
    #[command(flatten)]
    pub device: DeviceArg,
    /// Output report (JSON).
    #[arg(long, value_name = "OUT.json")]
    pub json: OutFile,
}

pub fn exec(a: BenchArgs) -> Result<()> {
    let cfg = BenchConfig {
        agents: a.agents,
        steps: a.steps,
        sim_only: a.sim_only,
        repeats: a.repeats,
        checkpointing: a.checkpointing,
        force_kernel: ForceKernel::reference_if(a.reference_forces),
        device: a.device.device,
    };
    let r = run(&cfg, &a.json, &mut Bars::default()).map_err(|e| with_flags(e, &[]))?;
    println!("{r}");
    Ok(())
}
