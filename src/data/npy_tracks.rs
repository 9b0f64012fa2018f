//! Trajectories saved by idtracker.ai and trajectorytools as `.npy` files, read into
//! [`Tracks`] (pixels, y down, as in the video).
//!
//! Two layouts are accepted:
//! - the trackers' own file: a 0-d object array holding a pickled dict with `trajectories`
//!   (`[frames, animals, 2]` float64, NaN where an animal was not found), `frames_per_second`
//!   and, in trajectorytools' files, `body_length` and `setup_points` (the arena `border`);
//! - a plain numeric array `[frames, animals, 2]` (float64 or float32), as
//!   `np.save(path, t["trajectories"])` writes it; the frame rate must then be given.
//!
//! The pickle is decoded by serde-pickle with numpy's globals replaced by `None`: an ndarray
//! arrives as the state tuple `(version, shape, dtype, fortran, raw bytes)` of its
//! `__setstate__`, whose dtype object is lost, so the element type is inferred from the byte
//! count (8 bytes: float64, or int64 when the values read as float64 are subnormal; 4: float32;
//! little-endian, what both trackers write). numpy scalars
//! (trajectorytools' `body_length`) do not survive that replacement; the body length is then
//! asked of the caller.

use crate::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
use crate::error::{Error, Result};
use serde_pickle::{HashableValue, Value};
use std::path::Path;

/// What a trajectories `.npy` holds.
#[derive(Clone, Debug)]
pub struct NpyTrajectories {
    /// Positions in pixels (y down), one row per tracked animal and frame (NaN frames skipped).
    pub tracks: Tracks,
    /// Body length in pixels, when the file records one.
    pub body_length_px: Option<f64>,
    /// The arena border polygon in pixels (trajectorytools' `setup_points.border`), if any.
    pub border: Option<Vec<[f64; 2]>>,
    /// Animals and frames of the array (before NaN rows were dropped).
    pub shape: [usize; 2],
}

/// A numeric array decoded from a pickled ndarray state.
struct Array {
    shape: Vec<usize>,
    data: Vec<f64>,
}

fn array_of(v: &Value, path: &Path, what: &str) -> Result<Array> {
    let bad = |m: &str| Error::file(path, format!("{what}: {m}"));
    let Value::Tuple(t) = v else {
        return Err(bad("not an ndarray"));
    };
    if t.len() != 5 {
        return Err(bad("not an ndarray state"));
    }
    let Value::Tuple(dims) = &t[1] else {
        return Err(bad("no shape"));
    };
    let shape: Vec<usize> = dims
        .iter()
        .map(|d| match d {
            Value::I64(n) if *n >= 0 => Ok(*n as usize),
            _ => Err(bad("shape is not a tuple of sizes")),
        })
        .collect::<Result<_>>()?;
    if matches!(t[3], Value::Bool(true)) {
        return Err(bad("Fortran-ordered arrays are not supported"));
    }
    let Value::Bytes(raw) = &t[4] else {
        return Err(bad("no raw data"));
    };
    let n = shape
        .iter()
        .try_fold(1usize, |a, &d| a.checked_mul(d))
        .ok_or_else(|| bad(&format!("shape {shape:?} overflows")))?;
    let data = decode_floats(raw, n).ok_or_else(|| {
        bad(&format!(
            "{} bytes for {n} elements: not float64 or float32",
            raw.len()
        ))
    })?;
    Ok(Array { shape, data })
}

/// Little-endian float64 or float32 values, told apart by the byte count; 8-byte words with
/// subnormal float64 values are int64.
fn decode_floats(raw: &[u8], n: usize) -> Option<Vec<f64>> {
    if n == 0 {
        return Some(Vec::new());
    }
    match raw.len() / n {
        8 if raw.len() == 8 * n => {
            let words = raw.chunks_exact(8).map(|c| c.try_into().expect("8 bytes"));
            let f: Vec<f64> = words.clone().map(f64::from_le_bytes).collect();
            // Small int64 values (trajectorytools' pixel `border`) read as float64 are subnormal;
            // real coordinates never are.
            if f.iter().any(|x| x.is_subnormal()) {
                Some(words.map(|w| i64::from_le_bytes(w) as f64).collect())
            } else {
                Some(f)
            }
        }
        4 if raw.len() == 4 * n => Some(
            raw.chunks_exact(4)
                .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")) as f64)
                .collect(),
        ),
        _ => None,
    }
}

fn get<'a>(
    d: &'a std::collections::BTreeMap<HashableValue, Value>,
    key: &str,
) -> Option<&'a Value> {
    d.get(&HashableValue::String(key.into()))
}

/// The `.npy` header's end offset and its text.
fn header(bytes: &[u8], path: &Path) -> Result<(usize, String)> {
    if bytes.len() < 10 || &bytes[..6] != b"\x93NUMPY" {
        return Err(Error::file(path, "not a .npy file (no \\x93NUMPY magic)"));
    }
    let (len, start) = match bytes[6] {
        1 => (u16::from_le_bytes([bytes[8], bytes[9]]) as usize, 10usize),
        2 | 3 if bytes.len() >= 12 => (
            u32::from_le_bytes([bytes[8], bytes[9], bytes[10], bytes[11]]) as usize,
            12,
        ),
        v => return Err(Error::file(path, format!("unsupported .npy version {v}"))),
    };
    let end = start
        .checked_add(len)
        .filter(|&e| e <= bytes.len())
        .ok_or_else(|| Error::file(path, "truncated .npy header"))?;
    Ok((
        end,
        String::from_utf8_lossy(&bytes[start..end]).into_owned(),
    ))
}

/// The shape a plain array's header declares, checked against the bytes that follow it before
/// anything is allocated (issue #47: a header declaring 10^6 × 10^6 × 2 aborted the reader).
fn check_declared(head: &str, body: usize, path: &Path) -> Result<()> {
    let bad = |m: String| Error::file(path, m);
    let shape_text = head
        .split_once("'shape':")
        .and_then(|(_, r)| r.split_once('(')?.1.split_once(')'))
        .map(|(inside, _)| inside)
        .ok_or_else(|| bad("the .npy header has no shape".into()))?;
    let mut n: usize = 1;
    let mut dims = Vec::new();
    for d in shape_text
        .split(',')
        .map(str::trim)
        .filter(|d| !d.is_empty())
    {
        let v: usize = d
            .parse()
            .map_err(|_| bad(format!("the .npy header's shape has '{d}'")))?;
        dims.push(v);
        n = n.saturating_mul(v);
    }
    let item = if head.contains("f4") { 4 } else { 8 };
    let need = n.saturating_mul(item);
    if need != body {
        return Err(bad(format!(
            "the header declares shape {dims:?} ({need} bytes) but {body} bytes follow it"
        )));
    }
    crate::limits::check_memory("trajectories", "reading the .npy array", need as f64 * 2.0)
        .map_err(|e| e.in_file(path))
}

/// Reads a trajectories `.npy` (either layout, see the module docs). `fps` overrides the file's
/// `frames_per_second` and is required for plain arrays.
pub fn read_npy_trajectories(path: &Path, fps: Option<f64>) -> Result<NpyTrajectories> {
    crate::data::atomic::note_input(path);
    let bytes = std::fs::read(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let (end, head) = header(&bytes, path)?;
    let (traj, file_fps, body, border) = if head.contains("'|O'") {
        let opts = serde_pickle::DeOptions::new().replace_unresolved_globals();
        let v: Value = serde_pickle::value_from_slice(&bytes[end..], opts)
            .map_err(|e| Error::file(path, format!("cannot decode the pickled dict: {e}")))?;
        // A 0-d object array: (1, (), dtype, False, [dict]).
        let dict = match &v {
            Value::Tuple(t) if t.len() == 5 => match &t[4] {
                Value::List(l) if l.len() == 1 => match &l[0] {
                    Value::Dict(d) => Some(d),
                    _ => None,
                },
                _ => None,
            },
            _ => None,
        }
        .ok_or_else(|| Error::file(path, "the object array does not hold one dict"))?;
        let traj = get(dict, "trajectories")
            .ok_or_else(|| Error::file(path, "the dict has no 'trajectories'"))?;
        let traj = array_of(traj, path, "trajectories")?;
        let file_fps = match get(dict, "frames_per_second") {
            Some(Value::I64(n)) => Some(*n as f64),
            Some(Value::F64(x)) => Some(*x),
            _ => None,
        };
        let body = match get(dict, "body_length") {
            Some(Value::F64(x)) => Some(*x),
            _ => None,
        };
        let border = match get(dict, "setup_points") {
            Some(Value::Dict(sp)) => match get(sp, "border") {
                Some(b) => {
                    let a = array_of(b, path, "setup_points.border")?;
                    (a.shape.len() == 2 && a.shape[1] == 2 && a.shape[0] >= 3)
                        .then(|| a.data.chunks_exact(2).map(|c| [c[0], c[1]]).collect())
                }
                None => None,
            },
            _ => None,
        };
        (traj, file_fps, body, border)
    } else {
        check_declared(&head, bytes.len() - end, path)?;
        let arr: ndarray::ArrayD<f64> = match ndarray_npy::read_npy(path) {
            Ok(a) => a,
            Err(_) => {
                let a: ndarray::ArrayD<f32> = ndarray_npy::read_npy(path)
                    .map_err(|e| Error::file(path, format!("not a float64/float32 array: {e}")))?;
                a.mapv(f64::from)
            }
        };
        let shape = arr.shape().to_vec();
        let data = arr.as_standard_layout().iter().copied().collect();
        (Array { shape, data }, None, None, None)
    };
    if traj.shape.len() != 3 || traj.shape[2] != 2 {
        return Err(Error::file(
            path,
            format!(
                "trajectories have shape {:?}, expected [frames, animals, 2]",
                traj.shape
            ),
        ));
    }
    let fps = fps
        .or(file_fps)
        .ok_or_else(|| Error::config("fps", "the file records no frame rate: give it"))?;
    if !(fps.is_finite() && fps > 0.0) {
        return Err(Error::config("fps", format!("{fps} must be positive")));
    }
    let (nf, na) = (traj.shape[0], traj.shape[1]);
    let mut rows = Vec::new();
    for f in 0..nf {
        for a in 0..na {
            let i = (f * na + a) * 2;
            let (x, y) = (traj.data[i], traj.data[i + 1]);
            if x.is_finite() && y.is_finite() {
                rows.push(TrackRow {
                    frame: f as u64,
                    time: f as f64 / fps,
                    id: a as u64,
                    pos: [x, y, 0.0],
                    vel: None,
                    role: None,
                });
            }
        }
    }
    if rows.is_empty() {
        return Err(Error::file(path, "no finite positions in the trajectories"));
    }
    let mut meta = TracksMeta::new(Units::Pixels, fps, 2);
    meta.provenance = serde_json::json!({ "source": path.display().to_string(), "format": "npy" });
    let tracks = Tracks::new(meta, rows).map_err(|e| e.in_file(path))?;
    Ok(NpyTrajectories {
        tracks,
        body_length_px: body,
        border,
        shape: [nf, na],
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn floats_are_told_apart_by_byte_count() {
        let raw: Vec<u8> = [1.5f64, -2.0]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        assert_eq!(decode_floats(&raw, 2), Some(vec![1.5, -2.0]));
        let raw: Vec<u8> = [0.25f32, 4.0]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        assert_eq!(decode_floats(&raw, 2), Some(vec![0.25, 4.0]));
        assert_eq!(decode_floats(&raw[..7], 2), None);
        let raw: Vec<u8> = [2019i64, 158]
            .iter()
            .flat_map(|x| x.to_le_bytes())
            .collect();
        assert_eq!(decode_floats(&raw, 2), Some(vec![2019.0, 158.0]));
    }

    #[test]
    fn a_plain_array_needs_a_frame_rate_and_keeps_nan_gaps_out() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("t.npy");
        let mut a = ndarray::Array3::<f64>::zeros((3, 2, 2));
        a[[0, 0, 0]] = 10.0;
        a[[1, 1, 0]] = f64::NAN;
        ndarray_npy::write_npy(&p, &a).unwrap();
        let e = read_npy_trajectories(&p, None).unwrap_err().to_string();
        assert!(e.contains("fps"), "{e}");
        let t = read_npy_trajectories(&p, Some(25.0)).unwrap();
        assert_eq!(t.tracks.rows.len(), 5, "6 positions, one NaN");
        assert_eq!(t.shape, [3, 2]);
        assert_eq!(t.tracks.rows[0].pos, [10.0, 0.0, 0.0]);
        assert_eq!(t.tracks.rows[4].time, 2.0 / 25.0);
    }
}
