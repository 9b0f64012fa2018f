//! The fit's training log: one row per window, written as CSV (`PARAMS.log.csv`).

use crate::data::atomic::write_atomic;
use crate::error::Result;
use crate::herd::params::{param_names, N_PARAMS};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// One row of the training log.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LogRow {
    pub epoch: usize,
    /// Frame reached at the end of the window.
    pub frame: usize,
    pub e_mean: f64,
    pub e_var: f64,
    /// The field-matching loss: the objective of `--loss fields` (logged with `--loss paper`), or
    /// the ensemble objective with `--loss ensemble`.
    #[serde(default)]
    pub e_fields: f64,
    pub density_error: f64,
    pub velocity_error: f64,
    pub agents: usize,
    pub theta: [f64; N_PARAMS],
    /// Index of the clip (in the order given) the window belongs to.
    #[serde(default)]
    pub clip: usize,
}

/// The log as CSV.
pub fn log_csv(rows: &[LogRow]) -> String {
    let mut s =
        String::from("epoch,frame,e_mean,e_var,e_fields,density_error,velocity_error,agents");
    for n in param_names() {
        s.push(',');
        s.push_str(&n);
    }
    s.push_str(",clip\n");
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{}",
            r.epoch,
            r.frame,
            r.e_mean,
            r.e_var,
            r.e_fields,
            r.density_error,
            r.velocity_error,
            r.agents
        ));
        for v in r.theta {
            s.push_str(&format!(",{v}"));
        }
        s.push_str(&format!(",{}", r.clip));
        s.push('\n');
    }
    s
}

/// Writes the training log CSV atomically.
pub fn write_log(path: &Path, rows: &[LogRow]) -> Result<()> {
    write_atomic(path, log_csv(rows).as_bytes())
}
