//! Gradient check (DESIGN §7): the gradient of a scalar objective of an unrolled run with respect
//! to all 12 parameters, by reverse-mode autodiff and by central finite differences with the
//! same (replayed) perception, roles and noise.

use crate::backend::{cpu_device, Precision};
use crate::error::{Error, Result};
use crate::io::AgentRow;
use crate::params::{param_names, Params, N_PARAMS};
use crate::sim::{
    random_herd, read_vec, theta_tensor, Decide, Guidance, HerdSpec, HerdState, Model, Recording,
    World,
};
use burn::tensor::{Device, Tensor};
use herdfit_kernels::ObstacleMap;
use rand::SeedableRng;
use serde::Serialize;

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
    };
    let init = random_herd(&spec, &params.speed, &world, seed)?;
    Ok(Scenario {
        model: Model {
            params,
            world,
            dt: 1.0 / 25.0,
            force_kernel: crate::sim::ForceKernel::default(),
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

/// Records the decisions of `steps` live steps at the scenario's parameters.
pub fn record(sc: &Scenario, steps: usize, seed: u64, device: &Device) -> Result<Recording> {
    let theta = theta_tensor(&sc.model.params.to_vec(), device);
    let state = HerdState::from_rows(&sc.init, device);
    let mut rec = Recording::new(sc.init.len());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    sc.model.rollout(
        &theta,
        state,
        steps,
        Decide::Live {
            rng: &mut rng,
            record: Some(&mut rec),
        },
        |_, _, _| Ok(()),
    )?;
    Ok(rec)
}

/// J(θ) with replayed decisions, no gradient.
pub fn objective_value(
    sc: &Scenario,
    theta: &[f64; N_PARAMS],
    rec: &Recording,
    steps: usize,
    device: &Device,
) -> Result<f64> {
    let state = HerdState::from_rows(&sc.init, device);
    let t = theta_tensor(theta, device);
    let end = sc.model.rollout::<rand_chacha::ChaCha8Rng>(
        &t,
        state,
        steps,
        Decide::Replay(rec),
        |_, _, _| Ok(()),
    )?;
    Ok(read_vec(&objective(
        &end,
        sc.model.params.constants.perception_radius,
    ))?[0])
}

/// ∇J by reverse-mode autodiff through the unrolled steps (replayed decisions).
pub fn autodiff_gradient(
    sc: &Scenario,
    theta: &[f64; N_PARAMS],
    rec: &Recording,
    steps: usize,
    device: &Device,
) -> Result<(f64, [f64; N_PARAMS])> {
    let ad = device.clone().autodiff();
    let t = theta_tensor(theta, &ad).require_grad();
    let state = HerdState::from_rows(&sc.init, &ad);
    let end = sc.model.rollout::<rand_chacha::ChaCha8Rng>(
        &t,
        state,
        steps,
        Decide::Replay(rec),
        |_, _, _| Ok(()),
    )?;
    let j = objective(&end, sc.model.params.constants.perception_radius);
    let value = read_vec(&j.clone().detach())?[0];
    let grads = j.backward();
    let g = t
        .grad(&grads)
        .ok_or_else(|| Error::Internal("no gradient reached the parameters".into()))?;
    let g = read_vec(&g)?;
    let mut out = [0.0; N_PARAMS];
    out.copy_from_slice(&g);
    Ok((value, out))
}

/// ∂J/∂θ_p by the 4-point central difference
/// (8(J(θ+h) − J(θ−h)) − (J(θ+2h) − J(θ−2h))) / 12h, error O(h⁴).
pub fn finite_difference_gradient(
    sc: &Scenario,
    theta: &[f64; N_PARAMS],
    rec: &Recording,
    steps: usize,
    h: f64,
    device: &Device,
    mut progress: impl FnMut(),
) -> Result<[f64; N_PARAMS]> {
    let mut g = [0.0; N_PARAMS];
    for (p, gp) in g.iter_mut().enumerate() {
        let at = |off: f64| -> Result<f64> {
            let mut th = *theta;
            th[p] += off;
            objective_value(sc, &th, rec, steps, device)
        };
        let (p1, m1, p2, m2) = (at(h)?, at(-h)?, at(2.0 * h)?, at(-2.0 * h)?);
        *gp = (8.0 * (p1 - m1) - (p2 - m2)) / (12.0 * h);
        progress();
    }
    Ok(g)
}

/// One row of the gradcheck report.
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct GradRow {
    pub name: String,
    pub autodiff: f64,
    pub finite_difference: f64,
    pub rel_err: f64,
}

/// The gradcheck report (the JSON written by `herdfit gradcheck`).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct GradReport {
    pub steps: usize,
    pub agents: usize,
    pub precision: Precision,
    pub objective: f64,
    pub fd_step: f64,
    pub parameters: Vec<GradRow>,
    pub max_rel_err: f64,
}

/// Relative error |a − f| / max(|a|, |f|, 1e-12).
pub fn rel_err(a: f64, f: f64) -> f64 {
    (a - f).abs() / a.abs().max(f.abs()).max(1e-12)
}

/// Runs the check: records (or takes) the decisions, then autodiff and finite differences.
pub fn gradcheck(
    sc: &Scenario,
    steps: usize,
    precision: Precision,
    fd_step: f64,
    rec: &Recording,
    mut progress: impl FnMut(),
) -> Result<GradReport> {
    if !(fd_step.is_finite() && fd_step > 0.0) {
        return Err(Error::invalid("--fd-step must be > 0"));
    }
    let device = cpu_device(precision)?;
    let theta = sc.model.params.to_vec();
    let (value, ad) = autodiff_gradient(sc, &theta, rec, steps, &device)?;
    progress();
    let fd = finite_difference_gradient(sc, &theta, rec, steps, fd_step, &device, progress)?;
    let parameters: Vec<GradRow> = param_names()
        .into_iter()
        .enumerate()
        .map(|(p, name)| GradRow {
            name,
            autodiff: ad[p],
            finite_difference: fd[p],
            rel_err: rel_err(ad[p], fd[p]),
        })
        .collect();
    let max_rel_err = parameters.iter().map(|r| r.rel_err).fold(0.0, f64::max);
    if !max_rel_err.is_finite() || !value.is_finite() {
        return Err(Error::Internal(
            "the objective or a gradient is not finite".into(),
        ));
    }
    Ok(GradReport {
        steps,
        agents: sc.init.len(),
        precision,
        objective: value,
        fd_step,
        parameters,
        max_rel_err,
    })
}

/// The fit's loss as the objective: the mean over `steps` steps of the loss of `kind` — E_mean +
/// λ E_var (eq. 7–8), field matching + λ E_var, or the ensemble objective + λ E_var over
/// `replicas` herds — from herds initialised from the clip's frame `start`, with the planned
/// decisions and targets (perception, roles, noise, cells, U) recorded once per herd and replayed
/// for every evaluation.
pub struct LossScenario {
    pub model: Model,
    pub clip: crate::fields::ClipFields,
    pub start: usize,
    pub kind: super::fit::LossKind,
    /// One initial herd and one plan per replica.
    pub init: Vec<Vec<AgentRow>>,
    pub plans: Vec<Vec<(crate::sim::StepDecisions, super::loss::StepTarget)>>,
    pub var_weight: f64,
}

impl LossScenario {
    /// Plans `steps` steps from frame `start` of `clip` with the parameters `params`, for
    /// `replicas` herds (1 unless `kind` is the ensemble objective).
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        clip: &crate::fields::ClipFields,
        params: &Params,
        start: usize,
        steps: usize,
        beta: f64,
        var_weight: f64,
        (kind, replicas): (super::fit::LossKind, usize),
        seed: u64,
        device: &Device,
    ) -> Result<Self> {
        use super::fit::{guidance_fields, init_herd, plan_step, LossKind};
        if start + steps >= clip.frames() {
            return Err(Error::invalid(format!(
                "{steps} steps from frame {start} need {} frames; the clip has {}",
                start + steps + 1,
                clip.frames()
            )));
        }
        if (kind == LossKind::Ensemble) != (replicas >= 2) || replicas == 0 {
            return Err(Error::invalid(
                "the ensemble objective needs --replicas ≥ 2, the others one herd",
            ));
        }
        let mut params = params.clone();
        params.speed = clip.speed_model(&params.speed);
        let mut model = super::fit::clip_model(params, clip);
        let guidance = guidance_fields(clip, super::fit::GUIDANCE_SCALE);
        let stencil = super::target::Stencil::new(clip);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let theta = theta_tensor(&model.params.to_vec(), device);
        let f = crate::sim::ForceTensors::new(&theta, &model.params.constants);
        let (mut inits, mut all_plans) = (Vec::new(), Vec::new());
        for _ in 0..replicas {
            let init = init_herd(clip, start, &model.params.speed, &mut rng);
            if init.is_empty() {
                return Err(Error::invalid(format!(
                    "frame {start} of the clip holds no agents"
                )));
            }
            let mut state = HerdState::from_rows(&init, device);
            let mut plans = Vec::with_capacity(steps);
            for s in 0..steps {
                let plan = plan_step(
                    &mut model,
                    clip,
                    &guidance,
                    &stencil,
                    beta,
                    false,
                    &state,
                    start + s,
                    &mut rng,
                )?;
                state = model.step(&f, &state, &plan.0)?;
                plans.push(plan);
            }
            inits.push(init);
            all_plans.push(plans);
        }
        Ok(LossScenario {
            model,
            clip: clip.clone(),
            start,
            kind,
            init: inits,
            plans: all_plans,
            var_weight,
        })
    }

    fn loss(&self, theta: &[f64; N_PARAMS], device: &Device) -> Result<(Tensor<1>, Tensor<1>)> {
        use super::fit::{ensemble_loss, fields_loss, window_loss, LossKind};
        let t = theta_tensor(theta, device);
        let t = if device.is_autodiff() {
            t.require_grad()
        } else {
            t
        };
        let f = crate::sim::ForceTensors::new(&t, &self.model.params.constants);
        let k = self.init.len() as f64;
        let steps = self.plans[0].len();
        let mean_weight = if self.kind == LossKind::Paper {
            1.0
        } else {
            0.0
        };
        let mut total: Option<Tensor<1>> = None;
        let mut add = |l: Tensor<1>| super::fit::add(&mut total, l);
        let mut per_step: Vec<Vec<HerdState>> = vec![Vec::new(); steps];
        for (init, plans) in self.init.iter().zip(&self.plans) {
            let mut state = HerdState::from_rows(init, device);
            for (s, plan) in plans.iter().enumerate() {
                let (next, l, _, _) = window_loss(
                    &self.model,
                    &f,
                    state,
                    std::slice::from_ref(plan),
                    (mean_weight, self.var_weight),
                )?;
                state = next;
                add(l.div_scalar(k * steps as f64));
                match self.kind {
                    LossKind::Fields => add(fields_loss(&self.clip, &state, self.start + s + 1)?
                        .div_scalar(steps as f64)),
                    LossKind::Ensemble => per_step[s].push(state.clone()),
                    LossKind::Paper => {}
                }
            }
        }
        if self.kind == LossKind::Ensemble {
            for (s, states) in per_step.iter().enumerate() {
                add(ensemble_loss(&self.clip, states, self.start + s + 1)?.div_scalar(steps as f64));
            }
        }
        let loss = total.ok_or_else(|| Error::invalid("no steps"))?;
        Ok((loss, t))
    }

    /// Gradient check of the loss: autodiff vs 4-point central differences.
    pub fn check(
        &self,
        precision: Precision,
        h: f64,
        mut progress: impl FnMut(),
    ) -> Result<GradReport> {
        let device = cpu_device(precision)?;
        let theta = self.model.params.to_vec();
        let ad = device.clone().autodiff();
        let (loss, t) = self.loss(&theta, &ad)?;
        let value = read_vec(&loss.clone().detach())?[0];
        let grads = loss.backward();
        let g = read_vec(
            &t.grad(&grads)
                .ok_or_else(|| Error::Internal("no gradient reached the parameters".into()))?,
        )?;
        progress();
        let mut parameters = Vec::with_capacity(N_PARAMS);
        for (p, name) in param_names().into_iter().enumerate() {
            let at = |off: f64| -> Result<f64> {
                let mut th = theta;
                th[p] += off;
                Ok(read_vec(&self.loss(&th, &device)?.0)?[0])
            };
            let fd = (8.0 * (at(h)? - at(-h)?) - (at(2.0 * h)? - at(-2.0 * h)?)) / (12.0 * h);
            parameters.push(GradRow {
                name,
                autodiff: g[p],
                finite_difference: fd,
                rel_err: rel_err(g[p], fd),
            });
            progress();
        }
        let max_rel_err = parameters.iter().map(|r| r.rel_err).fold(0.0, f64::max);
        Ok(GradReport {
            steps: self.plans[0].len(),
            agents: self.init[0].len(),
            precision,
            objective: value,
            fd_step: h,
            parameters,
            max_rel_err,
        })
    }
}
