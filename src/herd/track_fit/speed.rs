//! The speed model of eq. 6 (and §6.2's speed–density table) learnt from the tracks: what a track
//! fit exports beside the forces, and what every set runs with when a track evaluation compares
//! them.
//!
//! Eq. 6 is an Ornstein–Uhlenbeck process stepped by Euler, v' = v − θ_OU (v − v_μ(ρ)) Δt +
//! v_σ √Δt ξ, an AR(1) process with coefficient φ = 1 − θ_OU Δt per step. From every animal
//! tracked in two consecutive frames, its speed v = |p(f) − p(f−1)| / Δt (the model's own speed,
//! p' = p + Δt v' d') and its local density ρ (animals within R_perc, itself included, per πR²:
//! the perception kernel's definition):
//! - v_μ(ρ): the mean speed in up to 8 density bins of equal count (one value when the densities
//!   do not spread);
//! - φ: the deviations u = v − v_μ(ρ) along each track have autocovariance c(τ) = a c(0) φ^τ for
//!   τ ≥ 1, where a ≤ 1 is the share of the variance that is the process's and not the tracker's
//!   frame-to-frame noise (which decorrelates after one lag); ln(c(τ)/c(0)) is fitted by least
//!   squares over the lags from 2 frames (1 when 2 s hold fewer than 3) up to 2 s, while c(τ) >
//!   0.05 c(0);
//! - θ_OU = (1 − φ)/Δt and v_σ from the process's stationary variance a c(0) = v_σ² Δt / (1 − φ²).

use super::data::TrackSet;
use crate::error::{Error, Result};
use crate::herd::params::SpeedModel;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::ops::Range;

/// How the speed model was learnt (recorded in the fitted set's provenance).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SpeedFit {
    /// Speed samples (animal-frames with the frame before tracked).
    pub samples: usize,
    /// Lags used for the autocorrelation (frames).
    pub lags: usize,
    /// Per-step autocorrelation φ of the process.
    pub phi: f64,
    /// Share of the speeds' variance that is the process's (the rest is tracking noise).
    pub signal_share: f64,
}

/// One speed sample: the animal, its frame, its speed and local density.
struct Sample {
    set: usize,
    id: u64,
    frame: usize,
    speed: f64,
    density: f64,
}

/// The animals' speeds and local densities in `frames` (each frame with the one before it).
fn samples(sets: &[(&TrackSet, Range<usize>)], radius: f64) -> Vec<Sample> {
    let r2 = radius * radius;
    let area = std::f64::consts::PI * r2;
    let mut out = Vec::new();
    for (s, (t, frames)) in sets.iter().enumerate() {
        for f in frames.start + 1..frames.end.min(t.len()) {
            let here = t.at(f);
            for a in here {
                let Some(v) = t.back_vel(f, a.id) else {
                    continue;
                };
                let near = here
                    .iter()
                    .filter(|b| {
                        let d2 = (b.pos[0] - a.pos[0]).powi(2) + (b.pos[1] - a.pos[1]).powi(2);
                        d2 < r2 && (b.id == a.id || d2 > 1e-18)
                    })
                    .count();
                out.push(Sample {
                    set: s,
                    id: a.id,
                    frame: f,
                    speed: v[0].hypot(v[1]),
                    density: near as f64 / area,
                });
            }
        }
    }
    out
}

/// v_μ(ρ) by density bins of about equal count (at most 8, at least 200 samples each; local
/// densities are counts over an area, so equal densities are never split between bins):
/// `[mean density, mean speed]` rows, density increasing; empty when the densities do not spread.
fn density_table(samples: &[Sample]) -> Vec<[f64; 2]> {
    let mut by_rho: Vec<(f64, f64)> = samples.iter().map(|s| (s.density, s.speed)).collect();
    by_rho.sort_by(|a, b| a.0.total_cmp(&b.0));
    let target = (by_rho.len() / 8).max(200);
    let mut rows: Vec<[f64; 2]> = Vec::new();
    let (mut start, mut i) = (0, 0);
    while i < by_rho.len() {
        // The end of the run of equal densities starting at i.
        let mut j = i + 1;
        while j < by_rho.len() && by_rho[j].0 == by_rho[i].0 {
            j += 1;
        }
        let rest = by_rho.len() - j;
        if j - start >= target && (rest >= target || rest == 0) || j == by_rho.len() {
            let part = &by_rho[start..j];
            let n = part.len() as f64;
            rows.push([
                part.iter().map(|p| p.0).sum::<f64>() / n,
                part.iter().map(|p| p.1).sum::<f64>() / n,
            ]);
            start = j;
        }
        i = j;
    }
    if rows.len() < 2 {
        rows.clear();
    }
    rows
}

/// Learns eq. 6's speed model from the tracks `sets` (each with the frames it may read) with
/// perception radius `radius`; `base` gives the cap's floor. An error when no animal is tracked
/// in two consecutive frames.
pub fn learn_speed(
    sets: &[(&TrackSet, Range<usize>)],
    radius: f64,
    base: &SpeedModel,
) -> Result<(SpeedModel, SpeedFit)> {
    let all = samples(sets, radius);
    if all.is_empty() {
        return Err(Error::invalid(
            "no animal is tracked in two consecutive frames: no speed to learn",
        ));
    }
    let n = all.len() as f64;
    let mean = all.iter().map(|s| s.speed).sum::<f64>() / n;
    let table = density_table(&all);
    let model = SpeedModel {
        mean,
        density_table: (!table.is_empty()).then_some(table),
        ..base.clone()
    };
    // Deviations from v_μ(ρ) along each track.
    let dev: BTreeMap<(usize, u64, usize), f64> = all
        .iter()
        .map(|s| ((s.set, s.id, s.frame), s.speed - model.mean_at(s.density)))
        .collect();
    let centre = dev.values().sum::<f64>() / n;
    let fps = sets[0].0.fps;
    let max_lag = ((2.0 * fps).round() as usize).clamp(1, 200);
    let cov = |lag: usize| -> Option<f64> {
        let (mut s, mut k) = (0.0, 0usize);
        for (&(set, id, f), &u) in &dev {
            if let Some(&w) = dev.get(&(set, id, f + lag)) {
                s += (u - centre) * (w - centre);
                k += 1;
            }
        }
        (k >= 10).then(|| s / k as f64)
    };
    let c0 = cov(0).unwrap_or(0.0);
    // ln(c(τ)/c(0)) = ln a + τ ln φ over the lags with a clear correlation.
    // Lag 1 also holds the (negative) covariance of consecutive differences of the tracker's
    // noise; from lag 2 on it is the process's alone.
    let first = if max_lag >= 3 { 2 } else { 1 };
    let mut pts: Vec<(f64, f64)> = Vec::new();
    for lag in first..=max_lag {
        match cov(lag) {
            Some(c) if c0 > 0.0 && c > 0.05 * c0 => pts.push((lag as f64, (c / c0).ln())),
            _ => break,
        }
    }
    let (ln_a, ln_phi) = match pts.len() {
        0 => (0.0, (1.0 - base.reversion / fps).max(1e-3).ln()),
        1 => (0.0, pts[0].1),
        _ => {
            let m = pts.len() as f64;
            let (sx, sy) = pts.iter().fold((0.0, 0.0), |(a, b), p| (a + p.0, b + p.1));
            let (mx, my) = (sx / m, sy / m);
            let sxx: f64 = pts.iter().map(|p| (p.0 - mx).powi(2)).sum();
            let sxy: f64 = pts.iter().map(|p| (p.0 - mx) * (p.1 - my)).sum();
            let slope = sxy / sxx;
            (my - slope * mx, slope)
        }
    };
    let phi = ln_phi.exp().clamp(0.0, 1.0 - 1e-6);
    let share = ln_a.exp().clamp(0.0, 1.0);
    let dt = 1.0 / fps;
    let reversion = (1.0 - phi) / dt;
    let std = (share * c0 * (1.0 - phi * phi) / dt).max(0.0).sqrt();
    let mut speeds: Vec<f64> = all.iter().map(|s| s.speed).collect();
    speeds.sort_by(f64::total_cmp);
    let q999 = speeds[((speeds.len() - 1) as f64 * 0.999) as usize];
    let model = SpeedModel {
        std,
        reversion,
        max: base.max.max(1.5 * q999),
        ..model
    };
    let fit = SpeedFit {
        samples: all.len(),
        lags: pts.len(),
        phi,
        signal_share: share,
    };
    Ok((model, fit))
}

#[cfg(test)]
mod tests {
    use super::super::data::Fix;
    use super::*;
    use rand::{Rng, SeedableRng};
    use rand_distr::StandardNormal;

    /// Two animals far apart whose speeds follow eq. 6 exactly (θ_OU 0.8, v_σ 0.5 around 2 BL/s
    /// at 25 fps), observed with or without tracking noise: the learnt model is eq. 6's.
    #[test]
    fn an_ou_process_is_recovered_with_and_without_tracking_noise() {
        for noise in [0.0, 0.01] {
            let (fps, theta, sigma, mu): (f64, f64, f64, f64) = (25.0, 0.8, 0.5, 2.0);
            let dt = 1.0 / fps;
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(4);
            let mut frames = vec![Vec::new(); 20_000];
            for id in 0..2u64 {
                let (mut x, mut v) = (0.0, mu);
                for fr in frames.iter_mut() {
                    let e: f64 = rng.sample(StandardNormal);
                    fr.push(Fix {
                        id,
                        pos: [x + noise * e, 100.0 * id as f64],
                        vel: None,
                    });
                    let xi: f64 = rng.sample(StandardNormal);
                    v = v - theta * (v - mu) * dt + sigma * dt.sqrt() * xi;
                    x += v * dt;
                }
            }
            let t = TrackSet::new(fps, frames);
            let (m, fit) = learn_speed(&[(&t, 0..20_000)], 4.0, &SpeedModel::default()).unwrap();
            assert!((m.mean - mu).abs() < 0.05, "{m:?}");
            assert!(
                (m.reversion - theta).abs() < 0.15,
                "noise {noise}: {m:?} {fit:?}"
            );
            assert!((m.std - sigma).abs() < 0.05, "noise {noise}: {m:?} {fit:?}");
            assert!(m.density_table.is_none(), "one density: no table");
            if noise > 0.0 {
                assert!(fit.signal_share < 0.95, "{fit:?}");
            }
        }
    }

    /// Local densities are counts: animals alone run at 1 BL/s, in pairs at 3; the table keeps
    /// the two densities apart (one row each) whatever the order of the samples.
    #[test]
    fn equal_densities_are_never_split_between_bins() {
        let mut frames = vec![Vec::new(); 400];
        for (f, fr) in frames.iter_mut().enumerate() {
            let t = f as f64;
            // Two far apart animals at 1 BL/s, and a pair 1 BL apart at 3 BL/s.
            for (id, v, y) in [
                (0, 0.1, 0.0),
                (1, 0.1, 50.0),
                (2, 0.3, 100.0),
                (3, 0.3, 101.0),
            ] {
                fr.push(Fix {
                    id,
                    pos: [t * v, y],
                    vel: None,
                });
            }
        }
        let t = TrackSet::new(10.0, frames);
        let (m, _) = learn_speed(&[(&t, 0..400)], 4.0, &SpeedModel::default()).unwrap();
        let table = m.density_table.expect("two densities");
        let area = std::f64::consts::PI * 16.0;
        assert_eq!(table.len(), 2, "{table:?}");
        assert!((table[0][0] - 1.0 / area).abs() < 1e-12 && (table[0][1] - 1.0).abs() < 1e-9);
        assert!((table[1][0] - 2.0 / area).abs() < 1e-12 && (table[1][1] - 3.0).abs() < 1e-9);
    }
}
