//! Checkpoints of a fit (`herdfit.checkpoint/1`), written after every epoch for an exact resume.

use super::config::FitConfig;
use super::log::LogRow;
use crate::herd::params::N_PARAMS;
use crate::optim::OptState;
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
        if !(sized(&k.opt.m) && sized(&k.opt.v) && finite(&k.opt.m) && finite(&k.opt.v)) {
            return Err(Error::file(
                path,
                format!("opt: m and v must hold {N_PARAMS} finite values"),
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
}
