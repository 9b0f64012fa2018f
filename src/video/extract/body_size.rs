//! The body size of an extraction's animals from the connected components of the sampled herd
//! masks (paper §4: N_bp, the pixels per animal, and the body length L): the mode of log-area,
//! or the components around the area-weighted median when the mode is fragments.

use super::blobs::{Blob, MIN_COMPONENT};

/// Body size from the components of the sampled frames ([`body_size`]).
#[derive(Clone, Copy, Debug)]
pub(super) struct BodySize {
    /// Median area, major and minor axis of the components taken as single animals.
    pub blob: Blob,
    /// How many components that was.
    pub n: usize,
    /// Their share of all the components' pixels.
    pub share: f64,
    /// Whether they were found by the area-weighted median rather than the mode.
    pub weighted: bool,
}

/// The single animals among `blobs`: the median area (N_bp), major axis (L) and minor axis of
/// the components within ×0.7–1.4 of the mode of log-area. When the most common component is no
/// larger than twice [`MIN_COMPONENT`], or the components at the mode hold less than
/// [`MIN_SHARE`] of the pixels — fragments and ground texture, not animals — the components
/// around the area-weighted median are taken instead: the size below which half the herd pixels
/// lie (animals that vary in size, as walkers at different distances do, have no sharp mode).
pub(super) fn body_size(blobs: &[Blob]) -> Option<BodySize> {
    if blobs.is_empty() {
        return None;
    }
    let logs: Vec<f64> = blobs.iter().map(|b| b.area.ln()).collect();
    let total: f64 = blobs.iter().map(|b| b.area).sum();
    let around = |m: f64| -> (Vec<Blob>, f64) {
        let near: Vec<Blob> = blobs
            .iter()
            .copied()
            .filter(|b| b.area >= 0.7 * m && b.area <= 1.4 * m)
            .collect();
        let share = near.iter().map(|b| b.area).sum::<f64>() / total;
        (near, share)
    };
    let m = log_area_mode(&logs).exp();
    let (mut near, mut share) = around(m);
    let weighted = m <= 2.0 * MIN_COMPONENT as f64 || share < MIN_SHARE;
    if weighted {
        let mut areas: Vec<f64> = blobs.iter().map(|b| b.area).collect();
        areas.sort_by(f64::total_cmp);
        let mut below = 0.0;
        let half = areas
            .iter()
            .copied()
            .find(|&a| {
                below += a;
                below >= total / 2.0
            })
            .unwrap_or(m);
        (near, share) = around(half);
    }
    if near.is_empty() {
        return None;
    }
    let med = |v: &mut Vec<f64>| {
        v.sort_by(f64::total_cmp);
        v[v.len() / 2]
    };
    let blob = Blob {
        area: med(&mut near.iter().map(|b| b.area).collect()),
        major: med(&mut near.iter().map(|b| b.major).collect()),
        minor: med(&mut near.iter().map(|b| b.minor).collect()),
    };
    Some(BodySize {
        blob,
        n: near.len(),
        share,
        weighted,
    })
}

impl BodySize {
    /// "N isolated animals (S % of the herd pixels)", naming the weighted median when it was used.
    pub(super) fn what(&self) -> String {
        let pct = 100.0 * self.share;
        if self.weighted {
            format!(
                "{} components around the area-weighted median ({pct:.0} % of the herd pixels; \
                 the most common components were fragments)",
                self.n
            )
        } else {
            format!(
                "{} isolated animals ({pct:.0} % of the herd pixels)",
                self.n
            )
        }
    }
}

/// Smallest share of the herd pixels the components at the mode of log-area must hold to be
/// taken for single animals ([`body_size`]).
const MIN_SHARE: f64 = 0.1;

/// The mode of a kernel density (Gaussian, bandwidth 0.12) of `logs` on a grid of 0.01 over
/// their range.
fn log_area_mode(logs: &[f64]) -> f64 {
    let (lo, hi) = logs
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &v| {
            (a.min(v), b.max(v))
        });
    let bw = 0.12;
    let steps = (((hi - lo) / 0.01).ceil() as usize).max(1);
    let mut mode = (f64::NEG_INFINITY, lo);
    // Terms beyond 12 bandwidths (e^-72 < 1e-31, where the density at the mode is ≥ 1) are
    // left out of the sum, which otherwise keeps its order.
    let reach = 12.0 * bw;
    for k in 0..=steps {
        let x = lo + (hi - lo) * k as f64 / steps as f64;
        let dens: f64 = logs
            .iter()
            .filter(|&&v| (v - x).abs() <= reach)
            .map(|&v| (-(v - x).powi(2) / (2.0 * bw * bw)).exp())
            .sum();
        if dens > mode.0 {
            mode = (dens, x);
        }
    }
    mode.1
}
