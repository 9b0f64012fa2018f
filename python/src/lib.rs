//! `herdfit._herdfit`: the native half of the `herdfit` Python package. Each function is one
//! library call: arrays and JSON text in, arrays and JSON text out; the configs are taken from
//! Python dicts through serde (pythonize), so their `deny_unknown_fields` refuses an unknown key
//! by name. Long calls release the GIL and report to a Python progress object ([`progress`]),
//! which also carries Ctrl-C into the library. The pure-Python half (`python/herdfit/`) wraps
//! these in the documented API.

mod errors;
mod jobs;
mod progress;
mod systems;
mod tracks;

use errors::to_py;
use herdfit::data::agents::AgentRow;
use herdfit::data::clip::{ClipFields, ClipMeta};
use herdfit::herd::params::{param_names, Params};
use herdfit::herd::simulate::{simulate_frames, Herd, SimulateConfig};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyArray3, PyArray4};
use numpy::{PyReadonlyArray2, PyReadonlyArray3, PyReadonlyArray4};
use progress::PyProgress;
use pyo3::prelude::*;
use std::path::PathBuf;

/// Cargo features this build was compiled with (`video`: OpenCV; `gpu`: burn's wgpu backend).
#[pyfunction]
fn features() -> Vec<&'static str> {
    let mut f = Vec::new();
    if cfg!(feature = "video") {
        f.push("video");
    }
    if herdfit::backend::GPU_BUILT {
        f.push("gpu");
    }
    f
}

/// JSON text of a serialisable value (a library value never fails to serialise).
fn json<T: serde::Serialize>(value: &T) -> PyResult<String> {
    serde_json::to_string_pretty(value)
        .map_err(|e| pyo3::exceptions::PyRuntimeError::new_err(format!("internal error: {e}")))
}

/// A parameter set from JSON text, validated; bad text → HerdfitError.
fn params_of(py: Python<'_>, text: &str) -> PyResult<Params> {
    let p: Params = serde_json::from_str(text).map_err(|e| {
        to_py(
            py,
            herdfit::Error::invalid(format!("not a herdfit.params/1 set: {e}")),
            None,
        )
    })?;
    p.validate().map_err(|e| to_py(py, e, None))?;
    Ok(p)
}

/// The clip folder at `path`: (clip.json text, density, velocity, dir_variance, obstacles).
#[pyfunction]
#[allow(clippy::type_complexity)]
fn load_clip<'py>(
    py: Python<'py>,
    path: PathBuf,
) -> PyResult<(
    String,
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray4<f32>>,
    Bound<'py, PyArray3<f32>>,
    Bound<'py, PyArray2<u8>>,
)> {
    let c = py
        .detach(|| ClipFields::load(&path))
        .map_err(|e| to_py(py, e, None))?;
    Ok((
        json(&c.meta)?,
        c.density.into_pyarray(py),
        c.velocity.into_pyarray(py),
        c.dir_variance.into_pyarray(py),
        c.obstacles.into_pyarray(py),
    ))
}

/// Writes a clip folder (validated first, written atomically).
#[pyfunction]
fn save_clip(
    py: Python<'_>,
    path: PathBuf,
    meta: &str,
    density: PyReadonlyArray3<f32>,
    velocity: PyReadonlyArray4<f32>,
    dir_variance: PyReadonlyArray3<f32>,
    obstacles: PyReadonlyArray2<u8>,
) -> PyResult<()> {
    let meta: ClipMeta = serde_json::from_str(meta).map_err(|e| {
        to_py(
            py,
            herdfit::Error::config("meta", format!("not a herdfit.clip/1 clip.json: {e}")),
            None,
        )
    })?;
    let clip = ClipFields {
        meta,
        density: density.as_array().to_owned(),
        velocity: velocity.as_array().to_owned(),
        dir_variance: dir_variance.as_array().to_owned(),
        obstacles: obstacles.as_array().to_owned(),
    };
    py.detach(|| clip.validate().and_then(|_| clip.save(&path, &[])))
        .map_err(|e| to_py(py, e, None))
}

/// The built-in parameter set, as JSON text.
#[pyfunction]
fn params_default() -> PyResult<String> {
    json(&Params::default())
}

/// The 12 parameters' names (`cohesion.weight`, …) in vector order.
#[pyfunction]
fn params_names() -> Vec<String> {
    param_names()
}

/// The parameter file at `path`, read and validated, as JSON text.
#[pyfunction]
fn params_load(py: Python<'_>, path: PathBuf) -> PyResult<String> {
    json(&Params::load(&path).map_err(|e| to_py(py, e, None))?)
}

/// Validates a parameter set given as JSON text and writes it as the library does (with its
/// physical values).
#[pyfunction]
fn params_save(py: Python<'_>, text: &str, path: PathBuf) -> PyResult<()> {
    params_of(py, text)?
        .save(&path)
        .map_err(|e| to_py(py, e, None))
}

/// The 12 normalised values of a parameter set (JSON text).
#[pyfunction]
fn params_vector(py: Python<'_>, text: &str) -> PyResult<Vec<f64>> {
    Ok(params_of(py, text)?.to_vec().to_vec())
}

/// The set with its 12 normalised values replaced (clamped to their ranges), as JSON text.
#[pyfunction]
fn params_with_vector(py: Python<'_>, text: &str, values: Vec<f64>) -> PyResult<String> {
    let p = params_of(py, text)?;
    let mut v: [f64; herdfit::herd::params::N_PARAMS] =
        values.try_into().map_err(|v: Vec<f64>| {
            to_py(
                py,
                herdfit::Error::config("values", format!("{} values; 12 expected", v.len())),
                None,
            )
        })?;
    Params::clamp_vec(&mut v);
    json(&p.with_vec(&v))
}

/// Runs a simulation in memory: (ids, frames `[steps + 1, agents, 5]` of x, y, vx, vy, leader).
#[pyfunction]
#[pyo3(signature = (params, agents, init, config, progress=None))]
#[allow(clippy::type_complexity)]
fn simulate<'py>(
    py: Python<'py>,
    params: Option<&str>,
    agents: Option<usize>,
    init: Option<PyReadonlyArray2<'py, f64>>,
    config: &Bound<'py, PyAny>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(Bound<'py, PyArray1<u64>>, Bound<'py, PyArray3<f64>>)> {
    let cfg: SimulateConfig =
        pythonize::depythonize(config).map_err(|e| errors::from_serde(py, "simulate", e))?;
    let params = params.map(|t| params_of(py, t)).transpose()?;
    let herd = match (agents, init) {
        (Some(n), None) => Herd::Agents(n),
        (None, Some(a)) => Herd::Rows(rows_of(py, a)?),
        _ => {
            return Err(to_py(
                py,
                herdfit::Error::config("herd", "give either a number of agents or an initial herd"),
                None,
            ))
        }
    };
    let mut prog = PyProgress::new(progress);
    let run = py.detach(|| simulate_frames(params, herd, &cfg, &mut prog));
    let t = run.map_err(|e| to_py(py, e, Some(&mut prog)))?;
    Ok((t.ids.into_pyarray(py), t.frames.into_pyarray(py)))
}

/// Agent rows from an `[n, 5]` array of id, x, y, vx, vy.
fn rows_of(py: Python<'_>, a: PyReadonlyArray2<'_, f64>) -> PyResult<Vec<AgentRow>> {
    let a = a.as_array();
    if a.ncols() != 5 {
        return Err(to_py(
            py,
            herdfit::Error::config(
                "herd",
                format!("{} columns; 5 expected (id, x, y, vx, vy)", a.ncols()),
            ),
            None,
        ));
    }
    a.rows()
        .into_iter()
        .map(|r| {
            if !(r[0] >= 0.0 && r[0].fract() == 0.0 && r[0] < 9.0e15) {
                return Err(to_py(
                    py,
                    herdfit::Error::config(
                        "herd",
                        format!("id {} is not a whole number ≥ 0", r[0]),
                    ),
                    None,
                ));
            }
            Ok(AgentRow {
                id: r[0] as u64,
                x: r[1],
                y: r[2],
                vx: r[3],
                vy: r[4],
            })
        })
        .collect()
}

#[pymodule]
fn _herdfit(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(features, m)?)?;
    m.add_function(wrap_pyfunction!(load_clip, m)?)?;
    m.add_function(wrap_pyfunction!(save_clip, m)?)?;
    m.add_function(wrap_pyfunction!(params_default, m)?)?;
    m.add_function(wrap_pyfunction!(params_names, m)?)?;
    m.add_function(wrap_pyfunction!(params_load, m)?)?;
    m.add_function(wrap_pyfunction!(params_save, m)?)?;
    m.add_function(wrap_pyfunction!(params_vector, m)?)?;
    m.add_function(wrap_pyfunction!(params_with_vector, m)?)?;
    m.add_function(wrap_pyfunction!(simulate, m)?)?;
    m.add_function(wrap_pyfunction!(tracks::tracks_load, m)?)?;
    m.add_function(wrap_pyfunction!(tracks::tracks_save, m)?)?;
    jobs::register(m)?;
    systems::register(m)?;
    Ok(())
}
