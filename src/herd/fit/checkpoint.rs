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
