//! The global phase of a fit (issue #15 item 3): escaping the basin the start lies in.
//!
//! The fit's objective over the 12 parameters has several basins (RESULTS.md §1: two of five
//! fits from random starts stayed in the basin they started in). With `global.starts` = K > 1
//! the frames `a..b` are split: the refinement frames `a..c` and the held-out frames `c..b`
//! (the last `global.holdout` of them). K candidates — the given start, then K − 1 points of a
//! Latin hypercube over [0.05, 0.95]¹² — are each refined by the gradient fit (paper §6.1) on
//! `a..c`, all with the same seed, so the same initial herds, noise and population control
//! (common random numbers). Each refined set is then scored by the fit's own objective on
//! `c..b` — E_mean + λ_var E_var (eq. 7–8) for `loss paper`, the field-matching term + λ_var
//! E_var otherwise — one epoch without updates from the fields of frame c, again with common
//! random numbers; the lowest score wins. Candidate 0 is the plain fit on `a..c`, so the chosen
//! set never scores worse on the held-out frames than the plain fit does.
//!
//! A zone fit's global phase ([`fit_zones_global`]) is the same over every zone's set at once:
//! candidate 0 is the given starts, the others Latin-hypercube points in 12 dimensions per zone.
//!
//! Checkpoints: candidate k checkpoints into `DIR/start-k/` after every epoch; a resumed run
//! continues each candidate where it stopped, and the held-out scores are recomputed (they are
//! deterministic), so a killed and resumed fit ends with the same bytes.

use super::checkpoint::CheckpointDir;
use super::config::{FitConfig, GlobalPhase, LossKind};
use super::run::{fit_clips, fit_zones, loss_of, zone_loss_of, FitResult, ZoneFitResult};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::params::{Params, N_PARAMS};
use crate::herd::zones::Zones;
use crate::optim::multistart::{latin_hypercube, multistart, Candidate};
use crate::progress::Proceed;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::ops::Range;

/// What the global phase did (recorded as `global` in the fitted set's provenance).
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct GlobalReport {
    pub starts: usize,
    /// Frames every candidate was refined on, and the held-out frames that ranked them.
    pub refine_frames: Range<usize>,
    pub holdout_frames: Range<usize>,
    /// What the score is.
    pub objective: String,
    pub candidates: Vec<Candidate>,
    /// Index of the chosen candidate (0: the given start).
    pub chosen: usize,
}

/// The refinement and held-out frames of `frames` under `g` (errors name `global.holdout`
/// when either part would hold fewer than 2 frames).
pub fn split_frames(
    frames: &Range<usize>,
    g: &GlobalPhase,
) -> Result<(Range<usize>, Range<usize>)> {
    let n = frames.end - frames.start;
    let h = ((n as f64) * g.holdout).round() as usize;
    if h < 2 || n < h + 2 {
        return Err(Error::config(
            "global.holdout",
            format!(
                "{} of frames {}..{} leaves {h} held-out and {} refinement frames: each needs at least 2",
                g.holdout,
                frames.start,
                frames.end,
                n.saturating_sub(h)
            ),
        ));
    }
    let c = frames.end - h;
    Ok((frames.start..c, c..frames.end))
}

/// The global phase's candidate starts: `init`, then `starts − 1` Latin-hypercube points in
/// [0.05, 0.95]^n drawn from the fit's seed (n = `init.len()`: 12, or 12 per zone for a zone fit).
pub fn candidate_starts(init: &[f64], g: &GlobalPhase, seed: u64) -> Vec<Vec<f64>> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed ^ 0x6C0B_A15E_ED00_0015);
    let mut v = vec![init.to_vec()];
    v.extend(latin_hypercube(
        g.starts.saturating_sub(1),
        init.len(),
        0.05,
        0.95,
        &mut rng,
    ));
    v
}

/// The fit's objective from [`loss_of`]'s (E_mean, E_var, E_fields).
pub fn objective(cfg: &FitConfig, (em, ev, ef): (f64, f64, f64)) -> f64 {
    match cfg.loss {
        LossKind::Paper => em + cfg.var_weight * ev,
        // (`auto` is resolved before the global phase: a fitting routine refuses it.)
        LossKind::Fields | LossKind::Ensemble | LossKind::Auto => ef + cfg.var_weight * ev,
    }
}

/// The fit with its global phase: [`fit_clips`] alone when `cfg.global` is off, otherwise the
/// multi-start of the module documentation. `progress` is called after every window of every
/// candidate's refinement.
pub fn fit_global<R: Proceed>(
    clips: &[&ClipFields],
    init: &Params,
    cfg: &FitConfig,
    ckpt: Option<&CheckpointDir>,
    mut progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<(FitResult, Option<GlobalReport>)> {
    if cfg.global.is_off() {
        return Ok((fit_clips(clips, init, cfg, ckpt, progress)?, None));
    }
    let phase = Phase::new(cfg, &init.to_vec())?;
    let (inner, held, starts) = (&phase.inner, &phase.held, &phase.starts);
    let (chosen, candidates, mut results) = multistart(
        starts,
        |k, s| -> Result<(Vec<f64>, FitResult)> {
            let sub = candidate_dir(ckpt, k)?;
            let r = fit_clips(
                clips,
                &init.with_vec(&to_array(s)),
                inner,
                sub.as_ref(),
                &mut progress,
            )?;
            Ok((r.params.to_vec().to_vec(), r))
        },
        |_, end| {
            let set = init.with_vec(&to_array(end));
            Ok(objective(held, loss_of(clips, &set, held)?))
        },
    )?;
    let mut res = results.swap_remove(chosen);
    // The user's start, not the candidate's: the summary and provenance compare with it.
    res.start = init.to_vec();
    Ok((res, Some(phase.report(candidates, chosen))))
}

/// A zone fit with its global phase: [`fit_zones`] alone when `cfg.global` is off, otherwise the
/// multi-start of the module documentation over every zone's set at once — candidate 0 is the
/// given starts, the others Latin-hypercube points in 12 dimensions per zone — each refined by
/// [`fit_zones`] and ranked by [`zone_loss_of`] on the held-out frames. Checkpoints as for one set.
pub fn fit_zones_global<R: Proceed>(
    clip: &ClipFields,
    starts: &[Params],
    cfg: &FitConfig,
    zones: &Zones,
    ckpt: Option<&CheckpointDir>,
    mut progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<(ZoneFitResult, Option<GlobalReport>)> {
    if cfg.global.is_off() {
        return Ok((fit_zones(clip, starts, cfg, zones, ckpt, progress)?, None));
    }
    let flat = |sets: &[Params]| -> Vec<f64> { sets.iter().flat_map(Params::to_vec).collect() };
    let sets_of = |v: &[f64]| -> Vec<Params> {
        let parts = v.chunks(N_PARAMS).zip(starts);
        parts.map(|(x, p)| p.with_vec(&to_array(x))).collect()
    };
    let phase = Phase::new(cfg, &flat(starts))?;
    let (inner, held) = (&phase.inner, &phase.held);
    let (chosen, candidates, mut results) = multistart(
        &phase.starts,
        |k, s| -> Result<(Vec<f64>, ZoneFitResult)> {
            let sub = candidate_dir(ckpt, k)?;
            let r = fit_zones(clip, &sets_of(s), inner, zones, sub.as_ref(), &mut progress)?;
            Ok((flat(&r.sets), r))
        },
        |_, end| {
            Ok(objective(
                held,
                zone_loss_of(clip, &sets_of(end), held, zones)?,
            ))
        },
    )?;
    Ok((
        results.swap_remove(chosen),
        Some(phase.report(candidates, chosen)),
    ))
}

/// The settings of a global phase: the refinement and held-out frames and fits, and the
/// candidate starts (frozen parameters at the given start's value in every candidate).
struct Phase {
    refine_frames: Range<usize>,
    holdout_frames: Range<usize>,
    inner: FitConfig,
    held: FitConfig,
    starts: Vec<Vec<f64>>,
    objective: &'static str,
}

impl Phase {
    /// The phase of `cfg` from the given start `init` (12 values per parameter set).
    fn new(cfg: &FitConfig, init: &[f64]) -> Result<Phase> {
        let (refine_frames, holdout_frames) = split_frames(&cfg.frames, &cfg.global)?;
        let inner = FitConfig {
            frames: refine_frames.clone(),
            global: GlobalPhase {
                starts: 1,
                ..cfg.global
            },
            ..cfg.clone()
        };
        let held = FitConfig {
            frames: holdout_frames.clone(),
            ..inner.clone()
        };
        let mut starts = candidate_starts(init, &cfg.global, cfg.seed);
        let frozen = cfg.frozen_indices()?;
        for s in starts.iter_mut() {
            for set in 0..init.len() / N_PARAMS {
                for &p in &frozen {
                    s[set * N_PARAMS + p] = init[set * N_PARAMS + p];
                }
            }
        }
        let objective = match cfg.loss {
            LossKind::Paper => "mean E_mean + λ_var E_var over the held-out frames (one epoch without updates, the fit's seed)",
            _ => "mean field-matching loss + λ_var E_var over the held-out frames (one epoch without updates, the fit's seed)",
        };
        Ok(Phase {
            refine_frames,
            holdout_frames,
            inner,
            held,
            starts,
            objective,
        })
    }

    fn report(self, candidates: Vec<Candidate>, chosen: usize) -> GlobalReport {
        GlobalReport {
            starts: self.starts.len(),
            refine_frames: self.refine_frames,
            holdout_frames: self.holdout_frames,
            objective: self.objective.into(),
            candidates,
            chosen,
        }
    }
}

fn to_array(v: &[f64]) -> [f64; N_PARAMS] {
    let mut a = [0.0; N_PARAMS];
    a.copy_from_slice(v);
    a
}

/// Candidate k's checkpoint folder, `DIR/start-k/` (created), when the fit checkpoints.
fn candidate_dir(c: Option<&CheckpointDir>, k: usize) -> Result<Option<CheckpointDir>> {
    let Some(c) = c else {
        return Ok(None);
    };
    let dir = c.dir.join(format!("start-{k}"));
    crate::data::atomic::make_dir(&dir)?;
    Ok(Some(CheckpointDir {
        dir,
        resume: c.resume,
    }))
}

impl std::fmt::Display for GlobalReport {
    /// One line per candidate: its held-out score and distance from the given start.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "global phase: {} starts refined on frames {}..{}, ranked on held-out frames {}..{}",
            self.starts,
            self.refine_frames.start,
            self.refine_frames.end,
            self.holdout_frames.start,
            self.holdout_frames.end
        )?;
        for (k, c) in self.candidates.iter().enumerate() {
            let moved = c
                .start
                .iter()
                .zip(&c.end)
                .map(|(a, b)| (a - b).abs())
                .sum::<f64>()
                / c.start.len().max(1) as f64;
            writeln!(
                f,
                "  start {k}{}: held-out objective {:.5}, mean |Δθ| in refinement {:.3}{}",
                if k == 0 { " (given)" } else { "" },
                c.score,
                moved,
                if k == self.chosen { "  ← chosen" } else { "" }
            )?;
        }
        Ok(())
    }
}
