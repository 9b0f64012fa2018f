//! Gradient check (DESIGN §7): the gradient of a scalar objective of an unrolled run with respect
//! to all 12 parameters, by reverse-mode autodiff and by central finite differences with the
//! same (replayed) perception, roles and noise.

use crate::backend::{device, Compute, Precision};
use crate::error::{Error, Result};
use crate::herd::params::{param_names, N_PARAMS};
use crate::herd::sim::{read_vec, theta_tensor, Decide, HerdState, Recording};
use burn::tensor::{Device, Tensor};
use rand::SeedableRng;
use serde::Serialize;

mod job;
mod loss;

pub use super::scenario::{default_scenario, objective, Scenario};
pub use job::{run, GradcheckConfig, GradcheckJob, Objective};
pub use loss::LossScenario;

/// Records the decisions of `steps` live steps at the scenario's parameters.
pub fn record(sc: &Scenario, steps: usize, seed: u64, device: &Device) -> Result<Recording> {
    let theta = theta_tensor(&sc.model.params.to_vec(), device);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    sc.model.record(&theta, &sc.init, steps, &mut rng)
}

/// J(θ) with replayed decisions, no gradient.
pub fn objective_value(
    sc: &Scenario,
    theta: &[f64; N_PARAMS],
    rec: &Recording,
    steps: usize,
    device: &Device,
) -> Result<f64> {
    let end = replayed(sc, &theta_tensor(theta, device), rec, steps)?;
    Ok(read_vec(&objective(
        &end,
        sc.model.params.constants.perception_radius,
    ))?[0])
}

/// The scenario's herd after `steps` replayed steps with parameters `t` (on `t`'s device).
fn replayed(sc: &Scenario, t: &Tensor<1>, rec: &Recording, steps: usize) -> Result<HerdState> {
    let state = HerdState::from_rows(&sc.init, &t.device());
    sc.model
        .rollout::<rand_chacha::ChaCha8Rng>(t, state, steps, Decide::Replay(rec), |_, _, _| Ok(()))
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
    let end = replayed(sc, &t, rec, steps)?;
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

/// Schema tag of gradcheck reports.
pub const GRADCHECK_SCHEMA: &str = "herdfit.gradcheck/1";

/// The gradcheck report (the JSON written by `herdfit gradcheck`).
#[derive(Clone, Debug, Serialize, PartialEq)]
pub struct GradReport {
    /// [`GRADCHECK_SCHEMA`].
    pub schema: String,
    pub steps: usize,
    pub agents: usize,
    pub precision: Precision,
    /// Where the tensors lived (`--device`). Not written when `cpu`.
    #[serde(skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
    pub objective: f64,
    pub fd_step: f64,
    pub parameters: Vec<GradRow>,
    pub max_rel_err: f64,
    /// Which implementation computed the forces of the autodiff pass; written for `--device gpu`
    /// only (on the CPU it follows `force_kernel`, and CPU reports keep their bytes).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub force_op: Option<crate::herd::sim::ForceOp>,
}

/// Relative error |a − f| / max(|a|, |f|, 1e-12).
pub fn rel_err(a: f64, f: f64) -> f64 {
    (a - f).abs() / a.abs().max(f.abs()).max(1e-12)
}

/// Runs the check on the device `compute` names in `precision`: records (or takes) the
/// decisions, then autodiff and finite differences.
pub fn gradcheck(
    sc: &Scenario,
    steps: usize,
    (compute, precision): (Compute, Precision),
    fd_step: f64,
    rec: &Recording,
    mut progress: impl FnMut(),
) -> Result<GradReport> {
    if !(fd_step.is_finite() && fd_step > 0.0) {
        return Err(Error::config("fd_step", "must be > 0"));
    }
    let device = device(compute, precision)?;
    let theta = sc.model.params.to_vec();
    let before = crate::herd::sim::fused_op_passes();
    let (value, ad) = autodiff_gradient(sc, &theta, rec, steps, &device)?;
    let force_op = (compute == Compute::Gpu).then(|| crate::herd::sim::ForceOp::since(before));
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
        schema: GRADCHECK_SCHEMA.into(),
        steps,
        agents: sc.init.len(),
        precision,
        device: compute,
        objective: value,
        fd_step,
        parameters,
        max_rel_err,
        force_op,
    })
}
