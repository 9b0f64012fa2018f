//! Fits from a single image (paper §7.2.4): a clip of one frame (density and direction variance,
//! no velocity) fitted as a stationary target.
//!
//! The frame is repeated `settle + average + 1` times ([`stationary_clip`]) and fitted by the
//! ordinary loop ([`super::run`]) with [`super::FitConfig::still`] set: each epoch starts the herd
//! from the image's density with random headings (the velocity is zero), simulates `settle` steps
//! without learning, then unrolls the `average` steps in windows whose loss is the time average of
//! the density match Σ(ρ' − Kρ)² / Σ(Kρ)² ([`super::loss::density_loss`], `--loss fields`, the
//! default) or of E_mean (eq. 7) towards U = N(D) (eq. 10–11 with no velocity, the paper's β = 1;
//! `--loss paper`), and λ_var E_var (eq. 8) against the image's direction variance S. With the
//! paper's split (§6.1) the alignment parameters follow ∇E_var and the others the density term
//! (or E_mean). No leaders (a still shows no direction to follow) and no rebalancing between
//! windows (agents that leave the grid are replaced). A still measures no speeds: the start set's speed model is used, as the paper sets
//! the seals' speeds from their known behaviour.

use super::loss::density_loss;
use crate::backend::{cpu_device, Precision};
use crate::data::agents::AgentRow;
use crate::data::boundary::Gates;
use crate::data::{ClipFields, ClipSpeed};
use crate::error::{Error, Result};
use crate::herd::eval::run_from;
use crate::herd::params::{Params, SpeedModel};
use crate::herd::sim::Guidance;
use crate::herd::sim::{read_vec, HerdState};
use crate::herd::start::Settle;
use crate::herd::zoned::ZoneSets;
use crate::measure::emergent::polarization;
use crate::measure::fields::{cell_counts, field_errors};
use serde::{Deserialize, Serialize};
use std::collections::HashMap;

/// The schedule of a fit from a single image.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct StillConfig {
    /// Steps simulated from the image's density before the objective is averaged (no learning).
    pub settle: usize,
    /// Steps over which the density and direction-variance match is averaged (the learning
    /// windows).
    pub average: usize,
}

impl Default for StillConfig {
    fn default() -> Self {
        StillConfig {
            settle: 25,
            average: 50,
        }
    }
}

impl StillConfig {
    /// Checks the ranges; errors name `still.settle` / `still.average`.
    pub fn check(&self) -> Result<()> {
        if self.settle > 100_000 {
            return Err(Error::config(
                "still.settle",
                format!("{} is out of range 0..=100000", self.settle),
            ));
        }
        if self.average == 0 || self.average > 100_000 {
            return Err(Error::config(
                "still.average",
                format!("{} is out of range 1..=100000", self.average),
            ));
        }
        Ok(())
    }

    /// Frames of the stationary clip: frame 0, the settling steps and the averaged steps.
    pub fn frames(&self) -> usize {
        self.settle + self.average + 1
    }
}

/// The stationary target of a one-frame clip: its frame repeated [`StillConfig::frames`] times
/// with zero velocity; its speed model is `speed`'s when the still measured none (v_μ = 0).
pub fn stationary_clip(still: &ClipFields, cfg: &StillConfig, speed: &SpeedModel) -> ClipFields {
    let n = cfg.frames();
    let one = |a: &ndarray::Array3<f32>| {
        let f0 = a.index_axis(ndarray::Axis(0), 0);
        ndarray::Array3::from_shape_fn((n, f0.dim().0, f0.dim().1), |(_, y, x)| f0[[y, x]])
    };
    let mut meta = still.meta.clone();
    meta.frames = n;
    if meta.speed.mean <= 0.0 {
        meta.speed = ClipSpeed {
            mean: speed.mean,
            std: speed.stationary_std(),
            density_table: speed.density_table.clone().unwrap_or_default(),
        };
    }
    ClipFields {
        meta,
        density: one(&still.density),
        velocity: ndarray::Array4::zeros((n, still.meta.ny, still.meta.nx, 2)),
        dir_variance: one(&still.dir_variance),
        obstacles: still.obstacles.clone(),
    }
}

/// What a parameter set does with the image, each measure averaged over the `average` steps
/// after `settle` of runs from the image's density (no population control, no leaders), and over
/// `seeds` runs (seeds `seed`, `seed + 1`, …): the density error against the image, raw
/// ([`field_errors`]) and smoothed (the fit's own density term,
/// [`super::loss::density_loss`]), the crowding (the density around an average animal,
/// Σn²/(A Σn) over cells, relative to the image's) and the polarization (eq. 12). The `start`
/// measures are those of the herd as drawn from the image, before any step. `clip` is the
/// [`stationary_clip`].
pub fn still_measures(
    clip: &ClipFields,
    params: &Params,
    cfg: &StillConfig,
    seed: u64,
    seeds: usize,
    precision: Precision,
) -> Result<[StillMeasures; 2]> {
    let run = StillRun {
        cfg,
        seed,
        seeds,
        precision,
    };
    Ok(still_measures_in(clip, params, None, &run)?.0)
}

/// How [`still_measures_in`] runs: the schedule, the first seed, the number of seeds and the
/// precision.
pub struct StillRun<'a> {
    pub cfg: &'a StillConfig,
    pub seed: u64,
    pub seeds: usize,
    pub precision: Precision,
}

/// [`still_measures`] of one set, or with `zones` of one set per zone (each agent with its
/// zone's set and speed, paper §7.2.4), and the mean speed each zone set (BL/s: the agents'
/// speeds by the zone they stood in when the step began, over the averaged steps and the seeds;
/// one value without zones).
pub fn still_measures_in(
    clip: &ClipFields,
    params: &Params,
    zones: Option<&ZoneSets>,
    run: &StillRun,
) -> Result<([StillMeasures; 2], Vec<f64>)> {
    let StillRun {
        cfg,
        seed,
        seeds,
        precision,
    } = *run;
    let nz = zones.map_or(1, |z| z.sets.len());
    let mut speed_sum = vec![0.0f64; nz];
    let mut speed_n = vec![0.0f64; nz];
    let device = cpu_device(precision)?;
    let grid = clip.grid();
    let guidance = vec![Guidance::None; clip.frames()];
    let area = clip.grid().cell_area();
    let crowding = |n: &[f64]| {
        let (s1, s2) = n.iter().fold((0.0, 0.0), |(a, b), &x| (a + x, b + x * x));
        s2 / (area * s1.max(1e-12))
    };
    let image: Vec<f64> = clip
        .density
        .index_axis(ndarray::Axis(0), 0)
        .iter()
        .map(|&r| r as f64 * area)
        .collect();
    let image_crowding = crowding(&image);
    let mut sum = [0.0f64; 4];
    let mut n = 0.0f64;
    let mut start = [0.0f64; 4];
    let measure = |f: usize, state: &HerdState, rows: &[AgentRow]| -> Result<[f64; 4]> {
        let vel: Vec<[f64; 2]> = rows.iter().map(|r| [r.vx, r.vy]).collect();
        let (counts, _) = cell_counts(clip, rows);
        Ok([
            field_errors(clip, f, rows).0,
            read_vec(&density_loss(clip, state, f)?)?[0],
            crowding(&counts) / image_crowding.max(1e-12),
            polarization(&vel, &vec![1.0; vel.len()]),
        ])
    };
    for k in 0..seeds.max(1) {
        let mut before: HashMap<u64, usize> = HashMap::new();
        let (rows0, _) = run_from(
            clip,
            params,
            zones,
            None,
            &Gates::closed(),
            (0, cfg.settle + cfg.average),
            seed.wrapping_add(k as u64),
            &Settle::default(),
            &guidance,
            &device,
            |f, state, ids| {
                // From the last settling frame on: each agent's zone (agents in the view only:
                // outside it they are in no zone), by id; the settling steps measure nothing.
                if f < cfg.settle {
                    return Ok(());
                }
                let rows = state.rows(ids)?;
                let inside: Vec<&AgentRow> = rows
                    .iter()
                    .filter(|r| grid.cell_of([r.x, r.y]).is_some())
                    .collect();
                let pos: Vec<[f64; 2]> = inside.iter().map(|r| [r.x, r.y]).collect();
                let zone = zones.map_or_else(|| vec![0; pos.len()], |z| z.zone_of(&pos));
                let here: HashMap<u64, usize> =
                    inside.iter().zip(zone).map(|(r, z)| (r.id, z)).collect();
                if f > cfg.settle {
                    let m = measure(f, state, &rows)?;
                    sum.iter_mut().zip(m).for_each(|(s, v)| *s += v);
                    n += 1.0;
                    // A speed belongs to the zone that set it: where the agent stood when the
                    // step began (eq. 6 draws it there). An agent that crossed a zone's edge
                    // during the step still moves at the zone it left.
                    for r in &inside {
                        if let Some(&z) = before.get(&r.id) {
                            speed_sum[z] += r.vx.hypot(r.vy);
                            speed_n[z] += 1.0;
                        }
                    }
                }
                before = here;
                Ok(())
            },
        )?;
        let s0 = HerdState::from_rows(&rows0, &device);
        let ids: Vec<u64> = rows0.iter().map(|r| r.id).collect();
        let m = measure(0, &s0, &s0.rows(&ids)?)?;
        start.iter_mut().zip(m).for_each(|(s, v)| *s += v);
    }
    let k = seeds.max(1) as f64;
    let of = |m: [f64; 4], n: f64| StillMeasures {
        density_error: m[0] / n,
        smooth_density_error: m[1] / n,
        crowding: m[2] / n,
        polarization: m[3] / n,
    };
    let speeds = speed_sum
        .iter()
        .zip(&speed_n)
        .map(|(s, n)| if *n > 0.0 { s / n } else { f64::NAN })
        .collect();
    Ok(([of(start, k), of(sum, n.max(1.0))], speeds))
}

/// [`still_measures`]' result.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct StillMeasures {
    /// Σ|ρ' − ρ| / Σρ against the image (cell counts; its floor is the sampling noise of the
    /// herd drawn from the image, the `start` value).
    pub density_error: f64,
    /// Σ(ρ' − Kρ)² / Σ(Kρ)², ρ' splatted and Kρ blurred alike (the fit's density term).
    pub smooth_density_error: f64,
    /// The density around an average animal, Σn²/(A Σn), over the image's (1: kept; < 1:
    /// spread out; > 1: clumped).
    pub crowding: f64,
    /// Polarization of the whole herd (eq. 12).
    pub polarization: f64,
}
