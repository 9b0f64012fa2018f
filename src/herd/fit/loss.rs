//! The fit's losses over followers (paper §6.1): E_mean (eq. 7) and E_var (eq. 8).
//!
//! Normalisation (ours; the paper sums): both are divided by the number of followers that take
//! part, so they do not grow with the herd. E_mean ∈ [0, 2] is the mean distance between a
//! follower's unit direction and its cell's unit target N(U); E_var is the follower-weighted mean
//! of |Var_cell − S_cell| over cells holding ≥ 2 followers (rad²). Norms and absolute values are
//! smoothed, √(x² + 1e-12), so the gradient exists everywhere.

use super::target;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::sim::HerdState;
use burn::tensor::{Device, IndexingUpdateOp, Int, Tensor, TensorData};
use herdfit_kernels::P2;
use serde::{Deserialize, Serialize};

const SMOOTH: f64 = 1e-12;

/// What a step's losses compare against, fixed without gradient when the step is planned (so it
/// can be recorded and replayed like the perception).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct StepTarget {
    /// Cell of each agent at the start of the step, −1 outside the grid.
    pub cell: Vec<i64>,
    /// Followers (leaders are excluded from the losses).
    pub follower: Vec<bool>,
    /// Unit target direction N(U) per cell (zero where U vanishes).
    pub u: Vec<P2>,
    /// The clip's direction variance S per cell (rad²) at the step's frame.
    pub s: Vec<f64>,
    /// E_mean on cell means: compare each cell's mean follower direction N(Σ d_i) with N(U)
    /// (weighted by the cell's followers) instead of every follower's direction. The spread of
    /// directions is then left to E_var alone.
    #[serde(default)]
    pub cell_mean: bool,
}

/// The two loss values of a step (tensors `[1]`).
pub struct StepLoss {
    pub e_mean: Tensor<1>,
    pub e_var: Tensor<1>,
}

fn floats(v: Vec<f64>, device: &Device) -> Tensor<1> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

/// E_mean (eq. 7) and E_var (eq. 8) of the new unit directions `(hx, hy)` (`[n]`).
pub fn step_loss(hx: &Tensor<1>, hy: &Tensor<1>, t: &StepTarget) -> StepLoss {
    let device = hx.device();
    let n = t.cell.len();
    let cells = t.u.len();
    // E_mean over followers in cells with a target.
    let mut mean_mask = vec![0.0; n];
    let mut ux = vec![0.0; n];
    let mut uy = vec![0.0; n];
    // E_var over followers in cells (target or not).
    let mut var_mask = vec![0.0; n];
    let mut cell_idx = vec![0i64; n];
    let mut count = vec![0.0f64; cells];
    for i in 0..n {
        if !t.follower[i] || t.cell[i] < 0 {
            continue;
        }
        let c = t.cell[i] as usize;
        var_mask[i] = 1.0;
        cell_idx[i] = c as i64;
        count[c] += 1.0;
        let u = t.u[c];
        if u != [0.0, 0.0] {
            mean_mask[i] = 1.0;
            ux[i] = u[0];
            uy[i] = u[1];
        }
    }
    let n_mean: f64 = mean_mask.iter().sum::<f64>().max(1.0);
    let n_var: f64 = var_mask.iter().sum::<f64>().max(1.0);
    let mm = floats(mean_mask, &device);
    let vm = floats(var_mask, &device);
    let idx = Tensor::<1, Int>::from_data(TensorData::new(cell_idx, [n]), &device);
    let zeros = Tensor::<1>::zeros([cells], &device);
    let e_mean = if t.cell_mean {
        // Σ_c n_c ‖N(Σ_{i∈c} d_i) − N(U_c)‖ / Σ_c n_c over cells with a target.
        let sx = zeros.clone().scatter(
            0,
            idx.clone(),
            hx.clone() * mm.clone(),
            IndexingUpdateOp::Add,
        );
        let sy = zeros.clone().scatter(
            0,
            idx.clone(),
            hy.clone() * mm.clone(),
            IndexingUpdateOp::Add,
        );
        let norm = (sx.clone().square() + sy.clone().square())
            .add_scalar(SMOOTH)
            .sqrt();
        let (mut cux, mut cuy, mut w) = (vec![0.0; cells], vec![0.0; cells], vec![0.0; cells]);
        for c in 0..cells {
            if t.u[c] != [0.0, 0.0] {
                cux[c] = t.u[c][0];
                cuy[c] = t.u[c][1];
                w[c] = count[c] / n_mean;
            }
        }
        let dist = ((sx / norm.clone() - floats(cux, &device)).square()
            + (sy / norm - floats(cuy, &device)).square())
        .add_scalar(SMOOTH)
        .sqrt();
        (dist * floats(w, &device)).sum()
    } else {
        let dist = ((hx.clone() - floats(ux, &device)).square()
            + (hy.clone() - floats(uy, &device)).square())
        .add_scalar(SMOOTH)
        .sqrt();
        (dist * mm.clone()).sum().div_scalar(n_mean)
    };
    // Cell mean directions Ṽ (sum of member directions), gathered back to the members.
    let member_sum = |h: &Tensor<1>| {
        zeros
            .clone()
            .scatter(
                0,
                idx.clone(),
                h.clone() * vm.clone(),
                IndexingUpdateOp::Add,
            )
            .gather(0, idx.clone())
    };
    let (mx, my) = (member_sum(hx), member_sum(hy));
    let cross = hx.clone() * my.clone() - hy.clone() * mx.clone();
    let dot = hx.clone() * mx + hy.clone() * my;
    let ang2 = cross.atan2(dot.add_scalar(1e-9)).square() * vm;
    let sum_c = zeros.scatter(0, idx, ang2, IndexingUpdateOp::Add);
    let (mut weight, mut inv) = (vec![0.0; cells], vec![0.0; cells]);
    for c in 0..cells {
        if count[c] >= 2.0 {
            weight[c] = count[c] / n_var;
            inv[c] = 1.0 / count[c];
        }
    }
    let var_c = sum_c * floats(inv, &device);
    let dev_c = (var_c - floats(t.s.clone(), &device))
        .square()
        .add_scalar(SMOOTH)
        .sqrt();
    let e_var = (dev_c * floats(weight, &device)).sum();
    StepLoss { e_mean, e_var }
}

/// Field-matching loss of a state against frame `f` of the clip:
/// Σ(ρ' − Kρ)² / Σ(Kρ)² + Σ‖ρ'V' − K(ρV)‖² / Σ‖K(ρV)‖² with ρ' and ρ'V' by bilinear
/// splatting and K the blur that splatting applies to points uniform in a cell
/// ([`target::blur_like_splat`]), so that a herd matching the clip scores 0 on average.
pub fn fields_loss(clip: &ClipFields, state: &HerdState, f: usize) -> Result<Tensor<1>> {
    fields_loss_weighted(clip, state, f, 1.0)
}

/// [`fields_loss`] with its density term weighted by `density_weight` (0: the ablation of
/// density matching, §7.2.3).
pub fn fields_loss_weighted(
    clip: &ClipFields,
    state: &HerdState,
    f: usize,
    density_weight: f64,
) -> Result<Tensor<1>> {
    let ([rho, mx, my], norm_d, norm_m) = field_targets(clip, f, &state.x.device())?;
    let [rho_s, mx_s, my_s] = splatted_fields(state, &clip.grid())?;
    let ed = (rho_s - rho)
        .square()
        .sum()
        .div_scalar(norm_d)
        .mul_scalar(density_weight);
    let em = ((mx_s - mx).square() + (my_s - my).square())
        .sum()
        .div_scalar(norm_m);
    Ok(ed + em)
}

/// The density match of a still's stationary fit (paper §7.2.4, [`super::still`]):
/// Σ(ρ' − Kρ)² / Σ(Kρ)², ρ' by bilinear splatting, K the like-for-like blur (the density term of
/// [`fields_loss`] without its momentum term: a still has no velocity).
pub fn density_loss(clip: &ClipFields, state: &HerdState, f: usize) -> Result<Tensor<1>> {
    let ([rho, _, _], norm_d, _) = field_targets(clip, f, &state.x.device())?;
    let rho_s = target::splat(
        &state.x,
        &state.y,
        &state.snapshot()?.pos,
        &clip.grid(),
        None,
    );
    Ok((rho_s - rho).square().sum().div_scalar(norm_d))
}

/// The clip's splat-comparable density and momentum of frame `f`
/// ([`target::splat_comparable_targets`]) and their normalisers Σρ², Σ‖m‖².
fn field_targets(
    clip: &ClipFields,
    f: usize,
    device: &Device,
) -> Result<([Tensor<1>; 3], f64, f64)> {
    let [rho, mx, my] = target::splat_comparable_targets(clip, f, device);
    let norm_d = crate::herd::sim::read_vec(&rho.clone().square().sum())?[0].max(1e-12);
    let norm_m = crate::herd::sim::read_vec(&(mx.clone().square() + my.clone().square()).sum())?[0]
        .max(1e-12);
    Ok(([rho, mx, my], norm_d, norm_m))
}

/// A herd's density and momentum fields by bilinear splatting (differentiable in positions,
/// headings and speeds).
fn splatted_fields(state: &HerdState, g: &crate::data::Grid) -> Result<[Tensor<1>; 3]> {
    use target::splat;
    let snap = state.snapshot()?;
    let vx = state.hx.clone() * state.speed.clone();
    let vy = state.hy.clone() * state.speed.clone();
    Ok([
        splat(&state.x, &state.y, &snap.pos, g, None),
        splat(&state.x, &state.y, &snap.pos, g, Some(&vx)),
        splat(&state.x, &state.y, &snap.pos, g, Some(&vy)),
    ])
}

/// Adds a loss term to a running total (the first term starts it).
pub(crate) fn add(total: &mut Option<Tensor<1>>, l: Tensor<1>) {
    *total = Some(match total.take() {
        None => l,
        Some(t) => t + l,
    });
}

/// The ensemble objective for one frame: with ρ_k, m_k the density and momentum fields splatted
/// from replica k (k = 1..K) and ρ̄, m̄ their means,
///
/// L = [‖ρ̄ − ρ‖² − S_ρ / K] / Σρ² + [‖m̄ − m‖² − S_m / K] / Σ‖m‖²,
/// S = Σ_k ‖x_k − x̄‖² / (K − 1),
///
/// an unbiased estimate of ‖E[ρ'] − ρ‖² / Σρ² + … : the replicas' own spread is subtracted, so a
/// parameter set is not rewarded for making the herd less variable (which matching one
/// simulated herd to one clip does: E‖ρ' − ρ‖² = ‖E ρ' − ρ‖² + Var ρ' + …; RESULTS.md §1).
pub fn ensemble_loss(clip: &ClipFields, states: &[HerdState], f: usize) -> Result<Tensor<1>> {
    ensemble_loss_weighted(clip, states, f, 1.0)
}

/// [`ensemble_loss`] with its density term weighted by `density_weight` (0: the ablation of
/// density matching, §7.2.3).
pub fn ensemble_loss_weighted(
    clip: &ClipFields,
    states: &[HerdState],
    f: usize,
    density_weight: f64,
) -> Result<Tensor<1>> {
    let k = states.len();
    if k < 2 {
        return Err(Error::invalid(
            "the ensemble loss needs at least 2 replicas",
        ));
    }
    let ([rho, mx, my], norm_d, norm_m) = field_targets(clip, f, &states[0].x.device())?;
    let g = clip.grid();
    let fields = states
        .iter()
        .map(|st| splatted_fields(st, &g))
        .collect::<Result<Vec<_>>>()?;
    let kf = k as f64;
    // k ≥ 2: sums start from zeros shaped like the first replica's.
    let mean = |i: usize| {
        fields
            .iter()
            .fold(fields[0][i].zeros_like(), |a, x| a + x[i].clone())
            .div_scalar(kf)
    };
    let (rb, mxb, myb) = (mean(0), mean(1), mean(2));
    let spread = |i: usize, m: &Tensor<1>| {
        fields
            .iter()
            .map(|x| (x[i].clone() - m.clone()).square().sum())
            .fold(fields[0][i].zeros_like().sum(), |a, b| a + b)
            .div_scalar((kf - 1.0) * kf)
    };
    let sd = spread(0, &rb);
    let sm = spread(1, &mxb) + spread(2, &myb);
    let ed = ((rb - rho).square().sum() - sd)
        .div_scalar(norm_d)
        .mul_scalar(density_weight);
    let em = ((mxb - mx).square().sum() + (myb - my).square().sum() - sm).div_scalar(norm_m);
    Ok(ed + em)
}
