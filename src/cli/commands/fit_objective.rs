//! `fit`'s objective flags: what it scores (`--objective`) and the track objective's choices,
//! shared by [`super::fit`] (the flags) and [`super::track_fit`] (the run).

use crate::herd::track_fit::{Leaders, Rollout, TrackFitConfig};

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

/// The values of `--leaders`.
pub const LEADERS: &[(&str, &str)] = &[
    (
        "off",
        "No tracked animal leads: the forces steer every animal (tracked groups are sparse: with the §5.1 rule nearly every animal leads and no set differs)",
    ),
    (
        "field",
        "The §5.1 rule: an animal with few visible neighbours ahead follows the clip's guidance field, as synth's herds do",
    ),
];

/// `Rollout`'s flag default, for clap.
pub fn default_rollout() -> Rollout {
    TrackFitConfig::default().rollout
}

/// `Leaders`' flag default, for clap.
pub fn default_leaders() -> Leaders {
    TrackFitConfig::default().leaders
}
