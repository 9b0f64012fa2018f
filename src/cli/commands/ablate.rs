//! `herdfit ablate`: flags → [`AblateJob`] → [`zoned::run_either`] → the report's Markdown.

use crate::cli::args::{choice, with_flags, DeviceArg, LOSSES};
use crate::cli::commands::fit::StepFlags;
use crate::cli::paths::{InDir, InFile, OutDir};
use crate::cli::Bars;
use crate::error::Result;
use crate::herd::ablate::{zoned, AblateConfig, AblateJob, Switch, SWITCHES};
use crate::herd::fit::{FitConfig, LossKind, Settle, GUIDANCE_SCALE};
use crate::herd::validate::ValidateConfig;
use clap::Args;

#[derive(Args, Debug)]
pub struct AblateArgs {
    #[arg(value_name = "CLIP/")]
    pub clip: InDir,
    /// Output report folder (ablation.json, ablation.md, plots, params-VARIANT.json).
    #[arg(long, value_name = "REPORT/")]
    pub out: OutDir,
    /// One parameter set per zone in every variant (herdfit.zones/1, as `fit --zones`); each is
    /// validated zone by zone and written as a bundle.
    #[arg(long, value_name = "ZONES.json")]
    pub zones: Option<InFile>,
    /// Starting parameters of every variant; a generic start (every value 0.5) when omitted.
    #[arg(long, value_name = "P.json")]
    pub start: Option<InFile>,
    /// The switches turned off in turn (comma-separated): occlusion, angular, density,
    /// dir-variance, speed-density. All when omitted.
    #[arg(long, value_name = "S,…", value_delimiter = ',')]
    pub switches: Option<Vec<String>>,
    /// Fraction of the clip fitted; the rest is held out for validation.
    #[arg(long, value_name = "S", default_value_t = 0.5)]
    pub split: f64,
    /// The full model's settings (β, λ_var as the switches leave them).
    #[command(flatten)]
    pub steps: StepFlags,
    /// Objective of every fit.
    #[arg(long, value_parser = choice::<LossKind>(LOSSES), default_value_t = LossKind::Paper)]
    pub loss: LossKind,
    /// Herds simulated side by side in the fit.
    #[arg(long, value_name = "K", default_value_t = 1)]
    pub replicas: usize,
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Simulations per variant in the validation.
    #[arg(long, value_name = "K", default_value_t = 3)]
    pub seeds: usize,
    /// Coarse grid (cells per side) of the validation's density and velocity errors.
    #[arg(long, value_name = "N", default_value_t = 10)]
    pub coarse_grid: usize,
    /// Iterations settling each starting herd (0: none).
    #[arg(long, value_name = "N", default_value_t = Settle::default().iterations)]
    pub settle: usize,
    /// σ (cells) of the smoothing of the clip's momentum into the leaders' guidance.
    #[arg(long, value_name = "S", default_value_t = GUIDANCE_SCALE, allow_hyphen_values = true)]
    pub guidance_scale: f64,
    /// Compare the seeds' mean prediction with the clip in the validation.
    #[arg(long)]
    pub ensemble_mean: bool,
    #[command(flatten)]
    pub device: DeviceArg,
}

pub fn exec(a: AblateArgs) -> Result<()> {
    let switches = match &a.switches {
        None => SWITCHES.to_vec(),
        Some(v) => v
            .iter()
            .map(|s| {
                s.parse::<Switch>()
                    .map_err(|e| crate::error::Error::invalid(format!("--switches: {e}")))
            })
            .collect::<Result<Vec<_>>>()?,
    };
    let settle = Settle::with_iterations(a.settle);
    let job = AblateJob {
        clip: a.clip.into(),
        start: a.start.map(Into::into),
        out: a.out.into(),
        zones: a.zones.map(Into::into),
        config: AblateConfig {
            fit: a.steps.apply(FitConfig {
                seed: a.seed,
                loss: a.loss,
                replicas: a.replicas,
                guidance_scale: a.guidance_scale,
                settle,
                device: a.device.device,
                ..FitConfig::default()
            }),
            validate: ValidateConfig {
                split: a.split,
                coarse_grid: a.coarse_grid,
                seeds: a.seeds,
                settle,
                guidance_scale: a.guidance_scale,
                ensemble_mean: a.ensemble_mean,
                device: a.device.device,
                ..ValidateConfig::default()
            },
            switches,
        },
    };
    let md = zoned::run_either(&job, &mut Bars::default()).map_err(|e| with_flags(e, &[]))?;
    print!("{md}");
    println!("wrote {}", job.out.display());
    Ok(())
}
