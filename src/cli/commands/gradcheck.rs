//! `herdfit gradcheck`: flags → [`GradcheckJob`] → [`run`] → the table.

use crate::backend::Precision;
use crate::cli::args::{choice, with_flags, DeviceArg, RunArgs, LOSSES, OBJECTIVES, PRECISIONS};
use crate::cli::paths::{InDir, OutFile};
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::fit::LossKind;
use crate::herd::gradcheck::{run, GradcheckConfig, GradcheckJob, Objective};
use clap::Args;

#[derive(Args, Debug)]
pub struct GradcheckArgs {
    #[command(flatten)]
    pub run: RunArgs,
    /// Unrolled steps.
    #[arg(long, value_name = "T", default_value_t = 10)]
    pub steps: usize,
    #[arg(long, value_parser = choice::<Precision>(PRECISIONS), default_value_t = Precision::F64)]
    pub precision: Precision,
    #[command(flatten)]
    pub device: DeviceArg,
    /// Step h of the 4-point central difference (default 1e-4 in f64, 1e-2 in f32).
    #[arg(long, value_name = "H")]
    pub fd_step: Option<f64>,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Objective: the documented herd objective, or the fit's loss on --clip.
    #[arg(long, value_parser = choice::<Objective>(OBJECTIVES), default_value_t = Objective::Herd)]
    pub objective: Objective,
    /// Clip for `--objective loss` (the herd starts from its first frame's fields).
    #[arg(long, value_name = "CLIP/", required_if_eq("objective", "loss"))]
    pub clip: Option<InDir>,
    /// Which of the fit's losses `--objective loss` checks.
    #[arg(long, value_parser = choice::<LossKind>(LOSSES), default_value_t = LossKind::Paper)]
    pub loss: LossKind,
    /// Herds for `--loss ensemble`.
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub replicas: usize,
    /// Output report (JSON).
    #[arg(long, value_name = "OUT.json")]
    pub json: OutFile,
}

pub fn exec(a: GradcheckArgs) -> Result<()> {
    let job = GradcheckJob {
        run: a.run.files(),
        clip: a.clip.map(Into::into),
        json: a.json.into(),
        config: GradcheckConfig {
            steps: a.steps,
            precision: a.precision,
            device: a.device.device,
            fd_step: a.fd_step,
            seed: a.seed,
            objective: a.objective,
            loss: a.loss,
            replicas: a.replicas,
        },
    };
    let report = run(&job, &mut Bars::default()).map_err(|e| with_flags(e, &[]))?;
    print!("{report}");
    Ok(())
}
