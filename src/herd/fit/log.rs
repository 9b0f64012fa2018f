//! The fit's training log: one row per window, written as CSV (`PARAMS.log.csv`), and its loss
//! curve (`PARAMS.loss.png`).

use crate::data::atomic::write_atomic;
use crate::error::Result;
use crate::herd::params::{param_names, N_PARAMS};
use plotters::style::RGBColor;
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

/// The loss curve, or why it cannot be drawn on this machine (no usable font: the fit is written
/// without it). A curve that can be drawn but not written (a full disk) fails the run, so that no
/// summary claims a file that is not there (issue #47).
pub(super) fn plot_or_warn(path: &Path, log: &[LogRow], epochs: usize) -> Result<Option<String>> {
    match crate::plot::font_ready() {
        Ok(()) => loss_plot(path, log, epochs).map(|_| None),
        Err(e) => Ok(Some(e.in_file(path).to_string())),
    }
}

/// The loss curve: per epoch, the mean E_mean, E_var, density and velocity errors of its windows.
pub(super) fn loss_plot(path: &Path, log: &[LogRow], epochs: usize) -> Result<()> {
    let columns: [EpochColumn<LogRow>; 4] = [
        ("E_mean", |r| r.e_mean, RGBColor(31, 119, 180)),
        ("E_var", |r| r.e_var, RGBColor(255, 127, 14)),
        ("density error", |r| r.density_error, RGBColor(44, 160, 44)),
        (
            "velocity error",
            |r| r.velocity_error,
            RGBColor(214, 39, 40),
        ),
    ];
    epoch_chart(path, "herdfit fit", log, |r| r.epoch, epochs, &columns)
}

/// One line of an [`epoch_chart`]: its name, a window's value, its colour.
pub type EpochColumn<T> = (&'static str, fn(&T) -> f64, RGBColor);

/// A training log as a line chart titled `title`: for each epoch `e` in `0..epochs` that has
/// rows (`epoch(row)`), at x = e + 1, the mean of each column over that epoch's rows.
pub fn epoch_chart<T>(
    path: &Path,
    title: &str,
    log: &[T],
    epoch: fn(&T) -> usize,
    epochs: usize,
    columns: &[EpochColumn<T>],
) -> Result<()> {
    let per_epoch = |f: fn(&T) -> f64| -> Vec<(f64, f64)> {
        (0..epochs)
            .filter_map(|e| {
                let rows: Vec<_> = log.iter().filter(|r| epoch(r) == e).collect();
                (!rows.is_empty()).then(|| {
                    (
                        e as f64 + 1.0,
                        rows.iter().map(|r| f(r)).sum::<f64>() / rows.len() as f64,
                    )
                })
            })
            .collect()
    };
    let series: Vec<_> = columns
        .iter()
        .map(|&(name, f, colour)| crate::plot::Series {
            name,
            points: per_epoch(f),
            colour,
        })
        .collect();
    crate::plot::line_chart(
        path,
        title,
        "epoch",
        "mean over the epoch's windows",
        &series,
    )
}
