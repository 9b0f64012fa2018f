//! Tracks files (`herdfit.tracks/1`: CSV + JSON sidecar) to and from column arrays.

use crate::errors::to_py;
use herdfit::data::tracks::{TrackRow, Tracks, TracksMeta};
use numpy::{IntoPyArray, PyArray1, PyArray2, PyReadonlyArray1, PyReadonlyArray2};
use pyo3::prelude::*;
use std::path::PathBuf;

pub type Columns<'py> = (
    String,
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray1<f64>>,
    Bound<'py, PyArray1<u64>>,
    Bound<'py, PyArray2<f64>>,
    Option<Bound<'py, PyArray2<f64>>>,
    Option<Vec<String>>,
);

/// The tracks file at `path` (CSV with sidecar, or any format herdfit reads as tracks):
/// (sidecar JSON, frame, time, id, pos `[n, 3]`, vel `[n, 3]` or None, roles or None).
#[pyfunction]
pub fn tracks_load(py: Python<'_>, path: PathBuf) -> PyResult<Columns<'_>> {
    let t = py
        .detach(|| Tracks::load(&path))
        .map_err(|e| to_py(py, e, None))?;
    Ok(columns(py, &t))
}

/// `t` as the columns [`tracks_load`] returns.
pub fn columns<'py>(py: Python<'py>, t: &Tracks) -> Columns<'py> {
    let n = t.rows.len();
    let meta = serde_json::to_string(&t.meta).unwrap_or_default();
    let frame: Vec<u64> = t.rows.iter().map(|r| r.frame).collect();
    let time: Vec<f64> = t.rows.iter().map(|r| r.time).collect();
    let id: Vec<u64> = t.rows.iter().map(|r| r.id).collect();
    let pos = ndarray::Array2::from_shape_fn((n, 3), |(i, k)| t.rows[i].pos[k]);
    let vel = t.has_velocity().then(|| {
        ndarray::Array2::from_shape_fn((n, 3), |(i, k)| t.rows[i].vel.map_or(f64::NAN, |v| v[k]))
    });
    let role = t.has_role().then(|| {
        t.rows
            .iter()
            .map(|r| r.role.clone().unwrap_or_default())
            .collect()
    });
    (
        meta,
        frame.into_pyarray(py),
        time.into_pyarray(py),
        id.into_pyarray(py),
        pos.into_pyarray(py),
        vel.map(|v| v.into_pyarray(py)),
        role,
    )
}

/// Writes a tracks file from columns (rows sorted by frame and id, checked, written atomically).
#[pyfunction]
#[pyo3(signature = (path, meta, frame, time, id, pos, vel=None))]
#[allow(clippy::too_many_arguments)]
pub fn tracks_save(
    py: Python<'_>,
    path: PathBuf,
    meta: &str,
    frame: PyReadonlyArray1<'_, u64>,
    time: PyReadonlyArray1<'_, f64>,
    id: PyReadonlyArray1<'_, u64>,
    pos: PyReadonlyArray2<'_, f64>,
    vel: Option<PyReadonlyArray2<'_, f64>>,
) -> PyResult<()> {
    let bad = |msg: String| to_py(py, herdfit::Error::config("tracks", msg), None);
    let meta: TracksMeta =
        serde_json::from_str(meta).map_err(|e| bad(format!("bad sidecar: {e}")))?;
    let (frame, time, id, pos) = (
        frame.as_array(),
        time.as_array(),
        id.as_array(),
        pos.as_array(),
    );
    let vel = vel.as_ref().map(|v| v.as_array());
    let n = frame.len();
    let d = pos.ncols();
    if time.len() != n || id.len() != n || pos.nrows() != n || !(2..=3).contains(&d) {
        return Err(bad(format!(
            "frame ({n}), time ({}), id ({}) and positions ({} × {d}, 2 or 3 columns) must have one row per animal and frame",
            time.len(), id.len(), pos.nrows()
        )));
    }
    if vel
        .as_ref()
        .is_some_and(|v| v.nrows() != n || v.ncols() != d)
    {
        return Err(bad("velocities must have the positions' shape".into()));
    }
    let take = |a: ndarray::ArrayView1<'_, f64>| {
        let mut out = [0.0; 3];
        for (o, x) in out.iter_mut().zip(a.iter()) {
            *o = *x;
        }
        out
    };
    let rows = (0..n)
        .map(|i| TrackRow {
            frame: frame[i],
            time: time[i],
            id: id[i],
            pos: take(pos.row(i)),
            vel: vel.as_ref().map(|v| take(v.row(i))),
            role: None,
        })
        .collect();
    py.detach(|| Tracks::new(meta, rows).and_then(|t| t.save(&path)))
        .map_err(|e| to_py(py, e, None))
}
