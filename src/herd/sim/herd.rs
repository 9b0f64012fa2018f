//! Built-in random herds.

use super::World;
use crate::data::agents::AgentRow;
use crate::error::{Error, Result};
use crate::herd::params::SpeedModel;
use rand::{Rng, SeedableRng};
use rand_distr::StandardNormal;

/// A random herd: `agents` agents uniform in a square of area `agents / density` centred at
/// `centre`, headings `heading_deg` ± a normal spread, speeds from the speed model.
#[derive(Clone, Debug, PartialEq)]
pub struct HerdSpec {
    pub agents: usize,
    /// Agents per BL² (the benchmarks' standard herd uses 0.5: one agent per 2 BL²).
    pub density: f64,
    pub centre: [f64; 2],
    pub heading_deg: f64,
    /// Standard deviation of the headings (degrees); infinite: headings uniform on the circle
    /// (randomly aligned agents, as in a still of resting animals, paper §7.2.4).
    pub heading_spread_deg: f64,
}

impl HerdSpec {
    /// The standard herd: one agent per 2 BL² around the origin, heading +x ± 20°.
    pub fn standard(agents: usize) -> Self {
        HerdSpec {
            agents,
            density: 0.5,
            centre: [0.0, 0.0],
            heading_deg: 0.0,
            heading_spread_deg: 20.0,
        }
    }

    /// Side of the square the herd fills (BL).
    pub fn side(&self) -> f64 {
        (self.agents as f64 / self.density).sqrt()
    }
}

/// Samples a herd (ids 0..N) with a seeded ChaCha8 generator; positions inside obstacle cells of
/// `world` are re-drawn.
pub fn random_herd(
    spec: &HerdSpec,
    speed: &SpeedModel,
    world: &World,
    seed: u64,
) -> Result<Vec<AgentRow>> {
    if spec.agents == 0 {
        return Err(Error::config("agents", "the herd is empty: must be ≥ 1"));
    }
    if !(spec.density.is_finite() && spec.density > 0.0) {
        return Err(Error::invalid("herd density must be > 0"));
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let side = spec.side();
    let mut rows = Vec::with_capacity(spec.agents);
    let mut tries = 0usize;
    while rows.len() < spec.agents {
        tries += 1;
        if tries > 1000 * spec.agents + 1000 {
            return Err(Error::invalid(
                "cannot place the herd: its square is covered by obstacles",
            ));
        }
        let x = spec.centre[0] + (rng.gen::<f64>() - 0.5) * side;
        let y = spec.centre[1] + (rng.gen::<f64>() - 0.5) * side;
        if world.in_obstacle([x, y]) {
            continue;
        }
        let z: f64 = rng.sample(StandardNormal);
        let a = match spec.heading_spread_deg.is_infinite() {
            true => (rng.gen::<f64>() * 2.0 - 1.0) * std::f64::consts::PI,
            false => (spec.heading_deg + spec.heading_spread_deg * z).to_radians(),
        };
        let zs: f64 = rng.sample(StandardNormal);
        let s = (speed.mean + speed.std * zs).clamp(0.0, speed.max);
        rows.push(AgentRow {
            id: rows.len() as u64,
            x,
            y,
            vx: s * a.cos(),
            vy: s * a.sin(),
        });
    }
    Ok(rows)
}
