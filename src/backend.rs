//! Device selection. Model code never names a backend: it receives a burn [`Device`] and creates
//! every tensor on it. [`device`] gives burn's ndarray CPU device ([`Compute::Cpu`], the default)
//! or, built with the cargo feature `gpu`, burn's wgpu device ([`Compute::Gpu`]: CubeCL over
//! Vulkan, Metal or DX12; a software Vulkan driver such as Mesa's lavapipe also counts). On the GPU
//! the forces of eq. 3–5 run as the fused op's CubeCL kernels (`herd::sim::fused_cube`; the
//! tensor ops with `ForceKernel::Reference`), the rest of the step as burn tensor ops, and
//! perception stays on the CPU, reading each step's state back (DESIGN §9).

use crate::error::{Error, Result};
use burn::tensor::{Device, FloatDType};

/// Float precision of the tensors of a run.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    F32,
    F64,
}

enum_names!(Precision { F32 = "f32", F64 = "f64" });

impl Precision {
    fn dtype(self) -> FloatDType {
        match self {
            Precision::F32 => FloatDType::F32,
            Precision::F64 => FloatDType::F64,
        }
    }
}

/// Whether this build has the GPU backend (cargo feature `gpu`).
pub const GPU_BUILT: bool = cfg!(feature = "gpu");

/// Where a run's tensors live (`--device`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Compute {
    /// burn's ndarray backend on the CPU.
    #[default]
    Cpu,
    /// burn's wgpu backend (cargo feature `gpu`); f32 only.
    Gpu,
}

enum_names!(Compute { Cpu = "cpu", Gpu = "gpu" });

impl Compute {
    /// True for the default, [`Compute::Cpu`] (configs leave the key out of their files then, so
    /// files written before the key existed keep their bytes).
    pub fn is_cpu(&self) -> bool {
        *self == Compute::Cpu
    }
}

/// The device `compute` names, computing in `precision`.
pub fn device(compute: Compute, precision: Precision) -> Result<Device> {
    match compute {
        Compute::Cpu => cpu_device(precision),
        Compute::Gpu => gpu_device(precision),
    }
}

/// The wgpu device (the adapter wgpu prefers, or `CUBECL_WGPU_DEFAULT_DEVICE`, e.g. `Cpu` for a
/// software Vulkan driver), initialised once per process.
#[cfg(feature = "gpu")]
pub fn gpu_device(precision: Precision) -> Result<Device> {
    use std::sync::OnceLock;
    static DEVICE: OnceLock<std::result::Result<Device, String>> = OnceLock::new();
    if precision != Precision::F32 {
        return Err(Error::config(
            "precision",
            "the GPU backend computes in f32 (WGSL has no f64): use --precision f32",
        ));
    }
    DEVICE
        .get_or_init(|| {
            Device::wgpu_options().init().map_err(|e| {
                format!(
                    "no GPU device for --device gpu ({e}); install a Vulkan driver (on Debian, \
                     mesa-vulkan-drivers gives the software one, lavapipe)"
                )
            })
        })
        .clone()
        .map_err(Error::invalid)
}

/// Without the cargo feature `gpu`: an error saying how to get it.
#[cfg(not(feature = "gpu"))]
pub fn gpu_device(_precision: Precision) -> Result<Device> {
    Err(Error::invalid(
        "this herdfit was built without the GPU backend: rebuild with `cargo build --release \
         --features gpu` (or use --device cpu)",
    ))
}

/// The CPU device with its default float dtype set to `precision`.
///
/// burn fixes a device's default dtype the first time it is used, for the whole process; asking
/// for another precision afterwards is an error (run f32 and f64 in separate processes).
pub fn cpu_device(precision: Precision) -> Result<Device> {
    #[allow(deprecated)] // the design card fixes burn-ndarray; flex is one line away
    let mut device = Device::ndarray();
    let want = precision.dtype();
    if device.configure(want).is_err() && device.settings().float_dtype != want {
        return Err(Error::invalid(format!(
            "this process already runs in {:?}; cannot switch to {precision:?}",
            device.settings().float_dtype
        )));
    }
    // Check what tensors on this device really hold.
    let probe = burn::tensor::Tensor::<1>::zeros([1], &device);
    let got = probe.dtype();
    if got != want.into() {
        return Err(Error::Internal(format!(
            "asked for {precision:?} tensors, the device makes {got:?}"
        )));
    }
    Ok(device)
}
