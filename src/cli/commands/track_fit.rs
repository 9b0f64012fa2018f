//! `herdfit fit --objective tracks`: the track objective's flags of `fit` → [`TrackFitJob`] →
//! [`run`] → the summary.

use super::fit::{uncertainty_of, FitArgs};
use crate::cli::args::with_flags;
use crate::cli::Bars;
use crate::error::{Error, Result};
use crate::herd::boundary::BoundaryChoice;
use crate::herd::fit::LossKind;
use crate::herd::sim::ForceKernel;
use crate::herd::track_fit::job::{run, TrackFitJob};
use crate::herd::track_fit::TrackFitConfig;

/// `fit` with `--objective tracks`: the flags that make no sense for it are refused.
pub fn exec(a: FitArgs) -> Result<()> {
    let refuse = |flag: &str| {
        Err(Error::invalid(format!(
            "{flag} is an option of the fields objective, not of --objective tracks"
        )))
    };
    if !a.device.device.is_cpu() {
        return refuse("--device gpu");
    }
    if a.zones.is_some() {
        return refuse("--zones");
    }
    if a.holdout != crate::herd::fit::GlobalPhase::default().holdout {
        return refuse("--holdout");
    }
    if a.checkpoint.is_some() {
        return refuse("--checkpoint");
    }
    if a.replicas != 1 {
        return refuse("--replicas");
    }
    if a.loss != LossKind::Auto {
        return refuse("--loss");
    }
    if a.choice_seeds != crate::herd::fit::FitJob::default().choice_seeds {
        return refuse("--choice-seeds");
    }
    // The tracked animals enter and leave by themselves: a window starts whoever is tracked.
    if crate::cli::args::boundary(&a.boundary)? != BoundaryChoice::default() {
        return refuse("--boundary");
    }
    let defaults = TrackFitConfig::default();
    let uncertainty = uncertainty_of(&a);
    let job = TrackFitJob {
        inputs: a.clips.into_iter().map(Into::into).collect(),
        tracks: a.tracks.into_iter().map(Into::into).collect(),
        start: a.start.map(Into::into),
        config: TrackFitConfig {
            rollout: a.rollout,
            horizon: a.horizon,
            stride: a.stride,
            speeds: a.train_speeds,
            heading_weight: a.heading_weight,
            spacing_weight: a.spacing_weight,
            epochs: a.steps.epochs,
            lr: a.steps.lr,
            optimizer: a.steps.optimizer,
            frames: a.frames.map_or(0..0, |(x, y)| x..y),
            seed: a.seed,
            precision: a.precision,
            guidance_scale: a.guidance_scale,
            leaders: a.leaders,
            starts: a.starts.unwrap_or(defaults.starts),
            start_epochs: a.start_epochs,
            frozen: a.freeze,
            force_kernel: ForceKernel::reference_if(a.reference_forces),
            ..defaults
        },
        out: a.out.into(),
        log: a.log.map(Into::into),
        plot: a.plot.map(Into::into),
        uncertainty,
    };
    let summary = run(&job, &mut Bars::default()).map_err(|e| {
        with_flags(
            e,
            &[
                ("inputs", "CLIP/"),
                ("frozen", "--freeze"),
                ("starts", "--starts"),
                ("start_epochs", "--start-epochs"),
                ("uncertainty.seeds", "--uncertainty-seeds"),
                ("uncertainty.step", "--uncertainty-step"),
            ],
        )
    })?;
    print!("{summary}");
    Ok(())
}
