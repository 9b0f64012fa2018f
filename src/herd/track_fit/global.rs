//! The track fit's global phase (`fit --objective tracks --starts K`): from the given start and
//! K − 1 points of a Latin hypercube over the parameter box (0.05–0.95, the frozen parameters
//! kept), each refined by a short track fit of `start_epochs` epochs
//! ([`crate::optim::multistart`]); the refinement with the lowest objective (the mean window loss
//! over one epoch, [`mean_loss`]) is where the full fit starts.
//!
//! The track objective's local minima lie well above its good minimum in value (measured on the
//! synthetic recovery clip in docs/notes/2026-12-07-track-fit-results.md), so the objective
//! itself ranks the candidates.

use super::config::TrackFitConfig;
use super::fit::{fit_tracks, mean_loss};
use super::rollout::TrackClip;
use crate::error::Result;
use crate::herd::params::{Params, N_PARAMS};
use crate::optim::multistart::{latin_hypercube, multistart, Candidate};
use crate::progress::Progress;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The global phase's outcome: the candidates (start, end of the short fit, objective) in start
/// order and the index of the one the full fit starts from.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct TrackGlobal {
    pub best: usize,
    pub candidates: Vec<Candidate>,
    pub start_epochs: usize,
}

/// Runs the global phase from `start` (`cfg.starts` candidates, `cfg.start_epochs` epochs each)
/// and returns the set the full fit starts from, with the outcome.
pub fn global_start(
    clips: &[TrackClip],
    start: &Params,
    cfg: &TrackFitConfig,
    progress: &mut dyn Progress,
) -> Result<(Params, TrackGlobal)> {
    let frozen = cfg.frozen_indices()?;
    let mut rng = ChaCha8Rng::seed_from_u64(cfg.seed ^ 0x5EED_57A2);
    let own = start.to_vec().to_vec();
    let mut starts = vec![own.clone()];
    for mut p in latin_hypercube(cfg.starts - 1, N_PARAMS, 0.05, 0.95, &mut rng) {
        for &j in &frozen {
            p[j] = own[j];
        }
        starts.push(p);
    }
    let short = TrackFitConfig {
        epochs: cfg.start_epochs,
        ..cfg.clone()
    };
    let at = |v: &[f64]| {
        let mut a = [0.0; N_PARAMS];
        a.copy_from_slice(v);
        start.with_vec(&a)
    };
    let windows = clips.iter().enumerate().map(|(i, c)| {
        c.windows(
            i,
            cfg.steps(c.tracks.fps),
            cfg.stride_frames(c.tracks.fps),
            0,
        )
        .len()
    });
    progress.start(
        "track fit: starts",
        (windows.sum::<usize>() * cfg.start_epochs * cfg.starts) as u64,
    );
    let (best, candidates, _) = multistart(
        &starts,
        |k, s| {
            let (end, _) = fit_tracks(clips, &at(s), &short, |_, _, l| {
                progress.message(&format!("start {}/{} loss {l:.4}", k + 1, cfg.starts));
                progress.inc(1);
            })?;
            Ok((end.to_vec().to_vec(), ()))
        },
        |_, end| mean_loss(clips, &at(end), cfg),
    )?;
    progress.finish();
    let chosen = at(&candidates[best].end);
    Ok((
        chosen,
        TrackGlobal {
            best,
            candidates,
            start_epochs: cfg.start_epochs,
        },
    ))
}
