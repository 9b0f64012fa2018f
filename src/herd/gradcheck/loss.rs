//! The gradient check of the fit's losses (`gradcheck --objective loss`): herds started from a
//! clip's fields, their planned decisions and targets recorded once and replayed for every
//! evaluation.

use super::{rel_err, GradReport, GradRow};
use crate::backend::{device, Compute, Precision};
use crate::data::agents::AgentRow;
use crate::error::{Error, Result};
use crate::herd::params::{param_names, Params, N_PARAMS};
use crate::herd::sim::{read_vec, theta_tensor, HerdState, Model};
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;

/// The fit's loss as the objective: the mean over `steps` steps of the loss of `kind` — E_mean +
/// λ E_var (eq. 7–8), field matching + λ E_var, or the ensemble objective + λ E_var over
/// `replicas` herds — from herds initialised from the clip's frame `start`, with the planned
/// decisions and targets (perception, roles, noise, cells, U) recorded once per herd and replayed
/// for every evaluation.
pub struct LossScenario {
    pub model: Model,
    pub clip: crate::data::ClipFields,
    pub start: usize,
    pub kind: crate::herd::fit::LossKind,
    /// One initial herd and one plan per replica.
    pub init: Vec<Vec<AgentRow>>,
    pub plans: Vec<
        Vec<(
            crate::herd::sim::StepDecisions,
            crate::herd::fit::loss::StepTarget,
        )>,
    >,
    pub var_weight: f64,
}

impl LossScenario {
    /// Plans `steps` steps from frame `start` of `clip` with the parameters `params`, for
    /// `replicas` herds (1 unless `kind` is the ensemble objective).
    #[allow(clippy::too_many_arguments)]
    pub fn record(
        clip: &crate::data::ClipFields,
        params: &Params,
        start: usize,
        steps: usize,
        beta: f64,
        var_weight: f64,
        (kind, replicas): (crate::herd::fit::LossKind, usize),
        seed: u64,
        device: &Device,
    ) -> Result<Self> {
        use crate::herd::fit::{guidance_fields, init_herd, plan_step, LossKind};
        if start + steps >= clip.frames() {
            return Err(Error::invalid(format!(
                "{steps} steps from frame {start} need {} frames; the clip has {}",
                start + steps + 1,
                clip.frames()
            )));
        }
        if kind == LossKind::Auto {
            return Err(Error::config(
                "loss",
                "auto chooses an objective for a fit: check fields, paper or ensemble",
            ));
        }
        if (kind == LossKind::Ensemble) != (replicas >= 2) || replicas == 0 {
            return Err(Error::config(
                "replicas",
                "the ensemble objective needs 2 or more, the others one herd",
            ));
        }
        let mut params = params.clone();
        params.speed = crate::herd::params::SpeedModel::of_clip(clip, &params.speed);
        let mut model = crate::herd::fit::clip_model(params, clip);
        let guidance = guidance_fields(clip, crate::herd::fit::GUIDANCE_SCALE);
        let stencil = crate::herd::fit::target::Stencil::new(clip);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let theta = theta_tensor(&model.params.to_vec(), device);
        let f = crate::herd::sim::ForceTensors::new(&theta, &model.params.constants);
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
        use crate::herd::fit::{ensemble_loss, fields_loss, window_loss, LossKind};
        let t = theta_tensor(theta, device);
        let t = if device.is_autodiff() {
            t.require_grad()
        } else {
            t
        };
        let f = crate::herd::sim::ForceTensors::new(&t, &self.model.params.constants);
        let k = self.init.len() as f64;
        let steps = self.plans[0].len();
        let mean_weight = if self.kind == LossKind::Paper {
            1.0
        } else {
            0.0
        };
        let mut total: Option<Tensor<1>> = None;
        let mut add = |l: Tensor<1>| crate::herd::fit::loss::add(&mut total, l);
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
                    // (`auto` is refused in `new`.)
                    LossKind::Paper | LossKind::Auto => {}
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
        (compute, precision): (Compute, Precision),
        h: f64,
        mut progress: impl FnMut(),
    ) -> Result<GradReport> {
        let device = device(compute, precision)?;
        let theta = self.model.params.to_vec();
        let ad = device.clone().autodiff();
        let before = crate::herd::sim::fused_op_passes();
        let (loss, t) = self.loss(&theta, &ad)?;
        let force_op = (compute == Compute::Gpu).then(|| crate::herd::sim::ForceOp::since(before));
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
            schema: super::GRADCHECK_SCHEMA.into(),
            steps: self.plans[0].len(),
            agents: self.init[0].len(),
            precision,
            device: compute,
            objective: value,
            fd_step: h,
            parameters,
            max_rel_err,
            force_op,
        })
    }
}
