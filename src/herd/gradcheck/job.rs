//! `herdfit gradcheck` as a library call: which objective, on which herd or clip, written where.

use super::{default_scenario, gradcheck, record, GradReport, LossScenario, Scenario};
use crate::backend::{cpu_device, Compute, Precision};
use crate::data::agents::read_init_csv;
use crate::data::atomic::{check_writable, write_atomic};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::fit::LossKind;
use crate::herd::sim::Recording;
use crate::herd::simulate::{load_params, HerdSource, RunFiles};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// What `gradcheck` differentiates.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Objective {
    /// Spread + mean heading of the default scenario's herd after T steps.
    Herd,
    /// The fit's loss (`--loss`: E_mean + λ E_var, eq. 7–8, or field matching, or the ensemble
    /// objective) over T steps on a clip.
    Loss,
}

enum_names!(Objective { Herd = "herd", Loss = "loss" });

/// Settings of a gradient check.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GradcheckConfig {
    /// Unrolled steps.
    pub steps: usize,
    pub precision: Precision,
    /// Where the tensors live (`--device`); the GPU computes in f32. Not written when `cpu`.
    #[serde(default, skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
    /// Step h of the 4-point central difference (default 1e-4 in f64, 1e-2 in f32).
    pub fd_step: Option<f64>,
    pub seed: u64,
    pub objective: Objective,
    /// Which of the fit's losses the `loss` objective checks.
    pub loss: LossKind,
    /// Herds for the ensemble loss.
    pub replicas: usize,
}

impl Default for GradcheckConfig {
    fn default() -> Self {
        GradcheckConfig {
            steps: 10,
            precision: Precision::F64,
            device: Compute::Cpu,
            fd_step: None,
            seed: 0,
            objective: Objective::Herd,
            loss: LossKind::Paper,
            replicas: 1,
        }
    }
}

impl GradcheckConfig {
    /// The finite-difference step: `fd_step`, or 1e-4 in f64 and 1e-2 in f32.
    pub fn h(&self) -> f64 {
        self.fd_step.unwrap_or(match self.precision {
            Precision::F64 => 1e-4,
            Precision::F32 => 1e-2,
        })
    }
}

impl GradcheckConfig {
    /// Checks the steps, the finite-difference step and the replicas; errors name the key.
    pub fn check(&self) -> Result<()> {
        crate::error::check_counts(&[("steps", self.steps)])?;
        crate::limits::check_count("steps", self.steps, crate::limits::MAX_STEPS)?;
        if let Some(h) = self.fd_step {
            crate::error::check_positive(&[("fd_step", h)])?;
            // An absolute step on θ: beyond 1 it measures no derivative (issue #47: 1e300 ran).
            crate::limits::check_range("fd_step", h, 0.0, 1.0, "")?;
        }
        if self.replicas == 0 || self.replicas > 64 {
            return Err(Error::config(
                "replicas",
                format!("{} is out of range 1..=64", self.replicas),
            ));
        }
        Ok(())
    }
}

/// A gradient check with its files: the run's ([`RunFiles`]: the herd of the herd objective,
/// the default scenario's 200 agents when absent), the clip of the loss objective, and the JSON
/// report.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct GradcheckJob {
    pub run: RunFiles,
    pub clip: Option<PathBuf>,
    pub json: PathBuf,
    pub config: GradcheckConfig,
}

impl GradcheckJob {
    /// Checks the settings, and that the loss objective has a clip; errors name the key.
    pub fn check(&self) -> Result<()> {
        self.config.check()?;
        self.run.check()?;
        if self.config.objective == Objective::Loss && self.clip.is_none() {
            return Err(Error::config("clip", "{objective} loss needs a clip"));
        }
        Ok(())
    }
}

/// Runs the check and writes its JSON report.
pub fn run(job: &GradcheckJob, progress: &mut dyn Progress) -> Result<GradReport> {
    job.check()?;
    let cfg = &job.config;
    let params = load_params(job.run.params.as_deref())?;
    let report = if cfg.objective == Objective::Loss {
        let path = job
            .clip
            .clone()
            .ok_or_else(|| Error::config("clip", "{objective} loss needs a clip"))?;
        let clip = ClipFields::load(&path)?;
        check_writable(&job.json)?;
        let device = cpu_device(cfg.precision)?;
        let sc = LossScenario::record(
            &clip,
            &params,
            0,
            cfg.steps,
            0.7,
            1.0,
            (cfg.loss, cfg.replicas),
            cfg.seed,
            &device,
        )
        .map_err(|e| e.in_file(&path))?;
        progress.start("gradcheck", 13);
        let report = sc.check((cfg.device, cfg.precision), cfg.h(), || progress.inc(1))?;
        progress.finish();
        report
    } else {
        let sc = match &job.run.herd {
            Some(HerdSource::Init(p)) => {
                let base = default_scenario(params, 1, cfg.seed)?;
                Scenario {
                    init: read_init_csv(p)?,
                    ..base
                }
            }
            Some(HerdSource::Agents(n)) => default_scenario(params, *n, cfg.seed)?,
            None => default_scenario(params, 200, cfg.seed)?,
        };
        check_writable(&job.json)?;
        let device = cpu_device(cfg.precision)?;
        let rec = match &job.run.replay {
            Some(p) => Recording::load(p)?,
            None => record(&sc, cfg.steps, cfg.seed, &device)?,
        };
        if let Some(p) = &job.run.record {
            rec.save(p)?;
        }
        progress.start("gradcheck", 13);
        let report = gradcheck(
            &sc,
            cfg.steps,
            (cfg.device, cfg.precision),
            cfg.h(),
            &rec,
            || progress.inc(1),
        )?;
        progress.finish();
        report
    };
    let text = serde_json::to_string_pretty(&report)
        .map_err(|e| Error::Internal(format!("serialising report: {e}")))?;
    write_atomic(&job.json, format!("{text}\n").as_bytes())?;
    Ok(report)
}

impl std::fmt::Display for GradReport {
    /// The table `herdfit gradcheck` prints.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "gradcheck: {} agents, {} unrolled steps, {:?} on {}, J = {:.6e}, h = {:e}",
            self.agents, self.steps, self.precision, self.device, self.objective, self.fd_step
        )?;
        writeln!(
            f,
            "{:<20} {:>16} {:>18} {:>10}",
            "parameter", "autodiff", "finite difference", "rel err"
        )?;
        for r in &self.parameters {
            writeln!(
                f,
                "{:<20} {:>16.9e} {:>18.9e} {:>10.2e}",
                r.name, r.autodiff, r.finite_difference, r.rel_err
            )?;
        }
        writeln!(f, "max rel err {:.3e}", self.max_rel_err)
    }
}
