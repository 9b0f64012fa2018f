//! `herdfit bench`: wall time per step of simulation and of forward + backward through unrolled
//! steps on the standard random herd, and the process's peak resident memory.

use crate::backend::{device, Compute, Precision};
use crate::data::agents::AgentRow;
use crate::data::atomic::{check_writable, write_atomic};
use crate::error::Result;
use crate::herd::params::N_PARAMS;
use crate::herd::scenario::{bench_model, objective};
use crate::herd::sim::{theta_tensor, Decide, ForceKernel, HerdState, Model};
use crate::progress::Progress;
use burn::tensor::Device;
use rand::SeedableRng;
use serde::Serialize;
use std::path::Path;
use std::time::Instant;

/// Schema tag of benchmark reports.
pub const BENCH_SCHEMA: &str = "herdfit.bench/1";

/// The JSON written by `herdfit bench`.
#[derive(Clone, Debug, Serialize)]
pub struct BenchReport {
    /// [`BENCH_SCHEMA`].
    pub schema: String,
    pub agents: usize,
    pub steps: usize,
    pub sim_ms_per_step: f64,
    /// Forward + backward with every step's decisions (perception with occlusion, roles, noise)
    /// made live inside the timed pass.
    pub grad_ms_per_step: Option<f64>,
    /// Forward + backward replaying decisions recorded by an untimed no-gradient run of the same
    /// steps, as `fit` does after its plan (and as the JAX peer does with precomputed lists).
    pub replay_grad_ms_per_step: Option<f64>,
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
    /// Where the tensors lived (not written when `cpu`).
    #[serde(skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
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
/// `repeats` forward + backward passes through `steps` unrolled steps (median per step) with live
/// decisions, and as many replaying recorded ones, with the forces computed by `force_kernel`.
pub fn run_bench(cfg: &BenchConfig, mut progress: impl FnMut()) -> Result<BenchReport> {
    let BenchConfig {
        agents,
        steps,
        sim_only,
        repeats,
        checkpointing,
        force_kernel,
        device: compute,
    } = cfg.clone();
    if steps == 0 {
        return Err(crate::Error::config("steps", "must be ≥ 1"));
    }
    let device = device(compute, Precision::F32)?;
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
    let mut grad = |replay: bool| -> Result<Option<f64>> {
        if sim_only {
            return Ok(None);
        }
        let pass = GradPass {
            model: &model,
            theta: &theta_v,
            init: &init,
            steps,
            checkpointing,
            replay,
        };
        let mut per_step = Vec::with_capacity(repeats);
        for r in 0..repeats.max(1) {
            per_step.push(pass.time(3 + r as u64, &device)?);
            progress();
        }
        Ok(Some(median(per_step)))
    };
    let grad_ms_per_step = grad(false)?;
    let replay_grad_ms_per_step = grad(true)?;
    Ok(BenchReport {
        schema: BENCH_SCHEMA.into(),
        agents,
        steps,
        sim_ms_per_step,
        grad_ms_per_step,
        replay_grad_ms_per_step,
        peak_rss_mb: peak_rss_mb(),
        precision: Precision::F32,
        occlusion: model.params.constants.occlusion,
        mean_neighbours,
        k,
        checkpointing,
        force_kernel,
        device: compute,
    })
}

/// One timed forward + backward pass through `steps` unrolled steps from `init`.
struct GradPass<'a> {
    model: &'a Model,
    theta: &'a [f64; N_PARAMS],
    init: &'a [AgentRow],
    steps: usize,
    checkpointing: bool,
    /// Replay decisions recorded (untimed) by a no-gradient run with the same seed.
    replay: bool,
}

impl GradPass<'_> {
    /// Milliseconds per step of one pass whose live decisions draw from `seed`.
    fn time(&self, seed: u64, device: &Device) -> Result<f64> {
        let m = self.model;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let recording = if self.replay {
            let th = theta_tensor(self.theta, device);
            Some(m.record(&th, self.init, self.steps, &mut rng)?)
        } else {
            None
        };
        let ad = if self.checkpointing {
            device.clone().autodiff().gradient_checkpointing()
        } else {
            device.clone().autodiff()
        };
        let t0 = Instant::now();
        let th = theta_tensor(self.theta, &ad).require_grad();
        let s = HerdState::from_rows(self.init, &ad);
        let decide = match &recording {
            Some(rec) => Decide::Replay(rec),
            None => Decide::Live {
                rng: &mut rng,
                record: None,
            },
        };
        let end = m.rollout(&th, s, self.steps, decide, |_, _, _| Ok(()))?;
        let grads = objective(&end, m.params.constants.perception_radius).backward();
        if th.grad(&grads).map(|g| g.into_data()).is_none() {
            return Err(crate::Error::Internal("no gradient in benchmark".into()));
        }
        Ok(t0.elapsed().as_secs_f64() * 1e3 / self.steps as f64)
    }
}

/// Settings of a benchmark.
#[derive(Clone, Debug, PartialEq, Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct BenchConfig {
    pub agents: usize,
    pub steps: usize,
    /// Skip the forward + backward measurement.
    pub sim_only: bool,
    /// Forward + backward repetitions (median reported).
    pub repeats: usize,
    /// burn's balanced gradient checkpointing in the backward pass.
    pub checkpointing: bool,
    /// Which implementation computes the forces of eq. 3–5 (on the GPU always the tensor ops).
    pub force_kernel: ForceKernel,
    /// Where the tensors live.
    #[serde(skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
}

impl Default for BenchConfig {
    fn default() -> Self {
        BenchConfig {
            agents: 1500,
            steps: 20,
            sim_only: false,
            repeats: 3,
            checkpointing: false,
            force_kernel: ForceKernel::Fused,
            device: Compute::Cpu,
        }
    }
}

impl BenchConfig {
    /// Checks the herd and the steps; errors name the key.
    pub fn check(&self) -> Result<()> {
        if self.agents == 0 {
            return Err(crate::Error::config(
                "agents",
                "the herd is empty: must be ≥ 1",
            ));
        }
        if self.steps == 0 {
            return Err(crate::Error::config("steps", "must be ≥ 1"));
        }
        if self.repeats == 0 && !self.sim_only {
            return Err(crate::Error::config("repeats", "0 must be ≥ 1"));
        }
        use crate::limits::{check_count, MAX_AGENTS, MAX_RUNS, MAX_STEPS};
        check_count("agents", self.agents, MAX_AGENTS)?;
        check_count("steps", self.steps, MAX_STEPS)?;
        check_count("repeats", self.repeats, MAX_RUNS)?;
        Ok(())
    }
}

/// Runs the benchmark ([`run_bench`]) and writes its JSON report to `json`.
pub fn run(cfg: &BenchConfig, json: &Path, progress: &mut dyn Progress) -> Result<BenchReport> {
    cfg.check()?;
    check_writable(json)?;
    let total = cfg.steps
        + 1
        + if cfg.sim_only {
            0
        } else {
            2 * cfg.repeats.max(1)
        };
    progress.start("bench", total as u64);
    let r = run_bench(cfg, || progress.inc(1))?;
    progress.finish();
    let text = serde_json::to_string_pretty(&r)
        .map_err(|e| crate::Error::Internal(format!("serialising report: {e}")))?;
    write_atomic(json, format!("{text}\n").as_bytes())?;
    Ok(r)
}

impl std::fmt::Display for BenchReport {
    /// The line `herdfit bench` prints.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "bench: {} agents, {} steps on the {}: simulation {:.3} ms/step{}{}, peak RSS {:.1} MB (K = {}, {:.1} visible neighbours/agent)",
            self.agents,
            self.steps,
            self.device,
            self.sim_ms_per_step,
            self.grad_ms_per_step
                .map_or(String::new(), |g| format!(", forward+backward {g:.3} ms/step")),
            self.replay_grad_ms_per_step.map_or(String::new(), |g| format!(
                " (replaying recorded decisions {g:.3} ms/step)"
            )),
            self.peak_rss_mb,
            self.k,
            self.mean_neighbours
        )
    }
}
