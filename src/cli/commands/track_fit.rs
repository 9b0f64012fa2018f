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
use crate::herd::track_fit::{Rollout, TrackFitConfig};

/// What `fit` scores.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Objective {
    /// The clip's fields (paper §6): `--loss` says how.
    #[default]
    Fields,
    /// Each tracked animal's motion over short windows.
    Tracks,
}

enum_names!(Objective { Fields = "fields", Tracks = "tracks" });

/// The values of `--objective`.
pub const OBJECTIVES: &[(&str, &str)] = &[
    (
        "fields",
        "The clip's density and velocity fields (paper §6; --loss says how)",
    ),
    (
        "tracks",
        "Each tracked animal's motion: windows of --horizon seconds started from the tracked animals, scored by the squared position and heading error against the tracks (the clip's tracks.csv or trajectories.csv, or --tracks)",
    ),
];

/// The values of `--rollout`.
pub const ROLLOUTS: &[(&str, &str)] = &[
    (
        "conditioned",
        "Each animal is stepped by the model among its neighbours replayed from their tracks (not a forecast)",
    ),
    (
        "free",
        "The animals of a window are stepped jointly by the model, neighbours included (a forecast)",
    ),
];

/// The values of `--train-speeds`.
pub const SPEEDS: &[(&str, &str)] = &[
    (
        "tracks",
        "Each animal at its tracked speed (eq. 6 where untracked): the error is the direction's, what θ steers",
    ),
    (
        "expected",
        "Eq. 6 without its noise: each animal at its expected speed",
    ),
    ("noisy", "Eq. 6 with its noise, as a simulation runs"),
];

/// `fit` with `--objective tracks`: the flags that make no sense for it are refused.
pub fn exec(a: FitArgs) -> Result<()> {
    let refuse = |flag: &str| {
        Err(Error::invalid(format!(
            "{flag} is an option of the fields objective, not of --objective tracks"
        )))
    };
    if a.zones.is_some() {
        return refuse("--zones");
    }
    if a.starts != 1 {
        return refuse("--starts");
    }
    if a.checkpoint.is_some() {
        return refuse("--checkpoint");
    }
    if a.replicas != 1 {
        return refuse("--replicas");
    }
    if a.loss != LossKind::Fields {
        return refuse("--loss");
    }
    // The tracked animals enter and leave by themselves: a window starts whoever is tracked.
    if a.boundary != BoundaryChoice::default() {
        return refuse("--boundary");
    }
    let defaults = TrackFitConfig::default();
    let uncertainty = uncertainty_of(&a);
    let job = TrackFitJob {
        inputs: a.clips,
        tracks: a.tracks,
        start: a.start,
        config: TrackFitConfig {
            rollout: a.rollout,
            horizon: a.horizon,
            stride: a.stride,
            speeds: a.train_speeds,
            heading_weight: a.heading_weight,
            epochs: a.steps.epochs,
            lr: a.steps.lr,
            optimizer: a.steps.optimizer,
            frames: a.frames.map_or(0..0, |(x, y)| x..y),
            seed: a.seed,
            precision: a.precision,
            guidance_scale: a.guidance_scale,
            frozen: a.freeze,
            force_kernel: ForceKernel::reference_if(a.reference_forces),
            ..defaults
        },
        out: a.out,
        log: a.log,
        plot: a.plot,
        uncertainty,
    };
    let summary = run(&job, &mut Bars::default()).map_err(|e| {
        with_flags(
            e,
            &[
                ("inputs", "CLIP/"),
                ("frozen", "--freeze"),
                ("uncertainty.seeds", "--uncertainty-seeds"),
                ("uncertainty.step", "--uncertainty-step"),
            ],
        )
    })?;
    print!("{summary}");
    Ok(())
}

/// `Rollout`'s flag default, for clap.
pub fn default_rollout() -> Rollout {
    TrackFitConfig::default().rollout
}
