//! The scenes that the gradient check and the benchmark unroll: a herd, its surroundings and a
//! time step, and the documented scalar objective of a run (DESIGN §7).

use crate::data::AgentRow;
use crate::error::Result;
use crate::herd::params::Params;
use crate::herd::sim::{random_herd, Guidance, HerdSpec, HerdState, Model, World};
use burn::tensor::Tensor;
use herdfit_kernels::ObstacleMap;

/// A herd, its surroundings and a time step: what a gradient check (or a benchmark) unrolls.
#[derive(Clone, Debug)]
pub struct Scenario {
    pub model: Model,
    pub init: Vec<AgentRow>,
}

/// The default scenario: `agents` agents (one per 2 BL², heading +x ± 20°) on a 2-BL grid with two
/// obstacle blocks inside the herd and a uniform guidance direction, so that all four forces and
/// the leader rule take part. 25 fps.
pub fn default_scenario(params: Params, agents: usize, seed: u64) -> Result<Scenario> {
    let spec = HerdSpec::standard(agents);
    let half = spec.side() / 2.0;
    let cell = 2.0;
    let n = ((2.0 * half + 8.0) / cell).ceil() as usize;
    let origin = [-(n as f64) * cell / 2.0; 2];
    let mut map = ObstacleMap::empty(origin, cell, n, n);
    // A 1×2 block ahead of the herd's centre and a single cell behind-left of it.
    let mut block = |x: f64, y: f64| {
        if let Some((ix, iy)) = map.cell_of([x, y]) {
            map.blocked[iy * n + ix] = true;
        }
    };
    block(0.4 * half, 0.1);
    block(0.4 * half, -cell + 0.1);
    block(-0.5 * half, 0.5 * half);
    let world = World {
        obstacles: Some(map),
        guidance: Guidance::Uniform([0.98, 0.2]),
        fixed_speed: None,
    };
    let init = random_herd(&spec, &params.speed, &world, seed)?;
    Ok(Scenario {
        model: Model {
            params,
            world,
            dt: 1.0 / 25.0,
            force_kernel: crate::herd::sim::ForceKernel::default(),
        },
        init,
    })
}

/// The documented objective of `gradcheck`, on the final state of the unrolled run:
///
/// J(θ) = (1/N) Σ_i ‖p_i − p̄‖² / R_perc² + (1/N) Σ_i ⟨d_i, ĝ⟩,
///
/// the herd's spread (shaped by cohesion, avoidance and obstacles) plus the mean heading along
/// ĝ = (0.6, 0.8) (shaped by alignment and obstacles). Returns a `[1]` tensor.
pub fn objective(s: &HerdState, perception_radius: f64) -> Tensor<1> {
    let cx = s.x.clone().mean();
    let cy = s.y.clone().mean();
    let spread = ((s.x.clone() - cx).square() + (s.y.clone() - cy).square())
        .mean()
        .div_scalar(perception_radius * perception_radius);
    let heading = (s.hx.clone().mul_scalar(0.6) + s.hy.clone().mul_scalar(0.8)).mean();
    spread + heading
}

/// The benchmark scene: the standard herd (one agent per 2 BL²), default parameters, occlusion on,
/// a uniform guidance direction (so the leader rule is active), 25 fps.
pub fn bench_model(
    agents: usize,
    seed: u64,
) -> Result<(Model, Vec<crate::data::agents::AgentRow>)> {
    let params = Params::default();
    let world = World {
        obstacles: None,
        guidance: Guidance::Uniform([1.0, 0.0]),
        fixed_speed: None,
    };
    let init = random_herd(&HerdSpec::standard(agents), &params.speed, &world, seed)?;
    Ok((
        Model {
            params,
            world,
            dt: 1.0 / 25.0,
            force_kernel: crate::herd::sim::ForceKernel::default(),
        },
        init,
    ))
}
