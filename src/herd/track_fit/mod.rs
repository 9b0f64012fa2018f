//! Fits from tracked animals (issue #49): the same 12-parameter model learnt from each animal's
//! motion instead of from fields.
//!
//! Fields keep where the herd is and how it moves on average; tracks keep each animal. The track
//! objective starts short windows (about a second) from the tracked state of every animal present
//! and steps them by the model (eq. 2–6, the fused force op of eq. 3–5, [`rollout`]) while their
//! neighbours are either replayed from the tracks (neighbour-conditioned, the calibration of
//! pedestrian studies) or simulated with them (a free rollout); the loss is the squared position
//! and heading error against the tracks, back-propagated through the window (BPTT) to θ
//! ([`fit`]). The speed model of eq. 6 is learnt from the tracks ([`speed`]). Leaders (§5.1)
//! follow the clip's guidance field as in a fit from fields, from frames no later than the
//! window's start.
//!
//! - [`data`]: the tracks by frame (gaps and `NaN` rows are untracked frames);
//! - [`config`]: [`TrackFitConfig`], [`Rollout`];
//! - [`rollout`]: one window, both rollouts, its loss;
//! - [`speed`]: eq. 6 from the tracks;
//! - [`spacing`]: the nearest-neighbour distances against the tracks', a term of the loss;
//! - [`fit`]: the loop, the per-window probes of the identifiability estimate;
//! - [`global`]: `--starts K`, the best of K short fits starts the full fit;
//! - [`job`]: `herdfit fit --objective tracks` (files in and out);
//! - [`eval`], [`report`]: `herdfit validate-tracks`, scores on held-out tracks.

pub mod config;
pub mod data;
pub mod eval;
pub mod fit;
pub mod global;
pub mod job;
pub mod report;
pub mod rollout;
pub mod spacing;
pub mod speed;

pub use config::{Leaders, Rollout, Scoring, Speeds, TrackFitConfig};
pub use data::{Fix, TrackSet};
pub use fit::{fit_tracks, mean_loss, prepare, window_gradients, TrackFitResult, TrackLogRow};
pub use rollout::{roll, window_loss, TrackClip, Window};
pub use speed::{learn_speed, SpeedFit};

use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::eval::clip_model;
use crate::herd::guidance::guidance_fields;
use crate::herd::params::Params;
use crate::herd::sim::{ForceKernel, Model, World};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// The tracks file of a clip folder: `tracks.csv` (import-tracks) or `trajectories.csv` (synth).
pub fn clip_tracks(dir: &Path) -> Result<PathBuf> {
    ["tracks.csv", "trajectories.csv"]
        .iter()
        .map(|n| dir.join(n))
        .find(|p| p.is_file())
        .ok_or_else(|| {
            Error::file(
                dir,
                "the clip holds no tracks.csv (import-tracks) or trajectories.csv (synth): give \
                 the tracks with --tracks",
            )
        })
}

/// One input of a track fit or evaluation: a clip folder (its obstacles, frame rate and leader
/// guidance; its tracks from `tracks` or the folder) or a bare tracks file in body lengths (an
/// open plane, no leaders). `frames` (`0..0`: all) are the frames learnt from or scored; with
/// [`Leaders::Off`] the clip's guidance is left out, so no animal leads.
pub fn load_input(
    input: &Path,
    tracks: Option<&Path>,
    frames: Range<usize>,
    (leaders, guidance_scale): (Leaders, f64),
    params: &Params,
) -> Result<TrackClip> {
    let name = input.display().to_string();
    let (set, model, guidance, lookahead) = if input.is_dir() {
        let clip = ClipFields::load(input)?;
        let path = match tracks {
            Some(p) => p.to_path_buf(),
            None => clip_tracks(input)?,
        };
        let set = TrackSet::load(&path, Some(clip.meta.fps), Some(clip.frames()))?;
        // Velocities by central differences reach ⌊w/2⌋ + 1 frames ahead; a simulation's are the
        // animals' own state.
        let lookahead = match clip.meta.provenance["source"] == "synth" {
            true => 0,
            false => clip.meta.velocity_window() / 2 + 1,
        };
        let guidance = match leaders {
            Leaders::Field => guidance_fields(&clip, guidance_scale),
            Leaders::Off => Vec::new(),
        };
        (set, clip_model(params.clone(), &clip), guidance, lookahead)
    } else {
        let set = TrackSet::load(tracks.unwrap_or(input), None, None)?;
        let model = Model {
            params: params.clone(),
            world: World::open(),
            dt: 1.0 / set.fps,
            force_kernel: ForceKernel::default(),
        };
        (set, model, Vec::new(), 0)
    };
    let frames = match frames {
        r if r.end == 0 => 0..set.len(),
        r if r.end > set.len() => {
            return Err(Error::config(
                "frames",
                format!(
                    "{}..{} is out of range: {name} has frames 0..{}",
                    r.start,
                    r.end,
                    set.len()
                ),
            ))
        }
        r => r,
    };
    set.check_frames(frames.clone())?;
    Ok(TrackClip {
        name,
        tracks: set,
        model,
        guidance,
        lookahead,
        frames,
    })
}
