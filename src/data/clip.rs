//! Clip fields (paper §4, DESIGN §3, §6): per-frame density, mean velocity and direction variance
//! on a grid of square cells, plus obstacle cells and the clip's speed statistics. They are the
//! contract between video extraction, fitting and validation.
//!
//! On disk a clip is a folder: `fields.npz` (`density [F,ny,nx] f32` agents/BL², `velocity
//! [F,ny,nx,2] f32` BL/s, `dir_variance [F,ny,nx] f32` rad², `obstacles [ny,nx] u8`) and
//! `clip.json` (schema `herdfit.clip/1`). Row 0 of every grid is the bottom row (y up); cell
//! `(ix, iy)` covers `origin + [ix, ix+1) × [iy, iy+1) · cell_size`.

use crate::data::atomic::AtomicDir;
use crate::error::{Error, Result};
use ndarray::{Array2, Array3, Array4};
use ndarray_npy::{NpzReader, NpzWriter};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Width of an animal's body in body lengths (its length is 1): rendered videos draw bodies as
/// ellipses of 1 × 0.4 BL, and extraction estimates the body pixels per animal and the size of its
/// morphological opening from it.
pub const BODY_WIDTH_BL: f64 = 0.4;

/// Schema tag of `clip.json`.
pub const CLIP_SCHEMA: &str = "herdfit.clip/1";

/// A grid of `nx × ny` square cells of side `cell_size` (BL), lower-left corner at `origin`.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Grid {
    pub origin: [f64; 2],
    pub cell_size: f64,
    pub nx: usize,
    pub ny: usize,
}

impl Grid {
    /// Area of one cell (BL²).
    pub fn cell_area(&self) -> f64 {
        self.cell_size * self.cell_size
    }

    /// The cell holding `p`, if inside.
    pub fn cell_of(&self, p: [f64; 2]) -> Option<(usize, usize)> {
        let fx = (p[0] - self.origin[0]) / self.cell_size;
        let fy = (p[1] - self.origin[1]) / self.cell_size;
        if !(fx >= 0.0 && fy >= 0.0 && fx < self.nx as f64 && fy < self.ny as f64) {
            return None;
        }
        Some((fx as usize, fy as usize))
    }

    /// Centre of cell `(ix, iy)`.
    pub fn centre(&self, ix: usize, iy: usize) -> [f64; 2] {
        [
            self.origin[0] + (ix as f64 + 0.5) * self.cell_size,
            self.origin[1] + (iy as f64 + 0.5) * self.cell_size,
        ]
    }

    /// Width and height (BL).
    pub fn size(&self) -> [f64; 2] {
        [
            self.nx as f64 * self.cell_size,
            self.ny as f64 * self.cell_size,
        ]
    }
}

/// Speed statistics of a clip (§6.2).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipSpeed {
    /// v_μ (BL/s).
    pub mean: f64,
    /// v_σ (BL/s): the per-animal standard deviation.
    pub std: f64,
    /// `[density (agents/BL²), mean speed (BL/s)]` rows, density increasing.
    #[serde(default)]
    pub density_table: Vec<[f64; 2]>,
}

/// `clip.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClipMeta {
    pub schema: String,
    pub fps: f64,
    /// Cell side (BL).
    pub cell_size: f64,
    pub nx: usize,
    pub ny: usize,
    pub frames: usize,
    /// World position of the grid's lower-left corner (BL).
    #[serde(default)]
    pub origin: [f64; 2],
    /// Body length in video pixels, when the clip came from a video.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body_length_px: Option<f64>,
    /// Body pixels per animal, when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub body_pixel_coverage: Option<f64>,
    pub speed: ClipSpeed,
    /// The spread of the animals' directions (rad² about their mean; π²/3 when uniform) when it
    /// was given rather than measured: a still image's `extract --dir-variance`, or one frame of
    /// `synth --random-headings`. E_var (eq. 8) then targets, in each cell, the expected
    /// direction variance of the *simulated* animals in it for that spread
    /// ([`crate::measure::dir_variance::SampleVariance`]), not the value for the image's count.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dir_spread: Option<f64>,
    /// The video's own per-frame measures, when its extractor computed them (the public
    /// Herds-From-Video extractor's frame headers, kept by `import-reference`): the targets of
    /// the reference's polarization and angular momentum ([`crate::measure::reference`]).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub frame_measures: Option<FrameMeasures>,
    /// Where the clip came from (command, source files, settings).
    #[serde(default)]
    pub provenance: serde_json::Value,
}

/// Measures an extractor computed for every frame of a clip (from the body pixels' flow).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FrameMeasures {
    /// The extractor's frame numbers.
    pub frame: Vec<u64>,
    /// Mean speed of the body pixels (BL/s).
    pub average_speed: Vec<f64>,
    /// Polarization (eq. 12) of the body pixels' flow.
    pub polarization: Vec<f64>,
    /// Angular momentum (eq. 13) of the body pixels' flow about their centroid.
    pub angular_momentum: Vec<f64>,
}

impl ClipMeta {
    /// The meta of a clip of `frames` frames at `fps` on `grid` with speed statistics `speed`;
    /// no body size, direction spread, frame measures or provenance (set them after).
    pub fn of_grid(grid: &super::Grid, fps: f64, frames: usize, speed: ClipSpeed) -> ClipMeta {
        ClipMeta {
            schema: CLIP_SCHEMA.into(),
            fps,
            cell_size: grid.cell_size,
            nx: grid.nx,
            ny: grid.ny,
            frames,
            origin: grid.origin,
            body_length_px: None,
            body_pixel_coverage: None,
            speed,
            dir_spread: None,
            frame_measures: None,
            provenance: serde_json::Value::Null,
        }
    }

    /// The temporal window (frames) over which the clip's velocities were averaged: the extraction's
    /// `smooth` setting for clips extracted from video, 1 otherwise.
    pub fn velocity_window(&self) -> usize {
        let p = &self.provenance;
        if p["source"] == "extract" {
            p["settings"]["smooth"].as_u64().unwrap_or(9).max(1) as usize
        } else if p["source"] == "import-tracks" {
            p["settings"]["smooth"].as_u64().unwrap_or(1).max(1) as usize
        } else {
            1
        }
    }
}

/// A clip's fields in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct ClipFields {
    pub meta: ClipMeta,
    /// Agents per BL², `[F, ny, nx]`.
    pub density: Array3<f32>,
    /// Mean velocity (BL/s), `[F, ny, nx, 2]`.
    pub velocity: Array4<f32>,
    /// Variance of the angle between each animal's direction and its cell's mean direction
    /// (rad²), `[F, ny, nx]`.
    pub dir_variance: Array3<f32>,
    /// 1 for an obstacle (non-accessible) cell, `[ny, nx]`.
    pub obstacles: Array2<u8>,
}

impl ClipFields {
    /// The grid of the clip.
    pub fn grid(&self) -> Grid {
        Grid {
            origin: self.meta.origin,
            cell_size: self.meta.cell_size,
            nx: self.meta.nx,
            ny: self.meta.ny,
        }
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.meta.frames
    }

    /// Agents in frame `f` (Σ density × cell area).
    pub fn count(&self, f: usize) -> f64 {
        let a = self.meta.cell_size * self.meta.cell_size;
        self.density
            .index_axis(ndarray::Axis(0), f)
            .iter()
            .map(|&d| d as f64 * a)
            .sum()
    }

    /// Checks shapes and values; messages name the array or key.
    pub fn validate(&self) -> Result<()> {
        let m = &self.meta;
        super::check_schema(&m.schema, CLIP_SCHEMA)
            .map_err(|e| Error::invalid(format!("clip.json: {e}")))?;
        use crate::limits::{FPS_RANGE, MAX_COORD, MAX_DENSITY, MAX_SPEED};
        if !(m.fps.is_finite() && (FPS_RANGE.0..=FPS_RANGE.1).contains(&m.fps)) {
            return Err(Error::invalid(format!(
                "clip.json: fps = {} is outside {}..={}",
                m.fps, FPS_RANGE.0, FPS_RANGE.1
            )));
        }
        crate::limits::check_grid("nx, ny", m.nx, m.ny)
            .map_err(|e| Error::invalid(format!("clip.json: {e}")))?;
        let extent = m.cell_size * m.nx.max(m.ny) as f64;
        if !(extent <= MAX_COORD
            && m.origin[0].abs() <= MAX_COORD
            && m.origin[1].abs() <= MAX_COORD)
        {
            return Err(Error::invalid(format!(
                "clip.json: origin {:?} and cell_size {} put the grid beyond ±{MAX_COORD} BL",
                m.origin, m.cell_size
            )));
        }
        if !(m.cell_size.is_finite() && m.cell_size > 0.0) {
            return Err(Error::invalid(format!(
                "clip.json: cell_size = {} must be > 0",
                m.cell_size
            )));
        }
        if m.nx == 0 || m.ny == 0 || m.frames == 0 {
            return Err(Error::invalid(format!(
                "clip.json: empty clip (nx = {}, ny = {}, frames = {})",
                m.nx, m.ny, m.frames
            )));
        }
        if !(m.origin[0].is_finite() && m.origin[1].is_finite()) {
            return Err(Error::invalid("clip.json: origin must be finite"));
        }
        for (k, v) in [("speed.mean", m.speed.mean), ("speed.std", m.speed.std)] {
            if !(v.is_finite() && (0.0..=MAX_SPEED).contains(&v)) {
                return Err(Error::invalid(format!(
                    "clip.json: {k} = {v} must be in [0, {MAX_SPEED}]"
                )));
            }
        }
        for (r, row) in m.speed.density_table.iter().enumerate() {
            if !(row[0].is_finite() && row[1].is_finite() && row[0] >= 0.0 && row[1] >= 0.0)
                || (r > 0 && row[0] < m.speed.density_table[r - 1][0])
            {
                return Err(Error::invalid(format!(
                    "clip.json: speed.density_table[{r}] = {row:?} (finite, ≥ 0, density increasing)"
                )));
            }
        }
        if let Some(v) = m.dir_spread {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!(
                    "clip.json: dir_spread = {v} (rad², finite and ≥ 0)"
                )));
            }
        }
        if let Some(fm) = &m.frame_measures {
            for (k, len) in [
                ("frame", fm.frame.len()),
                ("average_speed", fm.average_speed.len()),
                ("polarization", fm.polarization.len()),
                ("angular_momentum", fm.angular_momentum.len()),
            ] {
                if len != m.frames {
                    return Err(Error::invalid(format!(
                        "clip.json: frame_measures.{k} holds {len} values for {} frames",
                        m.frames
                    )));
                }
            }
            for (k, v) in [
                ("average_speed", &fm.average_speed),
                ("polarization", &fm.polarization),
                ("angular_momentum", &fm.angular_momentum),
            ] {
                if let Some((i, x)) = v
                    .iter()
                    .enumerate()
                    .find(|(_, x)| !(x.is_finite() && **x >= 0.0))
                {
                    return Err(Error::invalid(format!(
                        "clip.json: frame_measures.{k}[{i}] = {x} (finite, ≥ 0)"
                    )));
                }
            }
        }
        let (f, ny, nx) = (m.frames, m.ny, m.nx);
        let check = |name: &str, got: &[usize], want: &[usize]| -> Result<()> {
            if got != want {
                return Err(Error::invalid(format!(
                    "fields.npz: {name} has shape {got:?}, clip.json says {want:?}"
                )));
            }
            Ok(())
        };
        check("density", self.density.shape(), &[f, ny, nx])?;
        check("velocity", self.velocity.shape(), &[f, ny, nx, 2])?;
        check("dir_variance", self.dir_variance.shape(), &[f, ny, nx])?;
        check("obstacles", self.obstacles.shape(), &[ny, nx])?;
        let bad = |name: &str, idx: Vec<usize>, v: f32, what: &str| {
            Error::invalid(format!("fields.npz: {name}{idx:?} = {v} {what}"))
        };
        for (name, a) in [
            ("density", &self.density),
            ("dir_variance", &self.dir_variance),
        ] {
            let insane = |v: f32| !(v.is_finite() && (0.0..=MAX_DENSITY as f32).contains(&v));
            if let Some((i, &v)) = a.indexed_iter().find(|(_, v)| insane(**v)) {
                return Err(bad(
                    name,
                    vec![i.0, i.1, i.2],
                    v,
                    &format!("(must be finite, in [0, {MAX_DENSITY}])"),
                ));
            }
        }
        for (i, &v) in self.velocity.indexed_iter() {
            if !(v.is_finite() && f64::from(v).abs() <= MAX_SPEED) {
                return Err(bad(
                    "velocity",
                    vec![i.0, i.1, i.2, i.3],
                    v,
                    &format!("(must be finite, within ±{MAX_SPEED})"),
                ));
            }
        }
        if let Some(((iy, ix), v)) = self.obstacles.indexed_iter().find(|(_, &v)| v > 1) {
            return Err(Error::invalid(format!(
                "fields.npz: obstacles[{iy}, {ix}] = {v} (must be 0 or 1)"
            )));
        }
        Ok(())
    }

    /// Writes `dir/fields.npz` and `dir/clip.json`, plus extra files, all-or-nothing: the folder
    /// is assembled beside `dir` and renamed into place.
    pub fn save(&self, dir: &Path, extra: &[(&str, Vec<u8>)]) -> Result<()> {
        self.validate().map_err(|e| e.in_file(dir))?;
        let out = AtomicDir::create(dir)?;
        let mut buf = std::io::Cursor::new(Vec::new());
        {
            let mut npz = NpzWriter::new(&mut buf);
            let fail = |e: ndarray_npy::WriteNpzError| {
                Error::file(dir, format!("writing fields.npz: {e}"))
            };
            npz.add_array("density", &self.density).map_err(fail)?;
            npz.add_array("velocity", &self.velocity).map_err(fail)?;
            npz.add_array("dir_variance", &self.dir_variance)
                .map_err(fail)?;
            npz.add_array("obstacles", &self.obstacles).map_err(fail)?;
            npz.finish().map_err(fail)?;
        }
        out.write("fields.npz", buf.get_ref())?;
        let json = serde_json::to_string_pretty(&self.meta)
            .map_err(|e| Error::Internal(format!("serialising clip.json: {e}")))?;
        out.write("clip.json", format!("{json}\n").as_bytes())?;
        for (name, bytes) in extra {
            out.write(name, bytes)?;
        }
        out.commit()
    }

    /// Reads and validates a clip folder.
    pub fn load(dir: &Path) -> Result<ClipFields> {
        crate::data::atomic::note_input(dir);
        if !dir.is_dir() {
            return Err(Error::file(
                dir,
                "not a clip folder (missing or not a directory)",
            ));
        }
        let meta_path = dir.join("clip.json");
        let text = std::fs::read_to_string(&meta_path)
            .map_err(|e| Error::file(&meta_path, format!("cannot read: {e}")))?;
        let meta: ClipMeta = serde_json::from_str(&text)
            .map_err(|e| Error::file(&meta_path, format!("not a {CLIP_SCHEMA} file: {e}")))?;
        let npz_path = dir.join("fields.npz");
        check_npz_sizes(&npz_path)?;
        let file = std::fs::File::open(&npz_path)
            .map_err(|e| Error::file(&npz_path, format!("cannot read: {e}")))?;
        let mut npz = NpzReader::new(file)
            .map_err(|e| Error::file(&npz_path, format!("not a valid npz archive: {e}")))?;
        let fail = |name: &str, e: ndarray_npy::ReadNpzError| {
            Error::file(&npz_path, format!("array '{name}': {e}"))
        };
        let density: Array3<f32> = npz.by_name("density").map_err(|e| fail("density", e))?;
        let velocity: Array4<f32> = npz.by_name("velocity").map_err(|e| fail("velocity", e))?;
        let dir_variance: Array3<f32> = npz
            .by_name("dir_variance")
            .map_err(|e| fail("dir_variance", e))?;
        let obstacles: Array2<u8> = npz.by_name("obstacles").map_err(|e| fail("obstacles", e))?;
        let clip = ClipFields {
            meta,
            density,
            velocity,
            dir_variance,
            obstacles,
        };
        clip.validate().map_err(|e| e.in_file(dir))?;
        Ok(clip)
    }
}

/// Most header bytes of an npy array read, preamble included (NumPy's own default limit is
/// 10,000).
const NPY_MAX_HEADER: usize = 65_536;

/// Every array of a clip's `fields.npz`: its npy header read first and the bytes its shape and
/// element type claim checked against the memory limit, before ndarray-npy allocates them (a
/// damaged header — one flipped digit of a shape — can claim gigabytes; issue #14).
fn check_npz_sizes(path: &Path) -> Result<()> {
    let file =
        std::fs::File::open(path).map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let Ok(mut zip) = zip::ZipArchive::new(file) else {
        // Not an archive: ndarray-npy's reader says so in its own words.
        return Ok(());
    };
    let mut total = 0f64;
    for i in 0..zip.len() {
        let Ok(mut entry) = zip.by_index(i) else {
            continue;
        };
        let name = entry.name().trim_end_matches(".npy").to_string();
        // The preamble first (magic, version, header length: u16 in version 1, u32 after): a
        // damaged version byte turns two bytes of the header text into a length of hundreds of
        // megabytes, which ndarray-npy's header reader would allocate. NumPy itself reads at
        // most 10,000 header bytes unless told otherwise.
        let bad = |m: String| Error::file(path, format!("array '{name}': {m}"));
        let mut head = vec![0u8; 10];
        std::io::Read::read_exact(&mut entry, &mut head).map_err(|e| bad(e.to_string()))?;
        if &head[..6] != b"\x93NUMPY" {
            return Err(bad("not an npy array (no npy magic)".into()));
        }
        let len = match head[6] {
            1 => 10 + u16::from_le_bytes([head[8], head[9]]) as usize,
            2 | 3 => {
                head.resize(12, 0);
                std::io::Read::read_exact(&mut entry, &mut head[10..])
                    .map_err(|e| bad(e.to_string()))?;
                12 + u32::from_le_bytes([head[8], head[9], head[10], head[11]]) as usize
            }
            v => return Err(bad(format!("npy version {v} is not 1, 2 or 3"))),
        };
        if len > NPY_MAX_HEADER {
            return Err(bad(format!(
                "its npy header claims {len} bytes (at most {NPY_MAX_HEADER})"
            )));
        }
        // Only the header: reading on to the end would check the data's CRC here already.
        let done = head.len();
        head.resize(len, 0);
        std::io::Read::read_exact(&mut entry, &mut head[done..]).map_err(|e| bad(e.to_string()))?;
        let header = ndarray_npy::npy::header::Header::from_reader(&mut &head[..])
            .map_err(|e| Error::file(path, format!("array '{name}': {e}")))?;
        // The descriptor as its Python literal, e.g. '<f4' or '|u1': the element's byte size.
        let descr = header.type_descriptor.to_string();
        let elem = descr
            .trim_matches(|c: char| !c.is_ascii_digit())
            .parse::<f64>()
            .unwrap_or(8.0);
        let n = header.shape.iter().fold(1f64, |a, &d| a * d as f64);
        total += n * elem;
    }
    crate::limits::check_memory("fields.npz", "reading its arrays", total)
        .map_err(|e| e.in_file(path))
}

/// Checks a given spread of directions (rad² about their mean, [`ClipMeta::dir_spread`]): angles
/// within ±π of their mean spread at most π²; the error names `key`.
pub fn check_dir_spread(key: &str, v: f64) -> Result<()> {
    if v.is_finite() && (0.0..=std::f64::consts::PI.powi(2)).contains(&v) {
        Ok(())
    } else {
        Err(Error::config(
            key,
            format!("{v} rad² is out of range 0..=π² (9.87)"),
        ))
    }
}
