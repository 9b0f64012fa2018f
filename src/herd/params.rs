//! The herd model's parameters (paper §5.2–5.4, DESIGN §4): the 12 normalised force parameters,
//! the fixed constants and the speed model, with validation and the `herdfit.params/1` file format.

use crate::data::atomic::write_atomic;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema tag of parameter-set files.
pub const SCHEMA: &str = "herdfit.params/1";

/// The four component forces of eq. 3, in parameter order.
pub const FORCES: [&str; 4] = ["cohesion", "avoidance", "alignment", "obstacle"];
/// The three parameters of each force, in parameter order.
pub const FIELDS: [&str; 3] = ["weight", "radial", "angular"];
/// Number of optimisable parameters.
pub const N_PARAMS: usize = 12;
/// Indices of the alignment parameters in the θ vector.
pub const ALIGNMENT: [usize; 3] = [6, 7, 8];

/// `force.field` names of the 12 parameters in vector order
/// (cohesion.weight, cohesion.radial, cohesion.angular, avoidance.weight, …).
pub fn param_names() -> Vec<String> {
    FORCES
        .iter()
        .flat_map(|f| FIELDS.iter().map(move |p| format!("{f}.{p}")))
        .collect()
}

/// The vector indices of parameters given by name (`cohesion.angular`, …); an unknown name is an
/// error naming the config key `key`.
pub fn indices_of(names: &[String], key: &str) -> Result<Vec<usize>> {
    let all = param_names();
    names
        .iter()
        .map(|n| {
            all.iter().position(|m| m == n).ok_or_else(|| {
                Error::config(
                    key,
                    format!("'{n}' is not a parameter (one of {})", all.join(", ")),
                )
            })
        })
        .collect()
}

/// Lower clamp of the radial and angular parameters (DESIGN §4): a zero range would divide by 0.
pub const MIN_RANGE: f64 = 1e-3;

/// One force's normalised parameters, each in [0, 1]: `W_F = weight`, `R_F = radial · R_perc`,
/// `Φ_F = angular · π` (eq. 3–4).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ForceParams {
    pub weight: f64,
    pub radial: f64,
    pub angular: f64,
}

/// The four forces of eq. 3.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Forces {
    pub cohesion: ForceParams,
    pub avoidance: ForceParams,
    pub alignment: ForceParams,
    pub obstacle: ForceParams,
}

/// Fixed constants of a run (not optimised).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct Constants {
    /// Perception radius R_perc (BL).
    pub perception_radius: f64,
    /// Sensitivity Ω of eq. 3.
    pub sensitivity: f64,
    /// Half-length of the body capsule used for occlusion (BL).
    pub capsule_half_length: f64,
    /// Radius of the body capsule (BL).
    pub capsule_radius: f64,
    /// Half-angle of the leader rule's front cone (degrees).
    pub leader_cone_deg: f64,
    /// An agent with at most this many visible neighbours in its front cone is a leader (§5.1).
    pub leader_max_neighbours: u32,
    /// Occlusion-aware perception (§5.3); off reproduces the ablation of §7.2.1.
    pub occlusion: bool,
    /// Width cap of the padded neighbour lists (nearest visible neighbours kept).
    pub max_neighbours: usize,
    /// Width cap of the obstacle-point lists.
    pub max_obstacles: usize,
}

impl Default for Constants {
    fn default() -> Self {
        Constants {
            perception_radius: 4.0,
            sensitivity: 10.0,
            capsule_half_length: 0.3,
            capsule_radius: 0.2,
            leader_cone_deg: 60.0,
            leader_max_neighbours: 2,
            occlusion: true,
            max_neighbours: 32,
            max_obstacles: 16,
        }
    }
}

/// Speed model of eq. 6 and §6.2: an Ornstein–Uhlenbeck process around `mean` (or around the
/// speed–density table's value at the agent's local density), noise `std`, capped at `max`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpeedModel {
    /// v_μ (BL/s).
    pub mean: f64,
    /// v_σ (BL/s).
    pub std: f64,
    /// v_max (BL/s).
    pub max: f64,
    /// Mean-reversion rate θ_OU (1/s).
    #[serde(default = "one")]
    pub reversion: f64,
    /// `[density (agents/BL²), mean speed (BL/s)]` rows, density increasing.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub density_table: Option<Vec<[f64; 2]>>,
}

fn one() -> f64 {
    1.0
}

impl Default for SpeedModel {
    fn default() -> Self {
        SpeedModel {
            mean: 1.0,
            std: 0.2,
            max: 3.0,
            reversion: 1.0,
            density_table: None,
        }
    }
}

impl SpeedModel {
    /// Standard deviation of the speeds the OU process of eq. 6 settles to around its mean,
    /// v_σ / √(2 θ_OU) (the stationary spread; `std` is the noise v_σ). New agents draw their
    /// speed from this spread.
    pub fn stationary_std(&self) -> f64 {
        if self.reversion > 0.0 {
            self.std / (2.0 * self.reversion).sqrt()
        } else {
            self.std
        }
    }

    /// The speed model of a clip (stage 2, §6.2) for a parameter set whose model is `base`: the
    /// clip's mean, spread and speed–density table, `base`'s reversion rate, and a cap of at least
    /// `base.max`.
    pub fn of_clip(clip: &ClipFields, base: &SpeedModel) -> SpeedModel {
        let s = &clip.meta.speed;
        SpeedModel {
            mean: s.mean,
            // The clip measures the spread of speeds, which for the OU process of eq. 6 is
            // v_σ / √(2 θ_OU): the noise that reproduces it is v_σ = spread · √(2 θ_OU).
            std: if base.reversion > 0.0 {
                s.std * (2.0 * base.reversion).sqrt()
            } else {
                s.std
            },
            max: base.max.max(s.mean + 4.0 * s.std),
            reversion: base.reversion,
            density_table: (!s.density_table.is_empty()).then(|| s.density_table.clone()),
        }
    }

    /// The speed cap where a zone fixes the mean speed at `fixed` (§7.2.4): `max`, or more when
    /// the zone's speed lies above it, leaving it the room of 4 stationary STDs.
    pub fn cap_with_fixed(&self, fixed: f64) -> f64 {
        self.max.max(fixed + 4.0 * self.stationary_std())
    }

    /// v_μ(ρ): linear interpolation in the speed–density table, clamped at its ends; the global
    /// mean when there is no table (eq. 6, §6.2).
    pub fn mean_at(&self, density: f64) -> f64 {
        match self.density_table.as_deref() {
            None | Some([]) => self.mean,
            Some(t) => {
                if density <= t[0][0] {
                    return t[0][1];
                }
                for w in t.windows(2) {
                    if density <= w[1][0] {
                        let span = w[1][0] - w[0][0];
                        let a = if span > 0.0 {
                            (density - w[0][0]) / span
                        } else {
                            1.0
                        };
                        return w[0][1] + a * (w[1][1] - w[0][1]);
                    }
                }
                t[t.len() - 1][1]
            }
        }
    }
}

/// A complete parameter set.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Params {
    pub schema: String,
    pub forces: Forces,
    #[serde(default)]
    pub constants: Constants,
    #[serde(default)]
    pub speed: SpeedModel,
    /// Physical values derived from the normalised ones (written for readers; ignored on load).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub physical: Option<serde_json::Value>,
    /// Where the set came from (clip, frames, command, losses …); free-form.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<serde_json::Value>,
    /// What the fitting clip determines at these values (issue #15 item 2, written by `fit`):
    /// standard errors, eigen-directions and the objective's noise
    /// ([`crate::herd::fit::identify()`]; the format: [`crate::herd::uncertainty`]). Absent in
    /// older files, and not written when absent.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub uncertainty: Option<crate::herd::uncertainty::Uncertainty>,
}

impl Default for Params {
    /// The built-in parameter set: a cohesive, aligned herd with short-range avoidance.
    fn default() -> Self {
        let f = |weight, radial, angular| ForceParams {
            weight,
            radial,
            angular,
        };
        Params {
            schema: SCHEMA.into(),
            forces: Forces {
                cohesion: f(0.3, 0.6, 0.7),
                avoidance: f(0.6, 0.2, 0.6),
                alignment: f(0.5, 0.5, 0.5),
                obstacle: f(0.7, 0.3, 0.5),
            },
            constants: Constants::default(),
            speed: SpeedModel::default(),
            physical: None,
            provenance: None,
            uncertainty: None,
        }
    }
}

impl Params {
    /// A generic starting point for fitting: every normalised value at 0.5, default constants and
    /// speed model.
    pub fn neutral() -> Params {
        Params::default().with_vec(&[0.5; N_PARAMS])
    }

    /// The 12 normalised values in [`param_names`] order.
    pub fn to_vec(&self) -> [f64; N_PARAMS] {
        let f = &self.forces;
        let mut v = [0.0; N_PARAMS];
        for (g, fp) in [f.cohesion, f.avoidance, f.alignment, f.obstacle]
            .iter()
            .enumerate()
        {
            v[3 * g] = fp.weight;
            v[3 * g + 1] = fp.radial;
            v[3 * g + 2] = fp.angular;
        }
        v
    }

    /// A copy with the 12 normalised values replaced (in [`param_names`] order), without an
    /// `uncertainty` (it belonged to the old values).
    pub fn with_vec(&self, v: &[f64; N_PARAMS]) -> Params {
        let fp = |g: usize| ForceParams {
            weight: v[3 * g],
            radial: v[3 * g + 1],
            angular: v[3 * g + 2],
        };
        Params {
            forces: Forces {
                cohesion: fp(0),
                avoidance: fp(1),
                alignment: fp(2),
                obstacle: fp(3),
            },
            // An uncertainty describes the values it was estimated at.
            uncertainty: None,
            ..self.clone()
        }
    }

    /// Clamps a parameter vector to its valid box: weights to [0, 1], ranges to [1e-3, 1].
    pub fn clamp_vec(v: &mut [f64; N_PARAMS]) {
        for (i, x) in v.iter_mut().enumerate() {
            let lo = if i % 3 == 0 { 0.0 } else { MIN_RANGE };
            *x = x.clamp(lo, 1.0);
        }
    }

    /// Checks every value; the message names the offending key.
    pub fn validate(&self) -> Result<()> {
        crate::data::check_schema(&self.schema, SCHEMA).map_err(Error::invalid)?;
        for (name, v) in param_names().iter().zip(self.to_vec()) {
            let lo = if name.ends_with("weight") {
                0.0
            } else {
                MIN_RANGE
            };
            if !v.is_finite() || v < lo || v > 1.0 {
                return Err(Error::invalid(format!(
                    "forces.{name} = {v} is outside [{lo}, 1]"
                )));
            }
        }
        let c = &self.constants;
        let positive = [
            ("perception_radius", c.perception_radius),
            ("sensitivity", c.sensitivity),
            ("capsule_radius", c.capsule_radius),
        ];
        for (k, v) in positive {
            if !v.is_finite() || v <= 0.0 || v > crate::limits::MAX_COORD {
                return Err(Error::invalid(format!(
                    "constants.{k} = {v} must be in (0, {}]",
                    crate::limits::MAX_COORD
                )));
            }
        }
        if !c.capsule_half_length.is_finite() || c.capsule_half_length < 0.0 {
            return Err(Error::invalid(format!(
                "constants.capsule_half_length = {} must be ≥ 0",
                c.capsule_half_length
            )));
        }
        if !(0.0..=180.0).contains(&c.leader_cone_deg) {
            return Err(Error::invalid(format!(
                "constants.leader_cone_deg = {} is outside [0, 180]",
                c.leader_cone_deg
            )));
        }
        if c.max_neighbours == 0 || c.max_obstacles == 0 {
            return Err(Error::invalid(
                "constants.max_neighbours and constants.max_obstacles must be ≥ 1",
            ));
        }
        let s = &self.speed;
        for (k, v) in [
            ("mean", s.mean),
            ("std", s.std),
            ("max", s.max),
            ("reversion", s.reversion),
        ] {
            if !(0.0..=crate::limits::MAX_SPEED).contains(&v) {
                return Err(Error::invalid(format!(
                    "speed.{k} = {v} must be in [0, {}]",
                    crate::limits::MAX_SPEED
                )));
            }
        }
        if s.max <= 0.0 {
            return Err(Error::invalid("speed.max must be > 0"));
        }
        if let Some(t) = &s.density_table {
            for (r, row) in t.iter().enumerate() {
                let sane = |v: f64| v.is_finite() && (0.0..=crate::limits::MAX_SPEED).contains(&v);
                if !sane(row[0]) || !sane(row[1]) {
                    return Err(Error::invalid(format!(
                        "speed.density_table[{r}] = {row:?} must be finite and ≥ 0"
                    )));
                }
                if r > 0 && row[0] < t[r - 1][0] {
                    return Err(Error::invalid(format!(
                        "speed.density_table[{r}]: densities must increase"
                    )));
                }
            }
        }
        Ok(())
    }

    /// Physical values of the forces (W, R in BL, Φ in degrees), for readers of exported files.
    pub fn physical_values(&self) -> serde_json::Value {
        let r = self.constants.perception_radius;
        let v = self.to_vec();
        let mut m = serde_json::Map::new();
        for (g, f) in FORCES.iter().enumerate() {
            m.insert(
                f.to_string(),
                serde_json::json!({
                    "weight": v[3 * g],
                    "radius_bl": v[3 * g + 1] * r,
                    "angle_deg": v[3 * g + 2] * 180.0,
                }),
            );
        }
        serde_json::Value::Object(m)
    }

    /// Reads and validates a parameter file.
    pub fn load(path: &Path) -> Result<Params> {
        crate::data::atomic::note_input(path);
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let p: Params = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a herdfit.params/1 file: {e}")))?;
        p.validate().map_err(|e| e.in_file(path))?;
        Ok(p)
    }

    /// Writes the set (with its physical values) atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.validate()?;
        let mut out = self.clone();
        out.physical = Some(self.physical_values());
        let text = serde_json::to_string_pretty(&out)
            .map_err(|e| Error::Internal(format!("serialising parameters: {e}")))?;
        write_atomic(path, format!("{text}\n").as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn vector_round_trip_and_names() {
        let p = Params::default();
        let v = p.to_vec();
        assert_eq!(p.with_vec(&v), p);
        let names = param_names();
        assert_eq!(names.len(), 12);
        assert_eq!(names[0], "cohesion.weight");
        assert_eq!(names[5], "avoidance.angular");
        assert_eq!(names[11], "obstacle.angular");
        assert_eq!(v[4], p.forces.avoidance.radial);
    }

    #[test]
    fn minimal_file_parses_with_defaults() {
        let text = r#"{"schema": "herdfit.params/1", "forces": {
            "cohesion": {"weight": 0.1, "radial": 0.2, "angular": 0.3},
            "avoidance": {"weight": 0.4, "radial": 0.5, "angular": 0.6},
            "alignment": {"weight": 0.7, "radial": 0.8, "angular": 0.9},
            "obstacle": {"weight": 1.0, "radial": 0.5, "angular": 0.5}},
            "speed": {"mean": 1.2, "std": 0.1, "max": 2.0}}"#;
        let p: Params = serde_json::from_str(text).unwrap();
        p.validate().unwrap();
        assert_eq!(p.constants, Constants::default());
        assert_eq!(p.speed.reversion, 1.0);
        assert_eq!(p.to_vec()[7], 0.8);
    }

    #[test]
    fn unknown_keys_and_out_of_range_are_rejected() {
        let bad = r#"{"schema": "herdfit.params/1", "forces": {
            "cohesion": {"weight": 0.1, "radial": 0.2, "angular": 0.3, "colour": 1},
            "avoidance": {"weight": 0.4, "radial": 0.5, "angular": 0.6},
            "alignment": {"weight": 0.7, "radial": 0.8, "angular": 0.9},
            "obstacle": {"weight": 1.0, "radial": 0.5, "angular": 0.5}}}"#;
        let e = serde_json::from_str::<Params>(bad).unwrap_err().to_string();
        assert!(e.contains("colour"), "{e}");
        let mut p = Params::default();
        p.forces.alignment.radial = 1.5;
        let e = p.validate().unwrap_err().to_string();
        assert!(e.contains("alignment.radial"), "{e}");
        p.forces.alignment.radial = f64::NAN;
        assert!(p.validate().is_err());
        let mut p = Params::default();
        p.speed.density_table = Some(vec![[1.0, 1.0], [0.5, 1.0]]);
        assert!(p.validate().unwrap_err().to_string().contains("increase"));
    }

    #[test]
    fn speed_table_interpolates_and_clamps() {
        let s = SpeedModel {
            density_table: Some(vec![[0.0, 2.0], [1.0, 1.0], [2.0, 0.5]]),
            ..SpeedModel::default()
        };
        assert_eq!(s.mean_at(-1.0), 2.0);
        assert_eq!(s.mean_at(0.5), 1.5);
        assert_eq!(s.mean_at(1.5), 0.75);
        assert_eq!(s.mean_at(9.0), 0.5);
        assert_eq!(SpeedModel::default().mean_at(3.0), 1.0);
    }

    #[test]
    fn clamp_keeps_ranges_positive() {
        let mut v = [-1.0; 12];
        Params::clamp_vec(&mut v);
        assert_eq!(v[0], 0.0);
        assert_eq!(v[1], MIN_RANGE);
        let mut v = [2.0; 12];
        Params::clamp_vec(&mut v);
        assert!(v.iter().all(|&x| x == 1.0));
    }
}
