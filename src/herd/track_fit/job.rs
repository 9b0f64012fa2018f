//! `herdfit fit --objective tracks`: the inputs and start from files, the speed model and the
//! forces learnt from the tracks, the objective of the start and the fitted set, the
//! identifiability estimate of the track objective, and the parameter set, log and loss curve.

use super::config::TrackFitConfig;
use super::fit::{fit_tracks, mean_loss, prepare, window_gradients, TrackLogRow};
use super::global::{global_start, TrackGlobal};
use super::speed::SpeedFit;
use super::{load_input, TrackClip};
use crate::data::atomic::{check_writable, write_atomic};
use crate::error::{Error, Result};
use crate::herd::fit::identify::{identify_by, UncertaintyConfig};
use crate::herd::fit::job::{log_path_of, plot_path_of};
use crate::herd::fit::log::{epoch_chart, EpochColumn};
use crate::herd::params::{param_names, Params, N_PARAMS};
use crate::herd::uncertainty::{summary, Uncertainty};
use crate::progress::Progress;
use plotters::style::RGBColor;
use std::path::{Path, PathBuf};

/// A track fit with its files.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct TrackFitJob {
    /// Clip folders (holding `tracks.csv` or `trajectories.csv`) or tracks files in body
    /// lengths, fitted jointly.
    pub inputs: Vec<PathBuf>,
    /// Tracks files, one per input in input order, replacing the folders' own; empty: theirs.
    pub tracks: Vec<PathBuf>,
    /// Starting parameters (their constants are kept); the generic start when absent.
    pub start: Option<PathBuf>,
    pub config: TrackFitConfig,
    /// The parameter set written (`herdfit.params/1`).
    pub out: PathBuf,
    /// The training log CSV; next to `out` (`.log.csv`) when absent.
    pub log: Option<PathBuf>,
    /// The loss curve PNG; next to `out` (`.loss.png`) when absent.
    pub plot: Option<PathBuf>,
    /// The identifiability estimate of the track objective at the fitted point.
    pub uncertainty: UncertaintyConfig,
}

impl Default for TrackFitJob {
    fn default() -> Self {
        TrackFitJob {
            inputs: Vec::new(),
            tracks: Vec::new(),
            start: None,
            config: TrackFitConfig::default(),
            out: PathBuf::from("params.json"),
            log: None,
            plot: None,
            uncertainty: UncertaintyConfig::default(),
        }
    }
}

impl TrackFitJob {
    /// Checks the inputs and settings; errors name the key.
    pub fn check(&self) -> Result<()> {
        if self.inputs.is_empty() {
            return Err(Error::config(
                "inputs",
                "give at least one clip or tracks file",
            ));
        }
        if !self.tracks.is_empty() && self.tracks.len() != self.inputs.len() {
            return Err(Error::config(
                "tracks",
                format!(
                    "{} tracks files for {} inputs: give one per input, in input order",
                    self.tracks.len(),
                    self.inputs.len()
                ),
            ));
        }
        self.config.check()?;
        if self.uncertainty.enabled {
            self.uncertainty.check()?;
        }
        Ok(())
    }

    fn log_path(&self) -> PathBuf {
        log_path_of(&self.out, self.log.as_deref())
    }

    fn plot_path(&self) -> PathBuf {
        plot_path_of(&self.out, self.plot.as_deref())
    }
}

/// What a track fit did (printed by `herdfit fit --objective tracks`).
#[derive(Clone, Debug)]
pub struct TrackFitSummary {
    pub inputs: Vec<String>,
    pub config: TrackFitConfig,
    /// Steps per window, per input.
    pub steps: Vec<usize>,
    pub windows_per_epoch: usize,
    pub start: [f64; N_PARAMS],
    pub params: Params,
    pub speed: Option<SpeedFit>,
    /// The objective (mean window loss, one epoch with the fit's seed) of the start and the
    /// fitted set.
    pub objective: [f64; 2],
    pub uncertainty: Option<(Uncertainty, f64)>,
    /// The global phase's candidates (`--starts` > 1).
    pub global: Option<TrackGlobal>,
    pub out: PathBuf,
    pub log: PathBuf,
    pub plot: PathBuf,
    pub plot_warning: Option<String>,
}

/// The inputs of a job, loaded with `params`.
pub fn load_inputs(
    inputs: &[PathBuf],
    tracks: &[PathBuf],
    cfg: &TrackFitConfig,
    params: &Params,
) -> Result<Vec<TrackClip>> {
    inputs
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let t = tracks.get(i).map(PathBuf::as_path);
            load_input(
                p,
                t,
                cfg.frames.clone(),
                (cfg.leaders, cfg.guidance_scale),
                params,
            )
        })
        .collect()
}

/// The identifiability estimate of the track objective at `params` ([`identify_by`], the method
/// of `fit`'s estimate with the track windows as its probes).
pub fn identify_tracks(
    clips: &[TrackClip],
    params: &Params,
    cfg: &TrackFitConfig,
    ucfg: &UncertaintyConfig,
    progress: &mut dyn Progress,
) -> Result<Uncertainty> {
    identify_by(params, cfg.seed, ucfg, progress, |p, seed| {
        let c = TrackFitConfig {
            seed,
            ..cfg.clone()
        };
        window_gradients(clips, p, &c)
    })
}

/// Runs a track fit job and writes the parameter set, the log and the loss curve.
pub fn run(job: &TrackFitJob, progress: &mut dyn Progress) -> Result<TrackFitSummary> {
    job.check()?;
    let init = match &job.start {
        Some(p) => Params::load(p)?,
        None => Params::neutral(),
    };
    let cfg = &job.config;
    let mut clips = load_inputs(&job.inputs, &job.tracks, cfg, &init)?;
    let (log_path, plot_path) = (job.log_path(), job.plot_path());
    for p in [&job.out, &log_path, &plot_path] {
        check_writable(p)?;
    }
    let (start, speed) = prepare(&mut clips, &init, cfg)?;
    let steps: Vec<usize> = clips.iter().map(|c| cfg.steps(c.tracks.fps)).collect();
    let per_epoch: usize = clips
        .iter()
        .enumerate()
        .map(|(i, c)| {
            c.windows(i, steps[i], cfg.stride_frames(c.tracks.fps), 0)
                .len()
        })
        .sum();
    let (from, global) = match cfg.starts > 1 {
        true => {
            let (p, g) = global_start(&clips, &start, cfg, progress)?;
            (p, Some(g))
        }
        false => (start.clone(), None),
    };
    progress.start("track fit", (per_epoch * cfg.epochs) as u64);
    let (fitted, log) = fit_tracks(&clips, &from, cfg, |e, _, l| {
        progress.message(&format!("epoch {e} loss {l:.4}"));
        progress.inc(1);
    })?;
    progress.finish();
    let objective = [
        mean_loss(&clips, &start, cfg)?,
        mean_loss(&clips, &fitted, cfg)?,
    ];
    let uncertainty = match job.uncertainty.enabled {
        true => {
            let t0 = std::time::Instant::now();
            let u = identify_tracks(&clips, &fitted, cfg, &job.uncertainty, progress)?;
            Some((u, t0.elapsed().as_secs_f64()))
        }
        false => None,
    };
    let names: Vec<String> = clips.iter().map(|c| c.name.clone()).collect();
    let mut out = fitted.clone();
    let mut prov = provenance(job, &clips, &start, &speed, objective, &log);
    prov["global"] = serde_json::json!(global);
    out.provenance = Some(prov);
    out.uncertainty = uncertainty.as_ref().map(|(u, _)| u.clone());
    write_atomic(&log_path, log_csv(&log).as_bytes())?;
    let plot_warning = loss_plot(&plot_path, &log, cfg.epochs)
        .err()
        .map(|e| e.to_string());
    out.save(&job.out)?;
    Ok(TrackFitSummary {
        inputs: names,
        config: cfg.clone(),
        steps,
        windows_per_epoch: per_epoch,
        start: start.to_vec(),
        params: out,
        speed,
        objective,
        uncertainty,
        global,
        out: job.out.clone(),
        log: log_path,
        plot: plot_path,
        plot_warning,
    })
}

/// The fitted set's provenance.
fn provenance(
    job: &TrackFitJob,
    clips: &[TrackClip],
    start: &Params,
    speed: &Option<SpeedFit>,
    objective: [f64; 2],
    log: &[TrackLogRow],
) -> serde_json::Value {
    let cfg = &job.config;
    serde_json::json!({
        "source": "fit",
        "objective": "tracks",
        "inputs": clips.iter().map(|c| c.name.clone()).collect::<Vec<_>>(),
        "tracks": clips.iter().map(|c| c.tracks.path.display().to_string()).collect::<Vec<_>>(),
        "frames": clips.iter().map(|c| [c.frames.start, c.frames.end]).collect::<Vec<_>>(),
        "missing_rows": clips.iter().map(|c| c.tracks.missing_rows).collect::<Vec<_>>(),
        "settings": cfg,
        "start": start.to_vec(),
        "speed_model": speed.as_ref().map_or(
            serde_json::json!("the start set's"),
            |s| serde_json::json!({"learnt": "from the tracks (eq. 6)", "fit": s}),
        ),
        "objective_value": {
            "what": "mean window loss (mean squared position error, BL², + heading_weight × mean squared heading error + spacing_weight × mean squared difference of the sorted nearest-neighbour distances, BL²) over one epoch of windows with the fit's seed",
            "start": objective[0],
            "fitted": objective[1],
        },
        "windows": log.len(),
    })
}

/// The training log as CSV.
pub fn log_csv(rows: &[TrackLogRow]) -> String {
    let mut s = String::from("epoch,clip,frame,loss,pos_rmse,head_rmse,samples");
    for n in param_names() {
        s.push(',');
        s.push_str(&n);
    }
    s.push('\n');
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{}",
            r.epoch, r.clip, r.frame, r.loss, r.pos_rmse, r.head_rmse, r.samples
        ));
        for v in r.theta {
            s.push_str(&format!(",{v}"));
        }
        s.push('\n');
    }
    s
}

/// The loss curve: per epoch, the mean loss and RMS errors of its windows.
fn loss_plot(path: &Path, log: &[TrackLogRow], epochs: usize) -> Result<()> {
    let columns: [EpochColumn<TrackLogRow>; 3] = [
        ("loss", |r| r.loss, RGBColor(31, 119, 180)),
        ("position RMSE (BL)", |r| r.pos_rmse, RGBColor(44, 160, 44)),
        ("heading RMSE", |r| r.head_rmse, RGBColor(214, 39, 40)),
    ];
    let title = "herdfit fit --objective tracks";
    epoch_chart(path, title, log, |r| r.epoch, epochs, &columns)
}

impl std::fmt::Display for TrackFitSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let c = &self.config;
        writeln!(
            f,
            "fit (track objective, {} rollout): {} epochs × {} windows of {:.2} s ({} steps) on {}",
            c.rollout,
            c.epochs,
            self.windows_per_epoch,
            c.horizon,
            self.steps
                .iter()
                .map(|s| s.to_string())
                .collect::<Vec<_>>()
                .join("/"),
            self.inputs.join(", ")
        )?;
        let s = &self.params.speed;
        match &self.speed {
            Some(fit) => writeln!(
                f,
                "speed model (eq. 6) from {} samples: v_μ {:.3} BL/s ({} density rows), θ_OU {:.3} /s, v_σ {:.3}, cap {:.2}; tracker noise {:.0} % of the speed variance",
                fit.samples,
                s.mean,
                s.density_table.as_ref().map_or(0, |t| t.len()),
                s.reversion,
                s.std,
                s.max,
                100.0 * (1.0 - fit.signal_share)
            )?,
            None => writeln!(f, "speed model: the start set's")?,
        }
        if let Some(g) = &self.global {
            writeln!(
                f,
                "global phase: {} starts × {} epochs; objective after each: {} → start {} \
                 (candidate 1 is the given start)",
                g.candidates.len(),
                g.start_epochs,
                g.candidates
                    .iter()
                    .map(|c| format!("{:.5}", c.score))
                    .collect::<Vec<_>>()
                    .join(", "),
                g.best + 1
            )?;
        }
        writeln!(f, "{:<20} {:>8} {:>8}", "parameter", "start", "fitted")?;
        let v = self.params.to_vec();
        for (n, (a, b)) in param_names().iter().zip(self.start.iter().zip(v)) {
            writeln!(f, "{n:<20} {a:>8.4} {b:>8.4}")?;
        }
        if let Some((u, secs)) = &self.uncertainty {
            write!(f, "{}", summary(u, &v))?;
            writeln!(f, "  (estimated in {secs:.1} s)")?;
        }
        let spacing = match c.spacing_weight {
            w if w > 0.0 => format!(" + {w} × spacing"),
            _ => String::new(),
        };
        writeln!(
            f,
            "objective (mean squared position error + {} × heading error{spacing}) {:.4} → {:.4}",
            c.heading_weight, self.objective[0], self.objective[1]
        )?;
        if let Some(w) = &self.plot_warning {
            writeln!(f, "no loss curve: {w}")?;
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
