//! Planning a step without gradient (perception, roles, noise, cells and targets, paper §6.1)
//! and the loss of a planned window.

use super::loss::{step_loss, StepTarget};
use super::target::{target_directions, Stencil};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::sim::{ForceTensors, Guidance, HerdState, Model, StepDecisions};
use burn::tensor::Tensor;
use rand::Rng;

/// Plans one step without gradient: leader guidance from frame `f`, perception, roles and noise,
/// each agent's cell and the target directions toward frame `f + 1`.
#[allow(clippy::too_many_arguments)]
pub fn plan_step(
    model: &mut Model,
    clip: &ClipFields,
    guidance: &[Guidance],
    stencil: &Stencil,
    beta: f64,
    cell_mean: bool,
    state: &HerdState,
    f: usize,
    rng: &mut impl Rng,
) -> Result<(StepDecisions, StepTarget)> {
    let snap = state.snapshot()?;
    model.world.guidance = guidance[f].clone();
    let dec = model.decide(&snap, rng);
    let g = clip.grid();
    let cell = snap
        .pos
        .iter()
        .map(|p| g.cell_of(*p).map_or(-1, |(ix, iy)| (iy * g.nx + ix) as i64))
        .collect();
    let u = target_directions(clip, stencil, beta, &state.x, &state.y, &snap.pos, f + 1)?;
    let s = clip
        .dir_variance
        .index_axis(ndarray::Axis(0), f + 1)
        .iter()
        .map(|&v| v as f64)
        .collect();
    let follower = dec.leader.iter().map(|&l| !l).collect();
    Ok((
        dec,
        StepTarget {
            cell,
            follower,
            u,
            s,
            cell_mean,
        },
    ))
}

/// Loss of one window: mean over its steps of a·E_mean + b·E_var with `(a, b)` = `weights`. Returns the end state, the loss
/// tensor and the mean E_mean and E_var values.
pub fn window_loss(
    model: &Model,
    f: &ForceTensors,
    mut state: HerdState,
    plans: &[(StepDecisions, StepTarget)],
    (mean_weight, var_weight): (f64, f64),
) -> Result<(HerdState, Tensor<1>, f64, f64)> {
    let mut total: Option<Tensor<1>> = None;
    let (mut em, mut ev) = (0.0, 0.0);
    for (dec, tgt) in plans {
        state = model.step(f, &state, dec)?;
        let l = step_loss(&state.hx, &state.hy, tgt);
        em += crate::herd::sim::read_vec(&l.e_mean.clone().detach())?[0];
        ev += crate::herd::sim::read_vec(&l.e_var.clone().detach())?[0];
        let step = l.e_mean.mul_scalar(mean_weight) + l.e_var.mul_scalar(var_weight);
        total = Some(match total {
            None => step,
            Some(t) => t + step,
        });
    }
    let k = plans.len().max(1) as f64;
    let total = total
        .ok_or_else(|| Error::invalid("empty window"))?
        .div_scalar(k);
    Ok((state, total, em / k, ev / k))
}
