//! Identifiability at the fitted point (issue #15 item 2): which of the 12 parameters, and which
//! combinations of them, the clip determines, with standard errors. The objective is the fit's
//! own (its window loss, paper §6.1 eq. 7–8 or field matching, over one epoch of its schedule),
//! probed by [`window_gradients`] at the fitted θ and at θ ± h e_j with common random numbers;
//! [`crate::optim::curvature`] turns the probes into the curvature, the gradient's noise, the
//! sandwich covariance H⁻¹ Σ H⁻¹ and the determined directions (its module documentation gives
//! the method and the threshold). The result is written into the parameter file as
//! `uncertainty`, printed by `herdfit fit` and shown in `herdfit validate`'s report.

use super::config::FitConfig;
use super::run::window_gradients;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::params::{param_names, Params, MIN_RANGE, N_PARAMS};
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

/// Values keyed by parameter name, in parameter order (a JSON object).
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Named<T>(pub Vec<(String, T)>);

impl<T: Serialize> Serialize for Named<T> {
    fn serialize<S: serde::Serializer>(&self, s: S) -> std::result::Result<S::Ok, S::Error> {
        use serde::ser::SerializeMap;
        let mut m = s.serialize_map(Some(self.0.len()))?;
        for (k, v) in &self.0 {
            m.serialize_entry(k, v)?;
        }
        m.end()
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for Named<T> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> std::result::Result<Self, D::Error> {
        struct V<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> serde::de::Visitor<'de> for V<T> {
            type Value = Named<T>;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("an object keyed by parameter name")
            }
            fn visit_map<A: serde::de::MapAccess<'de>>(
                self,
                mut a: A,
            ) -> std::result::Result<Named<T>, A::Error> {
                let mut out = Vec::new();
                while let Some(e) = a.next_entry()? {
                    out.push(e);
                }
                Ok(Named(out))
            }
        }
        d.deserialize_map(V(std::marker::PhantomData))
    }
}

impl<T> Named<T> {
    /// The value of `name`.
    pub fn get(&self, name: &str) -> Option<&T> {
        self.0.iter().find(|(k, _)| k == name).map(|(_, v)| v)
    }
}

/// A parameter held at a bound, with the one-sided 2-std interval the data allow.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Bound {
    /// "lower" or "upper".
    pub side: String,
    pub within: [f64; 2],
}

/// One eigen-direction of the curvature.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DirectionReport {
    pub eigenvalue: f64,
    pub eigenvalue_std: f64,
    /// The estimate's standard deviation along the direction; null when it is not informative.
    pub std: Option<f64>,
    /// Where the quadratic model's minimum lies along the direction from the fitted point
    /// (−vᵀḡ/λ; null when not informative): more than 2 std means the fit stopped short.
    pub to_minimum: Option<f64>,
    pub determined: bool,
    /// Unit vector by parameter name (0 for parameters at a bound).
    pub vector: Named<f64>,
}

/// The objective's noise at the fitted point.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Noise {
    /// The objective (mean window loss) and its standard error.
    pub objective: f64,
    pub objective_std: f64,
    pub windows: usize,
    pub batches: usize,
    pub seeds: usize,
    /// The mean gradient at the fitted point and its standard error, by parameter.
    pub gradient: Named<f64>,
    pub gradient_std: Named<f64>,
}

/// What the clip determines at the fitted point (`uncertainty` of a `herdfit.params/1` file).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Uncertainty {
    pub method: String,
    pub step: f64,
    pub accuracy: f64,
    /// Standard error per parameter; null for a parameter at a bound (see `bounds`).
    pub std: Named<Option<f64>>,
    /// The parameters whose 2-std half-width is at most `accuracy`.
    pub determined: Vec<String>,
    pub bounds: Named<Bound>,
    /// Eigen-directions over the free parameters, eigenvalue decreasing.
    pub directions: Vec<DirectionReport>,
    pub noise: Noise,
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

/// A direction's largest components, "+0.71 avoidance.radial −0.52 cohesion.weight …".
pub fn components(d: &DirectionReport, k: usize) -> String {
    let mut c: Vec<&(String, f64)> = d.vector.0.iter().filter(|(_, v)| *v != 0.0).collect();
    c.sort_by(|a, b| b.1.abs().total_cmp(&a.1.abs()));
    c.iter()
        .take(k)
        .map(|(n, v)| format!("{}{:.2} {n}", if *v < 0.0 { "−" } else { "+" }, v.abs()))
        .collect::<Vec<_>>()
        .join(" ")
}

/// The compact summary `herdfit fit` prints: per parameter value ± std (or its one-sided
/// interval at a bound), then the determined directions.
pub fn summary(u: &Uncertainty, values: &[f64; N_PARAMS]) -> String {
    let mut s = format!(
        "identifiability at the fitted point (objective {:.4} ± {:.4}, {} windows × {} seeds; determined: 2 std ≤ {}):\n",
        u.noise.objective, u.noise.objective_std, u.noise.windows, u.noise.seeds, u.accuracy
    );
    for (i, (name, std)) in u.std.0.iter().enumerate() {
        let what = match (std, u.bounds.get(name)) {
            (_, Some(b)) => format!(
                "at the {} bound; the data allow {:.4}..{:.4} (one-sided, 2 std)",
                b.side, b.within[0], b.within[1]
            ),
            (Some(sd), None) => format!(
                "± {sd:.4}{}",
                if u.determined.contains(name) {
                    "  determined"
                } else {
                    ""
                }
            ),
            (None, None) => "—".into(),
        };
        s.push_str(&format!("  {name:<20} {:>8.4} {what}\n", values[i]));
    }
    let det: Vec<&DirectionReport> = u.directions.iter().filter(|d| d.determined).collect();
    s.push_str(&format!(
        "  {} of {} directions determined",
        det.len(),
        u.directions.len()
    ));
    s.push_str(if det.is_empty() { "\n" } else { ":\n" });
    for d in det {
        s.push_str(&format!(
            "    λ {:.4} ± {:.4}, std {:.4}, minimum at {:+.4} along it: {}\n",
            d.eigenvalue,
            d.eigenvalue_std,
            d.std.unwrap_or(f64::NAN),
            d.to_minimum.unwrap_or(f64::NAN),
            components(d, 4)
        ));
    }
    s
}
