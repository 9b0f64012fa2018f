//! A fit as `herdfit fit` runs it, and as `examples/fit_synthetic.rs` runs it: clips and start
//! from files, the fit, its evaluation (losses and field errors of the start and the fitted set),
//! the provenance recorded in the parameter file, the training log and the loss curve.

use super::anchor::Anchors;
use super::checkpoint::CheckpointDir;
use super::choose::LossChoice;
use super::config::FitConfig;
use super::global::{fit_global, split_frames, GlobalReport};
use super::identify::{identify, UncertaintyConfig};
use super::log::{plot_or_warn, write_log, LogRow};
use super::run::{loss_of, FitResult};
use super::still::{stationary_clip, still_measures, StillConfig, StillMeasures};
use crate::data::atomic::check_writable;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::eval::evaluate;
use crate::herd::guidance::guidance_fields;
use crate::herd::params::{param_names, Params, SpeedModel};
use crate::herd::sim::Guidance;
use crate::herd::uncertainty::Uncertainty;
use crate::progress::Progress;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// A fit with its files.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FitJob {
    /// One clip, or several clips of the same kind of herd fitted jointly (paper §7.6).
    pub clips: Vec<PathBuf>,
    /// Starting parameters; the generic start (every value 0.5) when absent.
    pub start: Option<PathBuf>,
    /// Frames used, `start..end`; all frames of the shortest clip when absent (`config.frames`
    /// is set from it).
    pub frames: Option<Range<usize>>,
    pub config: FitConfig,
    /// Runs (seeds S, S+1, …) averaged into the provenance's `evaluation`.
    pub eval_seeds: usize,
    /// Validation runs per candidate objective when `config.loss` is `auto`
    /// ([`super::choose`]).
    pub choice_seeds: usize,
    /// A folder for a checkpoint after every epoch, and whether to resume from it.
    pub checkpoint: Option<PathBuf>,
    pub resume: bool,
    /// The parameter set written (`herdfit.params/1`).
    pub out: PathBuf,
    /// The training log CSV; next to `out` (`.log.csv`) when absent.
    pub log: Option<PathBuf>,
    /// The loss curve PNG; next to `out` (`.loss.png`) when absent.
    pub plot: Option<PathBuf>,
    /// The identifiability estimate at the fitted point, written as the set's `uncertainty`.
    pub uncertainty: UncertaintyConfig,
    /// A zones file (`herdfit.zones/1`): one parameter set per zone, learnt jointly, written as a
    /// parameter-set bundle (`herdfit.param-sets/1`) at `out` ([`super::zone_job`]).
    pub zones: Option<PathBuf>,
    /// The schedule used when the clips are stills (one frame each, paper §7.2.4,
    /// [`super::still`]); ignored otherwise.
    pub still: StillConfig,
}

impl Default for FitJob {
    fn default() -> Self {
        FitJob {
            clips: Vec::new(),
            start: None,
            frames: None,
            config: FitConfig {
                loss: super::config::LossKind::Auto,
                ..FitConfig::default()
            },
            eval_seeds: 4,
            choice_seeds: 8,
            checkpoint: None,
            resume: false,
            out: PathBuf::from("params.json"),
            log: None,
            plot: None,
            uncertainty: UncertaintyConfig::default(),
            zones: None,
            still: StillConfig::default(),
        }
    }
}

/// `out` with its extension replaced by `suffix` (`params.json` → `params.log.csv`).
pub fn sibling(out: &Path, suffix: &str) -> PathBuf {
    let stem = out
        .file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "params".into());
    out.with_file_name(format!("{stem}{suffix}"))
}

impl FitJob {
    /// The training log's path.
    pub fn log_path(&self) -> PathBuf {
        log_path_of(&self.out, self.log.as_deref())
    }

    /// The loss curve's path.
    pub fn plot_path(&self) -> PathBuf {
        plot_path_of(&self.out, self.plot.as_deref())
    }
}

/// A fit's training log: `log` when given, else `<out stem>.log.csv` beside `out`.
pub fn log_path_of(out: &Path, log: Option<&Path>) -> PathBuf {
    log.map_or_else(|| sibling(out, ".log.csv"), Path::to_path_buf)
}

/// A fit's loss curve: `plot` when given, else `<out stem>.loss.png` beside `out`.
pub fn plot_path_of(out: &Path, plot: Option<&Path>) -> PathBuf {
    plot.map_or_else(|| sibling(out, ".loss.png"), Path::to_path_buf)
}

impl FitJob {
    /// Checks the evaluation's seeds and the fit's settings on their own
    /// ([`FitConfig::check`]; `config.frames` is checked once the clips are known).
    pub fn check(&self) -> Result<()> {
        for (key, n) in [
            ("eval_seeds", self.eval_seeds),
            ("choice_seeds", self.choice_seeds),
        ] {
            if n == 0 || n > 64 {
                return Err(Error::config(key, format!("{n} is out of range 1..=64")));
            }
        }
        if self.clips.is_empty() {
            return Err(Error::config("clips", "give at least one clip"));
        }
        // Checked even when switched off: a value given is a value judged (issue #47).
        self.uncertainty.check()?;
        if self.zones.is_some() {
            let refuse = |key: &str, why: &str| Err(Error::config(key, why.to_string()));
            if self.clips.len() != 1 {
                return refuse("zones", "a zone fit takes one clip");
            }
        }
        if crate::data::atomic::is_stdout(&self.out) && (self.log.is_none() || self.plot.is_none())
        {
            return Err(Error::config(
                "out",
                "'-' (standard output) needs the log and the plot given paths of their own",
            ));
        }
        Ok(())
    }
}

/// What a fit did: the schedule, the start and fitted parameters, and the losses and errors of
/// both (printed by `herdfit fit`).
#[derive(Clone, Debug)]
pub struct FitSummary {
    pub clips: Vec<String>,
    pub frames: Range<usize>,
    pub epochs: usize,
    pub window: usize,
    pub windows_per_epoch: usize,
    pub result: FitResult,
    /// The global phase's candidates and choice, when it ran.
    pub global: Option<GlobalReport>,
    /// The objective `auto` chose and why ([`super::choose`]); none when one was given.
    pub choice: Option<LossChoice>,
    /// (E_mean, E_var, E_fields) of the start and of the fitted set ([`loss_of`]).
    pub loss: [(f64, f64, f64); 2],
    /// (density error, velocity error) of the start and of the fitted set.
    pub errors: [(f64, f64); 2],
    pub out: PathBuf,
    pub log: PathBuf,
    pub plot: PathBuf,
    /// Why the loss curve could not be drawn, if it could not (the fit is written anyway).
    pub plot_warning: Option<String>,
    /// The identifiability estimate and its wall time in seconds (None when switched off).
    pub uncertainty: Option<(Uncertainty, f64)>,
    /// A still's measures ([`still_measures`]): of the herd as drawn from the image, and after
    /// settling with the start and with the fitted set.
    pub still: Option<(StillConfig, [StillMeasures; 3])>,
}

/// Runs a fit job: loads the clips and the start, fits, evaluates the start and the fitted set,
/// and writes the parameter set (with its provenance), the log and the loss curve.
pub fn run(job: &FitJob, progress: &mut dyn Progress) -> Result<FitSummary> {
    job.check()?;
    let loaded = job
        .clips
        .iter()
        .map(|p| ClipFields::load(p))
        .collect::<Result<Vec<_>>>()?;
    let init = match &job.start {
        Some(p) => Params::load(p)?,
        None => Params::neutral(),
    };
    let (loaded, still) = stills(loaded, job, &init.speed)?;
    let clips: Vec<&ClipFields> = loaded.iter().collect();
    // All frames of the shortest clip unless told otherwise.
    let shortest = clips.iter().map(|c| c.frames()).min().unwrap_or(0);
    let frames = job.frames.clone().unwrap_or(0..shortest);
    let mut cfg = FitConfig {
        frames: frames.clone(),
        still,
        ..job.config.clone()
    };
    cfg.check()?;
    for (c, p) in clips.iter().zip(&job.clips) {
        cfg.check_clip(c).map_err(|e| e.in_file(p))?;
    }
    // Bad tracks are reported before anything is written.
    let anchors = super::anchor::load_all(&cfg, &clips)?;
    let (log_path, plot_path) = (job.log_path(), job.plot_path());
    for p in [&job.out, &log_path, &plot_path] {
        check_writable(p)?;
    }
    let in_file = |e: Error| match job.clips.as_slice() {
        [one] => e.in_file(one),
        _ => e,
    };
    let (ckpt, windows_per_epoch) = start_fit(job, &cfg, clips.len(), progress)?;
    // `auto`: the objective chosen on the fit's own frames ([`super::choose`]).
    let choice = super::choose::resolve(
        &clips,
        &init,
        &cfg,
        job.choice_seeds,
        ckpt.as_ref(),
        window_progress(progress),
    )
    .map_err(in_file)?;
    if let Some(c) = &choice {
        cfg.loss = c.chosen;
    }
    let (res, global) = fit_global(
        &clips,
        &init,
        &cfg,
        ckpt.as_ref(),
        window_progress(progress),
    )
    .map_err(in_file)?;
    progress.finish();
    let mut start_params = init.clone();
    start_params.speed = res.params.speed.clone();
    let loss = [
        loss_of(&clips, &start_params, &cfg)?,
        loss_of(&clips, &res.params, &cfg)?,
    ];
    let errors = evaluation(
        &clips,
        &init.speed,
        &[&start_params, &res.params],
        job,
        &cfg,
        &anchors,
    )?;
    let still_eval = still_evaluation(clips[0], &cfg, job, &start_params, &res.params)?;
    let names: Vec<String> = job.clips.iter().map(|p| p.display().to_string()).collect();
    let mut out = res.params.clone();
    let mut prov = provenance(&names, &cfg, &res, loss, errors, job.eval_seeds);
    if let Some((_, m)) = &still_eval {
        prov["evaluation"]["still"] = still_provenance(m);
    }
    if let Some(g) = &global {
        prov["global"] = serde_json::to_value(g)
            .map_err(|e| Error::Internal(format!("serialising the global phase: {e}")))?;
    }
    if let Some(c) = &choice {
        prov["loss_choice"] = serde_json::to_value(c)
            .map_err(|e| Error::Internal(format!("serialising the loss choice: {e}")))?;
    }
    out.provenance = Some(prov);
    // Issue #15 item 2: what the clip determines at the fitted point.
    let uncertainty = match job.uncertainty.enabled {
        true => {
            let t0 = std::time::Instant::now();
            let at = init.with_vec(&res.params.to_vec());
            let u = identify(&clips, &at, &cfg, &job.uncertainty, progress)?;
            Some((u, t0.elapsed().as_secs_f64()))
        }
        false => None,
    };
    out.uncertainty = uncertainty.as_ref().map(|(u, _)| u.clone());
    write_log(&log_path, &res.log)?;
    let plot_warning = plot_or_warn(&plot_path, &res.log, cfg.epochs)?;
    out.save(&job.out)?;
    Ok(FitSummary {
        clips: names,
        frames,
        epochs: cfg.epochs,
        window: cfg.window,
        windows_per_epoch,
        result: res,
        global,
        choice,
        loss,
        errors: [errors[0], errors[1]],
        out: job.out.clone(),
        log: log_path,
        plot: plot_path,
        plot_warning,
        uncertainty,
        still: still_eval,
    })
}

/// A still's measures with the start and the fitted set ([`still_measures`]: the herd as drawn,
/// then after settling with each set); `None` for a video clip.
fn still_evaluation(
    clip: &ClipFields,
    cfg: &FitConfig,
    job: &FitJob,
    start: &Params,
    fitted: &Params,
) -> Result<Option<(StillConfig, [StillMeasures; 3])>> {
    let Some(s) = &cfg.still else {
        return Ok(None);
    };
    let m = |p: &Params| still_measures(clip, p, s, cfg.seed, job.eval_seeds, cfg.precision);
    let ([drawn, before], [_, after]) = (m(start)?, m(fitted)?);
    Ok(Some((*s, [drawn, before, after])))
}

/// The provenance's `evaluation.still`.
fn still_provenance([d, a, b]: &[StillMeasures; 3]) -> serde_json::Value {
    serde_json::json!({
        "what": "against the image: density error of cell counts and smoothed (the fit's density term), crowding (density around an average animal over the image's), polarization (eq. 12); averaged over the steps after settling and over the seeds; `drawn`: the herd as drawn from the image, before any step",
        "drawn": d,
        "start": a,
        "fitted": b,
    })
}

/// A fit from stills (paper §7.2.4): when every clip has one frame, each is replaced by its
/// stationary target ([`stationary_clip`]) and the fit's `still` schedule is set; a still among
/// video clips is an error naming it.
fn stills(
    loaded: Vec<ClipFields>,
    job: &FitJob,
    speed: &SpeedModel,
) -> Result<(Vec<ClipFields>, Option<StillConfig>)> {
    let one: Vec<bool> = loaded.iter().map(|c| c.frames() == 1).collect();
    if !one.iter().any(|&b| b) {
        return Ok((loaded, None));
    }
    if let Some(k) = one.iter().position(|&b| !b) {
        let still = &job.clips[one.iter().position(|&b| b).unwrap_or(0)];
        return Err(Error::file(
            &job.clips[k],
            format!(
                "a clip of several frames cannot be fitted with the still {} (one frame)",
                still.display()
            ),
        ));
    }
    job.still.check()?;
    let out = loaded
        .iter()
        .map(|c| stationary_clip(c, &job.still, speed))
        .collect();
    Ok((out, Some(job.still)))
}

/// Density and velocity errors of each parameter set in `sets`, averaged over the clips (each
/// simulated with its own speeds, from `base`) and `job.eval_seeds` seeds; a clip with tracked
/// animals (`anchors`) is run from them, as the fit's windows were.
fn evaluation(
    clips: &[&ClipFields],
    base: &SpeedModel,
    sets: &[&Params; 2],
    job: &FitJob,
    cfg: &FitConfig,
    anchors: &[Option<Anchors>],
) -> Result<[(f64, f64); 2]> {
    let guidance: Vec<Vec<Guidance>> = clips
        .iter()
        .map(|c| guidance_fields(c, cfg.guidance_scale))
        .collect();
    let gates = clips
        .iter()
        .map(|c| cfg.boundary.gates(c))
        .collect::<Result<Vec<_>>>()?;
    let errors = |p: &Params| -> Result<(f64, f64)> {
        let (mut d, mut v) = (0.0, 0.0);
        for (((c, guidance), a), gates) in clips.iter().zip(&guidance).zip(anchors).zip(&gates) {
            let mut q = p.clone();
            q.speed = SpeedModel::of_clip(c, base);
            for k in 0..job.eval_seeds {
                let (x, y) = evaluate(
                    c,
                    &q,
                    a.as_ref().and_then(|a| a.at(cfg.frames.start)),
                    gates,
                    cfg.frames.clone(),
                    cfg.seed.wrapping_add(k as u64),
                    cfg.precision,
                    &cfg.settle,
                    guidance,
                )?;
                let w = (clips.len() * job.eval_seeds) as f64;
                d += x / w;
                v += y / w;
            }
        }
        Ok((d, v))
    };
    Ok([errors(sets[0])?, errors(sets[1])?])
}

/// The provenance of a fitted parameter set: clips, frames, settings, start, the last epoch's
/// mean losses, the losses of one epoch without updates and the evaluation, for the start and
/// the fitted set.
fn provenance(
    clips: &[String],
    cfg: &FitConfig,
    res: &FitResult,
    loss: [(f64, f64, f64); 2],
    errors: [(f64, f64); 2],
    eval_seeds: usize,
) -> serde_json::Value {
    let last_epoch = res.log.last().map_or(0, |r| r.epoch);
    let last: Vec<&LogRow> = res.log.iter().filter(|r| r.epoch == last_epoch).collect();
    let mean = |f: &dyn Fn(&LogRow) -> f64| {
        last.iter().map(|r| f(r)).sum::<f64>() / last.len().max(1) as f64
    };
    let ([lb, la], [before, after]) = (loss, errors);
    serde_json::json!({
        "source": "fit",
        "clip": clips[0],
        "clips": clips,
        "frames": [cfg.frames.start, cfg.frames.end],
        "settings": cfg,
        "start": res.start,
        "final_losses": {
            "e_mean": mean(&|r| r.e_mean),
            "e_var": mean(&|r| r.e_var),
            "e_fields": mean(&|r| r.e_fields),
            "density_error": mean(&|r| r.density_error),
            "velocity_error": mean(&|r| r.velocity_error),
        },
        "loss": {
            "what": "mean E_mean and E_var over one epoch of the fit's schedule without updates (same herd and noise)",
            "start": {"e_mean": lb.0, "e_var": lb.1, "e_fields": lb.2},
            "fitted": {"e_mean": la.0, "e_var": la.1, "e_fields": la.2},
        },
        "evaluation": {
            "what": format!("mean per-frame errors of runs from {} (no population control), averaged over the seeds", super::anchor::runs_start_from(cfg)),
            "seeds": eval_seeds,
            "start": {"density_error": before.0, "velocity_error": before.1},
            "fitted": {"density_error": after.0, "velocity_error": after.1},
        },
    })
}

impl std::fmt::Display for FitSummary {
    /// What `herdfit fit` prints: the schedule, start vs fitted parameters, losses and errors.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "fit: {} epochs × {} windows of {} steps on frames {}..{} of {}",
            self.epochs,
            self.windows_per_epoch,
            self.window,
            self.frames.start,
            self.frames.end,
            self.clips.join(", ")
        )?;
        if let Some(c) = &self.choice {
            write!(f, "{c}")?;
        }
        if let Some(g) = &self.global {
            write!(f, "{g}")?;
        }
        writeln!(f, "{:<20} {:>8} {:>8}", "parameter", "start", "fitted")?;
        for (n, (s0, s1)) in param_names()
            .iter()
            .zip(self.result.start.iter().zip(self.result.params.to_vec()))
        {
            writeln!(f, "{n:<20} {s0:>8.4} {s1:>8.4}")?;
        }
        if let Some((u, secs)) = &self.uncertainty {
            let v = self.result.params.to_vec();
            write!(f, "{}", crate::herd::uncertainty::summary(u, &v))?;
            writeln!(f, "  (estimated in {secs:.1} s)")?;
        }
        let ([lb, la], [b, a]) = (self.loss, self.errors);
        writeln!(
            f,
            "loss E_mean {:.4} → {:.4}, E_var {:.4} → {:.4}, E_fields {:.4} → {:.4}; density error {:.4} → {:.4}, velocity error {:.4} → {:.4}",
            lb.0, la.0, lb.1, la.1, lb.2, la.2, b.0, a.0, b.1, a.1
        )?;
        if let Some((s, [d, a, b])) = &self.still {
            writeln!(
                f,
                "still, start → fitted after {} settling steps, over {} (the herd as drawn from the image in brackets): density error {:.4} → {:.4} ({:.4}), smoothed {:.4} → {:.4} ({:.4}), crowding {:.3} → {:.3} ({:.3}), polarization {:.4} → {:.4} ({:.4})",
                s.settle,
                s.average,
                a.density_error,
                b.density_error,
                d.density_error,
                a.smooth_density_error,
                b.smooth_density_error,
                d.smooth_density_error,
                a.crowding,
                b.crowding,
                d.crowding,
                a.polarization,
                b.polarization,
                d.polarization,
            )?;
        }
        writeln!(
            f,
            "wrote {}, {}, {}",
            self.out.display(),
            self.log.display(),
            self.plot.display()
        )
    }
}

/// The per-window callback of a fit's progress bar: the window's loss and speed as its message,
/// one unit done, and whether to stop.
fn window_progress(
    progress: &mut dyn Progress,
) -> impl FnMut(usize, usize, f64, f64) -> Result<()> + '_ {
    move |epoch, frame, e, ms| {
        progress.message(&format!(
            "epoch {epoch} frame {frame} E_mean {e:.4} {ms:.1} ms/step"
        ));
        progress.inc(1);
        progress.check()
    }
}

/// The job's checkpoint folder ([`checkpoint_dir`]) and the fit's progress bar started on `clips`
/// clips: one unit per window of every candidate's refinement, those a resumed checkpoint holds
/// counted done; returns the folder and the windows per epoch of a refinement. With the global
/// phase the first candidate's folder holds the first checkpoint, and every candidate is refined
/// on the frames before the held-out ones.
pub(super) fn start_fit(
    job: &FitJob,
    cfg: &FitConfig,
    clips: usize,
    progress: &mut dyn Progress,
) -> Result<(Option<CheckpointDir>, usize)> {
    let global = !cfg.global.is_off();
    let first = if global { "start-0" } else { "" };
    let ckpt = checkpoint_dir(job, std::path::Path::new(first))?;
    let (refine, candidates) = match global {
        false => (cfg.frames.clone(), 1),
        true => (split_frames(&cfg.frames, &cfg.global)?.0, cfg.global.starts),
    };
    let windows = cfg.windows_per_epoch(&refine, clips);
    let choosing = super::choose::windows(cfg, clips);
    progress.start("fit", (choosing + windows * cfg.epochs * candidates) as u64);
    if let Some(done) = ckpt.as_ref().and_then(CheckpointDir::epochs_done) {
        progress.inc((choosing + done * windows) as u64);
    }
    Ok((ckpt, windows))
}

/// The job's checkpoint folder (created), or none; with `--resume`, refused unless the
/// checkpoint to resume from (in `first` inside the folder) exists.
fn checkpoint_dir(job: &FitJob, first: &std::path::Path) -> Result<Option<CheckpointDir>> {
    if job.resume {
        let file = job
            .checkpoint
            .as_ref()
            .map(|d| d.join(first).join("checkpoint.json"));
        match file {
            None => return Err(Error::config("resume", "needs a checkpoint folder")),
            Some(f) if !f.is_file() => {
                return Err(Error::file(&f, "no checkpoint to resume from"));
            }
            Some(_) => {}
        }
    }
    match &job.checkpoint {
        Some(d) => {
            crate::data::atomic::make_dir(d)?;
            Ok(Some(CheckpointDir {
                dir: d.clone(),
                resume: job.resume,
            }))
        }
        None => Ok(None),
    }
}
