//! `herdfit flock animate`: an example's shape parameters → an initiation (§6) that converges to
//! the first key shape, a hand-over, and an F-frame steady flight (§5, Algorithm 1), written as
//! a folder: 3D tracks (metres, z = altitude), per-bird power reduction per steady frame, key
//! shapes and checks in `report.json`, two PNG plots and (feature `video`) an AVI from above.

use super::extract::ShapeParams;
use super::family::{self, Family};
use super::frames::{
    hand_over_time, initiation_frames, max_accel, rows_and_savings, steady_frames, Frames,
};
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
    /// Mean induced-power saving e of each bird over the steady frames (eq. 1 with C = 1: the
    /// fraction of a lone bird's induced power that the others' upwash removes), and of the flock:
    /// the figure field studies estimate from photographed skeins (RESULTS §3, "Energy").
    pub mean_saving: Vec<f64>,
    pub flock_mean_saving: f64,
    /// Mean wing-tip spacing over the steady frames: the lateral gap between neighbours minus
    /// one wingspan, wingspans (negative: wing tips overlap), the quantity field studies measure.
    pub mean_wing_tip_spacing: f64,
    /// The example's shape family and how the animation keeps it.
    pub shape_family: FamilyCheck,
    /// Steady frames × birds whose ξ lies in its Step 2 range [(1 − ε) p_i, (1 + ε) P_i], as a
    /// fraction, and the largest relative excursion outside it.
    pub xi_in_range_steady: f64,
    pub xi_worst_excursion_steady: f64,
    pub config: AnimateConfig,
}

/// The example's shape family (`flock::family`) and the animation's deviations from it,
/// wingspans, longitudinal, from each side's curve through the leader.
#[derive(Clone, Debug, Serialize)]
pub struct FamilyCheck {
    /// The side model (line for V and line shapes, parabola for U and J).
    pub model: super::ransac::Model,
    /// The worst bird's deviation over the example's own frames.
    pub example_worst: f64,
    /// The widest band a key shape was held to.
    pub band_widest: f64,
    /// The worst bird's deviation over the key shapes and over the steady frames.
    pub keys_worst: f64,
    pub steady_worst: f64,
    /// steady_worst / example_worst.
    pub ratio: f64,
}

/// What the steady flight starts from: Step 1's shapes and correspondence, Step 2's ranges, the
/// example's shape family carried to N birds and the first key shape (the initiation's target).
pub struct SteadySetup {
    pub init: steady::InitialShapes,
    pub range: Vec<[f64; 2]>,
    pub family: Family,
    pub first: KeyShape,
}

/// Steps 1–2 for `n` birds and the first key shape: Step 1's first shape brought into the
/// example's family ([`steady::settle`]).
pub fn steady_setup(
    params: &ShapeParams,
    n: usize,
    cfg: &SteadyConfig,
    rng: &mut rand_chacha::ChaCha8Rng,
) -> Result<SteadySetup> {
    let init = steady::initial_shapes(params, n, cfg, rng)?;
    let (_, range) = steady::ranges(&init.shapes)?;
    let family = Family::of_example(params, &init);
    let first = steady::settle(
        steady::first_key(&init.shapes[0])?,
        &range,
        &family,
        cfg,
        rng,
    );
    Ok(SteadySetup {
        init,
        range,
        family,
        first,
    })
}

/// Key shapes until the timeline covers `duration` seconds.
#[allow(clippy::too_many_arguments)]
fn build_keys(
    first: KeyShape,
    nl: usize,
    nr: usize,
    range: &[[f64; 2]],
    params: &ShapeParams,
    fam: &Family,
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
        let k = steady::next_key(
            keys.last().unwrap(),
            nl,
            nr,
            range,
            gap_range,
            fam,
            cfg,
            rng,
        );
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
    let SteadySetup {
        init,
        range,
        family: fam,
        first,
    } = steady_setup(params, n, &cfg.steady, &mut rng)?;
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
    let hand_s = if run.is_some() {
        hand_over_time(&ho.delta, &ho.w, cfg.steady.max_accel)
    } else {
        0.0
    };
    // The F steady frames start where the hand-over ends: the savings (eq. 1) describe the
    // formation the model assumes, not birds still moving to their places. The key shapes'
    // timeline starts there too (the first key shape is held during the hand-over), so the
    // hand-over's acceleration is the quintic's alone.
    let hand_count = (hand_s * fps).ceil() as usize;
    let count = hand_count + cfg.frames;
    let (keys, timeline) = build_keys(
        first,
        init.nl,
        init.nr,
        &range,
        params,
        &fam,
        ((count - 1) as f64 / fps - hand_s).max(0.0),
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
    let steady = &fr.pos[hand_frames.min(fr.pos.len())..];
    let shape_family = family_check(params, &fam, &keys, steady);
    let (xi_in_range_steady, xi_worst_excursion_steady) =
        xi_in_range(&savings, &range, cfg.steady.epsilon);
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
        mean_wing_tip_spacing: mean_wing_tip_spacing(steady),
        shape_family,
        xi_in_range_steady,
        xi_worst_excursion_steady,
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

/// The example's family and the animation's worst deviations from it (`FamilyCheck`).
fn family_check(
    params: &ShapeParams,
    fam: &Family,
    keys: &[KeyShape],
    steady: &[Vec<[f64; 2]>],
) -> FamilyCheck {
    let model = fam.model;
    let worst = |frames: &mut dyn Iterator<Item = Vec<[f64; 2]>>| {
        frames
            .map(|p| family::worst_deviation(model, &p))
            .fold(0.0, f64::max)
    };
    let example_worst = family::example_worst(params);
    let keys_worst = worst(&mut keys.iter().map(|k| k.pos.clone()));
    let steady_worst = worst(&mut steady.iter().cloned());
    FamilyCheck {
        model,
        example_worst,
        band_widest: fam.widest(),
        keys_worst,
        steady_worst,
        ratio: steady_worst / example_worst.max(f64::MIN_POSITIVE),
    }
}

/// Fraction of the savings rows whose ξ lies in its bird's Step 2 range widened by ε, and the
/// largest relative excursion outside it (0 when every row is inside).
fn xi_in_range(savings: &[(u64, f64, u64, f64, f64)], range: &[[f64; 2]], eps: f64) -> (f64, f64) {
    let (mut inside, mut worst) = (0usize, 0.0f64);
    for &(_, _, id, _, xi) in savings {
        let r = range[id as usize];
        let (lo, hi) = ((1.0 - eps) * r[0], (1.0 + eps) * r[1]);
        let out = ((lo - xi) / lo).max((xi - hi) / hi).max(0.0);
        if out <= 1e-9 {
            inside += 1;
        }
        worst = worst.max(out);
    }
    (inside as f64 / savings.len().max(1) as f64, worst)
}

/// Mean over frames and neighbour pairs of the lateral gap minus one wingspan.
fn mean_wing_tip_spacing(frames: &[Vec<[f64; 2]>]) -> f64 {
    let (mut sum, mut count) = (0.0, 0usize);
    for p in frames {
        let mut x: Vec<f64> = p.iter().map(|q| q[0]).collect();
        x.sort_by(f64::total_cmp);
        for w in x.windows(2) {
            sum += w[1] - w[0] - 1.0;
            count += 1;
        }
    }
    sum / count.max(1) as f64
}

/// The savings CSV: `frame,time,id,e,xi` (e: the bird's induced-power saving in units of a lone
/// bird's induced power, eq. 1 with C = 1; see `write_outputs`).
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
            "e": "induced-power saving e_i = Σ_j g_ij (Klotsman & Tal eq. 1 with the drag ratio C = 1; Hummel 1983): the induced power (induced drag × speed) the other birds' upwash removes from bird i, in units of the induced power of the same bird flying alone. Hummel's horseshoe-vortex model is linear and has no ceiling: e exceeds 1 where wing tips overlap (neighbours less than one wingspan apart laterally), the upwash there more than cancelling the bird's own induced drag. It is not the fraction of the bird's total flight power: that is C·e with C the induced share of its flight power at cruise (Cutts & Speakman 1994 estimate C ≈ 0.17 for pink-footed geese: 14 % of induced power, 2.4 % of total).",
      "flock mean": "report.json flock_mean_saving: e averaged over birds and steady frames, the figure field studies estimate from photographed skeins (14 %: Cutts & Speakman 1994, pink-footed geese; 36 %: Hainsworth 1987, Canada geese; both of induced power, with Lissaman & Shollenberger's model)",
            "xi": "relative power reduction ξ_i = e_i / Σ e (§5 Step 3)",
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
