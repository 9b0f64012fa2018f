//! Import of the public Herds-From-Video extractor's text output (DESIGN §6):
//! `<PREFIX>_data_meta.txt`, `<PREFIX>_data_frame.txt` and (optionally) `<PREFIX>_data_cell.txt`.
//!
//! Their conventions: a square ground of `GroundSize` BL split into `Resolution` cells per side
//! (cell side = GroundSize / Resolution BL); cell indices `x, y` from the top-left, **y down**
//! (image rows); per cell `n` animals, mean velocity in BL/s (vy positive down the image), angle
//! mean/variance in degrees / degrees². We flip rows (`iy = Resolution − 1 − y`) and vy, turn n into
//! agents/BL² and degrees² into rad². `FrameTime` is seconds per frame.
//!
//! Speed–density rows are `label meanSpeed sem`; label L holds cells whose animal count n lies in
//! [L − 1, L) (only cells with n ≥ 0.5 are written), so we place it at n = L − 0.5 (0.75 for L = 1)
//! animals per cell. Rows `0 0` mark empty bins and are skipped.

use super::clip::{ClipFields, ClipMeta, ClipSpeed, FrameMeasures, Grid};
use crate::error::{Error, Result};
use ndarray::{Array2, Array3, Array4};
use std::path::{Path, PathBuf};

fn with_suffix(prefix: &Path, suffix: &str) -> PathBuf {
    let mut s = prefix.as_os_str().to_os_string();
    s.push(suffix);
    PathBuf::from(s)
}

/// The cell `x y` in tokens 1 and 2 of line `ln`, inside a `res × res` grid.
fn cell_xy(path: &Path, ln: usize, tok: &[&str], res: usize) -> Result<(usize, usize)> {
    let x: usize = num(path, ln, tok.get(1).copied(), "x")?;
    let y: usize = num(path, ln, tok.get(2).copied(), "y")?;
    if x >= res || y >= res {
        return Err(Error::file(
            path,
            format!("line {ln}: cell ({x}, {y}) is outside the {res}×{res} grid"),
        ));
    }
    Ok((x, y))
}

fn num<T: std::str::FromStr>(path: &Path, line: usize, tok: Option<&str>, what: &str) -> Result<T> {
    let t = tok.ok_or_else(|| Error::file(path, format!("line {line}: missing {what}")))?;
    t.parse::<T>().map_err(|_| {
        Error::file(
            path,
            format!("line {line}: {what} = '{t}' is not a valid number"),
        )
    })
}

fn finite(path: &Path, line: usize, v: f64, what: &str) -> Result<f64> {
    if v.is_finite() {
        Ok(v)
    } else {
        Err(Error::file(path, format!("line {line}: {what} is {v}")))
    }
}

fn read(path: &Path) -> Result<String> {
    crate::data::atomic::note_input(path);
    std::fs::read_to_string(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))
}

struct Meta {
    resolution: usize,
    ground: f64,
    frame_time: Option<f64>,
    total_frames: Option<usize>,
    speed: Option<(f64, f64)>,
    table: Vec<(f64, f64)>,
}

fn parse_meta(path: &Path) -> Result<Meta> {
    let text = read(path)?;
    let (mut res, mut ground, mut ft, mut total, mut speed) = (None, None, None, None, None);
    let mut table = Vec::new();
    let mut in_table = false;
    for (i, raw) in text.lines().enumerate() {
        let ln = i + 1;
        let tok: Vec<&str> = raw.split_whitespace().collect();
        if tok.is_empty() {
            continue;
        }
        if in_table {
            match tok.as_slice() {
                ["SDEND"] => in_table = false,
                ["0", "0"] => {}
                [label, v, _sem] => {
                    let l: u32 = num(path, ln, Some(label), "speed-density label")?;
                    let v: f64 = num(path, ln, Some(v), "speed-density speed")?;
                    table.push((l as f64, finite(path, ln, v, "speed")?));
                }
                _ => {
                    return Err(Error::file(
                        path,
                        format!(
                            "line {ln}: expected 'label speed sem' or SDEND, got '{}'",
                            raw.trim()
                        ),
                    ))
                }
            }
            continue;
        }
        match tok[0] {
            "Resolution" => res = Some(num::<usize>(path, ln, tok.get(1).copied(), "Resolution")?),
            "GroundSize" => {
                let g: f64 = num(path, ln, tok.get(1).copied(), "GroundSize")?;
                ground = Some(finite(path, ln, g, "GroundSize")?);
            }
            "FrameTime" => {
                let f: f64 = num(path, ln, tok.get(1).copied(), "FrameTime")?;
                ft = Some(finite(path, ln, f, "FrameTime")?);
            }
            "TotalFrameCount" => {
                total = Some(num::<usize>(
                    path,
                    ln,
                    tok.get(1).copied(),
                    "TotalFrameCount",
                )?)
            }
            "OverallAverageSpeed" => {
                let m: f64 = num(path, ln, tok.get(1).copied(), "OverallAverageSpeed")?;
                if tok.get(2) != Some(&"OverallAverageSpeedSTD") {
                    return Err(Error::file(
                        path,
                        format!("line {ln}: expected OverallAverageSpeedSTD after the mean"),
                    ));
                }
                let s: f64 = num(path, ln, tok.get(3).copied(), "OverallAverageSpeedSTD")?;
                speed = Some((
                    finite(path, ln, m, "speed")?,
                    finite(path, ln, s, "speed STD")?,
                ));
            }
            "SpeedVSDensity" => in_table = true,
            other => {
                return Err(Error::file(
                    path,
                    format!("line {ln}: unknown keyword '{other}'"),
                ))
            }
        }
    }
    if in_table {
        return Err(Error::file(path, "SpeedVSDensity block has no SDEND"));
    }
    let resolution = res.ok_or_else(|| Error::file(path, "missing Resolution"))?;
    let ground = ground.ok_or_else(|| Error::file(path, "missing GroundSize"))?;
    if resolution == 0 || ground <= 0.0 {
        return Err(Error::file(path, "Resolution and GroundSize must be > 0"));
    }
    crate::limits::check_grid("Resolution", resolution, resolution).map_err(|e| e.in_file(path))?;
    if ft.is_some_and(|f| f <= 0.0) {
        return Err(Error::file(path, "FrameTime must be > 0"));
    }
    Ok(Meta {
        resolution,
        ground,
        frame_time: ft,
        total_frames: total,
        speed,
        table,
    })
}

/// Per-frame sparse rows: (x, y, n, optional (vx, vy, angVar)).
type Row = (usize, usize, f64, Option<(f64, f64, f64)>);

/// A frame header: the frame number and, when given, `AverageSpeed`, `Polarization` and
/// `AngularMomentum`.
type Header = (u64, Option<[f64; 3]>);

/// The measures of a `Frame` line after its number (`AverageSpeed a Polarization p
/// AngularMomentum m`), when all three are there.
fn header_measures(path: &Path, ln: usize, tok: &[&str]) -> Result<Option<[f64; 3]>> {
    let mut out = [None; 3];
    for pair in tok[2..].chunks(2) {
        let k = match pair[0] {
            "AverageSpeed" => 0,
            "Polarization" => 1,
            "AngularMomentum" => 2,
            other => {
                return Err(Error::file(
                    path,
                    format!("line {ln}: unknown frame measure '{other}'"),
                ))
            }
        };
        let v: f64 = num(path, ln, pair.get(1).copied(), pair[0])?;
        out[k] = Some(finite(path, ln, v, pair[0])?);
    }
    Ok(match out {
        [Some(a), Some(p), Some(m)] => Some([a, p, m]),
        _ => None,
    })
}

fn parse_frames(path: &Path, res: usize) -> Result<(Vec<Vec<Row>>, Vec<Header>)> {
    let text = read(path)?;
    let mut frames: Vec<Vec<Row>> = Vec::new();
    let mut headers: Vec<Header> = Vec::new();
    let mut last: Option<(u64, usize)> = None;
    for (i, raw) in text.lines().enumerate() {
        let ln = i + 1;
        let tok: Vec<&str> = raw.split_whitespace().collect();
        if tok.is_empty() {
            continue;
        }
        match tok[0] {
            "Frame" => {
                let f: u64 = num(path, ln, tok.get(1).copied(), "frame number")?;
                if let Some((g, at)) = last.filter(|&(g, _)| f <= g) {
                    let what = if f == g { "repeats" } else { "comes after" };
                    return Err(Error::file(
                        path,
                        format!("line {ln}: Frame {f} {what} Frame {g} (line {at}): frame numbers must increase"),
                    ));
                }
                last = Some((f, ln));
                frames.push(Vec::new());
                headers.push((f, header_measures(path, ln, &tok)?));
            }
            "Data" => {
                let Some(frame) = frames.last_mut() else {
                    return Err(Error::file(
                        path,
                        format!("line {ln}: Data row before any Frame line"),
                    ));
                };
                if tok.len() != 4 && tok.len() != 10 {
                    return Err(Error::file(
                        path,
                        format!(
                            "line {ln}: a Data row has 3 or 9 values, found {}",
                            tok.len() - 1
                        ),
                    ));
                }
                let (x, y) = cell_xy(path, ln, &tok, res)?;
                let n: f64 = num(path, ln, tok.get(3).copied(), "n")?;
                if !(n.is_finite() && n >= 0.0) {
                    return Err(Error::file(
                        path,
                        format!("line {ln}: n = {n} must be finite and ≥ 0"),
                    ));
                }
                let rest = if tok.len() == 10 {
                    let mut v = [0.0; 6];
                    let names = ["vxMean", "vxVar", "vyMean", "vyVar", "angMean", "angVar"];
                    for (k, name) in names.iter().enumerate() {
                        let val: f64 = num(path, ln, tok.get(4 + k).copied(), name)?;
                        v[k] = finite(path, ln, val, name)?;
                    }
                    if v[5] < 0.0 {
                        return Err(Error::file(
                            path,
                            format!("line {ln}: angVar = {} must be ≥ 0", v[5]),
                        ));
                    }
                    Some((v[0], v[2], v[5]))
                } else {
                    None
                };
                frame.push((x, y, n, rest));
            }
            other => {
                return Err(Error::file(
                    path,
                    format!("line {ln}: unknown keyword '{other}'"),
                ))
            }
        }
    }
    if frames.is_empty() {
        return Err(Error::file(path, "no Frame lines: the clip is empty"));
    }
    Ok((frames, headers))
}

fn parse_cells(path: &Path, res: usize) -> Result<Array2<u8>> {
    let mut obstacles = Array2::<u8>::zeros((res, res));
    if !path.exists() {
        return Ok(obstacles);
    }
    let text = read(path)?;
    let mut block: Option<&str> = None;
    for (i, raw) in text.lines().enumerate() {
        let ln = i + 1;
        let tok: Vec<&str> = raw.split_whitespace().collect();
        if tok.is_empty() {
            continue;
        }
        let cell = |tok: &[&str], want: usize| -> Result<(usize, usize)> {
            if tok.len() != want {
                return Err(Error::file(
                    path,
                    format!("line {ln}: expected {} values after {}", want - 1, tok[0]),
                ));
            }
            cell_xy(path, ln, tok, res)
        };
        match (block, tok[0]) {
            (None, "NonAccessibleGrid") => block = Some("NAG"),
            (None, "GuidanceField") => block = Some("GF"),
            (Some("NAG"), "NAGEND") | (Some("GF"), "GFEND") => block = None,
            (Some("NAG"), "NAG") => {
                let (x, y) = cell(&tok, 3)?;
                obstacles[[res - 1 - y, x]] = 1;
            }
            (Some("GF"), "GF") => {
                // The guidance field is the time-averaged velocity; fitting rebuilds it from the
                // fields, so only its format is checked here.
                cell(&tok, 5)?;
                for (k, name) in ["fx", "fy"].iter().enumerate() {
                    let v: f64 = num(path, ln, tok.get(3 + k).copied(), name)?;
                    finite(path, ln, v, name)?;
                }
            }
            (_, other) => {
                return Err(Error::file(
                    path,
                    format!("line {ln}: unexpected '{other}'"),
                ))
            }
        }
    }
    if block.is_some() {
        return Err(Error::file(
            path,
            "a block is not closed (NAGEND/GFEND missing)",
        ));
    }
    Ok(obstacles)
}

/// Reads `<prefix>_data_meta.txt`, `<prefix>_data_frame.txt` and, if present,
/// `<prefix>_data_cell.txt` into clip fields.
pub fn import_reference(prefix: &Path) -> Result<ClipFields> {
    let meta_path = with_suffix(prefix, "_data_meta.txt");
    let frame_path = with_suffix(prefix, "_data_frame.txt");
    let cell_path = with_suffix(prefix, "_data_cell.txt");
    let meta = parse_meta(&meta_path)?;
    let res = meta.resolution;
    let (frames, headers) = parse_frames(&frame_path, res)?;
    // The extractor's own per-frame measures, when every frame states them.
    let frame_measures = headers
        .iter()
        .all(|h| h.1.is_some())
        .then(|| FrameMeasures {
            frame: headers.iter().map(|h| h.0).collect(),
            average_speed: headers.iter().filter_map(|h| h.1.map(|m| m[0])).collect(),
            polarization: headers.iter().filter_map(|h| h.1.map(|m| m[1])).collect(),
            angular_momentum: headers.iter().filter_map(|h| h.1.map(|m| m[2])).collect(),
        });
    // Density, two velocity components and direction variance per cell and frame (f32), before
    // any of them is allocated: a Resolution within the grid limit can still ask for more memory
    // than there is over many frames.
    let cells = (res as f64) * (res as f64);
    crate::limits::check_memory(
        "Resolution",
        &format!("{} frames of {res}×{res} cells", frames.len()),
        frames.len() as f64 * cells * 16.0,
    )
    .map_err(|e| e.in_file(&meta_path))?;
    let obstacles = parse_cells(&cell_path, res)?;
    let cell = meta.ground / res as f64;
    let area = cell * cell;
    let nf = frames.len();
    let mut density = Array3::<f32>::zeros((nf, res, res));
    let mut velocity = Array4::<f32>::zeros((nf, res, res, 2));
    let mut dir_variance = Array3::<f32>::zeros((nf, res, res));
    let deg2 = (std::f64::consts::PI / 180.0).powi(2);
    for (f, rows) in frames.iter().enumerate() {
        for &(x, y, n, rest) in rows {
            let iy = res - 1 - y;
            density[[f, iy, x]] = (n / area) as f32;
            if let Some((vx, vy, ang_var)) = rest {
                velocity[[f, iy, x, 0]] = vx as f32;
                velocity[[f, iy, x, 1]] = (-vy) as f32;
                dir_variance[[f, iy, x]] = (ang_var * deg2) as f32;
            }
        }
    }
    let density_table = meta
        .table
        .iter()
        .map(|&(label, v)| {
            let n = if label <= 1.0 { 0.75 } else { label - 0.5 };
            [n / area, v]
        })
        .collect();
    let (mean, std) = meta.speed.unwrap_or((0.0, 0.0));
    let clip = ClipFields {
        meta: ClipMeta {
            frame_measures,
            provenance: serde_json::json!({
                "source": "import-reference",
                "prefix": prefix.display().to_string(),
                "frame_time_given": meta.frame_time.is_some(),
                "total_frame_count": meta.total_frames,
            }),
            ..ClipMeta::of_grid(
                &Grid {
                    origin: [0.0, 0.0],
                    cell_size: cell,
                    nx: res,
                    ny: res,
                },
                meta.frame_time.map_or(1.0, |t| 1.0 / t),
                nf,
                ClipSpeed {
                    mean,
                    std,
                    density_table,
                },
            )
        },
        density,
        velocity,
        dir_variance,
        obstacles,
    };
    clip.validate().map_err(|e| e.in_file(&frame_path))?;
    Ok(clip)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write_set(dir: &Path, meta: &str, frame: &str, cell: Option<&str>) -> PathBuf {
        let p = dir.join("clip");
        std::fs::write(with_suffix(&p, "_data_meta.txt"), meta).unwrap();
        std::fs::write(with_suffix(&p, "_data_frame.txt"), frame).unwrap();
        if let Some(c) = cell {
            std::fs::write(with_suffix(&p, "_data_cell.txt"), c).unwrap();
        }
        p
    }

    const META: &str = "Resolution 4\nGroundSize 8\nFrameTime 0.04\nTotalFrameCount 2\nOverallAverageSpeed 1.5 OverallAverageSpeedSTD 0.25 \nSpeedVSDensity\n1 1.8 0.1\n0 0\n3 1.2 0.1\nSDEND\n";

    /// The message of the error importing `prefix`.
    fn error_of(prefix: &Path) -> String {
        import_reference(prefix).unwrap_err().to_string()
    }

    #[test]
    fn crlf_files_import_as_the_lf_ones_with_the_frame_measures() {
        let dir = tempfile::tempdir().unwrap();
        let frame = "Frame 11 AverageSpeed 1.5 Polarization 0.97 AngularMomentum 0.01 \nData 1 0 2.0 1.0 0.1 -0.5 0.1 3.0 4.0\nData 2 3 0.0 0.5 0.1 0.0 0.1 1.0 1.0\nFrame 12 AverageSpeed 1.6 Polarization 0.98 AngularMomentum 0.02 \nData 1 1 1.0 1.0 0.1 0.0 0.1 0.0 2.0\n";
        let cell = "NonAccessibleGrid \nNAG 3 3\nNAGEND\nGuidanceField\nGF 1 0 1.0 0.0\nGFEND\n";
        let lf_dir = dir.path().join("lf");
        let crlf_dir = dir.path().join("crlf");
        std::fs::create_dir_all(&lf_dir).unwrap();
        std::fs::create_dir_all(&crlf_dir).unwrap();
        let crlf = |t: &str| t.replace('\n', "\r\n");
        let a = import_reference(&write_set(&lf_dir, META, frame, Some(cell))).unwrap();
        let b = import_reference(&write_set(
            &crlf_dir,
            &crlf(META),
            &crlf(frame),
            Some(&crlf(cell)),
        ))
        .unwrap();
        let strip = |mut c: ClipFields| {
            c.meta.provenance = serde_json::Value::Null;
            c
        };
        let (a, b) = (strip(a), strip(b));
        assert_eq!(a, b);
        // Row y = 0 is the top of the image: the bottom row of the clip, vy flipped.
        assert_eq!(a.density[[0, 3, 1]], 2.0 / 4.0);
        assert_eq!(a.velocity[[0, 3, 1, 1]], 0.5);
        assert_eq!(a.obstacles[[0, 3]], 1);
        let fm = a.meta.frame_measures.unwrap();
        assert_eq!(fm.frame, vec![11, 12]);
        assert_eq!(fm.polarization, vec![0.97, 0.98]);
        assert_eq!(fm.angular_momentum, vec![0.01, 0.02]);
        assert_eq!(fm.average_speed, vec![1.5, 1.6]);
    }

    #[test]
    fn malformed_rows_name_the_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = write_set(dir.path(), META, "Frame 1 \nData 0 0 2.0 1 0 1\n", None);
        let e = error_of(&p);
        assert!(e.contains("_data_frame.txt") && e.contains("line 2"), "{e}");
        let p = write_set(dir.path(), META, "Data 0 0 2.0\n", None);
        assert!(error_of(&p).contains("before any Frame"));
        let p = write_set(dir.path(), META, "Frame 1\nData 9 0 2.0\n", None);
        assert!(error_of(&p).contains("outside"));
        let p = write_set(dir.path(), META, "Frame 1\nData 0 0 x\n", None);
        assert!(error_of(&p).contains("n = 'x'"));
        let bad_meta = "Resolution 4\nGroundSize eight\n";
        let p = write_set(dir.path(), bad_meta, "Frame 1\n", None);
        let e = error_of(&p);
        assert!(e.contains("_data_meta.txt") && e.contains("line 2"), "{e}");
        let p = write_set(dir.path(), "GroundSize 8\n", "Frame 1\n", None);
        assert!(error_of(&p).contains("missing Resolution"));
        let p = write_set(
            dir.path(),
            META,
            "Frame 1\n",
            Some("NonAccessibleGrid\nNAG 1\nNAGEND\n"),
        );
        let e = error_of(&p);
        assert!(e.contains("_data_cell.txt") && e.contains("line 2"), "{e}");
        let p = write_set(dir.path(), META, "", None);
        assert!(error_of(&p).contains("empty"));
        let e = import_reference(&dir.path().join("nope"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("nope_data_meta.txt") && e.contains("cannot read"),
            "{e}"
        );
    }
}
