//! Hyper-parameters of `crowd evaluate` chosen by leave-one-scene-out inside each test scene's
//! training scenes (nested cross-validation: the test scene never takes part in the choice).

use super::forecast::{score_files, Forecast};
use super::model::{learn, LearnConfig};
use crate::data::tracks::Tracks;
use crate::error::{Error, Result};
use crate::progress::{NoProgress, Progress};
use serde::{Deserialize, Serialize};

/// Candidate hyper-parameters for each test scene, chosen by leave-one-scene-out inside that
/// scene's training scenes (the test scene never takes part in the choice): every combination
/// of the lists is learnt on all training scenes but one, scored on that one, and the candidate
/// with the least mean ADE + FDE over the held-out training scenes is learnt on all of them and
/// scored on the test scene. An empty list keeps `learn`'s value. The files of
/// [`super::eval::TRAIN_ONLY`] are in every training set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TuningConfig {
    /// Candidate σ (frames) of the training tracks' smoothing (`learn.smoothing`, §3).
    pub smoothing: Vec<f64>,
    /// Candidate eq. 3 bandwidth factors (`learn.action.bandwidth_scale`).
    pub bandwidth_scale: Vec<f64>,
    /// Candidate formation weights (`learn.features.weights.formation`, Table 1).
    pub formation: Vec<f64>,
    /// Candidate step inertias (`learn.action.inertia`).
    pub inertia: Vec<f64>,
    /// The inner folds score every `frame_stride`-th observation end (1: all of them).
    pub frame_stride: usize,
}

impl Default for TuningConfig {
    fn default() -> Self {
        TuningConfig {
            smoothing: vec![1.0, 3.0],
            bandwidth_scale: vec![1.0, 3.0],
            formation: vec![],
            inertia: vec![],
            frame_stride: 8,
        }
    }
}

/// One candidate's settings and its inner (training-scene) score.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Candidate {
    pub smoothing: f64,
    pub bandwidth_scale: f64,
    pub formation: f64,
    #[serde(default, skip_serializing_if = "super::features::is_zero")]
    pub inertia: f64,
    /// Mean ADE and FDE (m) over the held-out training scenes.
    pub inner_ade: f64,
    pub inner_fde: f64,
}

impl TuningConfig {
    pub(crate) fn check(&self) -> Result<()> {
        let bad = |v: &[f64]| v.iter().any(|x| !(x.is_finite() && *x >= 0.0));
        if bad(&self.smoothing) || bad(&self.formation) {
            return Err(Error::invalid(
                "tuning.smoothing and tuning.formation must be ≥ 0",
            ));
        }
        if self
            .bandwidth_scale
            .iter()
            .any(|x| !(x.is_finite() && *x > 0.0))
        {
            return Err(Error::invalid("tuning.bandwidth_scale must be > 0"));
        }
        if self.inertia.iter().any(|x| !(0.0..=1.0).contains(x)) {
            return Err(Error::invalid("tuning.inertia must be in [0, 1]"));
        }
        if self.frame_stride == 0 {
            return Err(Error::invalid("tuning.frame_stride must be ≥ 1"));
        }
        Ok(())
    }

    /// The candidate lists, `learn`'s value where a list is empty.
    pub(crate) fn lists(&self, l: &LearnConfig) -> [Vec<f64>; 4] {
        let or = |v: &[f64], d: f64| if v.is_empty() { vec![d] } else { v.to_vec() };
        [
            or(&self.smoothing, l.smoothing),
            or(&self.formation, l.features.weights.formation),
            or(&self.bandwidth_scale, l.action.bandwidth_scale),
            or(&self.inertia, l.action.inertia),
        ]
    }
}

/// A fold's training set: every scene but `skip`, then [`super::eval::TRAIN_ONLY`].
pub(crate) fn training<'a>(
    files: &'a [(&str, Vec<Tracks>)],
    extra: &'a [Tracks],
    skip: &[&str],
) -> Vec<Tracks> {
    files
        .iter()
        .filter(|(n, _)| !skip.contains(n))
        .flat_map(|(_, t)| t.iter().cloned())
        .chain(extra.iter().cloned())
        .collect()
}

/// A learn configuration with candidate `c` = (smoothing, formation weight, bandwidth scale,
/// inertia).
pub(crate) fn with(l: &LearnConfig, c: [f64; 4]) -> LearnConfig {
    let mut l = l.clone();
    l.smoothing = c[0];
    l.features.weights.formation = c[1];
    l.action.bandwidth_scale = c[2];
    l.action.inertia = c[3];
    l
}

/// Inner scores (mean ADE, FDE over the held-out training scenes) of every candidate for each
/// test scene. A model learnt without scenes {A, B} serves both (A tested, B held out) and
/// (B tested, A held out), so each pair of scenes is learnt once per (smoothing, formation).
pub(crate) fn inner_scores(
    files: &[(&str, Vec<Tracks>)],
    extra: &[Tracks],
    tests: &[&str],
    learnt: &LearnConfig,
    tuning: &TuningConfig,
    forecast: &Forecast,
    progress: &mut dyn Progress,
) -> Result<Vec<Vec<Candidate>>> {
    let [sm, fo, bw, ine] = tuning.lists(learnt);
    let mut cands: Vec<[f64; 4]> = Vec::new();
    for &a in &sm {
        for &b in &fo {
            for &c in &bw {
                cands.extend(ine.iter().map(|&d| [a, b, c, d]));
            }
        }
    }
    let names: Vec<&str> = files.iter().map(|(n, _)| *n).collect();
    // sums[test][candidate] = (ADE, FDE, held-out scenes)
    let mut sums = vec![vec![[0.0f64; 3]; cands.len()]; tests.len()];
    let pairs: Vec<(usize, usize)> = (0..names.len())
        .flat_map(|a| (a + 1..names.len()).map(move |b| (a, b)))
        .filter(|&(a, b)| tests.contains(&names[a]) || tests.contains(&names[b]))
        .collect();
    progress.start(
        "tune (inner folds)",
        (pairs.len() * sm.len() * fo.len()) as u64,
    );
    for &(a, b) in &pairs {
        let train = training(files, extra, &[names[a], names[b]]);
        for &s in &sm {
            for &w in &fo {
                let mut model = learn(
                    &train,
                    &with(learnt, [s, w, bw[0], ine[0]]),
                    &mut NoProgress,
                )?;
                for (ci, c) in cands.iter().enumerate() {
                    if c[0] != s || c[1] != w {
                        continue;
                    }
                    model.config.action.bandwidth_scale = c[2];
                    model.config.action.inertia = c[3];
                    for (t, h) in [(a, b), (b, a)] {
                        if let Some(ti) = tests.iter().position(|n| *n == names[t]) {
                            let acc =
                                score_files(&model, &files[h].1, forecast, tuning.frame_stride)?;
                            let n = acc.windows.max(1) as f64;
                            let e = &mut sums[ti][ci];
                            e[0] += acc.ade[0] / n;
                            e[1] += acc.fde[0] / n;
                            e[2] += 1.0;
                        }
                    }
                }
                progress.inc(1);
            }
        }
    }
    progress.finish();
    Ok(sums
        .iter()
        .map(|row| {
            row.iter()
                .zip(&cands)
                .map(|(e, c)| Candidate {
                    smoothing: c[0],
                    formation: c[1],
                    bandwidth_scale: c[2],
                    inertia: c[3],
                    inner_ade: e[0] / e[2].max(1.0),
                    inner_fde: e[1] / e[2].max(1.0),
                })
                .collect()
        })
        .collect())
}
