//! `herdfit import-tracks`: tracked trajectories → clip fields, so that the herd model can be
//! fitted to animals someone else tracked (issue #15).
//!
//! Inputs: a `herdfit.tracks/1` CSV, the ETH/UCY text format, or an idtracker.ai /
//! trajectorytools `.npy` ([`crate::data::npy_tracks`]). Positions become body lengths with
//! y up (pixels ÷ body length in pixels, y flipped; metres ÷ body length in metres). Velocities
//! are the file's own when it has them, else central differences (p(f+1) − p(f−1)) / 2Δt,
//! one-sided next to a gap or an end, then averaged over `smooth` frames like the extraction's
//! velocities (§6.1); a position with no tracked neighbour frame gets velocity 0. An animal lost for some frames keeps its other frames. The fields are the
//! same rasterisation as synthetic clips ([`crate::measure::rasterise`]): density (agents/BL²),
//! mean velocity (BL/s), direction variance, speed model. The clip folder also gets the animals
//! in its own coordinates and frames, `tracks.csv`, for `fit --tracks`.

use crate::data::agents::AgentRow;
use crate::data::clip::{ClipFields, Grid};
use crate::data::npy_tracks::read_npy_trajectories;
use crate::data::tracks::{read_eth_ucy, Tracks, Units};
use crate::error::{Error, Result};
use crate::measure::rasterise;
use ndarray::Array2;
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;
use std::path::PathBuf;

/// Which reader a file goes through.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TracksFormat {
    /// By extension: `.npy` → npy, `.csv` → tracks, anything else → ETH/UCY text.
    #[default]
    Auto,
    Tracks,
    EthUcy,
    Npy,
}
enum_names!(TracksFormat { Auto = "auto", Tracks = "tracks", EthUcy = "eth-ucy", Npy = "npy" });

/// Which cells become obstacles.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Arena {
    /// None: every cell is open.
    #[default]
    Open,
    /// Cells no animal entered in any imported frame.
    Unvisited,
    /// Cells whose centre lies outside this polygon (in the input's units and axes).
    Polygon(Vec<[f64; 2]>),
    /// The arena border the file records (trajectorytools' `setup_points.border`).
    Border,
}

/// Settings of an import.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ImportTracksConfig {
    pub format: TracksFormat,
    /// Frames per second: required for ETH/UCY text (2.5 in the standard files) and plain
    /// `.npy` arrays; overrides what a file records.
    pub fps: Option<f64>,
    /// Body length in pixels (tracks in pixels).
    pub body_length_px: Option<f64>,
    /// Body length in metres (tracks in metres).
    pub body_length_m: Option<f64>,
    /// Cells along the longer side of the tracks' bounding box.
    pub grid: usize,
    /// Cell side in BL (overrides `grid`).
    pub cell_size: Option<f64>,
    /// Frames used, `[a, b)` counted from the first tracked frame.
    pub frames: Option<(usize, usize)>,
    /// Frames over which velocities are averaged (odd, ≥ 1).
    pub smooth: usize,
    pub arena: Arena,
}

impl Default for ImportTracksConfig {
    fn default() -> Self {
        ImportTracksConfig {
            format: TracksFormat::Auto,
            fps: None,
            body_length_px: None,
            body_length_m: None,
            grid: 32,
            cell_size: None,
            frames: None,
            smooth: 1,
            arena: Arena::Open,
        }
    }
}

fn positive(key: &str, v: Option<f64>) -> Result<()> {
    match v {
        Some(x) if !(x.is_finite() && x > 0.0) => {
            Err(Error::config(key, format!("{x} must be a positive number")))
        }
        _ => Ok(()),
    }
}

impl ImportTracksConfig {
    /// Checks the settings; errors name the key.
    pub fn check(&self) -> Result<()> {
        positive("fps", self.fps)?;
        positive("body_length_px", self.body_length_px)?;
        positive("body_length_m", self.body_length_m)?;
        positive("cell_size", self.cell_size)?;
        // Physical ranges (issue #47: 1e300 was accepted or divided densities into infinities).
        use crate::limits::{check_fps, check_magnitude};
        if let Some(f) = self.fps {
            check_fps("fps", f)?;
        }
        if let Some(l) = self.body_length_px {
            check_magnitude("body_length_px", l, 65536.0)?;
        }
        if let Some(l) = self.body_length_m {
            // The longest animal is a blue whale (30 m); 1 km leaves room for any unit slip.
            check_magnitude("body_length_m", l, 1e3)?;
        }
        if let Some(c) = self.cell_size {
            check_magnitude("cell_size", c, 1e6)?;
        }
        if self.grid == 0 || self.grid > 4096 {
            return Err(Error::config("grid", "must be in 1..=4096"));
        }
        if self.smooth == 0 || self.smooth % 2 == 0 {
            return Err(Error::config("smooth", "must be odd and ≥ 1"));
        }
        if let Some((a, b)) = self.frames {
            if a + 1 >= b {
                return Err(Error::config(
                    "frames",
                    format!("{a}..{b} holds < 2 frames"),
                ));
            }
        }
        if let Arena::Polygon(p) = &self.arena {
            if p.len() < 3 || p.iter().flatten().any(|x| !x.is_finite()) {
                return Err(Error::config("arena", "a polygon needs ≥ 3 finite points"));
            }
        }
        Ok(())
    }
}

/// An import: the file in, the clip folder out.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ImportTracksJob {
    pub input: PathBuf,
    pub out: PathBuf,
    pub config: ImportTracksConfig,
}

/// What an import produced.
#[derive(Clone, Debug)]
pub struct ImportSummary {
    pub out: PathBuf,
    pub frames: usize,
    pub animals: usize,
    /// Mean animals per frame inside the grid.
    pub mean_count: f64,
    pub nx: usize,
    pub ny: usize,
    pub cell_size: f64,
    pub fps: f64,
    /// v_μ and v_σ of the clip's speed model (BL/s).
    pub speed: [f64; 2],
    pub obstacle_cells: usize,
}

impl std::fmt::Display for ImportSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "import-tracks: {} animals, {} frames at {} fps, {:.2} per frame; {}×{} cells of {:.4} BL ({} obstacle); speed {:.3} ± {:.3} BL/s; wrote {}",
            self.animals,
            self.frames,
            self.fps,
            self.mean_count,
            self.nx,
            self.ny,
            self.cell_size,
            self.obstacle_cells,
            self.speed[0],
            self.speed[1],
            self.out.display()
        )
    }
}

/// Tracks with the body length in pixels and the arena border the file may record.
type Loaded = (Tracks, Option<f64>, Option<Vec<[f64; 2]>>);

/// The file read by the chosen reader, with the border and body length it may record.
fn load(job: &ImportTracksJob) -> Result<Loaded> {
    let cfg = &job.config;
    let p = &job.input;
    let ext = p.extension().and_then(|e| e.to_str()).unwrap_or("");
    let format = match cfg.format {
        TracksFormat::Auto if ext.eq_ignore_ascii_case("npy") => TracksFormat::Npy,
        TracksFormat::Auto if ext.eq_ignore_ascii_case("csv") => TracksFormat::Tracks,
        TracksFormat::Auto => TracksFormat::EthUcy,
        f => f,
    };
    match format {
        TracksFormat::Npy => {
            let t = read_npy_trajectories(p, cfg.fps)?;
            Ok((t.tracks, t.body_length_px, t.border))
        }
        TracksFormat::Tracks => Ok((Tracks::load(p)?, None, None)),
        _ => {
            let fps = cfg.fps.ok_or_else(|| {
                Error::config(
                    "fps",
                    "ETH/UCY text records no frame rate: give it (2.5 in the standard files)",
                )
            })?;
            Ok((read_eth_ucy(p, fps)?, None, None))
        }
    }
}

/// Scale from the file's units to BL and the sign of y (−1 for pixels, y down).
fn to_body_lengths(
    units: Units,
    cfg: &ImportTracksConfig,
    recorded: Option<f64>,
) -> Result<(f64, f64, Option<f64>)> {
    match units {
        Units::BodyLengths => Ok((1.0, 1.0, None)),
        Units::Metres => {
            let bl = cfg.body_length_m.ok_or_else(|| {
                Error::config(
                    "body_length_m",
                    "the tracks are in metres: give the body length in metres",
                )
            })?;
            Ok((1.0 / bl, 1.0, None))
        }
        Units::Pixels => {
            let bl = cfg.body_length_px.or(recorded).ok_or_else(|| {
                Error::config(
                    "body_length_px",
                    "the tracks are in pixels and the file records no body length: give it",
                )
            })?;
            Ok((1.0 / bl, -1.0, Some(bl)))
        }
    }
}

/// Per-animal positions (BL, y up) and velocities (BL/s) by clip frame.
type Series = BTreeMap<u64, BTreeMap<usize, ([f64; 2], Option<[f64; 2]>)>>;

fn series(t: &Tracks, scale: f64, ysign: f64, first: u64) -> Series {
    let mut s: Series = BTreeMap::new();
    for r in &t.rows {
        let p = [r.pos[0] * scale, r.pos[1] * scale * ysign];
        let v = r.vel.map(|v| [v[0] * scale, v[1] * scale * ysign]);
        s.entry(r.id)
            .or_default()
            .insert((r.frame - first) as usize, (p, v));
    }
    s
}

/// Central differences, one-sided next to gaps, averaged over `smooth` frames.
fn velocities(
    track: &BTreeMap<usize, ([f64; 2], Option<[f64; 2]>)>,
    dt: f64,
    smooth: usize,
) -> BTreeMap<usize, [f64; 2]> {
    let pos = |f: usize| track.get(&f).map(|e| e.0);
    let mut raw = BTreeMap::new();
    for (&f, &(p, v)) in track {
        if let Some(v) = v {
            raw.insert(f, v);
            continue;
        }
        let prev = f.checked_sub(1).and_then(pos);
        let next = pos(f + 1);
        let v = match (prev, next) {
            (Some(a), Some(b)) => Some([(b[0] - a[0]) / (2.0 * dt), (b[1] - a[1]) / (2.0 * dt)]),
            (Some(a), None) => Some([(p[0] - a[0]) / dt, (p[1] - a[1]) / dt]),
            (None, Some(b)) => Some([(b[0] - p[0]) / dt, (b[1] - p[1]) / dt]),
            (None, None) => None,
        };
        if let Some(v) = v {
            raw.insert(f, v);
        }
    }
    let h = smooth / 2;
    raw.keys()
        .map(|&f| {
            let (mut s, mut n) = ([0.0; 2], 0.0);
            for g in f.saturating_sub(h)..=f + h {
                if let Some(v) = raw.get(&g) {
                    s[0] += v[0];
                    s[1] += v[1];
                    n += 1.0;
                }
            }
            (f, [s[0] / n, s[1] / n])
        })
        .collect()
}

fn inside(poly: &[[f64; 2]], p: [f64; 2]) -> bool {
    let mut c = false;
    let mut j = poly.len() - 1;
    for i in 0..poly.len() {
        let (a, b) = (poly[i], poly[j]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0]
        {
            c = !c;
        }
        j = i;
    }
    c
}

/// Reads the tracks, builds the clip and writes it (all-or-nothing).
pub fn import_tracks(job: &ImportTracksJob) -> Result<ImportSummary> {
    let cfg = &job.config;
    cfg.check()?;
    let (tracks, recorded_bl, border) = load(job)?;
    let (scale, ysign, bl_px) = to_body_lengths(tracks.meta.units, cfg, recorded_bl)?;
    let fps = cfg.fps.unwrap_or(tracks.meta.fps);
    crate::limits::check_fps("fps", fps)?;
    let first = tracks.rows.iter().map(|r| r.frame).min().unwrap_or(0);
    let last = tracks.rows.iter().map(|r| r.frame).max().unwrap_or(0);
    let span = (last - first) as usize + 1;
    let (a, b) = cfg.frames.unwrap_or((0, span));
    if b > span {
        return Err(Error::config(
            "frames",
            format!("{a}..{b} is past the {span} tracked frames"),
        ));
    }
    let s = series(&tracks, scale, ysign, first);
    let dt = 1.0 / fps;
    let mut frames: Vec<Vec<AgentRow>> = vec![Vec::new(); b - a];
    for (&id, track) in &s {
        let vel = velocities(track, dt, cfg.smooth);
        for (&f, &(p, _)) in track.range(a..b) {
            let v = vel.get(&f).copied().unwrap_or([0.0, 0.0]);
            frames[f - a].push(AgentRow {
                id,
                x: p[0],
                y: p[1],
                vx: v[0],
                vy: v[1],
            });
        }
    }
    let (lo, hi) = frames.iter().flatten().fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), r| {
            (
                [lo[0].min(r.x), lo[1].min(r.y)],
                [hi[0].max(r.x), hi[1].max(r.y)],
            )
        },
    );
    if !lo[0].is_finite() {
        return Err(Error::config(
            "frames",
            "no tracked animal in the frames chosen",
        ));
    }
    let extent = (hi[0] - lo[0]).max(hi[1] - lo[1]).max(1e-9);
    let cell = cfg
        .cell_size
        .unwrap_or(extent / cfg.grid as f64 * (1.0 + 1e-9));
    // Counted in f64: a tiny cell would overflow an integer count.
    let (fx, fy) = (
        ((hi[0] - lo[0]) / cell).floor() + 1.0,
        ((hi[1] - lo[1]) / cell).floor() + 1.0,
    );
    let max = crate::limits::MAX_GRID_CELLS;
    if fx * fy > max as f64 {
        let key = if cfg.cell_size.is_some() {
            "cell_size"
        } else {
            "grid"
        };
        return Err(Error::config(
            key,
            format!("{:.3e} cells is above the limit of {max} cells", fx * fy),
        ));
    }
    let (nx, ny) = (fx as usize, fy as usize);
    let grid = Grid {
        origin: lo,
        cell_size: cell,
        nx,
        ny,
    };
    let obstacles = arena_mask(&cfg.arena, border.as_deref(), &grid, &frames, scale, ysign)?;
    let provenance = serde_json::json!({
        "source": "import-tracks",
        "input": job.input.display().to_string(),
        "tracks_units": tracks.meta.units.as_str(),
        "first_frame": first + a as u64,
        "settings": cfg,
    });
    let mut clip: ClipFields = rasterise(&frames, grid, fps, obstacles, provenance)?;
    clip.meta.body_length_px = bl_px;
    clip.save(
        &job.out,
        &[("tracks.csv", clip_tracks_csv(&frames, fps).into_bytes())],
    )?;
    let animals = s
        .values()
        .filter(|t| t.range(a..b).next().is_some())
        .count();
    let n = clip.frames();
    Ok(ImportSummary {
        out: job.out.clone(),
        frames: n,
        animals,
        mean_count: (0..n).map(|f| clip.count(f)).sum::<f64>() / n as f64,
        nx,
        ny,
        cell_size: cell,
        fps,
        speed: [clip.meta.speed.mean, clip.meta.speed.std],
        obstacle_cells: clip.obstacles.iter().filter(|&&o| o != 0).count(),
    })
}

/// The imported animals in the clip's coordinates and frames (`herdfit.tracks/1`, body lengths,
/// y up, frame 0 = the clip's first, velocities as rasterised): the clip folder's `tracks.csv`,
/// which `fit --tracks` starts its windows from.
fn clip_tracks_csv(frames: &[Vec<AgentRow>], fps: f64) -> String {
    use std::fmt::Write;
    let mut s = String::from("frame,time,id,x,y,vx,vy\n");
    for (f, rows) in frames.iter().enumerate() {
        let mut rows: Vec<&AgentRow> = rows.iter().collect();
        rows.sort_by_key(|r| r.id);
        for r in rows {
            let _ = writeln!(
                s,
                "{f},{},{},{},{},{},{}",
                f as f64 / fps,
                r.id,
                r.x,
                r.y,
                r.vx,
                r.vy
            );
        }
    }
    s
}

fn arena_mask(
    arena: &Arena,
    border: Option<&[[f64; 2]]>,
    grid: &Grid,
    frames: &[Vec<AgentRow>],
    scale: f64,
    ysign: f64,
) -> Result<Array2<u8>> {
    let (nx, ny) = (grid.nx, grid.ny);
    let mut m = Array2::<u8>::zeros((ny, nx));
    let poly = match arena {
        Arena::Open => return Ok(m),
        Arena::Unvisited => {
            m.fill(1);
            for r in frames.iter().flatten() {
                if let Some((ix, iy)) = grid.cell_of([r.x, r.y]) {
                    m[[iy, ix]] = 0;
                }
            }
            return Ok(m);
        }
        Arena::Polygon(p) => p.clone(),
        Arena::Border => border
            .ok_or_else(|| Error::config("arena", "the file records no arena border"))?
            .to_vec(),
    };
    let poly: Vec<[f64; 2]> = poly
        .iter()
        .map(|q| [q[0] * scale, q[1] * scale * ysign])
        .collect();
    for iy in 0..ny {
        for ix in 0..nx {
            if !inside(&poly, grid.centre(ix, iy)) {
                m[[iy, ix]] = 1;
            }
        }
    }
    Ok(m)
}
