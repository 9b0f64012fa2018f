//! `herdfit.tracks/1`: trajectories of individuals, 2D or 3D, shared by every system.
//!
//! A tracks file is a CSV with a header, one row per animal per frame:
//!
//! ```text
//! frame,time,id,x,y[,z][,vx,vy[,vz]][,role]
//! ```
//!
//! and an optional JSON sidecar beside it with the same stem (`flock.csv` → `flock.json`):
//!
//! ```json
//! {"schema": "herdfit.tracks/1", "units": "m", "fps": 2.5, "dimension": 2, "provenance": {…}}
//! ```
//!
//! Columns are found by name (any order; unknown columns are ignored), rows are ordered by frame
//! (non-decreasing) and a `(frame, id)` pair appears at most once. Without a sidecar, the units are
//! body lengths, the dimension follows from the presence of a `z` column and the frame rate from
//! the `time` column, so the `TRAJ.csv` files of `herdfit simulate` read as they are.
//!
//! Coordinates: in `BL` and `m` the axes are x right, y up (z up in 3D); in `px` they are image
//! coordinates, x right and y **down**, origin at the top-left corner of the image.

use crate::data::csv::Table;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// Schema tag of tracks sidecars.
pub const TRACKS_SCHEMA: &str = "herdfit.tracks/1";

/// Length unit of a tracks file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Units {
    /// Body lengths (the herd model's unit), y up.
    #[serde(rename = "BL")]
    BodyLengths,
    /// Metres, y up.
    #[serde(rename = "m")]
    Metres,
    /// Image pixels, y down.
    #[serde(rename = "px")]
    Pixels,
}

impl Units {
    /// The unit as written in the sidecar.
    pub fn as_str(self) -> &'static str {
        match self {
            Units::BodyLengths => "BL",
            Units::Metres => "m",
            Units::Pixels => "px",
        }
    }
}

/// The sidecar of a tracks file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TracksMeta {
    /// Always [`TRACKS_SCHEMA`].
    pub schema: String,
    /// Length unit of positions (velocities are in that unit per second).
    pub units: Units,
    /// Frames per second (`time = frame / fps` up to the first frame's offset).
    pub fps: f64,
    /// 2 or 3.
    pub dimension: u8,
    /// Where the tracks came from (free-form JSON).
    #[serde(default)]
    pub provenance: serde_json::Value,
}

impl TracksMeta {
    /// A sidecar for new tracks.
    pub fn new(units: Units, fps: f64, dimension: u8) -> Self {
        TracksMeta {
            schema: TRACKS_SCHEMA.into(),
            units,
            fps,
            dimension,
            provenance: serde_json::Value::Null,
        }
    }

    /// Checks the schema tag, the frame rate and the dimension; errors name the key.
    pub fn check(&self) -> Result<()> {
        crate::data::check_schema(&self.schema, TRACKS_SCHEMA).map_err(Error::invalid)?;
        if !(self.fps.is_finite() && self.fps > 0.0 && self.fps <= 1e6) {
            return Err(Error::invalid(format!(
                "fps = {} must be in (0, 1e6]",
                crate::limits::show(self.fps)
            )));
        }
        if self.dimension != 2 && self.dimension != 3 {
            return Err(Error::invalid(format!(
                "dimension = {} must be 2 or 3",
                self.dimension
            )));
        }
        Ok(())
    }
}

/// One animal in one frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackRow {
    pub frame: u64,
    /// Seconds.
    pub time: f64,
    pub id: u64,
    /// Position; `pos[2]` is 0 in 2D.
    pub pos: [f64; 3],
    /// Velocity (units per second) when the file has one; `vel[2]` is 0 in 2D.
    pub vel: Option<[f64; 3]>,
    /// A free-form role (`leader`, `follower`, a behaviour name) when the file has one.
    pub role: Option<String>,
}

/// A whole tracks file: sidecar plus rows ordered by `(frame, id)`.
#[derive(Clone, Debug, PartialEq)]
pub struct Tracks {
    pub meta: TracksMeta,
    pub rows: Vec<TrackRow>,
}

/// The sidecar path of a tracks CSV: same folder and stem, extension `json`.
pub fn sidecar_path(csv: &Path) -> PathBuf {
    csv.with_extension("json")
}

impl Tracks {
    /// Tracks from rows in any order; sorts them by `(frame, id)` and checks them.
    pub fn new(meta: TracksMeta, mut rows: Vec<TrackRow>) -> Result<Self> {
        rows.sort_by_key(|r| (r.frame, r.id));
        let t = Tracks { meta, rows };
        t.check()?;
        Ok(t)
    }

    /// Checks the sidecar and the rows: finite values, one row per `(frame, id)`, one time per
    /// frame, time increasing with frame, z = 0 in 2D. Errors name the key or row.
    pub fn check(&self) -> Result<()> {
        self.meta.check()?;
        self.check_rows()
    }

    /// Checks the rows (see [`Tracks::check`]): every value finite and within the limits of
    /// [`crate::limits`] (positions ±[`MAX_COORD`](crate::limits::MAX_COORD), velocities
    /// ±[`MAX_SPEED`](crate::limits::MAX_SPEED) per second, times ±1e9 s).
    pub fn check_rows(&self) -> Result<()> {
        use crate::limits::{beyond, not_finite, MAX_COORD, MAX_SPEED};
        let m = &self.meta;
        let has_vel = self.rows.first().is_some_and(|r| r.vel.is_some());
        let has_role = self.rows.first().is_some_and(|r| r.role.is_some());
        let mut prev: Option<&TrackRow> = None;
        for (i, r) in self.rows.iter().enumerate() {
            let row = i + 1;
            let bad = |what: &str| {
                Error::invalid(format!(
                    "row {row} (frame {}, id {}): {what}",
                    r.frame, r.id
                ))
            };
            let value = |name: &str, v: f64, max: f64| {
                if !v.is_finite() {
                    Err(bad(&format!("{name} = {}", not_finite(v))))
                } else if v.abs() > max {
                    Err(bad(&format!("{name} = {}", beyond(v, max))))
                } else {
                    Ok(())
                }
            };
            value("time", r.time, 1e9)?;
            for (name, v) in ["x", "y", "z"].into_iter().zip(r.pos) {
                value(name, v, MAX_COORD)?;
            }
            if m.dimension == 2 && r.pos[2] != 0.0 {
                return Err(bad("z given in 2D tracks"));
            }
            if r.vel.is_some() != has_vel || r.role.is_some() != has_role {
                return Err(bad("columns differ from the first row's"));
            }
            if let Some(v) = r.vel {
                for (name, c) in ["vx", "vy", "vz"].into_iter().zip(v) {
                    value(name, c, MAX_SPEED)?;
                }
            }
            if let Some(p) = prev {
                if (r.frame, r.id) <= (p.frame, p.id) {
                    return Err(bad(if r.frame == p.frame && r.id == p.id {
                        "duplicate (frame, id)"
                    } else {
                        "rows not ordered by (frame, id)"
                    }));
                }
                if r.frame == p.frame && r.time != p.time {
                    return Err(bad(&format!(
                        "time {} differs from {} earlier in the same frame",
                        r.time, p.time
                    )));
                }
                if r.frame > p.frame && r.time <= p.time {
                    return Err(bad(&format!(
                        "time {} does not increase with the frame (previous frame at {})",
                        r.time, p.time
                    )));
                }
            }
            prev = Some(r);
        }
        Ok(())
    }

    /// Whether the rows carry velocities.
    pub fn has_velocity(&self) -> bool {
        self.rows.first().is_some_and(|r| r.vel.is_some())
    }

    /// Whether the rows carry roles.
    pub fn has_role(&self) -> bool {
        self.rows.first().is_some_and(|r| r.role.is_some())
    }

    /// The distinct ids, ascending.
    pub fn ids(&self) -> Vec<u64> {
        let mut ids: Vec<u64> = self.rows.iter().map(|r| r.id).collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    /// Row indices per frame, frames ascending.
    pub fn frames(&self) -> Vec<(u64, std::ops::Range<usize>)> {
        let mut out = Vec::new();
        let mut start = 0;
        for i in 1..=self.rows.len() {
            if i == self.rows.len() || self.rows[i].frame != self.rows[start].frame {
                out.push((self.rows[start].frame, start..i));
                start = i;
            }
        }
        out
    }

    /// Row indices per id (each list ordered by frame).
    pub fn by_id(&self) -> BTreeMap<u64, Vec<usize>> {
        let mut m: BTreeMap<u64, Vec<usize>> = BTreeMap::new();
        for (i, r) in self.rows.iter().enumerate() {
            m.entry(r.id).or_default().push(i);
        }
        m
    }

    /// The CSV text (header + rows, shortest round-trip floats, so the bytes depend only on the
    /// values).
    pub fn to_csv(&self) -> String {
        use std::fmt::Write as _;
        let three = self.meta.dimension == 3;
        let mut head = String::from("frame,time,id,x,y");
        if three {
            head.push_str(",z");
        }
        if self.has_velocity() {
            head.push_str(if three { ",vx,vy,vz" } else { ",vx,vy" });
        }
        if self.has_role() {
            head.push_str(",role");
        }
        let mut s = head;
        s.push('\n');
        for r in &self.rows {
            let _ = write!(
                s,
                "{},{},{},{},{}",
                r.frame, r.time, r.id, r.pos[0], r.pos[1]
            );
            if three {
                let _ = write!(s, ",{}", r.pos[2]);
            }
            if let Some(v) = r.vel {
                let _ = write!(s, ",{},{}", v[0], v[1]);
                if three {
                    let _ = write!(s, ",{}", v[2]);
                }
            }
            if let Some(role) = &r.role {
                let _ = write!(s, ",{role}");
            }
            s.push('\n');
        }
        s
    }

    /// Writes `path` (CSV) and its sidecar, each atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.check().map_err(|e| e.in_file(path))?;
        if crate::data::atomic::is_stdout(path) {
            return Err(crate::data::atomic::stdout::not_a_stream(
                path,
                "a tracks file (CSV + sidecar)",
            ));
        }
        let side = sidecar_path(path);
        if side == path {
            return Err(Error::file(path, "a tracks CSV must not end in .json"));
        }
        let json = serde_json::to_string_pretty(&self.meta)
            .map_err(|e| Error::Internal(format!("tracks sidecar: {e}")))?;
        crate::data::atomic::write_atomic(path, self.to_csv().as_bytes())?;
        crate::data::atomic::write_atomic(&side, format!("{json}\n").as_bytes())
    }

    /// Reads a tracks CSV and its sidecar (when present; see the module docs for the defaults
    /// without one).
    pub fn load(path: &Path) -> Result<Tracks> {
        Ok(Self::read(path, false)?.0)
    }

    /// [`Tracks::load`] for trackers' output with lost animals: a row whose position or velocity
    /// is missing (`NaN` or an empty field) is left out, as if the animal were not tracked in
    /// that frame, and counted (the second value). A file whose every row is missing is an error.
    pub fn load_with_gaps(path: &Path) -> Result<(Tracks, usize)> {
        Self::read(path, true)
    }

    fn read(path: &Path, gaps: bool) -> Result<(Tracks, usize)> {
        crate::data::atomic::note_input(path);
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let side = sidecar_path(path);
        let meta = if side != path && side.is_file() {
            crate::data::atomic::note_input(&side);
            let s = std::fs::read_to_string(&side)
                .map_err(|e| Error::file(&side, format!("cannot read: {e}")))?;
            let m: TracksMeta = serde_json::from_str(&s)
                .map_err(|e| Error::file(&side, format!("not a tracks sidecar: {e}")))?;
            // A bad sidecar value is the sidecar's error, not the CSV's (issue #47).
            m.check().map_err(|e| e.in_file(&side))?;
            Some(m)
        } else {
            None
        };
        let (rows, has_z, missing) = parse_csv(path, &text, gaps)?;
        let meta = match meta {
            Some(m) => {
                if has_z != (m.dimension == 3) {
                    return Err(Error::file(
                        &side,
                        format!(
                            "dimension = {} but {} has {} z column",
                            m.dimension,
                            path.display(),
                            if has_z { "a" } else { "no" }
                        ),
                    ));
                }
                m
            }
            None => {
                // Rows first (their errors say more than a missing frame rate), then the rate.
                let provisional =
                    TracksMeta::new(Units::BodyLengths, 1.0, if has_z { 3 } else { 2 });
                let t = Tracks {
                    meta: provisional,
                    rows,
                };
                t.check().map_err(|e| e.in_file(path))?;
                let rows = t.rows;
                let meta = TracksMeta::new(
                    Units::BodyLengths,
                    infer_fps(&rows).ok_or_else(|| {
                        Error::file(
                            path,
                            format!(
                            "no sidecar {} and the frame rate cannot be read off the time column",
                            side.display()
                        ),
                        )
                    })?,
                    if has_z { 3 } else { 2 },
                );
                let t = Tracks { meta, rows };
                t.check().map_err(|e| e.in_file(path))?;
                return Ok((t, missing));
            }
        };
        let t = Tracks { meta, rows };
        t.check().map_err(|e| e.in_file(path))?;
        Ok((t, missing))
    }
}

/// Frames per second from rows ordered by frame: (frame difference) / (time difference) between
/// the first and the last frame, when both differ.
fn infer_fps(rows: &[TrackRow]) -> Option<f64> {
    let (a, b) = (rows.first()?, rows.last()?);
    let df = b.frame.checked_sub(a.frame)? as f64;
    let dt = b.time - a.time;
    (df > 0.0 && dt > 0.0 && dt.is_finite()).then(|| df / dt)
}

/// The rows of a tracks CSV, whether it has a z column, and (with `gaps`) how many rows were
/// left out for a missing position or velocity.
fn parse_csv(path: &Path, text: &str, gaps: bool) -> Result<(Vec<TrackRow>, bool, usize)> {
    let table = Table::parse(path, text, "frame,time,id,x,y,…")?;
    let (find, need) = (|name: &str| table.find(name), |name: &str| table.need(name));
    let (c_frame, c_time, c_id, c_x, c_y) = (
        need("frame")?,
        need("time")?,
        need("id")?,
        need("x")?,
        need("y")?,
    );
    let c_z = find("z");
    let (c_vx, c_vy, c_vz) = (find("vx"), find("vy"), find("vz"));
    if c_vx.is_some() != c_vy.is_some() {
        return Err(Error::file(path, "header has one of vx, vy but not both"));
    }
    if c_vz.is_some() && (c_z.is_none() || c_vx.is_none()) {
        return Err(Error::file(path, "header has vz without z and vx, vy"));
    }
    if c_z.is_some() && c_vx.is_some() && c_vz.is_none() {
        return Err(Error::file(path, "3D tracks with vx, vy need vz too"));
    }
    let c_role = find("role");
    let mut rows = Vec::new();
    let (mut missing, mut last_frame) = (0usize, None::<u64>);
    for r in table.records() {
        let line_no = r.line();
        let (get, int) = (
            |c: usize, name: &str| r.get(c, name),
            |c: usize, name: &str| r.int(c, name),
        );
        // A value; with `gaps`, `None` when missing (the row is then left out).
        let num = |c: usize, name: &str| -> Result<Option<f64>> {
            match gaps {
                true => r.num_or_missing(c, name),
                false => r.num(c, name).map(Some),
            }
        };
        let frame = int(c_frame, "frame")?;
        if let Some(p) = last_frame.filter(|&p| frame < p) {
            return Err(Error::file(
                path,
                format!(
                    "line {line_no}: frame {frame} after frame {p} (rows must be ordered by frame)"
                ),
            ));
        }
        last_frame = Some(frame);
        let z = match c_z {
            Some(c) => num(c, "z")?,
            None => Some(0.0),
        };
        let vel = match (c_vx, c_vy) {
            (Some(a), Some(b)) => {
                let vz = match c_vz {
                    Some(c) => num(c, "vz")?,
                    None => Some(0.0),
                };
                match (num(a, "vx")?, num(b, "vy")?, vz) {
                    (Some(x), Some(y), Some(z)) => Some(Some([x, y, z])),
                    _ => Some(None),
                }
            }
            _ => None,
        };
        let role = match c_role {
            Some(c) => Some(get(c, "role")?.to_string()),
            None => None,
        };
        let (x, y, time) = (num(c_x, "x")?, num(c_y, "y")?, r.num(c_time, "time")?);
        let id = int(c_id, "id")?;
        let (Some(x), Some(y), Some(z), Some(vel)) =
            (x, y, z, vel.map_or(Some(None), |v| v.map(Some)))
        else {
            missing += 1;
            continue;
        };
        rows.push(TrackRow {
            frame,
            time,
            id,
            pos: [x, y, z],
            vel,
            role,
        });
    }
    if rows.is_empty() {
        return Err(Error::file(
            path,
            match missing {
                0 => "no rows (empty tracks)".to_string(),
                m => format!(
                    "every row ({m}) has a missing position or velocity: nothing is tracked"
                ),
            },
        ));
    }
    // Within a frame the file may list ids in any order; duplicates are caught by `check`.
    rows.sort_by_key(|r| (r.frame, r.id));
    Ok((rows, c_z.is_some(), missing))
}

/// Reads the ETH/UCY pedestrian text format: whitespace-separated `frame id x y` rows, no header,
/// positions in metres. Video frames are numbered in steps of `frame_step` (10 in the standard
/// files, one row every 0.4 s); they become consecutive frames `frame / frame_step` at
/// `fps` (2.5 in the standard files). Rows may come in any order.
pub fn read_eth_ucy(path: &Path, fps: f64) -> Result<Tracks> {
    crate::data::atomic::note_input(path);
    if !(fps.is_finite() && fps > 0.0) {
        return Err(Error::invalid(format!("fps = {fps} must be positive")));
    }
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let mut raw: Vec<(f64, f64, f64, f64)> = Vec::new();
    for (ln, line) in text.lines().enumerate() {
        let f: Vec<&str> = line.split_whitespace().collect();
        if f.is_empty() {
            continue;
        }
        if f.len() != 4 {
            return Err(Error::file(
                path,
                format!(
                    "line {}: expected 4 fields (frame id x y), found {}",
                    ln + 1,
                    f.len()
                ),
            ));
        }
        let v = crate::data::csv::frame_id_row(path, ln, &f, ["frame", "id", "x", "y"])?;
        raw.push((v[0], v[1], v[2], v[3]));
    }
    if raw.is_empty() {
        return Err(Error::file(path, "no rows (empty tracks)"));
    }
    let mut frames: Vec<u64> = raw.iter().map(|r| r.0 as u64).collect();
    frames.sort_unstable();
    frames.dedup();
    let step = frames
        .windows(2)
        .map(|w| w[1] - w[0])
        .fold(0u64, gcd)
        .max(1);
    let first = frames[0];
    let rows = raw
        .iter()
        .map(|&(fr, id, x, y)| {
            let frame = (fr as u64 - first) / step;
            TrackRow {
                frame,
                time: frame as f64 / fps,
                id: id as u64,
                pos: [x, y, 0.0],
                vel: None,
                role: None,
            }
        })
        .collect();
    let mut meta = TracksMeta::new(Units::Metres, fps, 2);
    meta.provenance = serde_json::json!({
        "format": "eth-ucy",
        "source": path.display().to_string(),
        "first_video_frame": first,
        "video_frames_per_frame": step,
    });
    Tracks::new(meta, rows).map_err(|e| e.in_file(path))
}

fn gcd(a: u64, b: u64) -> u64 {
    if b == 0 {
        a
    } else {
        gcd(b, a % b)
    }
}

#[cfg(test)]
mod tests;
