//! `herdfit flock animate`: an example's shape parameters → an initiation (§6) that converges to
//! the first key shape, a hand-over, and an F-frame steady flight (§5, Algorithm 1), written as
//! a folder: 3D tracks (metres, z = altitude), per-bird power reduction per steady frame, key
//! shapes and checks in `report.json`, two PNG plots and (feature `video`) an AVI from above.

use super::extract::ShapeParams;
use super::initiation::{self, Initiation, InitiationConfig, InitiationRun, Target};
use super::power;
use super::steady::{self, KeyShape, SteadyConfig, Timeline};
use crate::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
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
    /// Steady-flight frames F (the hand-over included).
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
        }
        if !self.altitude_m.is_finite() {
            return Err(Error::invalid("altitude_m must be finite"));
        }
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
    /// Frames: initiation, then steady flight (the hand-over at its start).
    pub initiation_frames: usize,
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

/// Offsets of the hand-over: quintic with h(0) = δ, h'(0) = w, h''(0) = 0 and h = h' = h'' = 0
/// at T. Returns (h, h') at τ ∈ [0, T].
fn hand_over(delta: f64, w: f64, t: f64, big_t: f64) -> (f64, f64) {
    if t >= big_t {
        return (0.0, 0.0);
    }
    let s = t / big_t;
    // Hermite quintic basis: H0 for the value, H1 for the slope (times T).
    let h0 = 1.0 - 10.0 * s.powi(3) + 15.0 * s.powi(4) - 6.0 * s.powi(5);
    let h1 = s - 6.0 * s.powi(3) + 8.0 * s.powi(4) - 3.0 * s.powi(5);
    let d0 = (-30.0 * s.powi(2) + 60.0 * s.powi(3) - 30.0 * s.powi(4)) / big_t;
    let d1 = (1.0 - 18.0 * s.powi(2) + 32.0 * s.powi(3) - 15.0 * s.powi(4)) / big_t;
    (delta * h0 + w * big_t * h1, delta * d0 + w * big_t * d1)
}

/// Key shapes until the timeline covers `duration` seconds.
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

/// Assigns each initiation bird a distinct slot: its own where the slots are a bijection, else
/// the nearest free target position (greedy, in bird order).
fn assign_slots(run: &InitiationRun, target: &Target) -> Vec<usize> {
    let n = target.pos.len();
    let last = run.frames.last().map(|f| f.as_slice()).unwrap_or(&[]);
    let mut taken = vec![false; n];
    let mut slot = vec![usize::MAX; n];
    for (i, s) in run.slots.iter().enumerate() {
        if let Some(t) = s {
            if !taken[*t] {
                taken[*t] = true;
                slot[i] = *t;
            }
        }
    }
    let leader = run.slots.iter().position(|s| *s == Some(0)).unwrap_or(0);
    let l = last.get(leader).map_or([0.0, 0.0], |b| b.pos);
    for i in 0..n {
        if slot[i] != usize::MAX {
            continue;
        }
        let p = last.get(i).map_or([0.0, 0.0], |b| b.pos);
        let best = (0..n).filter(|&t| !taken[t]).min_by(|&a, &b| {
            let d = |t: usize| {
                (p[0] - l[0] - target.pos[t][0] + target.pos[0][0])
                    .hypot(p[1] - l[1] - target.pos[t][1] + target.pos[0][1])
            };
            d(a).total_cmp(&d(b))
        });
        if let Some(t) = best {
            taken[t] = true;
            slot[i] = t;
        }
    }
    slot
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
    let steady_s = (cfg.frames - 1) as f64 / fps;
    let (keys, timeline) = build_keys(
        first,
        init.nl,
        init.nr,
        &range,
        params,
        steady_s,
        &cfg.steady,
        &mut rng,
        progress,
    );
    let target = Target {
        pos: timeline.keys[0].clone(),
        nl: init.nl,
        nr: init.nr,
    };
    let run = initiate(&target, n, cfg, &mut rng, progress)?;
    let jitter =
        Normal::new(0.0, cfg.altitude_jitter).map_err(|e| Error::Internal(e.to_string()))?;
    let z: Vec<f64> = (0..n)
        .map(|_| cfg.altitude_m + wingspan_m * jitter.sample(&mut rng))
        .collect();
    let mut frames: Vec<Vec<[f64; 2]>> = Vec::new();
    let mut headings: Vec<Vec<[f64; 2]>> = Vec::new();
    let mut vels: Vec<Vec<[f64; 2]>> = Vec::new();
    // Initiation frames, birds renumbered by their final slot.
    let (origin, delta, w, init_frames) = match &run {
        Some(r) => {
            let slot = assign_slots(r, &target);
            for f in &r.frames[..r.frames.len() - 1] {
                let mut p = vec![[0.0; 2]; n];
                let mut h = vec![[0.0; 2]; n];
                let mut vv = vec![[0.0; 2]; n];
                for (i, b) in f.iter().enumerate() {
                    p[slot[i]] = b.pos;
                    h[slot[i]] = b.dir();
                    vv[slot[i]] = [b.dir()[0] * b.v * fps, b.dir()[1] * b.v * fps];
                }
                frames.push(p);
                headings.push(h);
                vels.push(vv);
            }
            let last = r.frames.last().unwrap();
            let mut pl = [0.0; 2];
            for (i, b) in last.iter().enumerate() {
                if slot[i] == 0 {
                    pl = b.pos;
                }
            }
            let origin = [pl[0] - target.pos[0][0], pl[1] - target.pos[0][1]];
            let mut delta = vec![[0.0; 2]; n];
            let mut w = vec![[0.0; 2]; n];
            for (i, b) in last.iter().enumerate() {
                let t = slot[i];
                delta[t] = [
                    b.pos[0] - origin[0] - target.pos[t][0],
                    b.pos[1] - origin[1] - target.pos[t][1],
                ];
                let d = b.dir();
                w[t] = [d[0] * b.v * fps, d[1] * b.v * fps - v];
            }
            (origin, delta, w, r.frames.len() - 1)
        }
        None => ([0.0, 0.0], vec![[0.0; 2]; n], vec![[0.0; 2]; n], 0),
    };
    let dmax = delta.iter().map(|d| d[0].hypot(d[1])).fold(0.0, f64::max);
    let wmax = w.iter().map(|d| d[0].hypot(d[1])).fold(0.0, f64::max);
    let a = cfg.steady.max_accel;
    let hand_s = if run.is_some() {
        (steady::MIN_JERK_PEAK * dmax / a)
            .sqrt()
            .max(6.0 * wmax / a)
            .max(1.0)
    } else {
        0.0
    };
    progress.start("frames", cfg.frames as u64);
    for k in 0..cfg.frames {
        let t = k as f64 / fps;
        let (rel, relv) = timeline.at(t);
        let mut p = vec![[0.0; 2]; n];
        let mut vv = vec![[0.0; 2]; n];
        for i in 0..n {
            let (hx, dhx) = hand_over(delta[i][0], w[i][0], t, hand_s);
            let (hy, dhy) = hand_over(delta[i][1], w[i][1], t, hand_s);
            p[i] = [
                origin[0] + rel[i][0] + hx,
                origin[1] + v * t + rel[i][1] + hy,
            ];
            vv[i] = [relv[i][0] + dhx, v + relv[i][1] + dhy];
        }
        headings.push(
            vv.iter()
                .map(|u| {
                    let l = u[0].hypot(u[1]).max(1e-12);
                    [u[0] / l, u[1] / l]
                })
                .collect(),
        );
        frames.push(p);
        vels.push(vv);
        progress.inc(1);
    }
    progress.finish();
    // Tracks (metres), savings per steady frame.
    let mut rows = Vec::with_capacity(frames.len() * n);
    let mut savings = Vec::with_capacity(cfg.frames * n);
    let mut sums = vec![0.0; n];
    let mut counted = 0usize;
    for (f, (p, vv)) in frames.iter().zip(&vels).enumerate() {
        let time = f as f64 / fps;
        let leader = (0..n)
            .max_by(|&a, &b| p[a][1].total_cmp(&p[b][1]))
            .unwrap_or(0);
        for i in 0..n {
            rows.push(TrackRow {
                frame: f as u64,
                time,
                id: i as u64,
                pos: [p[i][0] * wingspan_m, p[i][1] * wingspan_m, z[i]],
                vel: Some([vv[i][0] * wingspan_m, vv[i][1] * wingspan_m, 0.0]),
                role: Some(if i == leader { "leader" } else { "follower" }.into()),
            });
        }
        if f >= init_frames && power::check_lateral(p).is_ok() {
            let e = power::savings_unchecked(p);
            let xi = power::relative(&e);
            for i in 0..n {
                savings.push((f as u64, time, i as u64, e[i], xi[i]));
                sums[i] += e[i];
            }
            counted += 1;
        }
    }
    let mean_saving: Vec<f64> = sums.iter().map(|s| s / counted.max(1) as f64).collect();
    let flock_mean_saving = mean_saving.iter().sum::<f64>() / n as f64;
    let accel = |from: usize, to: usize| -> f64 {
        let mut m: f64 = 0.0;
        for f in from.max(1)..to.min(frames.len().saturating_sub(1)) {
            for i in 0..n {
                let ax =
                    (frames[f + 1][i][0] - 2.0 * frames[f][i][0] + frames[f - 1][i][0]) * fps * fps;
                let ay =
                    (frames[f + 1][i][1] - 2.0 * frames[f][i][1] + frames[f - 1][i][1]) * fps * fps;
                m = m.max(ax.hypot(ay));
            }
        }
        m
    };
    let hand_frames = init_frames + (hand_s * fps).ceil() as usize;
    let max_accel_steady = accel(hand_frames + 1, frames.len());
    let max_accel_hand_over = if run.is_some() {
        accel(init_frames + 1, hand_frames + 1)
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
        frames,
        headings,
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
        "frames": "steady flight only (the model assumes steady formation flight)",
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
