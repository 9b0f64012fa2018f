//! Planning a step without gradient (perception, roles, noise, cells and targets, paper §6.1)
//! and the loss of a planned window.

use super::loss::{step_loss, StepTarget};
use super::target::{target_directions, Stencil};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::sim::{ForceTensors, Guidance, HerdState, Model, StepDecisions};
use crate::measure::dir_variance::SampleVariance;
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
    let cell: Vec<i64> = snap
        .pos
        .iter()
        .map(|p| g.cell_of(*p).map_or(-1, |(ix, iy)| (iy * g.nx + ix) as i64))
        .collect();
    let u = target_directions(clip, stencil, beta, &state.x, &state.y, &snap.pos, f + 1)?;
    let follower: Vec<bool> = dec.leader.iter().map(|&l| !l).collect();
    let s = match clip.meta.dir_spread {
        Some(v) => spread_targets(v, &cell, &follower, g.nx * g.ny),
        None => clip
            .dir_variance
            .index_axis(ndarray::Axis(0), f + 1)
            .iter()
            .map(|&v| v as f64)
            .collect(),
    };
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

/// E_var's target S per cell (eq. 8) when the clip gives the directions' spread `v` rather than
/// measuring them: the expected direction variance of the simulated followers in the cell for
/// that spread ([`SampleVariance`]), so that a cell the simulation fills differently from the
/// image is not pushed to align (more animals than the image: a value the image's count cannot
/// reach) or to scatter.
fn spread_targets(v: f64, cell: &[i64], follower: &[bool], cells: usize) -> Vec<f64> {
    let mut count = vec![0.0; cells];
    for (&c, &f) in cell.iter().zip(follower) {
        if f && c >= 0 {
            count[c as usize] += 1.0;
        }
    }
    let table = SampleVariance::shared(v);
    count.iter().map(|&n| table.at(n)).collect()
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_targets_follow_the_simulated_followers_in_each_cell() {
        // Cell 0: two followers and a leader; cell 1: one follower; cell 2: none; one agent
        // outside the grid.
        let cell = [0, 0, 0, 1, -1];
        let follower = [true, true, false, true, true];
        let v = std::f64::consts::PI.powi(2) / 3.0;
        let s = spread_targets(v, &cell, &follower, 3);
        let table = SampleVariance::new(v);
        assert_eq!(s, vec![table.at(2.0), 0.0, 0.0]);
        // Two random headings sit π²/12 ≈ 0.82 rad² from their mean on average.
        assert!(
            (s[0] - std::f64::consts::PI.powi(2) / 12.0).abs() < 0.03,
            "{s:?}"
        );
        // The shared table is the table.
        assert_eq!(SampleVariance::shared(v).at(5.0), table.at(5.0));
    }
}
