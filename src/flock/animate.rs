//! `herdfit flock animate`: an example's shape parameters → an initiation (§6) that converges to
//! the first key shape, a hand-over, and an F-frame steady flight (§5, Algorithm 1), written as
//! a folder: 3D tracks (metres, z = altitude), per-bird power reduction per steady frame, key
//! shapes and checks in `report.json`, two PNG plots and (feature `video`) an AVI from above.

use super::extract::ShapeParams;
use super::frames::{initiation_frames, max_accel, rows_and_savings, steady_frames, Frames};
use super::initiation::{self, Initiation, InitiationConfig, InitiationRun, Target};
use super::steady::{self, KeyShape, SteadyConfig, Timeline};
use crate::data::tracks::{Tracks, TracksMeta, Units};
use crate::error::{Error, Result};
use crate::progress::Progress;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema tag of the animation report.
pub const REPORT_SCHEMA: &str = "herdfit.flock-animation/1";
/// Schema tag of the savings CSV's sidecar.
pub const SAVINGS_SCHEMA: &str = "herdfit.flock-savings/1";

/// Settings of [`animate`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AnimateConfig {
    /// Birds N (None: the example's N̂).
    pub birds: Option<usize>,
    /// Steady-flight frames F, after the hand-over (whose frames come on top).
    pub frames: usize,
    pub seed: u64,
    /// Wingspan of the animated birds, metres (None: the example's, when it is in metres, else
    /// 1.5).
    pub wingspan_m: Option<f64>,
    /// Flight altitude, metres, and the STD of each bird's constant offset from it, wingspans.
    pub altitude_m: f64,
    pub altitude_jitter: f64,
    /// Run the initiation first (else the steady flight starts at the first key shape).
    pub initiation: bool,
    /// Render the AVI (feature `video`).
    pub video: bool,
    /// Pixels per wingspan in the video.
    pub px_per_wingspan: f64,
    pub steady: SteadyConfig,
    /// The initiation; its `fps` and `speed` (wingspans/s) are those of the whole animation.
    pub init: InitiationConfig,
}

impl Default for AnimateConfig {
    fn default() -> Self {
        AnimateConfig {
            birds: None,
            frames: 250,
            seed: 0,
            wingspan_m: None,
            altitude_m: 100.0,
            altitude_jitter: 0.05,
            initiation: true,
            video: true,
            px_per_wingspan: 12.0,
            steady: SteadyConfig::default(),
            init: InitiationConfig::default(),
        }
    }
}

impl AnimateConfig {
    /// Checks the settings; errors name the config key.
    pub fn check(&self) -> Result<()> {
        if let Some(n) = self.birds {
            if !(3..=500).contains(&n) {
                return Err(Error::invalid(format!("birds = {n} must be in 3..=500")));
            }
        }
        if !(2..=1_000_000).contains(&self.frames) {
            return Err(Error::invalid(format!(
                "frames = {} must be in 2..=1000000",
                self.frames
            )));
        }
        if let Some(b) = self.wingspan_m {
            if !(b.is_finite() && b > 0.0) {
                return Err(Error::invalid(format!("wingspan_m = {b} must be > 0")));
            }
            // The largest bird's wingspan is under 4 m; 100 m leaves room for any model.
            crate::limits::within("wingspan_m", b, 0.0, 100.0)?;
        }
        // Up to the edge of the atmosphere (100 km), and jitter within it.
        crate::limits::within("altitude_m", self.altitude_m, -1e5, 1e5)?;
        crate::limits::within("altitude_jitter", self.altitude_jitter, 0.0, 1e5)?;
        if !(self.altitude_jitter.is_finite() && self.altitude_jitter >= 0.0) {
            return Err(Error::invalid(format!(
                "altitude_jitter = {} must be ≥ 0",
                self.altitude_jitter
            )));
        }
        if !(self.px_per_wingspan.is_finite() && (2.0..=200.0).contains(&self.px_per_wingspan)) {
            return Err(Error::invalid(format!(
                "px_per_wingspan = {} must be in [2, 200]",
                self.px_per_wingspan
            )));
        }
        self.steady.check().map_err(|e| prefix("steady", e))?;
        self.init.check().map_err(|e| prefix("init", e))
    }
}

fn prefix(p: &str, e: Error) -> Error {
    match e {
        Error::Invalid(m) => Error::Invalid(format!("{p}.{m}")),
        other => other,
    }
}

/// What the animation did, with its checks (`report.json`).
#[derive(Clone, Debug, Serialize)]
pub struct AnimationReport {
    pub schema: String,
    pub source: String,
    pub birds: usize,
    pub example_birds: usize,
    pub nl: usize,
    pub nr: usize,
    pub fps: f64,
    pub wingspan_m: f64,
    pub speed_mps: f64,
    /// Frames: initiation, hand-over, then the F steady frames (the frames with savings).
    pub initiation_frames: usize,
    pub hand_over_frames: usize,
    pub steady_frames: usize,
    /// Example bird of each animated bird (Step 1's correspondence).
    pub example_bird: Vec<Option<u64>>,
    /// Per bird [p_i, P_i] (Step 2).
    pub xi_range: Vec<[f64; 2]>,
    pub keys: Vec<KeyShape>,
    pub key_times: Vec<f64>,
    pub initiation: Option<InitiationRun>,
    pub hand_over_s: f64,
    /// Largest relative acceleration measured on the steady frames after the hand-over, and the
    /// bound it must respect (wingspans/s²); the hand-over's own peak.
    pub max_accel_steady: f64,
    pub accel_bound: f64,
    pub max_accel_hand_over: f64,
    /// Mean power reduction e of each bird over the steady frames, and of the flock.
    pub mean_saving: Vec<f64>,
    pub flock_mean_saving: f64,
    pub config: AnimateConfig,
}

/// Key shapes until the timeline covers `duration` seconds.
#[allow(clippy::too_many_arguments)]
fn build_keys(
    first: KeyShape,
    nl: usize,
    nr: usize,
    range: &[[f64; 2]],
    params: &ShapeParams,
    duration: f64,
    cfg: &SteadyConfig,
    rng: &mut rand_chacha::ChaCha8Rng,
    progress: &mut dyn Progress,
) -> (Vec<KeyShape>, Timeline) {
    let means: Vec<f64> = params.frames.iter().map(|f| f.mean_gap).collect();
    let gap_range = [
        means
            .iter()
            .cloned()
            .fold(f64::INFINITY, f64::min)
            .max(cfg.min_gap),
        means
            .iter()
            .cloned()
            .fold(f64::NEG_INFINITY, f64::max)
            .max(cfg.min_gap),
    ];
    let mut keys = vec![first];
    let estimate = (duration / cfg.key_interval).ceil() as u64 + 1;
    progress.start("key shapes", estimate);
    loop {
        let tl = Timeline::new(
            keys.iter().map(|k| k.pos.clone()).collect(),
            cfg.key_interval,
            cfg.max_accel,
        );
        if tl.duration() >= duration {
            progress.finish();
            return (keys, tl);
        }
        let k = steady::next_key(keys.last().unwrap(), nl, nr, range, gap_range, cfg, rng);
        keys.push(k);
        progress.inc(1);
    }
}

/// The whole animation in memory: tracks and savings rows, the report.
pub struct Animation {
    pub tracks: Tracks,
    /// (frame, time, id, e, ξ) per bird per steady frame.
    pub savings: Vec<(u64, f64, u64, f64, f64)>,
    pub report: AnimationReport,
    /// Positions (wingspans, world) per frame, for plots and video.
    pub frames: Vec<Vec<[f64; 2]>>,
    /// Headings per frame (unit vectors).
    pub headings: Vec<Vec<[f64; 2]>>,
}

/// Runs the initiation (or places the birds on the first key shape).
fn initiate(
    target: &Target,
    n: usize,
    cfg: &AnimateConfig,
    rng: &mut rand_chacha::ChaCha8Rng,
    progress: &mut dyn Progress,
) -> Result<Option<InitiationRun>> {
    if !cfg.initiation {
        return Ok(None);
    }
    progress.start("initiation", 0);
    let start = initiation::random_start(n, &cfg.init, rng);
    let sim = Initiation::new(cfg.init.clone(), target.clone(), start)?;
    let run = initiation::run(sim);
    progress.finish();
    Ok(Some(run))
}

/// Computes the animation (no files).
pub fn animate(
    params: &ShapeParams,
    source: &str,
    cfg: &AnimateConfig,
    progress: &mut dyn Progress,
) -> Result<Animation> {
    cfg.check()?;
    params.check()?;
    let n = cfg.birds.unwrap_or(params.birds);
    if n < 3 {
        return Err(Error::invalid(format!(
            "birds = {n}: a formation needs at least 3"
        )));
    }
    let wingspan_m = cfg.wingspan_m.unwrap_or(if params.units == Units::Metres {
        params.wingspan
    } else {
        1.5
    });
    let fps = cfg.init.fps;
    let v = cfg.init.speed; // wingspans/s
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(cfg.seed);
    let init = steady::initial_shapes(params, n, &cfg.steady, &mut rng)?;
    let (_, range) = steady::ranges(&init.shapes)?;
    let first = steady::first_key(&init.shapes[0])?;
    // The target is the first key shape as the timeline places it (centred on its centroid).
    let target = Target {
        pos: Timeline::new(
            vec![first.pos.clone()],
            cfg.steady.key_interval,
            cfg.steady.max_accel,
        )
        .keys
        .swap_remove(0),
        nl: init.nl,
        nr: init.nr,
    };
    let run = initiate(&target, n, cfg, &mut rng, progress)?;
    let jitter =
        Normal::new(0.0, cfg.altitude_jitter).map_err(|e| Error::Internal(e.to_string()))?;
    let z: Vec<f64> = (0..n)
        .map(|_| cfg.altitude_m + wingspan_m * jitter.sample(&mut rng))
        .collect();
    let mut fr = Frames::default();
    let ho = initiation_frames(run.as_ref(), &target, n, fps, v, &mut fr);
    let init_frames = ho.frames;
    let dmax = ho
        .delta
        .iter()
        .map(|d| d[0].hypot(d[1]))
        .fold(0.0, f64::max);
    let wmax = ho.w.iter().map(|d| d[0].hypot(d[1])).fold(0.0, f64::max);
    let a = cfg.steady.max_accel;
    let hand_s = if run.is_some() {
        (steady::MIN_JERK_PEAK * dmax / a)
            .sqrt()
            .max(6.0 * wmax / a)
            .max(1.0)
    } else {
        0.0
    };
    // The F steady frames start where the hand-over ends: the savings (eq. 1) describe the
    // formation the model assumes, not birds still moving to their places.
    let hand_count = (hand_s * fps).ceil() as usize;
    let count = hand_count + cfg.frames;
    let (keys, timeline) = build_keys(
        first,
        init.nl,
        init.nr,
        &range,
        params,
        (count - 1) as f64 / fps,
        &cfg.steady,
        &mut rng,
        progress,
    );
    steady_frames(&timeline, &ho, hand_s, n, count, fps, v, &mut fr, progress);
    let hand_frames = init_frames + hand_count;
    let (rows, savings, mean_saving) = rows_and_savings(&fr, &z, wingspan_m, fps, hand_frames);
    let flock_mean_saving = mean_saving.iter().sum::<f64>() / n as f64;
    let max_accel_steady = max_accel(&fr.pos, fps, hand_frames + 1, fr.pos.len());
    let max_accel_hand_over = if run.is_some() {
        max_accel(&fr.pos, fps, init_frames + 1, hand_frames + 1)
    } else {
        0.0
    };
    let mut meta = TracksMeta::new(Units::Metres, fps, 3);
    meta.provenance = serde_json::json!({
        "generator": "herdfit flock animate",
        "shape": source,
        "wingspan": wingspan_m,
        "initiation_frames": init_frames,
        "seed": cfg.seed,
    });
    let tracks = Tracks::new(meta, rows)?;
    let report = AnimationReport {
        schema: REPORT_SCHEMA.into(),
        source: source.into(),
        birds: n,
        example_birds: params.birds,
        nl: init.nl,
        nr: init.nr,
        fps,
        wingspan_m,
        speed_mps: v * wingspan_m,
        initiation_frames: init_frames,
        hand_over_frames: hand_count,
        steady_frames: cfg.frames,
        example_bird: init.example_bird.clone(),
        xi_range: range,
        keys,
        key_times: timeline.times.clone(),
        initiation: run,
        hand_over_s: hand_s,
        max_accel_steady,
        accel_bound: cfg.steady.max_accel,
        max_accel_hand_over,
        mean_saving,
        flock_mean_saving,
        config: cfg.clone(),
    };
    Ok(Animation {
        tracks,
        savings,
        report,
        frames: fr.pos,
        headings: fr.headings,
    })
}

/// The savings CSV: `frame,time,id,e,xi` (e: fraction of the bird's induced power saved).
pub fn savings_csv(rows: &[(u64, f64, u64, f64, f64)]) -> String {
    use std::fmt::Write as _;
    let mut s = String::from("frame,time,id,e,xi\n");
    for (f, t, id, e, xi) in rows {
        let _ = writeln!(s, "{f},{t},{id},{e},{xi}");
    }
    s
}

/// Reads `shape` (a `herdfit.flock-shape/1` file), animates it and writes the folder `out`
/// (all-or-nothing): `tracks.csv`/`tracks.json`, `savings.csv`/`savings.json`, `report.json`,
/// `shapes.png`, `savings.png` and, with the `video` feature and `video`, `flock.avi`.
pub fn animate_file(
    shape: &Path,
    out: &Path,
    cfg: &AnimateConfig,
    progress: &mut dyn Progress,
) -> Result<AnimationReport> {
    let params = ShapeParams::load(shape)?;
    let anim = animate(&params, &shape.display().to_string(), cfg, progress)?;
    write_outputs(&anim, out, progress)?;
    Ok(anim.report)
}

/// Writes an animation's folder atomically.
pub fn write_outputs(anim: &Animation, out: &Path, progress: &mut dyn Progress) -> Result<()> {
    let dir = crate::data::atomic::AtomicDir::create(out)?;
    anim.tracks.save(&dir.path("tracks.csv"))?;
    dir.write("savings.csv", savings_csv(&anim.savings).as_bytes())?;
    let side = serde_json::json!({
        "schema": SAVINGS_SCHEMA,
        "columns": {
            "frame": "frame of tracks.csv",
            "time": "seconds",
            "id": "bird id of tracks.csv",
            "e": "power reduction e_i = Σ_j g_ij (Klotsman & Tal eq. 1, Hummel 1983): fraction of the bird's induced power saved",
            "xi": "relative power reduction ξ_i = e_i / Σ e",
        },
        "frames": "the F steady-flight frames after the hand-over (the model assumes steady formation flight)",
    });
    dir.write(
        "savings.json",
        format!(
            "{}\n",
            serde_json::to_string_pretty(&side).map_err(|e| Error::Internal(e.to_string()))?
        )
        .as_bytes(),
    )?;
    let rep = serde_json::to_string_pretty(&anim.report)
        .map_err(|e| Error::Internal(format!("report: {e}")))?;
    dir.write("report.json", format!("{rep}\n").as_bytes())?;
    super::figures::shapes_png(&dir.path("shapes.png"), &anim.report)?;
    super::figures::savings_png(&dir.path("savings.png"), &anim.savings, anim.report.birds)?;
    #[cfg(feature = "video")]
    if anim.report.config.video {
        super::render::render(&dir.path("flock.avi"), anim, progress)?;
    }
    let _ = &progress;
    dir.commit()
}
