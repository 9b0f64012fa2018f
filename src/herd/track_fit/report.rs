//! `herdfit validate-tracks`: parameter sets scored on held-out tracks ([`super::eval`]) beside
//! constant velocity and the built-in generic and default sets, with paired verdicts over seeds
//! and over blocks of time, written as `report.json` (`herdfit.track-eval/1`) and `report.md`.

use super::config::{steps_of, Leaders, Rollout, Speeds};
use super::eval::{constant_velocity, device, free_run_samples, score, Sums, TrackEvalConfig};
use super::speed::{learn_speed, SpeedFit};
use super::{load_input, TrackClip};
use crate::data::atomic::AtomicDir;
use crate::error::{Error, Result};
use crate::herd::params::{Params, SpeedModel};
use crate::herd::validate::paired::{paired_row, PairedRow};
use crate::measure::distribution::{mean, wasserstein};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::PathBuf;

/// Schema tag of the report.
pub const SCHEMA: &str = "herdfit.track-eval/1";

/// A track evaluation with its files.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackEvalJob {
    /// Clip folders (with their tracks) or tracks files in body lengths, scored together.
    pub inputs: Vec<PathBuf>,
    /// Tracks files replacing the folders' own, one per input; empty: theirs.
    pub tracks: Vec<PathBuf>,
    /// Parameter sets: the first is the one evaluated, the others baselines.
    pub params: Vec<PathBuf>,
    /// Also score the built-in generic (every value 0.5) and default sets, with the first set's
    /// constants.
    pub builtin: bool,
    /// Fraction of each input before the scored frames (when `frames` is absent; 0: every frame
    /// is scored).
    pub split: f64,
    /// The scored frames; absent: from `split` to the end.
    pub frames: Option<Range<usize>>,
    /// The frames the shared speed model (eq. 6) is learnt from; absent: the frames before the
    /// scored ones (the scored ones when fewer than 3 precede them).
    pub speed_frames: Option<Range<usize>>,
    /// Every set runs with the first set's own speed model (e.g. a track fit's, learnt from its
    /// training tracks: leave-one-scene-out) instead of one learnt from `speed_frames`.
    pub own_speed: bool,
    pub config: TrackEvalConfig,
    /// The report folder.
    pub out: PathBuf,
}

impl Default for TrackEvalJob {
    fn default() -> Self {
        TrackEvalJob {
            inputs: Vec::new(),
            tracks: Vec::new(),
            params: Vec::new(),
            builtin: true,
            split: 0.5,
            frames: None,
            speed_frames: None,
            own_speed: false,
            config: TrackEvalConfig::default(),
            out: PathBuf::from("track-eval"),
        }
    }
}

/// One set's scores at one horizon.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct SetRow {
    pub set: String,
    /// Mean over the seeds (BL).
    pub ade: f64,
    pub fde: f64,
    /// Standard deviation of the per-seed ADE.
    pub ade_seed_sd: f64,
}

/// The first set against another set (or constant velocity) on one measure.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Verdict {
    pub against: String,
    pub measure: String,
    /// Over the seeds (common random numbers).
    pub seeds: PairedRow,
    /// Over blocks of consecutive windows (the held-out time's own variation), seeds averaged.
    pub blocks: PairedRow,
}

/// The scores of every set at one horizon of one rollout.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct HorizonReport {
    pub seconds: f64,
    /// Steps of the first input (`round(seconds · fps)`).
    pub steps: usize,
    /// Scored (animal, window) pairs.
    pub samples: usize,
    pub sets: Vec<SetRow>,
    pub constant_velocity: [f64; 2],
    pub verdicts: Vec<Verdict>,
}

/// One rollout's scores.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct RolloutReport {
    pub rollout: Rollout,
    /// Whether the numbers are forecasts (free rollouts) or not (neighbours replayed).
    pub forecast: bool,
    pub horizons: Vec<HorizonReport>,
}

/// One set's distance from the tracks on one motion measure.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DistributionRow {
    pub set: String,
    pub measure: String,
    pub unit: String,
    /// Mean of the free runs' samples (mean over seeds) and of the tracks'.
    pub mean: f64,
    pub tracks_mean: f64,
    /// 1-Wasserstein distance from the tracks' samples, mean and sd over seeds.
    pub wasserstein: f64,
    pub wasserstein_sd: f64,
}

/// The report.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct TrackEvalReport {
    pub schema: String,
    pub inputs: Vec<String>,
    pub frames: Vec<[usize; 2]>,
    pub speed_frames: Vec<[usize; 2]>,
    /// The speed model every set runs with: learnt from the tracks of `speed_frames`, or the
    /// first set's own (`own_speed`).
    pub speed_model: SpeedModel,
    /// How a speed model learnt from `speed_frames` came out (used unless `own_speed`).
    pub speed_fit: SpeedFit,
    pub own_speed: bool,
    pub sets: Vec<(String, String)>,
    /// Metres per body length, when the clip records it (import-tracks --body-length-m).
    pub metres_per_bl: Option<f64>,
    pub config: TrackEvalConfig,
    pub rollouts: Vec<RolloutReport>,
    pub distributions: Vec<DistributionRow>,
    /// The first set against the others on each measure's Wasserstein distance, over seeds.
    pub distribution_verdicts: Vec<(String, PairedRow)>,
}

/// The sets of a job: the files, then (with `builtin`) generic and default with the first set's
/// constants.
fn sets(job: &TrackEvalJob) -> Result<Vec<(String, String, Params)>> {
    let mut out: Vec<(String, String, Params)> = Vec::new();
    for p in &job.params {
        let stem = p
            .file_stem()
            .map_or("set".into(), |s| s.to_string_lossy().into_owned());
        let mut name = stem.clone();
        let mut k = 2;
        while out.iter().any(|s| s.0 == name) {
            name = format!("{stem}-{k}");
            k += 1;
        }
        out.push((name, p.display().to_string(), Params::load(p)?));
    }
    if out.is_empty() {
        return Err(Error::config(
            "params",
            "give the parameter set to evaluate",
        ));
    }
    if job.builtin {
        let c = out[0].2.constants.clone();
        let with = |mut p: Params| {
            p.constants = c.clone();
            p
        };
        out.push((
            "generic".into(),
            "built-in (every value 0.5)".into(),
            with(Params::neutral()),
        ));
        out.push((
            "default".into(),
            "built-in default set".into(),
            with(Params::default()),
        ));
    }
    Ok(out)
}

/// Metres per BL from a clip folder's import settings.
fn metres_per_bl(input: &std::path::Path) -> Option<f64> {
    let text = std::fs::read_to_string(input.join("clip.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    v["provenance"]["settings"]["body_length_m"].as_f64()
}

/// Runs the evaluation and writes the report folder.
pub fn run(job: &TrackEvalJob, progress: &mut dyn Progress) -> Result<TrackEvalReport> {
    let cfg = &job.config;
    cfg.check()?;
    if job.inputs.is_empty() {
        return Err(Error::config(
            "inputs",
            "give at least one clip or tracks file",
        ));
    }
    if !(job.split.is_finite() && job.split >= 0.0 && job.split < 1.0) {
        return Err(Error::config(
            "split",
            format!("{} is out of range [0, 1)", job.split),
        ));
    }
    let sets = sets(job)?;
    let dir = AtomicDir::create(&job.out)?;
    let mut clips: Vec<TrackClip> = Vec::new();
    let mut speed_sets = Vec::new();
    for (i, p) in job.inputs.iter().enumerate() {
        let t = job.tracks.get(i).map(PathBuf::as_path);
        let all = load_input(p, t, 0..0, (cfg.leaders, cfg.guidance_scale), &sets[0].2)?;
        let n = all.tracks.len();
        let frames = job
            .frames
            .clone()
            .unwrap_or(((n as f64 * job.split) as usize)..n);
        let mut clip = load_input(
            p,
            t,
            frames.clone(),
            (cfg.leaders, cfg.guidance_scale),
            &sets[0].2,
        )?;
        let speed = job.speed_frames.clone().unwrap_or(match frames.start >= 3 {
            true => 0..frames.start,
            false => frames.clone(),
        });
        speed_sets.push(speed);
        clip.frames = frames;
        clips.push(clip);
    }
    let pairs: Vec<_> = clips
        .iter()
        .zip(&speed_sets)
        .map(|(c, r)| (&c.tracks, r.clone()))
        .collect();
    let c0 = &sets[0].2;
    let (learnt, speed_fit) = learn_speed(&pairs, c0.constants.perception_radius, &c0.speed)?;
    let speed = match job.own_speed {
        true => c0.speed.clone(),
        false => learnt,
    };
    let dev = device(cfg)?;
    let runs = sets.len() * (cfg.rollouts.len() + usize::from(cfg.free_run > 0.0));
    progress.start("validate-tracks", (runs * cfg.seeds) as u64);
    let cv = constant_velocity(&clips, cfg);
    let mut rollouts = Vec::new();
    for &r in &cfg.rollouts {
        let mut per_set: Vec<Vec<Sums>> = Vec::new();
        for (_, _, p) in &sets {
            let mut q = p.clone();
            q.speed = speed.clone();
            let mut seeds = Vec::new();
            for s in 0..cfg.seeds {
                seeds.push(score(&clips, &q, r, s as u64, cfg, &dev)?);
                progress.inc(1);
            }
            per_set.push(seeds);
        }
        rollouts.push(rollout_report(r, &clips, cfg, &sets, &per_set, &cv));
    }
    let (distributions, distribution_verdicts) = match cfg.free_run > 0.0 {
        true => distributions(&clips, cfg, &sets, &speed, &dev, progress)?,
        false => (Vec::new(), Vec::new()),
    };
    progress.finish();
    let report = TrackEvalReport {
        schema: SCHEMA.into(),
        inputs: clips.iter().map(|c| c.name.clone()).collect(),
        frames: clips
            .iter()
            .map(|c| [c.frames.start, c.frames.end])
            .collect(),
        speed_frames: speed_sets.iter().map(|r| [r.start, r.end]).collect(),
        speed_model: speed,
        speed_fit,
        own_speed: job.own_speed,
        sets: sets.iter().map(|s| (s.0.clone(), s.1.clone())).collect(),
        metres_per_bl: metres_per_bl(&job.inputs[0]),
        config: cfg.clone(),
        rollouts,
        distributions,
        distribution_verdicts,
    };
    let json = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::Internal(format!("serialising the report: {e}")))?;
    dir.write("report.json", format!("{json}\n").as_bytes())?;
    dir.write("report.md", markdown(&report).as_bytes())?;
    dir.commit()?;
    Ok(report)
}

/// The per-seed totals of `sums` at horizon `h` (ADE or FDE by `m`).
fn seed_values(sums: &[Sums], h: usize, m: usize) -> Vec<f64> {
    sums.iter()
        .map(|s| {
            let t = s.total(h);
            [t.0, t.1][m]
        })
        .collect()
}

/// Per block, the mean over seeds (ADE or FDE by `m`); `None` for an empty block.
fn block_values(sums: &[Sums], h: usize, m: usize) -> Vec<Option<f64>> {
    let per: Vec<Vec<Option<(f64, f64)>>> = sums.iter().map(|s| s.per_block(h)).collect();
    (0..per[0].len())
        .map(|b| {
            let v: Option<Vec<f64>> = per.iter().map(|p| p[b].map(|x| [x.0, x.1][m])).collect();
            v.map(|v| v.iter().sum::<f64>() / v.len() as f64)
        })
        .collect()
}

fn rollout_report(
    r: Rollout,
    clips: &[TrackClip],
    cfg: &TrackEvalConfig,
    sets: &[(String, String, Params)],
    per_set: &[Vec<Sums>],
    cv: &Sums,
) -> RolloutReport {
    let fps = clips[0].tracks.fps;
    let horizons = cfg
        .horizons
        .iter()
        .enumerate()
        .map(|(h, &secs)| {
            let rows = sets
                .iter()
                .zip(per_set)
                .map(|((name, _, _), seeds)| {
                    let ade = seed_values(seeds, h, 0);
                    let m = ade.iter().sum::<f64>() / ade.len() as f64;
                    let sd = (ade.iter().map(|a| (a - m).powi(2)).sum::<f64>()
                        / (ade.len().max(2) - 1) as f64)
                        .sqrt();
                    let fde = seed_values(seeds, h, 1);
                    SetRow {
                        set: name.clone(),
                        ade: m,
                        fde: fde.iter().sum::<f64>() / fde.len() as f64,
                        ade_seed_sd: sd,
                    }
                })
                .collect();
            let mut verdicts = Vec::new();
            for m in 0..2 {
                let name = ["ade", "fde"][m];
                let first = &per_set[0];
                let mine = seed_values(first, h, m);
                let my_blocks = block_values(first, h, m);
                let mut against = |who: &str, seeds: Vec<f64>, blocks: Vec<Option<f64>>| {
                    let ds: Vec<f64> = mine.iter().zip(&seeds).map(|(a, b)| a - b).collect();
                    let db: Vec<f64> = my_blocks
                        .iter()
                        .zip(&blocks)
                        .filter_map(|(a, b)| Some((*a)? - (*b)?))
                        .collect();
                    verdicts.push(Verdict {
                        against: who.to_string(),
                        measure: name.into(),
                        seeds: paired_row(name, &ds),
                        blocks: paired_row(name, &db),
                    });
                };
                for ((other, _, _), seeds) in sets.iter().zip(per_set).skip(1) {
                    against(other, seed_values(seeds, h, m), block_values(seeds, h, m));
                }
                let c = [cv.total(h).0, cv.total(h).1][m];
                let cb = cv
                    .per_block(h)
                    .iter()
                    .map(|x| x.map(|x| [x.0, x.1][m]))
                    .collect();
                against("constant velocity", vec![c; mine.len()], cb);
            }
            let t = cv.total(h);
            HorizonReport {
                seconds: secs,
                steps: steps_of(secs, fps),
                samples: t.2,
                sets: rows,
                constant_velocity: [t.0, t.1],
                verdicts,
            }
        })
        .collect();
    RolloutReport {
        rollout: r,
        forecast: r == Rollout::Free,
        horizons,
    }
}

type Distributions = (Vec<DistributionRow>, Vec<(String, PairedRow)>);

/// Every set's free runs against the tracks, measure by measure, and the first set's paired
/// verdicts on the Wasserstein distances.
fn distributions(
    clips: &[TrackClip],
    cfg: &TrackEvalConfig,
    sets: &[(String, String, Params)],
    speed: &SpeedModel,
    dev: &burn::tensor::Device,
    progress: &mut dyn Progress,
) -> Result<Distributions> {
    let mut rows = Vec::new();
    // [set][seed][measure] distances.
    let mut w: Vec<Vec<[f64; 4]>> = Vec::new();
    for (name, _, p) in sets {
        let mut q = p.clone();
        q.speed = speed.clone();
        let mut per_seed = Vec::new();
        let mut means = [0.0; 4];
        let mut tracks_means = [0.0; 4];
        let mut units = Vec::new();
        for s in 0..cfg.seeds {
            let (sim, obs) = free_run_samples(clips, &q, s as u64, cfg, dev)?;
            let (a, b) = (sim.named("BL"), obs.named("BL"));
            let mut d = [0.0; 4];
            for k in 0..4 {
                d[k] = wasserstein(a[k].2, b[k].2);
                means[k] += mean(a[k].2) / cfg.seeds as f64;
                tracks_means[k] = mean(b[k].2);
            }
            units = a.iter().map(|x| (x.0, x.1.clone())).collect();
            per_seed.push(d);
            progress.inc(1);
        }
        for (k, (m, u)) in units.into_iter().enumerate() {
            let v: Vec<f64> = per_seed.iter().map(|d| d[k]).collect();
            let mean = v.iter().sum::<f64>() / v.len() as f64;
            let sd = (v.iter().map(|x| (x - mean).powi(2)).sum::<f64>()
                / (v.len().max(2) - 1) as f64)
                .sqrt();
            rows.push(DistributionRow {
                set: name.clone(),
                measure: m.into(),
                unit: u,
                mean: means[k],
                tracks_mean: tracks_means[k],
                wasserstein: mean,
                wasserstein_sd: sd,
            });
        }
        w.push(per_seed);
    }
    let names = ["speed", "nearest_neighbour", "turning_rate", "polarization"];
    let mut verdicts = Vec::new();
    for (j, (other, _, _)) in sets.iter().enumerate().skip(1) {
        for (k, m) in names.iter().enumerate() {
            let d: Vec<f64> = w[0].iter().zip(&w[j]).map(|(a, b)| a[k] - b[k]).collect();
            verdicts.push((other.clone(), paired_row(m, &d)));
        }
    }
    Ok((rows, verdicts))
}

/// The report in Markdown.
pub fn markdown(r: &TrackEvalReport) -> String {
    let m = r.metres_per_bl;
    let mut s = format!(
        "# Track evaluation of {}\n\nInputs: {}; scored frames {}; every set runs with the speed model (eq. 6) {} (v_μ {:.3} BL/s, θ_OU {:.3} /s, v_σ {:.3}). {} seeds (common random numbers: a seed fixes each window's speed noise for every set); windows every {} s; an animal is scored at a horizon when tracked through it and in the {} frames up to the window's start. Verdicts: the 95 % t-interval of the paired difference over the seeds, and over {} blocks of consecutive windows (seeds averaged).\n\n",
        r.sets[0].0,
        r.inputs.join(", "),
        ranges(&r.frames),
        match r.own_speed {
            true => format!("of {}", r.sets[0].0),
            false => format!("learnt from the tracks of frames {}", ranges(&r.speed_frames)),
        },
        r.speed_model.mean,
        r.speed_model.reversion,
        r.speed_model.std,
        r.config.seeds,
        r.config.stride,
        r.config.observe,
        r.config.blocks
    );
    s.push_str(&format!(
        "Leaders (§5.1): {}. Displacement errors with eq. 6's speeds {}.\n\n",
        match r.config.leaders {
            Leaders::Off => "off, the forces steer every animal",
            Leaders::Field =>
                "an animal with few visible neighbours ahead follows the clip's guidance",
        },
        match r.config.speeds {
            Speeds::Expected => "without their noise (a point forecast)",
            _ => "with their noise (one sample per seed)",
        }
    ));
    s.push_str("Sets: ");
    s.push_str(
        &r.sets
            .iter()
            .map(|(n, src)| format!("`{n}` ({src})"))
            .collect::<Vec<_>>()
            .join(", "),
    );
    s.push_str(".\n\n");
    for ro in &r.rollouts {
        s.push_str(&format!(
            "## {} rollouts{}\n\n| horizon | set | ADE (BL) | FDE (BL) |{}\n|---|---|---:|---:|{}\n",
            ro.rollout,
            match ro.forecast {
                true => " (forecasts: every animal stepped by the model)",
                false => " (not forecasts: the neighbours are replayed from the tracks)",
            },
            if m.is_some() { " ADE (m) | FDE (m) |" } else { "" },
            if m.is_some() { "---:|---:|" } else { "" },
        ));
        for h in &ro.horizons {
            let row = |name: &str, a: f64, f: f64| {
                let metres = m.map_or(String::new(), |k| format!(" {:.3} | {:.3} |", a * k, f * k));
                format!(
                    "| {:.2} s ({} steps, {} samples) | {name} | {a:.4} | {f:.4} |{metres}\n",
                    h.seconds, h.steps, h.samples
                )
            };
            for x in &h.sets {
                s.push_str(&row(&x.set, x.ade, x.fde));
            }
            s.push_str(&row(
                "constant velocity",
                h.constant_velocity[0],
                h.constant_velocity[1],
            ));
        }
        s.push_str(&format!(
            "\n{} against each, paired (negative: {} is better):\n\n| horizon | measure | against | difference | over seeds | over blocks |\n|---|---|---|---:|---|---|\n",
            r.sets[0].0, r.sets[0].0
        ));
        for h in &ro.horizons {
            for v in &h.verdicts {
                let se =
                    |p: &PairedRow| p.standard_error.map_or("—".into(), |x| format!("{x:.4}"));
                s.push_str(&format!(
                    "| {:.2} s | {} | {} | {:+.4} | {} (± {}) | {} (± {}) |\n",
                    h.seconds,
                    v.measure,
                    v.against,
                    v.seeds.difference,
                    v.seeds.verdict,
                    se(&v.seeds),
                    v.blocks.verdict,
                    se(&v.blocks)
                ));
            }
        }
        s.push('\n');
    }
    if !r.distributions.is_empty() {
        s.push_str(&format!(
            "## Free runs against the held-out tracks\n\nRuns of {} s from the tracked animals (restarted every {} s), sampled where each animal is still tracked; the tracks sampled over the same animals and frames. 1-Wasserstein distance from the tracks' distribution, mean ± sd over the seeds.\n\n| measure | unit | tracks' mean | set | run's mean | W |\n|---|---|---:|---|---:|---:|\n",
            r.config.free_run, r.config.free_run
        ));
        for d in &r.distributions {
            s.push_str(&format!(
                "| {} | {} | {:.4} | {} | {:.4} | {:.4} ± {:.4} |\n",
                d.measure, d.unit, d.tracks_mean, d.set, d.mean, d.wasserstein, d.wasserstein_sd
            ));
        }
        s.push_str(&format!(
            "\n{} against each on the distance (negative: closer to the tracks):\n\n| against | measure | difference | verdict |\n|---|---|---:|---|\n",
            r.sets[0].0
        ));
        for (who, p) in &r.distribution_verdicts {
            s.push_str(&format!(
                "| {who} | {} | {:+.4} | {} |\n",
                p.measure, p.difference, p.verdict
            ));
        }
    }
    s
}

fn ranges(r: &[[usize; 2]]) -> String {
    r.iter()
        .map(|x| format!("{}..{}", x[0], x[1]))
        .collect::<Vec<_>>()
        .join(", ")
}

impl std::fmt::Display for TrackEvalReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&markdown(self))
    }
}
