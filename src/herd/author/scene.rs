//! The scene file (`herdfit.scene/1`, DESIGN §6): world and grid, obstacles, guidance arrows, an
//! optional destination, behaviour regions with their parameter sets and speed caps, the herd's
//! spawn, duration, fps and seed. Validation names the JSON path of every problem.

use crate::data::Grid;
use crate::error::{Error, Result};
use crate::herd::params::Params;
use ndarray::Array2;
use serde::Deserialize;
use std::path::{Path, PathBuf};

pub const SCENE_SCHEMA: &str = "herdfit.scene/1";

type P2 = [f64; 2];

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct WorldSpec {
    /// Width and height (BL); the origin is the lower-left corner.
    pub width: f64,
    pub height: f64,
    /// Grid cell side (BL) of obstacles and the navigation field.
    pub cell_size: f64,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Circle {
    pub centre: P2,
    pub radius: f64,
}

#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ObstacleSpec {
    /// Grid cells [ix, iy] (row 0 at the bottom).
    pub cells: Vec<[i64; 2]>,
    /// Polygons (BL); a cell is blocked when its centre is inside.
    pub polygons: Vec<Vec<P2>>,
    pub circles: Vec<Circle>,
    /// A mask image (non-zero = obstacle) stretched over the world, path relative to the scene.
    pub mask: Option<PathBuf>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Destination {
    pub point: P2,
    /// Weight of the destination field in the blend with the arrows' field.
    #[serde(default = "one")]
    pub weight: f64,
}

fn one() -> f64 {
    1.0
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RegionSpec {
    pub polygon: Vec<P2>,
    /// Parameter-set file (relative to the scene), or a parameter-set bundle
    /// (`herdfit.param-sets/1`, a zone fit's output) when `set` names one of its sets.
    pub params: PathBuf,
    /// The name of the set in the bundle `params` (a zone's name).
    #[serde(default)]
    pub set: Option<String>,
    /// Speed cap (BL/s) inside the region.
    #[serde(default)]
    pub speed_cap: Option<f64>,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SpawnSpec {
    pub count: usize,
    pub centre: P2,
    /// Size of the spawn rectangle (BL); agents are placed uniformly inside it.
    pub size: P2,
    #[serde(default)]
    pub heading_deg: f64,
}

#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PredatorSpec {
    /// Polyline the predator walks along (BL).
    pub path: Vec<P2>,
    /// Its speed (BL/s).
    pub speed: f64,
    /// Agents closer than this flee (BL).
    pub radius: f64,
    /// Strength of the avoidance force.
    #[serde(default = "one")]
    pub strength: f64,
}

/// The navigation field's ranges; each missing key takes [`NavSpec::default`]'s value.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct NavSpec {
    /// Arrow directions are propagated at full strength out to this distance (BL) ...
    pub radius: f64,
    /// ... and decay as exp(−(d − radius) / decay) beyond it.
    pub decay: f64,
    /// Radius (BL) of the cancelling field around obstacles (eq. 14).
    pub cancel_radius: f64,
}

impl Default for NavSpec {
    fn default() -> Self {
        NavSpec {
            radius: 8.0,
            decay: 4.0,
            cancel_radius: 4.0,
        }
    }
}

/// The scene file as written.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneFile {
    pub schema: String,
    pub world: WorldSpec,
    #[serde(default)]
    pub obstacles: ObstacleSpec,
    /// Guidance arrows: oriented polylines (BL).
    #[serde(default)]
    pub arrows: Vec<Vec<P2>>,
    #[serde(default)]
    pub navigation: NavSpec,
    #[serde(default)]
    pub destination: Option<Destination>,
    #[serde(default)]
    pub regions: Vec<RegionSpec>,
    /// Parameter set outside every region; the built-in set when absent.
    #[serde(default)]
    pub default_params: Option<PathBuf>,
    #[serde(default)]
    pub default_speed_cap: Option<f64>,
    pub spawn: SpawnSpec,
    /// Simulated time (s).
    pub duration: f64,
    #[serde(default = "fps25")]
    pub fps: f64,
    #[serde(default)]
    pub seed: u64,
    #[serde(default)]
    pub predator: Option<PredatorSpec>,
    /// Open edges of the world (a stream of animals through an authored valley): the same gates
    /// as a clip's open boundary ([`crate::herd::boundary`]).
    #[serde(default)]
    pub boundary: Option<super::sources::SceneBoundary>,
}

fn fps25() -> f64 {
    25.0
}

/// A loaded, validated scene.
#[derive(Clone, Debug)]
pub struct Scene {
    pub file: SceneFile,
    pub path: PathBuf,
    pub grid: Grid,
    pub obstacles: Array2<u8>,
    /// Parameter sets: index 0 is the default, then one per region.
    pub params: Vec<Params>,
}

/// Is `p` inside the polygon (even–odd rule)?
pub fn in_polygon(p: P2, poly: &[P2]) -> bool {
    let mut inside = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1]) {
            let x = a[0] + (p[1] - a[1]) / (b[1] - a[1]) * (b[0] - a[0]);
            if p[0] < x {
                inside = !inside;
            }
        }
    }
    inside
}

impl Scene {
    /// Reads and validates a scene file.
    pub fn load(path: &Path) -> Result<Scene> {
        crate::data::atomic::note_input(path);
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let file: SceneFile = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a {SCENE_SCHEMA} file: {e}")))?;
        Scene::new(file, path)
    }

    /// Validates a parsed scene (`path` names it in errors and anchors relative file paths).
    pub fn new(file: SceneFile, path: &Path) -> Result<Scene> {
        if file.schema != SCENE_SCHEMA {
            return Err(bad(
                path,
                "schema",
                &format!("is '{}', expected '{SCENE_SCHEMA}'", file.schema),
            ));
        }
        let grid = world_grid(&file, path)?;
        let obstacles = obstacle_cells(&file, &grid, path)?;
        let ground = Ground {
            grid: &grid,
            obstacles: &obstacles,
            path,
        };
        check_guidance(&file, &ground)?;
        let params = region_params(&file, path)?;
        check_spawn_and_run(&file, &ground)?;
        Ok(Scene {
            path: path.to_path_buf(),
            grid,
            obstacles,
            params,
            file,
        })
    }

    /// The behaviour set (0 = default, k = region k − 1) at `p`: the first region containing it.
    pub fn region_at(&self, p: P2) -> usize {
        self.file
            .regions
            .iter()
            .position(|r| in_polygon(p, &r.polygon))
            .map_or(0, |k| k + 1)
    }

    /// The speed cap at `p`.
    pub fn speed_cap_at(&self, p: P2) -> Option<f64> {
        match self.region_at(p) {
            0 => self.file.default_speed_cap,
            k => self.file.regions[k - 1]
                .speed_cap
                .or(self.file.default_speed_cap),
        }
    }

    /// Is `p` outside the world or inside an obstacle cell?
    pub fn blocked(&self, p: P2) -> bool {
        match self.grid.cell_of(p) {
            None => true,
            Some((ix, iy)) => self.obstacles[[iy, ix]] != 0,
        }
    }
}

#[cfg(feature = "video")]
fn mask_cells(path: &Path, obstacles: &mut Array2<u8>) -> Result<()> {
    use opencv::prelude::*;
    // OpenCV logs a WARN line of its own for an unreadable file: the error below says it once.
    let _ = opencv::core::set_log_level(opencv::core::LogLevel::LOG_LEVEL_SILENT);
    if !path.is_file() {
        return Err(Error::file(path, "cannot read: no such file"));
    }
    let img = opencv::imgcodecs::imread(path.as_os_str(), opencv::imgcodecs::IMREAD_GRAYSCALE)
        .map_err(|e| Error::file(path, format!("OpenCV: {}", e.message)))?;
    if img.empty() {
        return Err(Error::file(path, "cannot read as an image"));
    }
    let (w, h) = (img.cols() as usize, img.rows() as usize);
    let data = img
        .data_bytes()
        .map_err(|e| Error::file(path, format!("OpenCV: {}", e.message)))?;
    let (ny, nx) = obstacles.dim();
    for iy in 0..ny {
        for ix in 0..nx {
            // The image covers the world; row 0 of the image is the top.
            let px = ((ix as f64 + 0.5) / nx as f64 * w as f64) as usize;
            let py = ((1.0 - (iy as f64 + 0.5) / ny as f64) * h as f64) as usize;
            if data[py.min(h - 1) * w + px.min(w - 1)] > 0 {
                obstacles[[iy, ix]] = 1;
            }
        }
    }
    Ok(())
}

#[cfg(not(feature = "video"))]
fn mask_cells(path: &Path, _obstacles: &mut Array2<u8>) -> Result<()> {
    Err(Error::file(
        path,
        "mask images need the `video` feature (OpenCV)",
    ))
}

/// An error at JSON path `at` of the scene file `path`.
fn bad(path: &Path, at: &str, msg: &str) -> Error {
    Error::file(path, format!("{at}: {msg}"))
}

/// Is `p` inside the world (and finite)?
fn in_world(w: &WorldSpec, p: P2) -> bool {
    p[0] >= 0.0
        && p[1] >= 0.0
        && p[0] <= w.width
        && p[1] <= w.height
        && p[0].is_finite()
        && p[1].is_finite()
}

/// The world's grid (`world.*` checked).
fn world_grid(file: &SceneFile, path: &Path) -> Result<Grid> {
    let bad = |at: &str, msg: &str| bad(path, at, msg);
    let w = &file.world;
    for (k, v) in [
        ("world.width", w.width),
        ("world.height", w.height),
        ("world.cell_size", w.cell_size),
    ] {
        if !(v.is_finite() && v > 0.0) {
            return Err(bad(k, "must be > 0"));
        }
    }
    // Counted in f64: a width of 1e300 cells would saturate the usize casts and wrap their product.
    let (fx, fy) = (
        (w.width / w.cell_size).ceil(),
        (w.height / w.cell_size).ceil(),
    );
    if (fx * fy).is_nan() || fx * fy > 4e6 {
        return Err(bad("world", "more than 4 million grid cells"));
    }
    let (nx, ny) = (fx as usize, fy as usize);
    let grid = Grid {
        origin: [0.0, 0.0],
        cell_size: w.cell_size,
        nx,
        ny,
    };
    Ok(grid)
}

/// The obstacle cells: `obstacles.cells`, polygons, circles and mask.
fn obstacle_cells(file: &SceneFile, grid: &Grid, path: &Path) -> Result<Array2<u8>> {
    let bad = |at: &str, msg: &str| bad(path, at, msg);
    let (nx, ny) = (grid.nx, grid.ny);
    let mut obstacles = Array2::<u8>::zeros((ny, nx));
    let o = &file.obstacles;
    for (k, c) in o.cells.iter().enumerate() {
        if c[0] < 0 || c[1] < 0 || c[0] as usize >= nx || c[1] as usize >= ny {
            return Err(bad(
                &format!("obstacles.cells[{k}]"),
                &format!("{c:?} is outside the {nx}×{ny} grid"),
            ));
        }
        obstacles[[c[1] as usize, c[0] as usize]] = 1;
    }
    for (k, poly) in o.polygons.iter().enumerate() {
        if let Some(m) = crate::data::polygon::polygon_problem(poly) {
            return Err(bad(&format!("obstacles.polygons[{k}]"), &m));
        }
        for iy in 0..ny {
            for ix in 0..nx {
                if in_polygon(grid.centre(ix, iy), poly) {
                    obstacles[[iy, ix]] = 1;
                }
            }
        }
    }
    for (k, c) in o.circles.iter().enumerate() {
        if !(c.radius.is_finite() && c.radius > 0.0) {
            return Err(bad(
                &format!("obstacles.circles[{k}].radius"),
                "must be > 0",
            ));
        }
        for iy in 0..ny {
            for ix in 0..nx {
                let p = grid.centre(ix, iy);
                if (p[0] - c.centre[0]).hypot(p[1] - c.centre[1]) <= c.radius {
                    obstacles[[iy, ix]] = 1;
                }
            }
        }
    }
    if let Some(m) = &o.mask {
        let mp = path.parent().unwrap_or(Path::new(".")).join(m);
        mask_cells(&mp, &mut obstacles).map_err(|e| match e {
            Error::File { msg, .. } => bad("obstacles.mask", &format!("{}: {msg}", mp.display())),
            other => other,
        })?;
    }
    Ok(obstacles)
}

/// The grid and obstacles that a scene's points are judged against.
struct Ground<'a> {
    grid: &'a Grid,
    obstacles: &'a Array2<u8>,
    path: &'a Path,
}

impl Ground<'_> {
    /// `p` (at JSON path `at`) is inside the world and not in an obstacle.
    fn free_point(&self, file: &SceneFile, at: &str, p: P2) -> Result<()> {
        if !in_world(&file.world, p) {
            return Err(bad(self.path, at, "is outside the world"));
        }
        if let Some((ix, iy)) = self.grid.cell_of(p) {
            if self.obstacles[[iy, ix]] != 0 {
                return Err(bad(self.path, at, "is inside an obstacle"));
            }
        }
        Ok(())
    }
}

/// Guidance: `arrows` inside the world, `navigation` ranges, the `destination`; one of arrows
/// or destination is required.
fn check_guidance(file: &SceneFile, ground: &Ground) -> Result<()> {
    let bad = |at: &str, msg: &str| bad(ground.path, at, msg);
    let w = &file.world;
    let inside = |p: P2| in_world(w, p);
    for (k, arrow) in file.arrows.iter().enumerate() {
        if arrow.len() < 2 {
            return Err(bad(
                &format!("arrows[{k}]"),
                "an arrow needs at least 2 points",
            ));
        }
        if let Some((j, p)) = arrow.iter().enumerate().find(|(_, p)| !inside(**p)) {
            return Err(bad(
                &format!("arrows[{k}][{j}]"),
                &format!("{p:?} is outside the {}×{} world", w.width, w.height),
            ));
        }
    }
    let n = &file.navigation;
    for (k, v) in [
        ("navigation.radius", n.radius),
        ("navigation.decay", n.decay),
        ("navigation.cancel_radius", n.cancel_radius),
    ] {
        if !(v.is_finite() && v >= 0.0) {
            return Err(bad(k, "must be ≥ 0"));
        }
    }
    if let Some(d) = &file.destination {
        ground.free_point(file, "destination.point", d.point)?;
        if !(d.weight.is_finite() && d.weight >= 0.0) {
            return Err(bad("destination.weight", "must be ≥ 0"));
        }
    }
    if file.arrows.is_empty() && file.destination.is_none() {
        return Err(bad("arrows", "give guidance arrows or a destination"));
    }
    Ok(())
}

/// The parameter sets: `default_params` (the built-in set when absent), then one per region
/// (`regions[k]` checked); `default_speed_cap` checked.
fn region_params(file: &SceneFile, path: &Path) -> Result<Vec<Params>> {
    let bad = |at: &str, msg: &str| bad(path, at, msg);
    let dir = path.parent().unwrap_or(Path::new("."));
    let load_params = |at: &str, p: &Path| -> Result<Params> {
        Params::load(&dir.join(p)).map_err(|e| bad(at, &e.to_string()))
    };
    let mut params = vec![match &file.default_params {
        Some(p) => load_params("default_params", p)?,
        None => Params::default(),
    }];
    for (k, r) in file.regions.iter().enumerate() {
        if let Some(m) = crate::data::polygon::polygon_problem(&r.polygon) {
            return Err(bad(&format!("regions[{k}].polygon"), &m));
        }
        if let Some(c) = r.speed_cap {
            if !(c.is_finite() && c > 0.0) {
                return Err(bad(&format!("regions[{k}].speed_cap"), "must be > 0"));
            }
        }
        let at = format!("regions[{k}].params");
        params.push(match &r.set {
            None => load_params(&at, &r.params)?,
            Some(name) => crate::herd::fit::zones::ParamSets::load(&dir.join(&r.params))
                .map_err(|e| bad(&at, &e.to_string()))?
                .get(name)
                .map_err(|m| bad(&format!("regions[{k}].set"), &m))?
                .clone(),
        });
    }
    if let Some(c) = file.default_speed_cap {
        if !(c.is_finite() && c > 0.0) {
            return Err(bad("default_speed_cap", "must be > 0"));
        }
    }
    Ok(params)
}

/// `spawn`, `duration`, `fps` and `predator`.
fn check_spawn_and_run(file: &SceneFile, ground: &Ground) -> Result<()> {
    let bad = |at: &str, msg: &str| bad(ground.path, at, msg);
    let s = &file.spawn;
    if s.count == 0 {
        return Err(bad("spawn.count", "the herd is empty"));
    }
    if s.count > crate::limits::MAX_AGENTS {
        let m = format!(
            "{} is above the limit of {}",
            s.count,
            crate::limits::MAX_AGENTS
        );
        return Err(bad("spawn.count", &m));
    }
    ground.free_point(file, "spawn.centre", s.centre)?;
    if !(s.size[0] > 0.0 && s.size[1] > 0.0 && s.size[0].is_finite() && s.size[1].is_finite()) {
        return Err(bad("spawn.size", "must be > 0"));
    }
    if !(file.duration.is_finite() && file.duration > 0.0) {
        return Err(bad("duration", "must be > 0"));
    }
    if let Err(e) = crate::limits::check_fps("fps", file.fps) {
        return Err(Error::file(ground.path, e.to_string()));
    }
    // The run keeps every frame's agents (5 f64 and a role each).
    let frames = file.duration * file.fps;
    if frames > crate::limits::MAX_STEPS as f64 {
        let m = format!(
            "duration × fps = {frames} frames is above the limit of {}",
            crate::limits::MAX_STEPS
        );
        return Err(bad("duration", &m));
    }
    // With sources, the count the boundary keeps or what its rate lets in over the run.
    let inflow = file.boundary.as_ref().map_or(0.0, |b| {
        b.count.unwrap_or(0) as f64 + b.rate.unwrap_or(0.0) * file.duration
    });
    if let Err(e) = crate::limits::check_memory(
        "duration",
        "the run",
        frames * (s.count as f64 + inflow) * 48.0,
    ) {
        return Err(Error::file(ground.path, e.to_string()));
    }
    if let Some(b) = &file.boundary {
        super::sources::check(b, ground.grid, ground.obstacles, ground.path)?;
    }
    if let Some(p) = &file.predator {
        if p.path.len() < 2 {
            return Err(bad("predator.path", "needs at least 2 points"));
        }
        if !(p.speed >= 0.0 && p.radius > 0.0 && p.strength >= 0.0) {
            return Err(bad(
                "predator",
                "speed ≥ 0, radius > 0 and strength ≥ 0 are required",
            ));
        }
    }
    Ok(())
}
