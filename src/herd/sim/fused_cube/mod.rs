//! The fused force op of eq. 3–5 on burn's CubeCL backend (`Cube`: wgpu over Vulkan, Metal,
//! DX12 or a software Vulkan such as lavapipe), beside the ndarray op of [`super::fused`]: the
//! same one burn operation with a hand-written backward, its math as CubeCL kernels
//! ([`kernel`], one thread per agent walking its recorded pair list, in f32).
//!
//! Per step the recorded pair lists ([`PairLists`] of the step's decisions) are uploaded once,
//! with their transpose (for each agent, the pairs that name it as the neighbour, in pair
//! order) for the backward pass's gather; positions, headings and coefficients stay on the
//! device. The backward step recomputes each pair's terms from the saved inputs (no kept
//! φ or exponentials) and runs three kernels: every agent's own gradients and what each of its
//! pairs passes on, the gather of those contributions per neighbour, and (for coefficients
//! shared by all agents) their sum in agent order. No atomics: the same inputs give the same
//! bytes.
//!
//! Registration follows [`super::fused`]: the backend-erased tensors are downcast to
//! `Cube` / `Autodiff<Cube, C>` primitives (burn's `extension` feature), the op's
//! [`Backward`] step is registered with burn-autodiff, and the result wrapped back. On any
//! other backend [`cube_forces`] returns `None`.

mod kernel;

use super::op_inputs::primitives;
use super::{ForceTensors, HerdState, StepDecisions};
use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::{
    BalancedCheckpointing, CheckpointStrategy, NoCheckpointing,
};
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::{Autodiff, Cube, DispatchKindConversion, DispatchTensor, TensorMetadata};
use burn::tensor::{DType, Shape, Tensor};
use burn_cubecl::kernel::into_contiguous;
use burn_cubecl::tensor::CubeTensor;
use cubecl::prelude::{BufferArg, CubeCount, CubeDim};
use cubecl::server::Handle;
use cubecl::CubeElement;
use herdfit_kernels::perception::{BRANCH_BEHIND, BRANCH_RIGHT};
use herdfit_kernels::{PairLists, N_COEF};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;

/// Threads per cube (workgroup) of the per-agent kernels.
const THREADS: u32 = 64;

static FORWARDS: AtomicU64 = AtomicU64::new(0);
static BACKWARDS: AtomicU64 = AtomicU64::new(0);

/// How many forward and backward passes of the CubeCL force op this process has run (what a
/// report or a test reads to say which force implementation computed a run).
pub fn cube_op_passes() -> (u64, u64) {
    (
        FORWARDS.load(Ordering::Relaxed),
        BACKWARDS.load(Ordering::Relaxed),
    )
}

/// A device buffer and its length in elements (at least one element is allocated, so an empty
/// list still binds).
#[derive(Clone, Debug)]
struct Buf {
    handle: Handle,
    len: usize,
}

impl Buf {
    fn arg(&self) -> BufferArg {
        // SAFETY: `len` is the number of elements the handle was created with.
        unsafe { BufferArg::from_raw_parts(self.handle.clone(), self.len.max(1)) }
    }
}

fn upload<E: CubeElement + Default>(client: &cubecl::client::Client, v: &[E]) -> Buf {
    let len = v.len();
    let handle = if len == 0 {
        client.create_from_slice(E::as_bytes(&[E::default()]))
    } else {
        client.create_from_slice(E::as_bytes(v))
    };
    Buf { handle, len }
}

fn empty(client: &cubecl::client::Client, len: usize) -> Buf {
    Buf {
        handle: client.empty(len.max(1) * std::mem::size_of::<f32>()),
        len,
    }
}

/// The branch code the kernels read: bit 0 the right-hand branch, bit 1 behind the agent.
fn code(branch: u8) -> u32 {
    u32::from(branch & BRANCH_RIGHT != 0) | (u32::from(branch & BRANCH_BEHIND != 0) << 1)
}

/// One step's pair lists on the device, with their transpose for the backward gather.
#[derive(Debug)]
struct DeviceLists {
    n: usize,
    pairs: usize,
    nb_start: Buf,
    nb: Buf,
    nb_code: Buf,
    ob_start: Buf,
    ob_xy: Buf,
    ob_code: Buf,
    tr_start: Buf,
    tr_pair: Buf,
}

impl DeviceLists {
    fn new(client: &cubecl::client::Client, l: &PairLists) -> Self {
        let n = l.n;
        // Transpose by counting sort: the pairs naming j as the neighbour, in pair order.
        let mut tr_start = vec![0u32; n + 1];
        for &j in &l.nb {
            tr_start[j as usize + 1] += 1;
        }
        for j in 0..n {
            tr_start[j + 1] += tr_start[j];
        }
        let mut fill: Vec<u32> = tr_start[..n].to_vec();
        let mut tr_pair = vec![0u32; l.nb.len()];
        for (e, &j) in l.nb.iter().enumerate() {
            tr_pair[fill[j as usize] as usize] = e as u32;
            fill[j as usize] += 1;
        }
        let nb_code: Vec<u32> = l.nb_branch.iter().map(|&b| code(b)).collect();
        let ob_code: Vec<u32> = l.ob_branch.iter().map(|&b| code(b)).collect();
        let ob_xy: Vec<f32> = l.ob_point.iter().flatten().map(|&v| v as f32).collect();
        DeviceLists {
            n,
            pairs: l.nb.len(),
            nb_start: upload(client, &l.nb_start),
            nb: upload(client, &l.nb),
            nb_code: upload(client, &nb_code),
            ob_start: upload(client, &l.ob_start),
            ob_xy: upload(client, &ob_xy),
            ob_code: upload(client, &ob_code),
            tr_start: upload(client, &tr_start),
            tr_pair: upload(client, &tr_pair),
        }
    }

    fn cubes(&self, threads: usize) -> CubeCount {
        CubeCount::Static(threads.div_ceil(THREADS as usize) as u32, 1, 1)
    }
}

/// Launches a per-agent kernel of [`kernel`] on `saved` ([`Saved`]): one thread per agent, the
/// op's inputs and pair lists in the kernels' shared parameter order, then `extra`, then the
/// coefficient stride.
macro_rules! launch_per_agent {
    ($kernel:ident, $saved:expr, $($extra:expr),+ $(,)?) => {{
        let (s, l) = ($saved, &$saved.lists);
        kernel::$kernel::launch(
            &s.inputs[0].client,
            l.cubes(l.n),
            CubeDim::new_1d(THREADS),
            s.input(0),
            s.input(1),
            s.input(2),
            s.input(3),
            s.input(4),
            l.nb_start.arg(),
            l.nb.arg(),
            l.nb_code.arg(),
            l.ob_start.arg(),
            l.ob_xy.arg(),
            l.ob_code.arg(),
            $($extra,)+
            s.stride(),
        )
    }};
}

/// The op's inputs on the device (contiguous f32) and its lists: the state of the backward step.
#[derive(Debug)]
struct Saved {
    /// x, y, hx, hy (`[n]`) and the coefficients (`[1, 12]` or `[n, 12]`).
    inputs: [CubeTensor; 5],
    lists: DeviceLists,
}

impl Saved {
    fn stride(&self) -> usize {
        if self.inputs[4].shape()[0] == 1 {
            0
        } else {
            N_COEF
        }
    }

    fn input(&self, k: usize) -> BufferArg {
        self.inputs[k].clone().into_buffer_arg()
    }

    fn tensor(&self, buf: Buf, shape: Vec<usize>) -> CubeTensor {
        let t = &self.inputs[0];
        CubeTensor::new_contiguous(
            t.client.clone(),
            t.device.clone(),
            Shape::from(shape),
            buf.handle,
            DType::F32,
        )
    }

    /// The forces `[n, 2]` (eq. 3–5).
    fn forward(&self) -> CubeTensor {
        FORWARDS.fetch_add(1, Ordering::Relaxed);
        let l = &self.lists;
        let client = &self.inputs[0].client;
        let out = empty(client, 2 * l.n);
        launch_per_agent!(forces_forward_kernel, self, out.arg());
        self.tensor(out, vec![l.n, 2])
    }

    /// The gradients of x, y, hx, hy and the coefficients from the upstream gradient `up`
    /// (`[n, 2]`, contiguous).
    fn backward(&self, up: CubeTensor) -> [CubeTensor; 5] {
        BACKWARDS.fetch_add(1, Ordering::Relaxed);
        let l = &self.lists;
        let client = &self.inputs[0].client;
        let (own, cg, to_nb) = (
            empty(client, 4 * l.n),
            empty(client, N_COEF * l.n),
            empty(client, 4 * l.pairs),
        );
        launch_per_agent!(
            forces_backward_own,
            self,
            up.into_buffer_arg(),
            own.arg(),
            cg.arg(),
            to_nb.arg()
        );
        let g: [Buf; 4] = std::array::from_fn(|_| empty(client, l.n));
        kernel::forces_backward_gather::launch(
            client,
            l.cubes(l.n),
            CubeDim::new_1d(THREADS),
            own.arg(),
            to_nb.arg(),
            l.tr_start.arg(),
            l.tr_pair.arg(),
            g[0].arg(),
            g[1].arg(),
            g[2].arg(),
            g[3].arg(),
        );
        let coef = if self.stride() == 0 {
            let out = empty(client, N_COEF);
            kernel::coef_reduce::launch(
                client,
                CubeCount::Static(1, 1, 1),
                CubeDim::new_1d(N_COEF as u32),
                cg.arg(),
                out.arg(),
            );
            self.tensor(out, vec![1, N_COEF])
        } else {
            self.tensor(cg, vec![l.n, N_COEF])
        };
        let [gx, gy, ghx, ghy] = g.map(|b| self.tensor(b, vec![l.n]));
        [gx, gy, ghx, ghy, coef]
    }
}

/// The backward step of the CubeCL op; parents: x, y, hx, hy (`[n]`) and the coefficients.
#[derive(Debug)]
struct CubeForcesBackward;

impl Backward<Cube, 5> for CubeForcesBackward {
    type State = Arc<Saved>;

    fn backward(self, ops: Ops<Self::State, 5>, grads: &mut Gradients, _: &mut Checkpointer) {
        let up = into_contiguous(grads.consume::<Cube>(&ops.node));
        let values = ops.state.backward(up);
        for (parent, v) in ops.parents.iter().zip(values) {
            if let Some(node) = parent {
                grads.register::<Cube>(node.id, v);
            }
        }
    }
}

/// The saved state of the op from its five inputs on the device, or `None` unless they are
/// f32 with at least one agent.
fn saved(inputs: [CubeTensor; 5], dec: &StepDecisions) -> Option<Saved> {
    if inputs.iter().any(|t| t.dtype != DType::F32) || dec.perception.n == 0 {
        return None;
    }
    let inputs = inputs.map(into_contiguous);
    let lists = DeviceLists::new(
        &inputs[0].client,
        &PairLists::from_perception(&dec.perception),
    );
    Some(Saved { inputs, lists })
}

/// On an autodiff device with checkpointing strategy `C`: the op with its backward step.
fn on_autodiff<C: CheckpointStrategy>(
    f: &ForceTensors,
    s: &HerdState,
    dec: &StepDecisions,
) -> Option<Tensor<2>>
where
    DispatchTensor: DispatchKindConversion<Autodiff<Cube, C>>,
{
    let prims = primitives::<Autodiff<Cube, C>>(f, s)?;
    let state = saved(prims.each_ref().map(|p| p.primitive().clone()), dec)?;
    let nodes = prims.each_ref().map(|p| p.node());
    let out = match CubeForcesBackward
        .prepare::<C>(nodes)
        .compute_bound()
        .stateful()
    {
        OpsKind::Tracked(prep) => {
            let out = state.forward();
            prep.finish(Arc::new(state), out)
        }
        OpsKind::UnTracked(prep) => prep.finish(state.forward()),
    };
    Some(Tensor::from_primitive::<Autodiff<Cube, C>>(out))
}

/// The forces of eq. 3–5 by the CubeCL op as a `[n, 2]` tensor, or `None` where the tensors do
/// not live on burn's Cube backend in f32.
pub fn cube_forces(f: &ForceTensors, s: &HerdState, dec: &StepDecisions) -> Option<Tensor<2>> {
    if s.x.device().is_autodiff() {
        on_autodiff::<NoCheckpointing>(f, s, dec)
            .or_else(|| on_autodiff::<BalancedCheckpointing>(f, s, dec))
    } else {
        let state = saved(primitives::<Cube>(f, s)?, dec)?;
        Some(Tensor::from_primitive::<Cube>(state.forward()))
    }
}
