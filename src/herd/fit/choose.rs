//! The fit's objective chosen per clip (`loss auto`, the default of `herdfit fit`; issue #46).
//!
//! Neither objective is best everywhere: on synthetic clips the field-matching objective moves a
//! fit towards the generating set's behaviour where the paper's E_mean + λ_var E_var (eq. 7–8)
//! moves it away, and on the paper's own sheep the paper's objective predicts held-out frames
//! better where field matching trades velocity for density (RESULTS.md). So the fit decides on
//! the clip itself, by the held-out prediction the paper validates with (§7.1), using only its
//! own frames: the frames `a..b` are split at their middle `c`; each candidate objective
//! (`fields`, then `paper`) fits `a..c` from the same start with the same seed; each fitted set
//! runs `c..b` from the fields of frame c (or the animals tracked there) through the clip's
//! boundary, for the job's evaluation seeds, with common random numbers; the candidate with the
//! lower mean density + velocity error (§7.1.2, the errors `fit` reports) is chosen, ties to
//! `fields`, and the fit proper then runs on all of `a..b` with it. Nothing of `b..` is seen.
//!
//! A still, a zone fit, and frames too few to split ([`min_frames`]) are not chosen for: there
//! `auto` is `fields`, and the report says why.

use super::checkpoint::CheckpointDir;
use super::config::{FitConfig, LossKind};
use super::run::fit_clips;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::params::Params;
use crate::herd::validate::{validate, ValidateConfig};
use crate::progress::Proceed;
use serde::{Deserialize, Serialize};
use std::ops::Range;

/// Fewest frames split for the choice with windows of `window` steps: each half holds at least
/// one window (`window` + 1 frames) and at least 4 frames.
pub fn min_frames(window: usize) -> usize {
    2 * (window + 1).max(4)
}

/// The objectives `auto` chooses between, in the order they are fitted (ties go to the first).
pub const CANDIDATES: [LossKind; 2] = [LossKind::Fields, LossKind::Paper];

/// The file in a checkpoint folder that keeps a finished choice, so that a resumed fit does not
/// repeat it.
pub const CHOICE_FILE: &str = "loss-choice.json";

/// One candidate objective's fit on the first part and its errors on the second.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct CandidateScore {
    pub loss: LossKind,
    /// The 12 values fitted on the first part.
    pub params: Vec<f64>,
    /// Mean density and velocity errors on the second part, over the seeds.
    pub density_error: f64,
    pub velocity_error: f64,
    /// Per seed, density + velocity error (the same seeds for every candidate).
    pub scores: Vec<f64>,
}

impl CandidateScore {
    /// The mean of [`Self::scores`].
    pub fn score(&self) -> f64 {
        self.scores.iter().sum::<f64>() / self.scores.len().max(1) as f64
    }
}

/// What `auto` chose and on what evidence (recorded as `loss_choice` in the fitted set's
/// provenance).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LossChoice {
    pub chosen: LossKind,
    /// Why no choice was made (a still, a zone fit, too few frames); empty when one was.
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub not_chosen: String,
    /// Frames each candidate was fitted on, and the frames that scored them.
    pub fit_frames: Range<usize>,
    pub scored_frames: Range<usize>,
    pub candidates: Vec<CandidateScore>,
}

impl LossChoice {
    /// `fields` without a choice, for `why`.
    pub fn unchosen(why: &str) -> LossChoice {
        LossChoice {
            chosen: LossKind::Fields,
            not_chosen: why.to_string(),
            fit_frames: 0..0,
            scored_frames: 0..0,
            candidates: Vec::new(),
        }
    }

    /// The second candidate's score minus the first's, per seed: mean and standard error.
    pub fn paired_difference(&self) -> Option<(f64, f64)> {
        let [a, b] = self.candidates.as_slice() else {
            return None;
        };
        let d: Vec<f64> = b.scores.iter().zip(&a.scores).map(|(y, x)| y - x).collect();
        let n = d.len() as f64;
        let mean = d.iter().sum::<f64>() / n;
        let var = d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
        Some((mean, (var / n).sqrt()))
    }
}

/// The two parts of `frames` (fit, scored): split at the middle, or `None` when there are fewer
/// than [`min_frames`]`(window)`.
pub fn halves(frames: &Range<usize>, window: usize) -> Option<(Range<usize>, Range<usize>)> {
    let n = frames.end.saturating_sub(frames.start);
    (n >= min_frames(window)).then(|| {
        let c = frames.start + n / 2;
        (frames.start..c, c..frames.end)
    })
}

/// Windows of the choice's fits (for a progress bar): every candidate's epochs over the first
/// part; 0 when no choice will be made.
pub fn windows(cfg: &FitConfig, clips: usize) -> usize {
    match (
        cfg.loss,
        cfg.still.is_some(),
        halves(&cfg.frames, cfg.window),
    ) {
        (LossKind::Auto, false, Some((first, _))) => {
            cfg.windows_per_epoch(&first, clips) * cfg.epochs * CANDIDATES.len()
        }
        _ => 0,
    }
}

/// Resolves `cfg.loss`: itself when it is not `auto` (no report), else the choice of the module
/// documentation (a finished choice read back from the checkpoint folder when resuming; a new
/// one written there). `progress` is called after every window of the candidates' fits.
pub fn resolve<R: Proceed>(
    clips: &[&ClipFields],
    init: &Params,
    cfg: &FitConfig,
    seeds: usize,
    ckpt: Option<&CheckpointDir>,
    progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<Option<LossChoice>> {
    if cfg.loss != LossKind::Auto {
        return Ok(None);
    }
    if cfg.still.is_some() {
        return Ok(Some(LossChoice::unchosen(
            "a still has no later frames to score on",
        )));
    }
    let Some((first, second)) = halves(&cfg.frames, cfg.window) else {
        return Ok(Some(LossChoice::unchosen(&format!(
            "{} frames: fewer than {} to split into two halves of windows of {} steps",
            cfg.frames.end.saturating_sub(cfg.frames.start),
            min_frames(cfg.window),
            cfg.window
        ))));
    };
    let file = ckpt.map(|c| c.dir.join(CHOICE_FILE));
    if let Some(f) = file
        .as_ref()
        .filter(|f| ckpt.is_some_and(|c| c.resume) && f.is_file())
    {
        let text = std::fs::read_to_string(f).map_err(|e| Error::file(f, e.to_string()))?;
        let stored: LossChoice = serde_json::from_str(&text)
            .map_err(|e| Error::file(f, format!("not a loss choice: {e}")))?;
        // The fit's other settings are checked against its checkpoint; the choice's own here.
        let same = stored.fit_frames == first
            && stored.scored_frames == second
            && stored.candidates.iter().all(|c| c.scores.len() == seeds);
        if !same {
            return Err(Error::file(
                f,
                "was made with other settings (frames or choice seeds): resume with those, or \
                 start without --resume",
            ));
        }
        return Ok(Some(stored));
    }
    let choice = choose(clips, init, cfg, seeds, (first, second), progress)?;
    if let Some(f) = &file {
        let text = serde_json::to_string_pretty(&choice)
            .map_err(|e| Error::Internal(format!("serialising the loss choice: {e}")))?;
        crate::data::atomic::write_atomic(f, text.as_bytes())?;
    }
    Ok(Some(choice))
}

/// Fits every candidate on `first`, scores it on `second`, and chooses.
fn choose<R: Proceed>(
    clips: &[&ClipFields],
    init: &Params,
    cfg: &FitConfig,
    seeds: usize,
    (first, second): (Range<usize>, Range<usize>),
    mut progress: impl FnMut(usize, usize, f64, f64) -> R,
) -> Result<LossChoice> {
    let mut fitted = Vec::with_capacity(CANDIDATES.len());
    for loss in CANDIDATES {
        let sub = FitConfig {
            loss,
            frames: first.clone(),
            ..cfg.clone()
        };
        let p = fit_clips(clips, init, &sub, None, &mut progress)?.params;
        fitted.push((loss.to_string(), p));
    }
    // Per candidate and seed, (density, velocity) error averaged over the clips.
    let mut per_seed = vec![vec![(0.0, 0.0); seeds]; fitted.len()];
    for (ci, clip) in clips.iter().enumerate() {
        let vcfg = ValidateConfig {
            frames: Some([second.start, second.end]),
            seeds,
            settle: cfg.settle,
            guidance_scale: cfg.guidance_scale,
            boundary: cfg.boundary.clone(),
            tracks: cfg.tracks.get(ci).cloned(),
            device: cfg.device,
            ..ValidateConfig::default()
        };
        let (report, _) = validate(clip, "", &fitted, &vcfg, || ())?;
        let w = clips.len() as f64;
        for (set, acc) in report.sets.iter().zip(&mut per_seed) {
            for (e, a) in set.seed_errors.iter().zip(acc.iter_mut()) {
                *a = (a.0 + e[0] / w, a.1 + e[1] / w);
            }
        }
    }
    let n = seeds.max(1) as f64;
    let candidates: Vec<CandidateScore> = CANDIDATES
        .iter()
        .zip(fitted)
        .zip(per_seed)
        .map(|((&loss, (_, p)), e)| CandidateScore {
            loss,
            params: p.to_vec().to_vec(),
            density_error: e.iter().map(|x| x.0).sum::<f64>() / n,
            velocity_error: e.iter().map(|x| x.1).sum::<f64>() / n,
            scores: e.iter().map(|x| x.0 + x.1).collect(),
        })
        .collect();
    // The lowest mean score; ties to the first candidate.
    let best = candidates.iter().enumerate().fold(0, |b, (k, c)| {
        match c.score() < candidates[b].score() {
            true => k,
            false => b,
        }
    });
    Ok(LossChoice {
        chosen: candidates[best].loss,
        not_chosen: String::new(),
        fit_frames: first,
        scored_frames: second,
        candidates,
    })
}

impl std::fmt::Display for LossChoice {
    /// One line for `herdfit fit`'s summary.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        if !self.not_chosen.is_empty() {
            return writeln!(f, "objective: {} (auto: {})", self.chosen, self.not_chosen);
        }
        let seeds = self.candidates.first().map_or(0, |c| c.scores.len());
        write!(
            f,
            "objective: {} (auto: each fitted on frames {}..{}, scored on {}..{} over {seeds} seeds, density + velocity error:",
            self.chosen,
            self.fit_frames.start,
            self.fit_frames.end,
            self.scored_frames.start,
            self.scored_frames.end,
        )?;
        for c in &self.candidates {
            write!(
                f,
                " {} {:.4} + {:.4} = {:.4};",
                c.loss,
                c.density_error,
                c.velocity_error,
                c.score()
            )?;
        }
        match self.paired_difference() {
            Some((m, se)) => writeln!(f, " paired difference {m:+.4} ± {se:.4})"),
            None => writeln!(f, ")"),
        }
    }
}
