//! The `uncertainty` block of a parameter file (`herdfit.params/1`): what the clip determines at
//! the fitted point, as [`crate::herd::fit::identify()`] estimates it, and its printed summary.
//! A format every reader of parameter files shares, so it lives beside [`crate::herd::params`],
//! not inside the fit.

use serde::{Deserialize, Serialize};

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
pub fn summary(u: &Uncertainty, values: &[f64]) -> String {
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
