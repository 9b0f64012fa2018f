//! The fused force operation: eq. 3–5 of the herd model as **one** burn operation with a
//! hand-written backward (DESIGN §9), computed by [`herdfit_kernels::forces_forward`] /
//! [`herdfit_kernels::forces_backward`] over compact pair lists.
//!
//! The tensor-op path of [`super::Model::forces`] builds ≈ 60 small `[N, K]` operations per step,
//! each with its own allocation and autodiff node; this op replaces them with one node whose
//! backward reads the bearings and weight exponentials its forward kept
//! ([`herdfit_kernels::PairTerms`]) and recomputes the rest from the saved inputs (positions,
//! headings, coefficients).
//!
//! How it reaches burn's autodiff (ARCHITECTURE.md, "Departures"): the project's tensors are
//! backend-erased (`Tensor<D>` on a runtime `Device`). burn 0.22's `extension` feature lets a
//! caller downcast such a tensor to the primitive of a concrete backend
//! (`Tensor::try_into_primitive::<Autodiff<NdArray, C>>()`), register a step that implements
//! burn-autodiff's `Backward` trait, and wrap the result back (`Tensor::from_primitive`). The op
//! is therefore available on the ndarray backend (with or without autodiff, with either
//! checkpointing strategy) and, with the cargo feature `gpu`, on burn's Cube backend as CubeCL
//! kernels (`fused_cube`); on any other backend [`fused_forces`] returns `None` and the caller
//! uses the tensor-op reference.

// The design card fixes burn's ndarray backend, which burn 0.22 marks deprecated (as in
// `backend.rs`).
#![allow(deprecated)]

use super::op_inputs::primitives;
use super::{at_rest, ForceTensors, HerdState, Model, StepDecisions, NORM_EPS};
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::{
    BalancedCheckpointing, CheckpointStrategy, NoCheckpointing,
};
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::ndarray::NdArrayTensor;
use burn::backend::ops::FloatTensorOps;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, DispatchKindConversion, DispatchTensor, NdArray, TensorMetadata};
use burn::tensor::{read_sync, DType, Tensor, TensorData};
use herdfit_kernels::{
    forces_backward, forces_forward, forces_forward_keep, AgentsRef, Coefficients, PairLists,
    PairTerms, N_COEF, P2,
};
use serde::{Deserialize, Serialize};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Which implementation computes the forces of eq. 3–5.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum ForceKernel {
    /// The fused operation where the backend supports it (ndarray; Cube with the cargo feature
    /// `gpu`), the tensor ops elsewhere.
    #[default]
    Fused,
    /// Always the tensor-op reference implementation.
    Reference,
}

impl ForceKernel {
    /// [`ForceKernel::Reference`] when `reference` is set, else the default.
    pub fn reference_if(reference: bool) -> Self {
        if reference {
            ForceKernel::Reference
        } else {
            ForceKernel::Fused
        }
    }

    /// The default, [`ForceKernel::Fused`].
    pub fn is_fused(&self) -> bool {
        *self == ForceKernel::Fused
    }
}

/// Which implementation computed the forces of a run, as a report names it (`force_op`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum ForceOp {
    /// The fused op on the ndarray backend (this module).
    Ndarray,
    /// The fused op's CubeCL kernels (`fused_cube`, cargo feature `gpu`).
    Cubecl,
    /// The tensor ops of [`Model::reference_forces`].
    TensorOps,
}

/// Forward passes of the ndarray op in this process.
static NDARRAY_PASSES: AtomicU64 = AtomicU64::new(0);

/// Forward passes of the fused op in this process: `[ndarray, CubeCL]`. Read before and after a
/// run, [`ForceOp::since`] says which implementation computed its forces.
pub fn fused_op_passes() -> [u64; 2] {
    [NDARRAY_PASSES.load(Ordering::Relaxed), cube_passes()]
}

impl ForceOp {
    /// The op that ran since the counts `before` ([`fused_op_passes`]): a fused op if one ran
    /// (the CubeCL one first), the tensor ops otherwise.
    pub fn since(before: [u64; 2]) -> Self {
        let now = fused_op_passes();
        if now[1] > before[1] {
            ForceOp::Cubecl
        } else if now[0] > before[0] {
            ForceOp::Ndarray
        } else {
            ForceOp::TensorOps
        }
    }
}

type NdDevice = <NdArray as burn::backend::BackendTypes>::Device;

/// The values of an ndarray tensor as f64. Contiguous f32 / f64 storage is widened straight from
/// its slice (the same values: f32 → f64 is exact) instead of burn's element-by-element
/// conversion through `TensorData` (its cost per step: BENCHMARKS.md, "Profile of one fused
/// step").
fn read(t: FloatTensor<NdArray>) -> Vec<f64> {
    match &t {
        NdArrayTensor::F32(s) => {
            if let Some(v) = s.view().as_slice() {
                return v.iter().map(|&x| x as f64).collect();
            }
        }
        NdArrayTensor::F64(s) => {
            if let Some(v) = s.view().as_slice() {
                return v.to_vec();
            }
        }
        _ => {}
    }
    let data = read_sync(NdArray::float_into_data(t)).expect("ndarray tensors are always readable");
    data.try_into_vec_as::<f64>()
        .expect("float tensors convert to f64")
}

fn upload(v: Vec<f64>, shape: Vec<usize>, dtype: DType) -> FloatTensor<NdArray> {
    NdArray::float_from_data(
        TensorData::new(v, shape).convert_dtype(dtype),
        &NdDevice::default(),
    )
}

/// The values of a rank-1 tensor on the ndarray backend (plain or autodiff) by [`read`], or
/// `None` on other backends.
pub(super) fn read_ndarray(t: &Tensor<1>) -> Option<Vec<f64>> {
    if let Ok(p) = t.clone().try_into_primitive::<NdArray>() {
        return Some(read(p));
    }
    fn on<C: CheckpointStrategy>(t: &Tensor<1>) -> Option<Vec<f64>>
    where
        DispatchTensor: DispatchKindConversion<Autodiff<NdArray, C>>,
    {
        let p = t
            .clone()
            .try_into_primitive::<Autodiff<NdArray, C>>()
            .ok()?;
        Some(read(p.primitive().clone()))
    }
    on::<NoCheckpointing>(t).or_else(|| on::<BalancedCheckpointing>(t))
}

/// Inputs saved for the backward pass (plain values, f64).
#[derive(Debug)]
struct Saved {
    lists: PairLists,
    x: Vec<f64>,
    y: Vec<f64>,
    hx: Vec<f64>,
    hy: Vec<f64>,
    coef: Vec<f64>,
    coef_rows: usize,
    dtype: DType,
    /// The pair terms of the forward pass (φ and the weights' exponentials), so the backward pass
    /// evaluates no `exp` or `atan2`; `None` until a forward pass keeps them.
    kept: Option<PairTerms>,
}

impl Saved {
    fn agents(&self) -> AgentsRef<'_> {
        AgentsRef {
            x: &self.x,
            y: &self.y,
            hx: &self.hx,
            hy: &self.hy,
        }
    }

    fn forward(&self) -> Vec<f64> {
        let mut out = vec![0.0; 2 * self.lists.n];
        forces_forward(
            &self.lists,
            self.agents(),
            Coefficients(&self.coef),
            &mut out,
        );
        out
    }

    /// [`Saved::forward`], keeping the pair terms for the backward pass.
    fn forward_keep(&mut self) -> Vec<f64> {
        let mut out = vec![0.0; 2 * self.lists.n];
        let kept = forces_forward_keep(
            &self.lists,
            self.agents(),
            Coefficients(&self.coef),
            &mut out,
        );
        self.kept = Some(kept);
        out
    }
}

/// The backward step of the fused op; parents: x, y, hx, hy (`[n]`) and the coefficients
/// (`[1, 12]` or `[n, 12]`); output `[n, 2]` = (F_x, F_y).
#[derive(Debug)]
struct FusedForcesBackward;

impl Backward<NdArray, 5> for FusedForcesBackward {
    type State = Arc<Saved>;

    fn backward(self, ops: Ops<Self::State, 5>, grads: &mut Gradients, _: &mut Checkpointer) {
        let s = ops.state;
        let up = read(grads.consume::<NdArray>(&ops.node));
        let g = forces_backward(
            &s.lists,
            s.agents(),
            Coefficients(&s.coef),
            &up,
            s.kept.as_ref(),
        );
        let n = s.lists.n;
        let values = [g.x, g.y, g.hx, g.hy, g.coef];
        let shapes = [
            vec![n],
            vec![n],
            vec![n],
            vec![n],
            vec![s.coef_rows, N_COEF],
        ];
        for ((parent, v), shape) in ops.parents.iter().zip(values).zip(shapes) {
            if let Some(node) = parent {
                grads.register::<NdArray>(node.id, upload(v, shape, s.dtype));
            }
        }
    }
}

fn saved(values: [Vec<f64>; 5], coef_rows: usize, dtype: DType, dec: &StepDecisions) -> Saved {
    let [x, y, hx, hy, coef] = values;
    Saved {
        lists: PairLists::from_perception(&dec.perception),
        x,
        y,
        hx,
        hy,
        coef,
        coef_rows,
        dtype,
        kept: None,
    }
}

/// On an autodiff device with checkpointing strategy `C`: the op with its backward step.
fn on_autodiff<C: CheckpointStrategy>(
    f: &ForceTensors,
    s: &HerdState,
    dec: &StepDecisions,
) -> Option<Tensor<2>>
where
    DispatchTensor: DispatchKindConversion<Autodiff<NdArray, C>>,
{
    let prims = primitives::<Autodiff<NdArray, C>>(f, s)?;
    NDARRAY_PASSES.fetch_add(1, Ordering::Relaxed);
    let dtype = prims[0].primitive().dtype();
    let coef_rows = prims[4].primitive().shape()[0];
    let values = prims.each_ref().map(|p| read(p.primitive().clone()));
    let mut state = saved(values, coef_rows, dtype, dec);
    let shape = vec![state.lists.n, 2];
    let nodes = prims.each_ref().map(|p| p.node());
    // Pair terms are kept only where a backward pass will read them.
    let out = match FusedForcesBackward
        .prepare::<C>(nodes)
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(prep) => {
            let out = upload(state.forward_keep(), shape, dtype);
            prep.finish(Arc::new(state), out)
        }
        OpsKind::UnTracked(prep) => prep.finish(upload(state.forward(), shape, dtype)),
    };
    Some(Tensor::from_primitive::<Autodiff<NdArray, C>>(out))
}

/// On a plain ndarray device: the forward pass only.
fn on_ndarray(f: &ForceTensors, s: &HerdState, dec: &StepDecisions) -> Option<Tensor<2>> {
    let prims = primitives::<NdArray>(f, s)?;
    NDARRAY_PASSES.fetch_add(1, Ordering::Relaxed);
    let dtype = prims[0].dtype();
    let coef_rows = prims[4].shape()[0];
    let state = saved(prims.map(read), coef_rows, dtype, dec);
    let out = upload(state.forward(), vec![state.lists.n, 2], dtype);
    Some(Tensor::from_primitive::<NdArray>(out))
}

/// The forces of eq. 3–5 by the fused op, as `[n, 1]` tensors (x and y), or `None` where the
/// tensors live on neither the ndarray backend nor (cargo feature `gpu`) burn's Cube backend.
pub fn fused_forces(
    f: &ForceTensors,
    s: &HerdState,
    dec: &StepDecisions,
) -> Option<(Tensor<2>, Tensor<2>)> {
    let out = if s.x.device().is_autodiff() {
        on_autodiff::<NoCheckpointing>(f, s, dec)
            .or_else(|| on_autodiff::<BalancedCheckpointing>(f, s, dec))
    } else {
        on_ndarray(f, s, dec)
    };
    let out = out.or_else(|| on_cube(f, s, dec))?;
    Some((out.clone().narrow(1, 0, 1), out.narrow(1, 1, 1)))
}

/// The CubeCL op of [`super::fused_cube`] (built with the cargo feature `gpu`).
#[cfg(feature = "gpu")]
fn on_cube(f: &ForceTensors, s: &HerdState, dec: &StepDecisions) -> Option<Tensor<2>> {
    super::fused_cube::cube_forces(f, s, dec)
}

/// Without the cargo feature `gpu` no other backend has the op.
#[cfg(not(feature = "gpu"))]
fn on_cube(_: &ForceTensors, _: &HerdState, _: &StepDecisions) -> Option<Tensor<2>> {
    None
}

#[cfg(feature = "gpu")]
fn cube_passes() -> u64 {
    super::fused_cube::cube_op_passes().0
}

#[cfg(not(feature = "gpu"))]
fn cube_passes() -> u64 {
    0
}

/// The element type of a plain step: it computes in the tensors' own type (f32 or f64), so every
/// operation rounds as the tensor op it replaces does.
trait Elem:
    Copy + std::ops::Add<Output = Self> + std::ops::Mul<Output = Self> + std::ops::Div<Output = Self>
{
    /// Rounds an f64 as burn does when it stores one in a tensor of this type.
    fn of(v: f64) -> Self;
    fn sqrt(self) -> Self;
    fn wide(self) -> f64;
}

impl Elem for f32 {
    fn of(v: f64) -> Self {
        v as f32
    }
    fn sqrt(self) -> Self {
        f32::sqrt(self)
    }
    fn wide(self) -> f64 {
        self as f64
    }
}

impl Elem for f64 {
    fn of(v: f64) -> Self {
        v
    }
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    fn wide(self) -> f64 {
        self
    }
}

/// What a plain step reads: the saved inputs of the force op, its output, old and new speeds.
struct PlainInputs<'a> {
    st: &'a Saved,
    force: &'a [f64],
    speed: &'a [f64],
    next_speed: &'a [f64],
}

/// Eq. 2, the leaders' directions and the position update on plain values of type `T`, in the
/// order of the tensor ops of [`Model::step_with`]: u = v·d + F·Δt (F plus the extra force),
/// d' = u / √(u_x² + u_y² + ε) (d' = d where the agent is at rest, [`at_rest`]),
/// d' ← d'·follow + guide where any agent leads, p' = p + d'·(v'·Δt).
fn plain_step_as<T: Elem>(
    model: &Model,
    inp: &PlainInputs<'_>,
    dec: &StepDecisions,
    extra: Option<&[P2]>,
) -> [Vec<f64>; 4] {
    let st = inp.st;
    let n = st.lists.n;
    let (dt, eps) = (T::of(model.dt), T::of(NORM_EPS));
    let lead = dec.leader.iter().any(|&l| l);
    let mut out: [Vec<f64>; 4] = std::array::from_fn(|_| Vec::with_capacity(n));
    for i in 0..n {
        let (mut fx, mut fy) = (T::of(inp.force[2 * i]), T::of(inp.force[2 * i + 1]));
        if let Some(e) = extra {
            fx = fx + T::of(e[i][0]);
            fy = fy + T::of(e[i][1]);
        }
        let v = T::of(inp.speed[i]);
        let ux = v * T::of(st.hx[i]) + fx * dt;
        let uy = v * T::of(st.hy[i]) + fy * dt;
        let norm = (ux * ux + uy * uy + eps).sqrt();
        let (mut hx, mut hy) = (ux / norm, uy / norm);
        if at_rest(inp.speed[i], ux.wide(), uy.wide()) {
            // At rest with no force on it: d' = d (as the tensor step).
            (hx, hy) = (T::of(st.hx[i]), T::of(st.hy[i]));
        }
        if lead {
            let follow = T::of(if dec.leader[i] { 0.0 } else { 1.0 });
            hx = hx * follow + T::of(dec.guide[i][0]);
            hy = hy * follow + T::of(dec.guide[i][1]);
        }
        let step = T::of(inp.next_speed[i]) * dt;
        out[0].push((T::of(st.x[i]) + hx * step).wide());
        out[1].push((T::of(st.y[i]) + hy * step).wide());
        out[2].push(hx.wide());
        out[3].push(hy.wide());
    }
    out
}

/// On a plain ndarray device (no autodiff): the whole step of [`Model::step_with`] — the fused
/// forces of eq. 3–5, eq. 2, the leaders, the OU speeds of eq. 6 and the position update — on
/// plain values read once, in the tensors' element type and the tensor ops' order, so the new
/// state has the same bytes as the tensor-op step around the fused forces; `None` on other
/// devices (the caller runs the tensor ops).
pub fn plain_step(
    model: &Model,
    f: &ForceTensors,
    s: &HerdState,
    dec: &StepDecisions,
    extra: Option<&[P2]>,
) -> Option<HerdState> {
    if s.x.device().is_autodiff() {
        return None;
    }
    let prims = primitives::<NdArray>(f, s)?;
    let speed = read(s.speed.clone().try_into_primitive::<NdArray>().ok()?);
    let dtype = prims[0].dtype();
    let coef_rows = prims[4].shape()[0];
    if !matches!(dtype, DType::F32 | DType::F64) {
        return None;
    }
    let st = saved(prims.map(read), coef_rows, dtype, dec);
    let force = st.forward();
    let next_speed = model.next_speeds(&speed, dec);
    let inp = PlainInputs {
        st: &st,
        force: &force,
        speed: &speed,
        next_speed: &next_speed,
    };
    let [x, y, hx, hy] = if dtype == DType::F32 {
        plain_step_as::<f32>(model, &inp, dec, extra)
    } else {
        plain_step_as::<f64>(model, &inp, dec, extra)
    };
    let n = st.lists.n;
    let up = |v: Vec<f64>| Tensor::from_primitive::<NdArray>(upload(v, vec![n], dtype));
    Some(HerdState {
        x: up(x),
        y: up(y),
        hx: up(hx),
        hy: up(hy),
        speed: up(next_speed),
    })
}
