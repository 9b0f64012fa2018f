//! Device selection. Model code never names a backend: it receives a burn [`Device`] and creates
//! every tensor on it. Today that is burn's ndarray CPU device; a GPU backend is one more arm here
//! behind a cargo feature.

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
