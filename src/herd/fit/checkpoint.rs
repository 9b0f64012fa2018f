//! Checkpoints of a fit (`herdfit.checkpoint/1`), written after every epoch for an exact resume.

use super::config::FitConfig;
use super::log::LogRow;
use crate::data::atomic::write_atomic;
use crate::error::{Error, Result};
use crate::herd::params::{Params, N_PARAMS};
use crate::optim::OptState;
use rand::Rng;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

/// Checkpoint of a fit, written after every epoch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checkpoint {
    pub schema: String,
    pub epochs_done: usize,
    pub theta: [f64; N_PARAMS],
    pub opt: OptState,
    pub log: Vec<LogRow>,
    /// The settings and start the run was made with (a resume must match).
    pub config: FitConfig,
    pub start: [f64; N_PARAMS],
    /// A zone fit's zones (absent for a fit of one set; a resume must match).
    #[serde(default, skip_serializing_if = "ZoneStarts::is_empty")]
    pub zone_starts: ZoneStarts,
    /// A zone fit's learnt state of every zone after the first (the first's is `theta`, `opt`).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub zones: Vec<ZoneState>,
}

/// A zone fit's zones as its checkpoint records them: every zone's name, and the start of every
/// zone after the first (the first zone's is the checkpoint's `start`).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZoneStarts {
    pub names: Vec<String>,
    pub starts: Vec<[f64; N_PARAMS]>,
}

impl ZoneStarts {
    /// No zones (a fit of one parameter set).
    pub fn is_empty(&self) -> bool {
        self.names.is_empty() && self.starts.is_empty()
    }
}

/// One zone's learnt parameter set and optimiser state.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZoneState {
    pub theta: [f64; N_PARAMS],
    pub opt: OptState,
}

pub const CHECKPOINT_SCHEMA: &str = "herdfit.checkpoint/1";

impl Checkpoint {
    /// Reads a checkpoint and checks what a resume relies on: the schema tag, a finite θ and
    /// optimiser state of the right length (a resume from a damaged file would otherwise
    /// continue from NaN). Errors name the file.
    pub fn load(path: &std::path::Path) -> crate::error::Result<Checkpoint> {
        use crate::error::Error;
        // Not recorded as an input (`note_input`): a resumed fit rewrites its checkpoint.
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let k: Checkpoint = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a {CHECKPOINT_SCHEMA} file: {e}")))?;
        if k.schema != CHECKPOINT_SCHEMA {
            return Err(Error::file(
                path,
                format!("schema is '{}', expected {CHECKPOINT_SCHEMA}", k.schema),
            ));
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&k.theta) || !finite(&k.start) {
            return Err(Error::file(path, "theta or start holds a non-finite value"));
        }
        let sized = |v: &[f64]| v.is_empty() || v.len() == N_PARAMS;
        let sound = |o: &OptState| sized(&o.m) && sized(&o.v) && finite(&o.m) && finite(&o.v);
        if !sound(&k.opt) {
            return Err(Error::file(
                path,
                format!("opt: m and v must hold {N_PARAMS} finite values"),
            ));
        }
        let z = &k.zone_starts;
        let zones_sized = z.is_empty()
            || (z.names.len() == z.starts.len() + 1 && k.zones.len() == z.starts.len());
        if !zones_sized {
            return Err(Error::file(
                path,
                format!(
                    "zones: {} names, {} starts and {} states do not describe one zone fit",
                    z.names.len(),
                    z.starts.len(),
                    k.zones.len()
                ),
            ));
        }
        let zones_sound = k.zones.iter().all(|s| finite(&s.theta) && sound(&s.opt))
            && z.starts.iter().all(|s| finite(s));
        if !zones_sound {
            return Err(Error::file(
                path,
                "zones: a zone's theta, start or optimiser state holds a non-finite value",
            ));
        }
        k.config.check().map_err(|e| e.in_file(path))?;
        Ok(k)
    }
}

/// Where checkpoints go.
pub struct CheckpointDir {
    pub dir: PathBuf,
    pub resume: bool,
}

impl CheckpointDir {
    /// The checkpoint file inside the folder.
    pub fn file(&self) -> PathBuf {
        self.dir.join("checkpoint.json")
    }

    /// The epochs the checkpoint a resume starts from holds (for a progress bar: none when not
    /// resuming or when there is no readable checkpoint, which the resume itself reports).
    pub fn epochs_done(&self) -> Option<usize> {
        let text = std::fs::read_to_string(self.file())
            .ok()
            .filter(|_| self.resume)?;
        serde_json::from_str::<Checkpoint>(&text)
            .ok()
            .map(|k| k.epochs_done)
    }
}

/// What a fit learns and a checkpoint keeps: θ, the optimiser's state and the log.
pub(super) struct Learnt {
    pub(super) theta: [f64; N_PARAMS],
    pub(super) opt: OptState,
    pub(super) log: Vec<LogRow>,
    /// Each window's (loss, gradient) when the run probes ([`super::run::window_gradients`]).
    pub(super) probes: Vec<(f64, [f64; N_PARAMS])>,
    /// A zone fit's other parameter sets (zones 1, 2, …; zone 0's is `theta`) and their
    /// optimiser states ([`super::run::fit_zones`]).
    pub(super) zones: Vec<([f64; N_PARAMS], OptState)>,
}

/// One optimiser step on `theta` with gradient `g` and step size `lr` ([`crate::optim::step`]
/// with `cfg.optimizer` and `cfg.zero_grad_step`), then clamped to the parameters' ranges.
pub fn update(
    theta: &mut [f64; N_PARAMS],
    g: &[f64; N_PARAMS],
    opt: &mut OptState,
    cfg: &FitConfig,
    lr: f64,
    rng: &mut impl Rng,
) {
    let before = *theta;
    crate::optim::step(cfg.optimizer, theta, g, opt, lr, cfg.zero_grad_step, rng);
    Params::clamp_vec(theta);
    // Frozen parameters keep their value (checked names; an unknown one was refused earlier).
    for p in cfg.frozen_indices().unwrap_or_default() {
        theta[p] = before[p];
    }
}

impl Learnt {
    /// Every parameter set, zone 0 first, one after another (`[12·Z]`).
    pub(super) fn flat(&self) -> Vec<f64> {
        let mut v = self.theta.to_vec();
        for (t, _) in &self.zones {
            v.extend_from_slice(t);
        }
        v
    }

    /// One optimiser step on every parameter set with its part of the gradient `g` (`[12·Z]`).
    pub(super) fn update(&mut self, g: &[f64], cfg: &FitConfig, lr: f64, rng: &mut impl Rng) {
        let part = |k: usize| -> [f64; N_PARAMS] {
            let mut p = [0.0; N_PARAMS];
            p.copy_from_slice(&g[k * N_PARAMS..(k + 1) * N_PARAMS]);
            p
        };
        update(&mut self.theta, &part(0), &mut self.opt, cfg, lr, rng);
        for (k, (t, o)) in self.zones.iter_mut().enumerate() {
            update(t, &part(k + 1), o, cfg, lr, rng);
        }
    }
}

/// The state to start from: θ = the start (and each further zone's set its start), or the
/// checkpoint's state when resuming (refused when the checkpoint was written with other
/// settings, another start or other zones).
pub(super) fn resume(
    ckpt: Option<&CheckpointDir>,
    cfg: &FitConfig,
    start: [f64; N_PARAMS],
    zones: &ZoneStarts,
) -> Result<(Learnt, usize)> {
    match ckpt {
        Some(c) if c.resume && c.file().exists() => {
            let k = Checkpoint::load(&c.file())?;
            if k.config != *cfg || k.start != start || k.zone_starts != *zones {
                return Err(Error::file(
                    c.file(),
                    "was written by a fit with other settings, another start or other zones; resume with the same flags",
                ));
            }
            let learnt = Learnt {
                theta: k.theta,
                opt: k.opt,
                log: k.log,
                probes: Vec::new(),
                zones: k.zones.into_iter().map(|z| (z.theta, z.opt)).collect(),
            };
            Ok((learnt, k.epochs_done))
        }
        _ => Ok((
            Learnt {
                theta: start,
                opt: OptState::new(N_PARAMS),
                log: Vec::new(),
                probes: Vec::new(),
                zones: zones
                    .starts
                    .iter()
                    .map(|s| (*s, OptState::new(N_PARAMS)))
                    .collect(),
            },
            0,
        )),
    }
}

/// Writes the checkpoint after `epochs_done` epochs.
pub(super) fn save_checkpoint(
    c: &CheckpointDir,
    epochs_done: usize,
    learnt: &Learnt,
    cfg: &FitConfig,
    start: [f64; N_PARAMS],
    zones: &ZoneStarts,
) -> Result<()> {
    let k = Checkpoint {
        schema: CHECKPOINT_SCHEMA.into(),
        epochs_done,
        theta: learnt.theta,
        opt: learnt.opt.clone(),
        log: learnt.log.clone(),
        config: cfg.clone(),
        start,
        zone_starts: zones.clone(),
        zones: learnt
            .zones
            .iter()
            .map(|(theta, opt)| ZoneState {
                theta: *theta,
                opt: opt.clone(),
            })
            .collect(),
    };
    let text = serde_json::to_string(&k)
        .map_err(|e| Error::Internal(format!("serialising checkpoint: {e}")))?;
    write_atomic(&c.file(), text.as_bytes())
}
