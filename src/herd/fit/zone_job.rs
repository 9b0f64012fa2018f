//! `herdfit fit CLIP --zones ZONES.json` (paper §7.2.4): one parameter set per zone learnt
//! jointly ([`super::run::fit_zones`]), evaluated against the start on the fitted frames, and
//! written as a parameter-set bundle (`herdfit.param-sets/1`) with the log and the loss curve.

use super::global::fit_zones_global;
use super::job::FitJob;
use super::log::plot_or_warn;
use super::log::write_log;
use super::still::{stationary_clip, still_measures_in, StillConfig, StillMeasures, StillRun};
use crate::backend::device;
use crate::data::agents::AgentRow;
use crate::data::atomic::check_writable;
use crate::data::ClipFields;
use crate::error::Result;
use crate::herd::eval::run_from;
use crate::herd::guidance::guidance_fields;
use crate::herd::params::{param_names, Params, SpeedModel};
use crate::herd::zoned::ZoneSets;
use crate::herd::zones::Zones;
use crate::measure::fields::field_errors;
use crate::progress::Progress;
use serde::Serialize;
use std::ops::Range;
use std::path::PathBuf;

/// What a zone fit did.
#[derive(Clone, Debug)]
pub struct ZoneFitSummary {
    pub frames: Range<usize>,
    pub epochs: usize,
    pub names: Vec<String>,
    pub start: [f64; 12],
    pub fitted: Vec<[f64; 12]>,
    /// (density error, velocity error) of the start and of the fitted sets on the fitted frames.
    pub errors: [(f64, f64); 2],
    pub out: PathBuf,
    pub log: PathBuf,
    pub plot: PathBuf,
    /// Why the loss curve could not be drawn, if it could not (the bundle is written anyway).
    pub plot_warning: Option<String>,
    /// The global phase's candidates and choice, when it ran.
    pub global: Option<super::global::GlobalReport>,
    /// A still's measures (the clip was one frame).
    pub still: Option<ZoneStill>,
}

/// Runs a zone fit job (`job.zones` set): loads the clip, the zones (checked against the clip's
/// cells and agents) and the start, fits, evaluates and writes the bundle, the log and the plot.
pub fn run_zones(job: &FitJob, progress: &mut dyn Progress) -> Result<ZoneFitSummary> {
    job.check()?;
    let Some(zpath) = &job.zones else {
        return Err(crate::error::Error::config("zones", "no zones file given"));
    };
    let clip = ClipFields::load(&job.clips[0])?;
    let start = match &job.start {
        Some(p) => Params::load(p)?,
        None => Params::neutral(),
    };
    // A still (one frame, paper §7.2.4) is fitted as its stationary target, as `fit` does.
    let still = (clip.frames() == 1).then_some(job.still);
    let clip = match &still {
        Some(s) => {
            s.check()?;
            stationary_clip(&clip, s, &start.speed)
        }
        None => clip,
    };
    let zones = Zones::load(zpath, &clip)?;
    let frames = match still {
        Some(_) => 0..clip.frames(),
        None => job.frames.clone().unwrap_or(0..clip.frames()),
    };
    let mut cfg = super::config::FitConfig {
        frames: frames.clone(),
        still,
        ..job.config.clone()
    };
    // `auto` is not chosen for zones ([`super::choose`]): their field objective.
    if cfg.loss == super::config::LossKind::Auto {
        cfg.loss = super::config::LossKind::Fields;
    }
    cfg.check_clip(&clip)
        .map_err(|e| e.in_file(&job.clips[0]))?;
    zones.check_agents(&clip, frames.clone())?;
    let anchors = super::anchor::load_all(&cfg, &[&clip])?;
    // With tracks, the evaluation runs start from the tracked animals, as the fit's windows did.
    let tracked = anchors[0].as_ref().and_then(|a| a.at(frames.start));
    let (log_path, plot_path) = (job.log_path(), job.plot_path());
    for p in [&job.out, &log_path, &plot_path] {
        check_writable(p)?;
    }
    let (ckpt, _) = super::job::start_fit(job, &cfg, 1, progress)?;
    let starts = vec![start.clone(); zones.len()];
    let (res, global) = fit_zones_global(
        &clip,
        &starts,
        &cfg,
        &zones,
        ckpt.as_ref(),
        |epoch, frame, e, ms| {
            progress.message(&format!(
                "epoch {epoch} frame {frame} E_mean {e:.4} {ms:.1} ms/step"
            ));
            progress.inc(1);
            progress.check()
        },
    )
    .map_err(|e| e.in_file(&job.clips[0]))?;
    progress.finish();
    let grid = clip.grid();
    let fitted = ZoneSets {
        zones: zones.clone(),
        sets: res.sets.clone(),
        grid,
    };
    let mut start_speed = start.clone();
    start_speed.speed = SpeedModel::of_clip(&clip, &start.speed);
    let unfitted = ZoneSets {
        zones: zones.clone(),
        sets: vec![start_speed; zones.len()],
        grid,
    };
    let still = match &cfg.still {
        Some(s) => Some(ZoneStill::of(&clip, &unfitted, &fitted, s, job)?),
        None => None,
    };
    let errors = match &still {
        Some(z) => [
            (z.start.density_error, f64::NAN),
            (z.fitted.density_error, f64::NAN),
        ],
        None => [
            errors_of(&clip, &unfitted, &frames, job, tracked)?,
            errors_of(&clip, &fitted, &frames, job, tracked)?,
        ],
    };
    let names: Vec<String> = zones.specs.iter().map(|z| z.name.clone()).collect();
    let mut prov = serde_json::json!({
        "source": "fit --zones",
        "clip": job.clips[0].display().to_string(),
        "zones": zpath.display().to_string(),
        "frames": [frames.start, frames.end],
        "settings": cfg,
        "start": start.to_vec(),
        "evaluation": {
            "what": format!("mean per-frame errors of runs from {} (each agent with its zone's set), averaged over the seeds", super::anchor::runs_start_from(&cfg)),
            "seeds": job.eval_seeds,
            "start": {"density_error": errors[0].0, "velocity_error": errors[0].1},
            "fitted": {"density_error": errors[1].0, "velocity_error": errors[1].1},
        },
    });
    if let Some(z) = &still {
        prov["evaluation"]["still"] = serde_json::to_value(z).map_err(|e| {
            crate::error::Error::Internal(format!("serialising the still's measures: {e}"))
        })?;
    }
    if let Some(g) = &global {
        prov["global"] = serde_json::to_value(g).map_err(|e| {
            crate::error::Error::Internal(format!("serialising the global phase: {e}"))
        })?;
    }
    write_log(&log_path, &res.log)?;
    // The curve is zone 0's θ.
    let plot_warning = plot_or_warn(&plot_path, &res.log, cfg.epochs)?;
    fitted.bundle(Some(prov)).save(&job.out)?;
    Ok(ZoneFitSummary {
        frames,
        epochs: cfg.epochs,
        names,
        start: start.to_vec(),
        fitted: res.sets.iter().map(Params::to_vec).collect(),
        errors,
        out: job.out.clone(),
        log: log_path,
        plot: plot_path,
        plot_warning,
        global,
        still,
    })
}

/// A still's measures with per-zone sets (paper §7.2.4, [`still_measures_in`]): the herd as drawn
/// from the image, and after settling with the start sets and with the fitted sets; the mean
/// speed each zone set (BL/s) with each.
#[derive(Clone, Debug, Serialize)]
pub struct ZoneStill {
    pub what: &'static str,
    pub drawn: StillMeasures,
    pub start: StillMeasures,
    pub fitted: StillMeasures,
    pub start_zone_speeds: Vec<f64>,
    pub fitted_zone_speeds: Vec<f64>,
}

impl ZoneStill {
    fn of(
        clip: &ClipFields,
        start: &ZoneSets,
        fitted: &ZoneSets,
        s: &StillConfig,
        job: &FitJob,
    ) -> Result<ZoneStill> {
        let run = StillRun {
            cfg: s,
            seed: job.config.seed,
            seeds: job.eval_seeds,
            precision: job.config.precision,
        };
        let ([drawn, before], v0) = still_measures_in(clip, &start.sets[0], Some(start), &run)?;
        let ([_, after], v1) = still_measures_in(clip, &fitted.sets[0], Some(fitted), &run)?;
        Ok(ZoneStill {
            what: "against the image: density error of cell counts and smoothed (the fit's density term), crowding, polarization (eq. 12), averaged over the steps after settling and over the seeds; zone speeds: mean |v| of the agents by the zone they stood in when the step began, the zone that set their speed (BL/s)",
            drawn,
            start: before,
            fitted: after,
            start_zone_speeds: v0,
            fitted_zone_speeds: v1,
        })
    }
}

/// Mean density and velocity errors of runs with `sets` through `frames`, over the job's seeds,
/// started from the animals `tracked` in the first frame when given.
fn errors_of(
    clip: &ClipFields,
    sets: &ZoneSets,
    frames: &Range<usize>,
    job: &FitJob,
    tracked: Option<&[AgentRow]>,
) -> Result<(f64, f64)> {
    let device = device(job.config.device, job.config.precision)?;
    let guidance = guidance_fields(clip, job.config.guidance_scale);
    let gates = job.config.boundary.gates(clip)?;
    let (mut d, mut v, mut n) = (0.0, 0.0, 0.0);
    for k in 0..job.eval_seeds {
        run_from(
            clip,
            &sets.sets[0],
            Some(sets),
            tracked,
            &gates,
            (frames.start, frames.end - 1),
            job.config.seed.wrapping_add(k as u64),
            &job.config.settle,
            &guidance,
            &device,
            |f, state, ids| {
                let (a, b) = field_errors(clip, f, &state.rows(ids)?);
                d += a;
                v += b;
                n += 1.0;
                Ok(())
            },
        )?;
    }
    let n = f64::max(n, 1.0);
    Ok((d / n, v / n))
}

impl std::fmt::Display for ZoneFitSummary {
    /// What `herdfit fit --zones` prints: start and fitted parameters per zone, the errors.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "fit --zones: {} zones, {} epochs on frames {}..{}",
            self.names.len(),
            self.epochs,
            self.frames.start,
            self.frames.end
        )?;
        if let Some(g) = &self.global {
            write!(f, "{g}")?;
        }
        write!(f, "{:<20} {:>8}", "parameter", "start")?;
        for n in &self.names {
            write!(f, " {n:>10}")?;
        }
        writeln!(f)?;
        for (i, n) in param_names().iter().enumerate() {
            write!(f, "{n:<20} {:>8.4}", self.start[i])?;
            for t in &self.fitted {
                write!(f, " {:>10.4}", t[i])?;
            }
            writeln!(f)?;
        }
        let [b, a] = self.errors;
        match &self.still {
            Some(z) => {
                writeln!(
                    f,
                    "still: density error {:.4} → {:.4} (as drawn {:.4}), smoothed {:.4} → {:.4}, polarization {:.4} → {:.4}",
                    z.start.density_error,
                    z.fitted.density_error,
                    z.drawn.density_error,
                    z.start.smooth_density_error,
                    z.fitted.smooth_density_error,
                    z.start.polarization,
                    z.fitted.polarization
                )?;
                write!(f, "mean speed per zone (BL/s), fitted:")?;
                for (n, v) in self.names.iter().zip(&z.fitted_zone_speeds) {
                    write!(f, " {n} {v:.3}")?;
                }
                writeln!(f)?;
            }
            None => writeln!(
                f,
                "density error {:.4} → {:.4}, velocity error {:.4} → {:.4}",
                b.0, a.0, b.1, a.1
            )?,
        }
        match &self.plot_warning {
            None => writeln!(
                f,
                "wrote {}, {}, {}",
                self.out.display(),
                self.log.display(),
                self.plot.display()
            ),
            Some(w) => writeln!(
                f,
                "wrote {}, {} (no loss curve: {w})",
                self.out.display(),
                self.log.display()
            ),
        }
    }
}
