//! The other systems' entry points: crowds (learn, simulate), flocks (animate), the 3D lift and
//! the glTF export. Settings come from Python dicts through serde, as the herd jobs'.

use crate::errors::{from_serde, to_py};
use crate::progress::PyProgress;
use crate::tracks::{columns, Columns};
use herdfit::crowd::entries::Entry;
use herdfit::crowd::features::Scene;
use herdfit::crowd::layout::Layout;
use herdfit::crowd::model::{learn, read_tracks, CrowdModel, LearnConfig};
use herdfit::crowd::sim::{
    entries_from_layout, entries_from_tracks, simulate, typical_speed, SimConfig,
};
use herdfit::data::atomic::write_atomic;
use herdfit::data::camera::Camera;
use herdfit::data::gltf::{export_glb, GltfConfig};
use herdfit::data::jackdaw::load_tracks;
use herdfit::data::tracks::sidecar_path;
use herdfit::flock::animate::AnimateConfig;
use herdfit::lift::{lift, LiftConfig};
use herdfit::Result;
use pyo3::prelude::*;
use serde::de::DeserializeOwned;
use std::path::{Path, PathBuf};

fn de<T: DeserializeOwned>(py: Python<'_>, what: &str, d: &Bound<'_, PyAny>) -> PyResult<T> {
    pythonize::depythonize(d).map_err(|e| from_serde(py, what, e))
}

/// Refuses an output `out` (a tracks CSV; its JSON sidecar beside it) that would overwrite one
/// of the inputs: inputs are never modified.
fn check_out(out: Option<&Path>, inputs: &[Option<&Path>]) -> Result<()> {
    let Some(out) = out else { return Ok(()) };
    let same = |a: &Path, b: &Path| match (a.canonicalize(), b.canonicalize()) {
        (Ok(x), Ok(y)) => x == y,
        _ => a == b,
    };
    for written in [out.to_path_buf(), sidecar_path(out)] {
        if let Some(i) = inputs.iter().flatten().find(|i| same(&written, i)) {
            return Err(herdfit::Error::config(
                "out",
                format!("{} is an input; refusing to overwrite it", i.display()),
            ));
        }
    }
    Ok(())
}

fn text<T: serde::Serialize>(v: &T) -> String {
    serde_json::to_string_pretty(v).unwrap_or_default()
}

/// The crowd learner's settings of a preset (`paper` or `pedestrians`), as a dict.
#[pyfunction]
fn crowd_defaults<'py>(py: Python<'py>, preset: &str) -> PyResult<Bound<'py, PyAny>> {
    let cfg = match preset {
        "paper" => LearnConfig::default(),
        "pedestrians" => LearnConfig::pedestrians(),
        _ => {
            let e = herdfit::Error::config(
                "preset",
                format!("'{preset}' is not one of paper, pedestrians"),
            );
            return Err(to_py(py, e, None));
        }
    };
    Ok(pythonize::pythonize(py, &cfg)?)
}

/// Learns a crowd model from tracks files and writes it to `out`; returns the model's JSON.
#[pyfunction]
#[pyo3(signature = (inputs, out, config, progress=None))]
fn crowd_learn(
    py: Python<'_>,
    inputs: Vec<PathBuf>,
    out: PathBuf,
    config: &Bound<'_, PyAny>,
    progress: Option<Py<PyAny>>,
) -> PyResult<()> {
    let cfg: LearnConfig = de(py, "crowd.learn", config)?;
    let mut prog = PyProgress::new(progress);
    let run = py.detach(|| -> Result<()> {
        cfg.check()?;
        let tracks = inputs
            .iter()
            .map(|p| read_tracks(p, cfg.eth_fps))
            .collect::<Result<Vec<_>>>()?;
        let m = learn(&tracks, &cfg, &mut prog).map_err(|e| match inputs.as_slice() {
            [one] => e.in_file(one),
            _ => e,
        })?;
        m.save(&out)
    });
    run.map_err(|e| to_py(py, e, Some(&mut prog)))
}

/// Simulates a crowd model from the entries of real tracks (`entries`) or a layout's spawns;
/// returns the simulated tracks' columns (and writes them to `out` when given).
#[pyfunction]
#[pyo3(signature = (model, entries, layout, config, out=None, progress=None))]
fn crowd_simulate<'py>(
    py: Python<'py>,
    model: PathBuf,
    entries: Option<PathBuf>,
    layout: Option<PathBuf>,
    config: &Bound<'py, PyAny>,
    out: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
) -> PyResult<Columns<'py>> {
    let cfg: SimConfig = de(py, "crowd.simulate", config)?;
    let mut prog = PyProgress::new(progress);
    let run = py.detach(|| {
        check_out(
            out.as_deref(),
            &[Some(&model), entries.as_deref(), layout.as_deref()],
        )?;
        let model = CrowdModel::load(&model)?;
        let layout = layout.as_deref().map(Layout::load).transpose()?;
        let who: Vec<Entry> = match (&entries, &layout) {
            (Some(p), _) => {
                let t = read_tracks(p, 1.0 / model.dt)?;
                entries_from_tracks(&Scene::from_tracks(&t, 0.0).map_err(|e| e.in_file(p))?)
            }
            (None, Some(l)) => entries_from_layout(l, model.dt, typical_speed(&model), cfg.seed),
            (None, None) => {
                return Err(herdfit::Error::config(
                    "entries",
                    "give real tracks' entries or a layout",
                ))
            }
        };
        let r = simulate(&model, layout.as_ref(), &who, &cfg, &mut prog)?;
        if let Some(o) = &out {
            r.tracks.save(o)?;
        }
        Ok(r.tracks)
    });
    let t = run.map_err(|e| to_py(py, e, Some(&mut prog)))?;
    Ok(columns(py, &t))
}

/// Animates a flock shape (`herdfit.flock-shape/1`) into the folder `out`; returns the report's
/// JSON.
#[pyfunction]
#[pyo3(signature = (shape, out, config, progress=None))]
fn flock_animate(
    py: Python<'_>,
    shape: PathBuf,
    out: PathBuf,
    config: &Bound<'_, PyAny>,
    progress: Option<Py<PyAny>>,
) -> PyResult<String> {
    let cfg: AnimateConfig = de(py, "flock.animate", config)?;
    let mut prog = PyProgress::new(progress);
    let run = py.detach(|| herdfit::flock::write::animate_file(&shape, &out, &cfg, &mut prog));
    Ok(text(&run.map_err(|e| to_py(py, e, Some(&mut prog)))?))
}

/// Lifts 2D pixel tracks seen by `camera` to 3D: (the 3D tracks' columns, the report's JSON);
/// with `out`, writes the tracks and `<out>.report.json` beside them.
#[pyfunction]
#[pyo3(signature = (tracks, camera, config, out=None, progress=None))]
fn lift_run<'py>(
    py: Python<'py>,
    tracks: PathBuf,
    camera: PathBuf,
    config: &Bound<'py, PyAny>,
    out: Option<PathBuf>,
    progress: Option<Py<PyAny>>,
) -> PyResult<(Columns<'py>, String)> {
    let cfg: LiftConfig = de(py, "lift.run", config)?;
    let mut prog = PyProgress::new(progress);
    let run = py.detach(|| {
        check_out(out.as_deref(), &[Some(&tracks), Some(&camera)])?;
        let cam = Camera::load(&camera)?;
        let t = load_tracks(&tracks)?;
        let l = lift(&t, &cam, &cfg, &mut prog).map_err(|e| e.in_file(&tracks))?;
        let report = text(&l.report);
        if let Some(o) = &out {
            l.tracks.save(o)?;
            write_atomic(
                &o.with_extension("report.json"),
                format!("{report}\n").as_bytes(),
            )?;
        }
        Ok((l.tracks, report))
    });
    let (t, report) = run.map_err(|e| to_py(py, e, Some(&mut prog)))?;
    Ok((columns(py, &t), report))
}

/// Exports tracks (2D or 3D) as a glTF binary `.glb`; returns the summary's JSON.
#[pyfunction]
fn export_gltf(
    py: Python<'_>,
    tracks: PathBuf,
    out: PathBuf,
    config: &Bound<'_, PyAny>,
) -> PyResult<String> {
    let cfg: GltfConfig = de(py, "export_gltf", config)?;
    let run = py.detach(|| {
        let t = load_tracks(&tracks)?;
        export_glb(&t, &cfg, &out).map_err(|e| e.in_file(&tracks))
    });
    Ok(text(&run.map_err(|e| to_py(py, e, None))?))
}

pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(crowd_defaults, m)?)?;
    m.add_function(wrap_pyfunction!(crowd_learn, m)?)?;
    m.add_function(wrap_pyfunction!(crowd_simulate, m)?)?;
    m.add_function(wrap_pyfunction!(flock_animate, m)?)?;
    m.add_function(wrap_pyfunction!(lift_run, m)?)?;
    m.add_function(wrap_pyfunction!(export_gltf, m)?)?;
    Ok(())
}
