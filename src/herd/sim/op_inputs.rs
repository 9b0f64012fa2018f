//! The inputs of the fused force op as primitives of a concrete burn backend, shared by its
//! ndarray registration (`fused.rs`) and its CubeCL one (`fused_cube/`).

use super::{ForceTensors, HerdState};
use burn::backend::tensor::FloatTensor;
use burn::backend::{DispatchKindConversion, DispatchTensor};
use burn::tensor::Tensor;

/// The five inputs of the op in parent order — x, y, hx, hy (`[n]`) and the coefficients
/// (`[1, 12]` or `[n, 12]`) — as primitives of backend `B`, or `None` if they live elsewhere.
pub(super) fn primitives<B: burn::backend::Backend>(
    f: &ForceTensors,
    s: &HerdState,
) -> Option<[FloatTensor<B>; 5]>
where
    DispatchTensor: DispatchKindConversion<B>,
{
    let one = |t: &Tensor<1>| t.clone().try_into_primitive::<B>().ok();
    Some([
        one(&s.x)?,
        one(&s.y)?,
        one(&s.hx)?,
        one(&s.hy)?,
        f.coef.clone().try_into_primitive::<B>().ok()?,
    ])
}
