//! Identifiability at the fitted point (issue #15 item 2): which of the 12 parameters, and which
//! combinations of them, the clip determines, with standard errors. The objective is the fit's
//! own (its window loss, paper §6.1 eq. 7–8 or field matching, over one epoch of its schedule),
//! probed by [`window_gradients`] at the fitted θ and at θ ± h e_j with common random numbers;
//! [`crate::optim::curvature`] turns the probes into the curvature, the gradient's noise, the
//! sandwich covariance H⁻¹ Σ H⁻¹ and the determined directions (its module documentation gives
//! the method and the threshold). The result ([`Uncertainty`], its format) is written into the parameter file
//! as `uncertainty`, printed by `herdfit fit` and shown in `herdfit validate`'s report.

use super::config::FitConfig;
use super::run::window_gradients;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::params::{param_names, Params, MIN_RANGE, N_PARAMS};
use crate::herd::uncertainty::{Bound, DirectionReport, Named, Noise, Uncertainty};
use crate::optim::curvature::{self, Estimate, Settings};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

/// The method string written into `uncertainty.method`.
pub const METHOD: &str = "sandwich H⁻¹ΣH⁻¹: H from central differences of the fit's per-window autodiff gradients with common random numbers (symmetrised), Σ from batch means of the per-window gradients at the fitted point";

/// Settings of the identifiability estimate (the fit job's `uncertainty` key).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct UncertaintyConfig {
    /// Estimate it at all (`herdfit fit --no-uncertainty` turns it off).
    pub enabled: bool,
    /// Finite-difference step h in the normalised parameters.
    pub step: f64,
    /// Random-number seeds: each probes the objective at the centre and at θ ± h e_j.
    pub seeds: usize,
    /// Batches of consecutive windows for the gradient's noise.
    pub batches: usize,
    /// A parameter or direction is determined when its 2-std half-width is at most this (0.06:
    /// the paper's per-parameter recovery figure, §7.1.1).
    pub accuracy: f64,
}

impl Default for UncertaintyConfig {
    fn default() -> Self {
        UncertaintyConfig {
            enabled: true,
            step: 0.05,
            seeds: 2,
            batches: 10,
            accuracy: 0.06,
        }
    }
}

impl UncertaintyConfig {
    /// The estimator's settings: a parameter within a tenth of the step of a bound is held there.
    pub fn settings(&self) -> Settings {
        Settings {
            step: self.step,
            seeds: self.seeds,
            batches: self.batches,
            accuracy: self.accuracy,
            bound_tol: self.step / 10.0,
        }
    }

    /// Checks the settings; errors name the key (`uncertainty.step`, …).
    pub fn check(&self) -> Result<()> {
        curvature::check(&self.settings())
            .map_err(|(k, msg)| Error::config(format!("uncertainty.{k}"), msg))
    }
}

/// The probe's seed for seed index `s`: apart from the fit's epochs' seeds.
fn probe_seed(seed: u64, s: usize) -> u64 {
    seed.wrapping_add(0x5EED_0000_u64.wrapping_mul(s as u64 + 1))
}

/// Estimates the identifiability at `params`'s 12 values for the fit's objective (`cfg`, the
/// fit's settings, with `clips`): `params` should be the fit's start with the fitted values
/// (its speed model the user's, as the fit uses it). Reports one progress unit per probe epoch.
pub fn identify(
    clips: &[&ClipFields],
    params: &Params,
    cfg: &FitConfig,
    ucfg: &UncertaintyConfig,
    progress: &mut dyn Progress,
) -> Result<Uncertainty> {
    identify_by(params, cfg.seed, ucfg, progress, |p, seed| {
        let c = FitConfig {
            seed,
            ..cfg.clone()
        };
        window_gradients(clips, p, &c)
    })
}

/// The estimate at `params` for any objective given by its probe: `probe(point, seed)` is each
/// window's (loss, gradient) over one epoch at `point` with that seed (the same seed, the same
/// windows and noise: common random numbers). The seeds are `seed`'s probe seeds, apart from the
/// fit's epochs'. Reports one progress unit per probe.
pub fn identify_by(
    params: &Params,
    seed: u64,
    ucfg: &UncertaintyConfig,
    progress: &mut dyn Progress,
    mut probe: impl FnMut(&Params, u64) -> Result<Vec<(f64, [f64; N_PARAMS])>>,
) -> Result<Uncertainty> {
    ucfg.check()?;
    let s = ucfg.settings();
    let x = params.to_vec();
    let lo: Vec<f64> = (0..N_PARAMS)
        .map(|i| if i % 3 == 0 { 0.0 } else { MIN_RANGE })
        .collect();
    let hi = vec![1.0; N_PARAMS];
    progress.start(
        "uncertainty",
        curvature::probes_needed(&x, &lo, &hi, &s) as u64,
    );
    let est = curvature::estimate(&x, &lo, &hi, &s, |p, k| -> Result<_> {
        let mut v = [0.0; N_PARAMS];
        v.copy_from_slice(p);
        let w = probe(&params.with_vec(&v), probe_seed(seed, k))?;
        progress.inc(1);
        Ok(w.into_iter().map(|(l, g)| (l, g.to_vec())).collect())
    })?;
    progress.finish();
    Ok(report(&est, ucfg))
}

/// The estimate by parameter name.
pub fn report(est: &Estimate, ucfg: &UncertaintyConfig) -> Uncertainty {
    let names = param_names();
    let named = |v: &[f64]| Named(names.iter().cloned().zip(v.iter().copied()).collect());
    Uncertainty {
        method: METHOD.into(),
        step: ucfg.step,
        accuracy: ucfg.accuracy,
        std: Named(names.iter().cloned().zip(est.std.iter().copied()).collect()),
        determined: names
            .iter()
            .zip(&est.determined)
            .filter(|(_, &d)| d)
            .map(|(n, _)| n.clone())
            .collect(),
        bounds: Named(
            names
                .iter()
                .zip(&est.bound)
                .filter_map(|(n, b)| {
                    b.as_ref().map(|b| {
                        let side = if b.upper { "upper" } else { "lower" };
                        (
                            n.clone(),
                            Bound {
                                side: side.into(),
                                within: b.within,
                            },
                        )
                    })
                })
                .collect(),
        ),
        directions: est
            .directions
            .iter()
            .map(|d| DirectionReport {
                eigenvalue: d.eigenvalue,
                eigenvalue_std: d.eigenvalue_std,
                std: d.std,
                to_minimum: d.to_minimum,
                determined: d.determined,
                vector: named(&d.vector),
            })
            .collect(),
        noise: Noise {
            objective: est.objective,
            objective_std: est.objective_std,
            windows: est.windows,
            batches: est.batches,
            seeds: ucfg.seeds,
            gradient: named(&est.gradient),
            gradient_std: named(&est.gradient_std),
        },
    }
}
