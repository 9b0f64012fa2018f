//! How far a lift can be trusted, from the lift alone (issue #50): no truth is needed.
//!
//! The whole-sequence energy's minimum is only as good as the tracks make it: where they tie the
//! birds' depths (perspective, alignment, smooth motion), a second optimisation from another
//! start lands on the same depths; where they do not, the energy is flat along depth and the
//! result depends on where the optimiser started. So the whole sequence is run again from a
//! start that carries no depth structure — every bird of every frame at the first result's
//! median depth — and the two results are compared:
//! - `disagreement`: the RMS over observations of ln(d₂ / d₁), the restart's relative difference;
//! - `structure`: the RMS over observations of ln d₁ minus its frame's median: the per-bird depth
//!   differences the lift claims (what it adds to a constant depth).
//!
//! A restart cannot see one failure: a flock flying at (or away from) the camera shows little
//! but looming, and every start then ends at the depths the speed term alone dictates along the
//! rays. So the lift also reports `transverse`, the median over its velocities of the share of
//! the speed across the line of sight, |v − (v·r̂) r̂| / |v|: near 1 when the birds cross the
//! view, small when they fly along it. The lift's own velocities can hide it (the speed term
//! spreads a wrong speed across the view), so the estimate also compares the image tracks'
//! turning rate with that of the same tracks laid on a horizontal plane (`foreshortening`,
//! [`super::estimate::plane_turning`]): a flock flying at the camera turns in the image mostly
//! by foreshortening, and the speed prior, which reads image turns as the birds' turns, then
//! guesses low.
//!
//! The lift is reported as not to be trusted when the restart disagrees by more than
//! `max_disagreement`, when `transverse` is below `min_transverse`, when more than
//! `max_at_bounds` of the depths sit on a bound (the energy wanted them further), when v_target
//! was estimated outside the turning rates its prior was fitted on, or when it was estimated
//! from image turns more than `max_foreshortening` times as sharp as the plane's. Which data
//! chose each threshold: RESULTS, "Lift without `--v-target`".

use super::estimate::{Estimate, Source};
use super::observe::Observations;
use super::{sequence, LiftConfig};
use crate::error::{Error, Result};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

/// Settings of the self-assessment (`confidence.<key>`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ConfidenceConfig {
    /// Run the whole sequence a second time from a flat start (doubles its time).
    pub restart: bool,
    /// Largest `disagreement` (RMS of ln d₂/d₁) of a trusted lift.
    pub max_disagreement: f64,
    /// Largest fraction of depths on d_near or d_far of a trusted lift.
    pub max_at_bounds: f64,
    /// Smallest `transverse` (median share of the speed across the line of sight) of a trusted
    /// lift.
    pub min_transverse: f64,
    /// Largest `estimate.foreshortening` (image turning rate over the horizontal plane's) of a
    /// trusted lift whose v_target was estimated.
    pub max_foreshortening: f64,
}

impl Default for ConfidenceConfig {
    fn default() -> Self {
        ConfidenceConfig {
            restart: true,
            max_disagreement: 0.1,
            max_at_bounds: 0.01,
            min_transverse: 0.5,
            max_foreshortening: 1.5,
        }
    }
}

impl ConfidenceConfig {
    /// Checks ranges; errors name the key (`confidence.<key>`).
    pub fn check(&self) -> Result<()> {
        for (k, v) in [
            ("max_disagreement", self.max_disagreement),
            ("max_at_bounds", self.max_at_bounds),
            ("min_transverse", self.min_transverse),
            ("max_foreshortening", self.max_foreshortening),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!("confidence.{k} = {v} must be ≥ 0")));
            }
        }
        Ok(())
    }
}

/// The self-assessment of one lift (module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Confidence {
    /// RMS of ln(d₂ / d₁) between the restart and the result (None without a restart).
    pub disagreement: Option<f64>,
    /// RMS of ln d minus its frame's median ln d.
    pub structure: f64,
    /// Fraction of depths on d_near or d_far.
    pub at_bounds: f64,
    /// Median over the lifted velocities of the share of the speed across the line of sight.
    pub transverse: f64,
    /// Whether none of the reasons below applies.
    pub trusted: bool,
    /// Why not, one line each.
    pub reasons: Vec<String>,
}

/// RMS over observations of ln d minus its frame's median ln d.
pub fn structure(obs: &Observations, depth: &[f64]) -> f64 {
    let mut sum = 0.0;
    for (_, r) in &obs.frames {
        let mut u: Vec<f64> = depth[r.clone()].iter().map(|d| d.ln()).collect();
        let all = u.clone();
        u.sort_by(f64::total_cmp);
        let m = u[u.len() / 2];
        sum += all.iter().map(|v| (v - m) * (v - m)).sum::<f64>();
    }
    (sum / depth.len().max(1) as f64).sqrt()
}

/// Median over the velocities of the depths `depth` of |v − (v·r̂) r̂| / |v| (r̂ the unit ray of
/// the later observation); 1 without velocities.
pub fn transverse(obs: &Observations, depth: &[f64]) -> f64 {
    let b = obs.positions(depth);
    let mut share: Vec<f64> = (0..obs.len())
        .filter_map(|i| {
            let p = obs.prev[i]?;
            let v = [b[i][0] - b[p][0], b[i][1] - b[p][1], b[i][2] - b[p][2]];
            let r = obs.ray[i];
            let rl = (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt();
            let along = (v[0] * r[0] + v[1] * r[1] + v[2] * r[2]) / rl;
            let speed = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            (speed > 0.0).then(|| ((speed * speed - along * along).max(0.0)).sqrt() / speed)
        })
        .collect();
    if share.is_empty() {
        return 1.0;
    }
    share.sort_by(f64::total_cmp);
    share[share.len() / 2]
}

/// RMS of ln(a / b).
pub fn log_rms(a: &[f64], b: &[f64]) -> f64 {
    let s: f64 = a.iter().zip(b).map(|(x, y)| (x / y).ln().powi(2)).sum();
    (s / a.len().max(1) as f64).sqrt()
}

/// Assesses the whole-sequence depths `depth` of `obs` lifted with the resolved `cfg` (module
/// docs); `est` says whether v_target was estimated and how.
pub fn assess(
    obs: &Observations,
    depth: &[f64],
    cfg: &LiftConfig,
    est: &Estimate,
    progress: &mut dyn Progress,
) -> Result<Confidence> {
    let c = &cfg.confidence;
    let mut reasons = Vec::new();
    let disagreement = if c.restart {
        let mut sorted = depth.to_vec();
        sorted.sort_by(f64::total_cmp);
        let flat = vec![sorted[sorted.len() / 2]; depth.len()];
        let (again, _) = sequence::whole_sequence(obs, &flat, cfg, progress)?;
        let d = log_rms(&again, depth);
        if d > c.max_disagreement {
            reasons.push(format!(
                "a restart from a constant depth ends {:.0} % away (RMS; at most {:.0} % trusted): \
                 the tracks do not pin the depths down",
                100.0 * d,
                100.0 * c.max_disagreement
            ));
        }
        Some(d)
    } else {
        None
    };
    let (lo, hi) = (cfg.near(), cfg.far());
    let on = depth
        .iter()
        .filter(|&&d| d <= lo * (1.0 + 1e-9) || d >= hi * (1.0 - 1e-9))
        .count();
    let at_bounds = on as f64 / depth.len().max(1) as f64;
    if at_bounds > c.max_at_bounds {
        reasons.push(format!(
            "{:.1} % of the depths sit on d_near or d_far (at most {:.1} % trusted): widen the \
             bounds or check v_target",
            100.0 * at_bounds,
            100.0 * c.max_at_bounds
        ));
    }
    let across = transverse(obs, depth);
    if across < c.min_transverse {
        reasons.push(format!(
            "the birds fly mostly along the line of sight (median {:.0} % of the speed across \
             it; at least {:.0} % trusted): the image shows them little but looming",
            100.0 * across,
            100.0 * c.min_transverse
        ));
    }
    if est.v_target_source == Source::Estimated && est.extrapolated {
        reasons.push(format!(
            "v_target was estimated from a turning rate of {:.3} rad/s, outside the {:.2}–{:.2} \
             rad/s its speed prior was fitted on: give v_target",
            est.turn_rate, cfg.estimate.calibrated[0], cfg.estimate.calibrated[1]
        ));
    }
    let prior_used = est.v_target_source == Source::Estimated;
    if let Some(f) = est
        .foreshortening
        .filter(|f| prior_used && *f > c.max_foreshortening)
    {
        reasons.push(format!(
            "the image tracks turn {f:.1}× as sharply as their paths on a horizontal plane (at \
             most {:.1}× trusted): the birds fly along the line of sight and the speed prior \
             reads foreshortening as turns: give v_target",
            c.max_foreshortening
        ));
    }
    Ok(Confidence {
        disagreement,
        structure: structure(obs, depth),
        at_bounds,
        transverse: across,
        trusted: reasons.is_empty(),
        reasons,
    })
}
