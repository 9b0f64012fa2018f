//! `herdfit bench`: wall time per step of simulation and of forward + backward through unrolled
//! steps on the standard random herd, and the process's peak resident memory.

use crate::backend::{cpu_device, Precision};
use crate::error::Result;
use crate::params::Params;
use crate::sim::{
    random_herd, theta_tensor, Decide, ForceKernel, Guidance, HerdSpec, HerdState, Model, World,
};
use crate::train::gradcheck::objective;
use rand::SeedableRng;
use serde::Serialize;
use std::time::Instant;

/// The JSON written by `herdfit bench`.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    pub agents: usize,
    pub steps: usize,
    pub sim_ms_per_step: f64,
    pub grad_ms_per_step: Option<f64>,
    pub peak_rss_mb: f64,
    pub precision: Precision,
    pub occlusion: bool,
    /// Mean visible neighbours per agent and the padded list width K, at the first step.
    pub mean_neighbours: f64,
    pub k: usize,
    /// burn's balanced gradient checkpointing was on for the forward+backward pass.
    pub checkpointing: bool,
    /// Which implementation computed the forces of eq. 3–5.
    pub force_kernel: ForceKernel,
}

/// The benchmark scene: the standard herd (one agent per 2 BL²), default parameters, occlusion on,
/// a uniform guidance direction (so the leader rule is active), 25 fps.
pub fn bench_model(agents: usize, seed: u64) -> Result<(Model, Vec<crate::io::AgentRow>)> {
    let params = Params::default();
    let world = World {
        obstacles: None,
        guidance: Guidance::Uniform([1.0, 0.0]),
    };
    let init = random_herd(&HerdSpec::standard(agents), &params.speed, &world, seed)?;
    Ok((
        Model {
            params,
            world,
            dt: 1.0 / 25.0,
            force_kernel: crate::sim::ForceKernel::default(),
        },
        init,
    ))
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Peak resident set size of this process (MB), from /proc (0 where unavailable).
pub fn peak_rss_mb() -> f64 {
    std::fs::read_to_string("/proc/self/status")
        .ok()
        .and_then(|s| {
            s.lines()
                .find(|l| l.starts_with("VmHWM:"))
                .and_then(|l| l.split_whitespace().nth(1)?.parse::<f64>().ok())
        })
        .map_or(0.0, |kb| kb / 1024.0)
}

/// Runs the benchmark: `steps` live simulation steps (median per step), then, unless `sim_only`,
/// `repeats` forward + backward passes through `steps` unrolled steps (median per step), with
/// the forces computed by `force_kernel`.
pub fn run_bench(
    agents: usize,
    steps: usize,
    sim_only: bool,
    repeats: usize,
    checkpointing: bool,
    force_kernel: ForceKernel,
    mut progress: impl FnMut(),
) -> Result<BenchReport> {
    if steps == 0 {
        return Err(crate::Error::invalid("--steps must be ≥ 1"));
    }
    let device = cpu_device(Precision::F32)?;
    let (mut model, init) = bench_model(agents, 1)?;
    model.force_kernel = force_kernel;
    let theta_v = model.params.to_vec();
    let theta = theta_tensor(&theta_v, &device);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
    let state = HerdState::from_rows(&init, &device);
    let first = model.decide(&state.snapshot()?, &mut rng);
    let p = &first.perception;
    let mean_neighbours =
        p.neighbour_mask.iter().map(|&m| m as f64).sum::<f64>() / agents.max(1) as f64;
    let k = p.k;
    // Simulation: one untimed warm-up step, then each step timed on its own.
    let mut times = Vec::with_capacity(steps);
    let mut t0 = Instant::now();
    model.rollout(
        &theta,
        state,
        steps + 1,
        Decide::Live {
            rng: &mut rng,
            record: None,
        },
        |t, _, s| {
            // Reading one value back waits for the step to finish on any backend.
            let _ = s.x.clone().narrow(0, 0, 1).into_data();
            if t > 0 {
                times.push(t0.elapsed().as_secs_f64() * 1e3);
            }
            progress();
            t0 = Instant::now();
            Ok(())
        },
    )?;
    let sim_ms_per_step = median(times);
    let grad_ms_per_step = if sim_only {
        None
    } else {
        let ad = if checkpointing {
            device.clone().autodiff().gradient_checkpointing()
        } else {
            device.clone().autodiff()
        };
        let mut per_step = Vec::with_capacity(repeats);
        for r in 0..repeats.max(1) {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3 + r as u64);
            let t0 = Instant::now();
            let th = theta_tensor(&theta_v, &ad).require_grad();
            let s = HerdState::from_rows(&init, &ad);
            let end = model.rollout(
                &th,
                s,
                steps,
                Decide::Live {
                    rng: &mut rng,
                    record: None,
                },
                |_, _, _| Ok(()),
            )?;
            let grads = objective(&end, model.params.constants.perception_radius).backward();
            let g = th.grad(&grads).map(|g| g.into_data());
            if g.is_none() {
                return Err(crate::Error::Internal("no gradient in benchmark".into()));
            }
            per_step.push(t0.elapsed().as_secs_f64() * 1e3 / steps as f64);
            progress();
        }
        Some(median(per_step))
    };
    Ok(BenchReport {
        agents,
        steps,
        sim_ms_per_step,
        grad_ms_per_step,
        peak_rss_mb: peak_rss_mb(),
        precision: Precision::F32,
        occlusion: model.params.constants.occlusion,
        mean_neighbours,
        k,
        checkpointing,
        force_kernel,
    })
}
