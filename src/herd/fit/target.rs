//! The target field of the fit (paper §6.1, eq. 10–11) as tensor ops:
//! ρ' by bilinear splatting of the agents onto the clip grid, D = −∇(ρ' − ρ) by central
//! differences over accessible cells, U = β N(D) + (1 − β) N(V̄).

use crate::data::{ClipFields, Grid};
use crate::herd::sim::read_vec;
use crate::Result;
use burn::tensor::{Device, IndexingUpdateOp, Int, Tensor, TensorData};
use herdfit_kernels::P2;

/// Guard of N(·) on target vectors.
const TARGET_EPS: f64 = 1e-12;

fn ints(v: Vec<i64>, device: &Device) -> Tensor<1, Int> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

fn floats(v: Vec<f64>, device: &Device) -> Tensor<1> {
    let n = v.len();
    Tensor::from_data(TensorData::new(v, [n]), device)
}

/// Simulated density ρ' (agents/BL², `[ny·nx]`, row-major, row 0 at the bottom) by bilinear
/// splatting: an agent spreads unit mass over the four cells whose centres surround it, with
/// weights linear in its position, so ρ' is differentiable in the positions. Mass falling outside
/// the grid is dropped. `pos` are the same positions as plain values (for the cell indices).
pub fn splat_density(x: &Tensor<1>, y: &Tensor<1>, pos: &[P2], grid: &Grid) -> Tensor<1> {
    splat(x, y, pos, grid, None)
}

/// Bilinear splatting of per-agent `values` (unit mass when `None`) onto the grid, per unit area.
pub fn splat(
    x: &Tensor<1>,
    y: &Tensor<1>,
    pos: &[P2],
    grid: &Grid,
    values: Option<&Tensor<1>>,
) -> Tensor<1> {
    let device = x.device();
    let (nx, ny) = (grid.nx as i64, grid.ny as i64);
    let c = grid.cell_size;
    let n = pos.len();
    // Cell-centred coordinates u = (x − ox)/c − ½; i0 = ⌊u⌋ is a no-gradient decision.
    let mut i0 = Vec::with_capacity(n);
    let mut j0 = Vec::with_capacity(n);
    for p in pos {
        i0.push(((p[0] - grid.origin[0]) / c - 0.5).floor());
        j0.push(((p[1] - grid.origin[1]) / c - 0.5).floor());
    }
    let fu = x.clone().mul_scalar(1.0 / c)
        - floats(
            i0.iter().map(|i| grid.origin[0] / c + 0.5 + i).collect(),
            &device,
        );
    let fv = y.clone().mul_scalar(1.0 / c)
        - floats(
            j0.iter().map(|j| grid.origin[1] / c + 0.5 + j).collect(),
            &device,
        );
    let gu = fu.clone().neg().add_scalar(1.0);
    let gv = fv.clone().neg().add_scalar(1.0);
    let corners = [(0i64, 0i64), (1, 0), (0, 1), (1, 1)];
    let mut idx = Vec::with_capacity(4 * n);
    let mut inside = Vec::with_capacity(4 * n);
    for &(di, dj) in &corners {
        for k in 0..n {
            let (i, j) = (i0[k] as i64 + di, j0[k] as i64 + dj);
            let ok = i >= 0 && j >= 0 && i < nx && j < ny;
            idx.push(if ok { j * nx + i } else { 0 });
            inside.push(if ok { 1.0 } else { 0.0 });
        }
    }
    let w = Tensor::cat(
        vec![
            gu.clone() * gv.clone(),
            fu.clone() * gv,
            gu * fv.clone(),
            fu * fv,
        ],
        0,
    ) * floats(inside, &device);
    let w = match values {
        Some(v) => w * Tensor::cat(vec![v.clone(), v.clone(), v.clone(), v.clone()], 0),
        None => w,
    };
    let cells = (nx * ny) as usize;
    Tensor::<1>::zeros([cells], &device)
        .scatter(0, ints(idx, &device), w, IndexingUpdateOp::Add)
        .div_scalar(grid.cell_area())
}

/// Finite-difference stencil of ∇ on the grid's accessible cells: for each cell and axis, the
/// cells `plus` and `minus` and the factor 1/(distance); central where both neighbours are
/// accessible, one-sided at borders and next to obstacles, zero where neither is.
#[derive(Clone, Debug)]
pub struct Stencil {
    pub plus: [Vec<i64>; 2],
    pub minus: [Vec<i64>; 2],
    pub factor: [Vec<f64>; 2],
}

impl Stencil {
    /// The stencil of a clip's grid and obstacle cells.
    pub fn new(clip: &ClipFields) -> Self {
        let g = clip.grid();
        let (nx, ny) = (g.nx, g.ny);
        let free = |ix: i64, iy: i64| -> bool {
            ix >= 0
                && iy >= 0
                && (ix as usize) < nx
                && (iy as usize) < ny
                && clip.obstacles[[iy as usize, ix as usize]] == 0
        };
        let mut s = Stencil {
            plus: [vec![], vec![]],
            minus: [vec![], vec![]],
            factor: [vec![], vec![]],
        };
        for iy in 0..ny as i64 {
            for ix in 0..nx as i64 {
                let here = iy * nx as i64 + ix;
                for (axis, (dx, dy)) in [(1i64, 0i64), (0, 1)].into_iter().enumerate() {
                    let p = free(ix + dx, iy + dy) && free(ix, iy);
                    let m = free(ix - dx, iy - dy) && free(ix, iy);
                    let pi = (iy + dy) * nx as i64 + ix + dx;
                    let mi = (iy - dy) * nx as i64 + ix - dx;
                    let (plus, minus, f) = match (p, m) {
                        (true, true) => (pi, mi, 0.5 / g.cell_size),
                        (true, false) => (pi, here, 1.0 / g.cell_size),
                        (false, true) => (here, mi, 1.0 / g.cell_size),
                        (false, false) => (here, here, 0.0),
                    };
                    s.plus[axis].push(plus);
                    s.minus[axis].push(minus);
                    s.factor[axis].push(f);
                }
            }
        }
        s
    }
}

/// D = −∇(ρ' − ρ) (eq. 10), `[cells]` x and y components, with `delta` = ρ' − ρ.
pub fn density_gradient(delta: &Tensor<1>, st: &Stencil) -> (Tensor<1>, Tensor<1>) {
    let device = delta.device();
    let comp = |axis: usize| {
        let plus = delta
            .clone()
            .gather(0, ints(st.plus[axis].clone(), &device));
        let minus = delta
            .clone()
            .gather(0, ints(st.minus[axis].clone(), &device));
        (minus - plus) * floats(st.factor[axis].clone(), &device)
    };
    (comp(0), comp(1))
}

fn normalise(x: Tensor<1>, y: Tensor<1>) -> (Tensor<1>, Tensor<1>) {
    let norm = (x.clone().square() + y.clone().square())
        .add_scalar(TARGET_EPS)
        .sqrt();
    (x / norm.clone(), y / norm)
}

/// U = β N(D) + (1 − β) N(V̄) (eq. 11) per cell, from the simulated density `rho_sim`, the clip's
/// density `rho` and mean velocity `(vx, vy)` (all `[cells]`).
pub fn target_field(
    rho_sim: &Tensor<1>,
    rho: &Tensor<1>,
    vx: &Tensor<1>,
    vy: &Tensor<1>,
    st: &Stencil,
    beta: f64,
) -> (Tensor<1>, Tensor<1>) {
    let (dx, dy) = density_gradient(&(rho_sim.clone() - rho.clone()), st);
    let (dx, dy) = normalise(dx, dy);
    let (vx, vy) = normalise(vx.clone(), vy.clone());
    (
        dx.mul_scalar(beta) + vx.mul_scalar(1.0 - beta),
        dy.mul_scalar(beta) + vy.mul_scalar(1.0 - beta),
    )
}

/// The clip's frame `f` as `[cells]` plain values: density, velocity x, velocity y, direction
/// variance.
fn frame_values(clip: &ClipFields, f: usize) -> [Vec<f64>; 4] {
    let plain = |a: ndarray::ArrayView2<f32>| a.iter().map(|&v| v as f64).collect::<Vec<f64>>();
    let vel = clip.velocity.index_axis(ndarray::Axis(0), f);
    [
        plain(clip.density.index_axis(ndarray::Axis(0), f)),
        plain(vel.index_axis(ndarray::Axis(2), 0)),
        plain(vel.index_axis(ndarray::Axis(2), 1)),
        plain(clip.dir_variance.index_axis(ndarray::Axis(0), f)),
    ]
}

/// The clip's frame `f` as `[cells]` tensors: density, velocity x, velocity y, direction variance.
pub fn frame_tensors(clip: &ClipFields, f: usize, device: &Device) -> [Tensor<1>; 4] {
    frame_values(clip, f).map(|v| floats(v, device))
}

/// The unit target direction of every cell for the step into frame `f + 1`, computed from the
/// current (detached) positions: plain values `[cells]`. Cells where U vanishes get (0, 0).
pub fn target_directions(
    clip: &ClipFields,
    st: &Stencil,
    beta: f64,
    x: &Tensor<1>,
    y: &Tensor<1>,
    pos: &[P2],
    f_next: usize,
) -> Result<Vec<P2>> {
    let device = x.device();
    let g = clip.grid();
    let rho_sim = splat_density(&x.clone().detach(), &y.clone().detach(), pos, &g);
    let [_, vx, vy, _] = frame_tensors(clip, f_next, &device);
    // The clip's density as splatting would see its agents, so that ρ' − ρ compares like with
    // like (a herd matching the clip exactly gives D = 0 on average).
    let [rho, _, _] = splat_comparable_targets(clip, f_next, &device);
    let (ux, uy) = target_field(&rho_sim, &rho, &vx, &vy, st, beta);
    let (ux, uy) = (read_vec(&ux)?, read_vec(&uy)?);
    Ok(ux
        .into_iter()
        .zip(uy)
        .map(|(a, b)| {
            let l = (a * a + b * b).sqrt();
            if l > 1e-6 {
                [a / l, b / l]
            } else {
                [0.0, 0.0]
            }
        })
        .collect())
}

/// A cell field (row-major `[ny·nx]`) convolved with the kernel that bilinear splatting applies to
/// box-binned counts: a point uniform inside its cell splats, on average, ¾ to its cell and ⅛ to
/// each side neighbour along each axis, so `E[splat] = K ∗ box` with K = [⅛, ¾, ⅛] ⊗ [⅛, ¾, ⅛].
/// Weights falling outside the grid are dropped, as splatting drops them.
pub fn blur_like_splat(field: &[f64], nx: usize, ny: usize) -> Vec<f64> {
    separable_filter(field, nx, ny, &[0.125, 0.75, 0.125])
}

pub use crate::measure::fields::separable_filter;

/// The clip's density and momentum (ρ, ρVx, ρVy) of frame `f` as splatting would see the same
/// agents ([`blur_like_splat`]), for comparison with splatted simulations.
pub fn splat_comparable_targets(clip: &ClipFields, f: usize, device: &Device) -> [Tensor<1>; 3] {
    let g = clip.grid();
    let [d, vx, vy, _] = frame_values(clip, f);
    let mx: Vec<f64> = vx.iter().zip(&d).map(|(v, r)| v * r).collect();
    let my: Vec<f64> = vy.iter().zip(&d).map(|(v, r)| v * r).collect();
    let blur = |v: Vec<f64>| blur_like_splat(&v, g.nx, g.ny);
    [
        floats(blur(d), device),
        floats(blur(mx), device),
        floats(blur(my), device),
    ]
}
