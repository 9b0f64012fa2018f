//! The validation report folder as `herdfit validate` writes it: `report.json`, `report.md`
//! (opening with the comparison table), `metrics.png`, `errors.png`, `error-map-*.png` and the
//! side-by-side video of the first run.

use super::{validate, Report, SetReport, Stat, ValidateConfig, MEASURES};
use crate::data::atomic::AtomicDir;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::params::Params;
use crate::herd::uncertainty::Uncertainty;
use crate::plot::Series;
use crate::progress::Progress;
use plotters::style::RGBColor;
use std::path::{Path, PathBuf};

/// The report as Markdown, opening with the comparison table.
pub fn markdown(r: &Report) -> String {
    let mut s = String::new();
    s.push_str(&format!(
        "# herdfit validation\n\n{}, {}.\n\n",
        r.run.summary(),
        if r.ensemble_mean {
            "of the seeds' mean prediction"
        } else {
            "averaged over the seeds' own errors"
        }
    ));
    s.push_str("| measure | video mean ± STD |");
    for set in &r.sets {
        s.push_str(&format!(
            " {} simulation mean ± STD | {} error mean ± STD |",
            set.name, set.name
        ));
    }
    s.push_str("\n|---|---:|");
    for _ in &r.sets {
        s.push_str("---:|---:|");
    }
    s.push('\n');
    let f = |x: &Option<Stat>| match x {
        Some(st) => format!("{:.4} ± {:.4}", st.mean, st.std),
        None => "—".into(),
    };
    for (m, name) in MEASURES.iter().enumerate() {
        let video = r
            .sets
            .first()
            .map(|s| f(&s.rows[m].video))
            .unwrap_or_default();
        s.push_str(&format!("| {name} | {video} |"));
        for set in &r.sets {
            let row = &set.rows[m];
            s.push_str(&format!(
                " {} | {:.4} ± {:.4} |",
                f(&row.simulation),
                row.error.mean,
                row.error.std
            ));
        }
        s.push('\n');
    }
    s.push_str("\nThe simulation's velocities are averaged over the same window of frames as the clip's (the extraction's smoothing) before they are compared. Density and velocity errors are relative (Σ|n' − n| / Σn and Σn‖V' − V‖ / Σn‖V‖ over coarse cells); the other errors are |simulation − video| per frame. Measures come from the fields of the video and of the rasterised simulation (paper §7.1.2).\n\n");
    s.push_str(&super::paired::markdown(&r.paired));
    s.push_str(&super::reference::markdown(r));
    s.push_str("| parameter |");
    for set in &r.sets {
        s.push_str(&format!(" {} |", set.name));
    }
    s.push_str("\n|---|");
    for _ in &r.sets {
        s.push_str("---:|");
    }
    s.push('\n');
    for (i, n) in crate::herd::params::param_names().iter().enumerate() {
        s.push_str(&format!("| {n} |"));
        for set in &r.sets {
            s.push_str(&format!(" {:.4} |", set.params[i]));
        }
        s.push('\n');
    }
    for set in &r.sets {
        if let Some(u) = &set.uncertainty {
            s.push_str(&identifiability_md(&set.name, u, &set.params));
        }
    }
    s.push_str("\nPlots: `metrics.png` (measures over time), `errors.png` (density and velocity errors over time), `error-map-*.png` (mean |ρ' − ρ| per coarse cell).\n");
    s
}

/// The identifiability section of a set fitted with an uncertainty estimate: per parameter the
/// value ± std (or its one-sided interval at a bound) and whether the clip determines it, then
/// the eigen-directions.
fn identifiability_md(name: &str, u: &Uncertainty, values: &[f64; 12]) -> String {
    let mut s = format!(
        "\n## What the fitting clip determines ({name})\n\nFrom the fit: {}. Determined: 2 std ≤ {}. Objective {:.4} ± {:.4} over {} windows × {} seeds.\n\n| parameter | value | ± std | determined |\n|---|---:|---:|---|\n",
        u.method, u.accuracy, u.noise.objective, u.noise.objective_std, u.noise.windows, u.noise.seeds
    );
    for (i, (n, sd)) in u.std.0.iter().enumerate() {
        let spread = match (sd, u.bounds.get(n)) {
            (_, Some(b)) => format!(
                "at the {} bound: {:.4}..{:.4} (one-sided)",
                b.side, b.within[0], b.within[1]
            ),
            (Some(x), None) => format!("{x:.4}"),
            (None, None) => "—".into(),
        };
        let det = if u.determined.contains(n) {
            "yes"
        } else {
            "no"
        };
        s.push_str(&format!("| {n} | {:.4} | {spread} | {det} |\n", values[i]));
    }
    s.push_str("\n| direction | eigenvalue | std along it | minimum along it | determined | largest components |\n|---:|---:|---:|---:|---|---|\n");
    for (k, d) in u.directions.iter().enumerate() {
        let sd = d.std.map_or("—".into(), |x| format!("{x:.4}"));
        let to = d.to_minimum.map_or("—".into(), |x| format!("{x:+.4}"));
        s.push_str(&format!(
            "| {} | {:.4} ± {:.4} | {sd} | {to} | {} | {} |\n",
            k + 1,
            d.eigenvalue,
            d.eigenvalue_std,
            if d.determined { "yes" } else { "no" },
            crate::herd::uncertainty::components(d, 4)
        ));
    }
    s
}

/// A validation with its files: the clip, the parameter set validated (`fitted`), an optional
/// baseline, and the report folder.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ValidateJob {
    pub clip: PathBuf,
    pub params: PathBuf,
    pub baseline: Option<PathBuf>,
    pub out: PathBuf,
    /// Also render the side-by-side video (feature `video`).
    pub video: bool,
    pub config: ValidateConfig,
}

impl Default for ValidateJob {
    fn default() -> Self {
        ValidateJob {
            clip: PathBuf::from("clip"),
            params: PathBuf::from("params.json"),
            baseline: None,
            out: PathBuf::from("report"),
            video: true,
            config: ValidateConfig::default(),
        }
    }
}

impl ValidateJob {
    /// Checks the settings ([`ValidateConfig::check`]).
    pub fn check(&self) -> Result<()> {
        self.config.check()
    }
}

/// Runs the validation and writes the report folder; returns the report and its Markdown.
pub fn run(job: &ValidateJob, progress: &mut dyn Progress) -> Result<(Report, String)> {
    job.check()?;
    let clip = ClipFields::load(&job.clip)?;
    let mut sets = vec![("fitted".to_string(), Params::load(&job.params)?)];
    if let Some(b) = &job.baseline {
        sets.push(("baseline".to_string(), Params::load(b)?));
    }
    let out = AtomicDir::create(&job.out)?;
    progress.start("validate", (sets.len() * job.config.seeds) as u64);
    let (report, runs) = validate(
        &clip,
        &job.clip.display().to_string(),
        &sets,
        &job.config,
        || {
            progress.inc(1);
            progress.check()
        },
    )
    .map_err(|e| e.in_file(&job.clip))?;
    progress.finish();
    let json = serde_json::to_string_pretty(&report).map_err(|e| Error::Internal(e.to_string()))?;
    out.write("report.json", format!("{json}\n").as_bytes())?;
    let md = markdown(&report);
    out.write("report.md", md.as_bytes())?;
    plots(&report, &out)?;
    if let Some(b) = &report.boundary {
        let text =
            serde_json::to_string_pretty(&b.gates).map_err(|e| Error::Internal(e.to_string()))?;
        out.write("boundary.json", format!("{text}\n").as_bytes())?;
        count_plot(&report, &b.video_count, &out)?;
    }
    for set in &report.sets {
        if let Some(r) = &set.reference {
            out.write(&format!("errorlog-{}.txt", set.name), r.log().as_bytes())?;
        }
    }
    #[cfg(feature = "video")]
    if job.video {
        if let Some(run) = runs.first().and_then(|r| r.first()) {
            crate::video::render::render_comparison(
                &out.path("side-by-side.avi"),
                &clip,
                &run.fields,
                &run.frames,
                report.run.frames[0],
            )?;
        }
    }
    #[cfg(not(feature = "video"))]
    let _ = &runs;
    out.commit()?;
    Ok((report, md))
}

use crate::plot::PALETTE as COLOURS;

/// `metrics.png` (the video's and each set's polarization and angular momentum over the
/// held-out frames), `errors.png` (each set's density and velocity errors) and one error map
/// per set.
fn plots(report: &Report, out: &AtomicDir) -> Result<()> {
    let start = report.run.frames[0];
    let at = |k: usize| (start + k) as f64;
    let video = |m: usize| -> Vec<(f64, f64)> {
        let rows = report.video_per_frame.iter().enumerate();
        rows.map(|(k, v)| (at(k), v[m])).collect()
    };
    let column = |set: &SetReport, m: usize| -> Vec<(f64, f64)> {
        let rows = set.per_frame.iter().enumerate();
        rows.map(|(k, v)| (at(k), v[m])).collect()
    };
    let mut metrics = vec![(
        "video polarization".to_string(),
        video(0),
        RGBColor(0, 0, 0),
    )];
    for (i, set) in report.sets.iter().enumerate() {
        let name = format!("{} polarization", set.name);
        metrics.push((name, column(set, 2), COLOURS[i % 6]));
    }
    let grey = RGBColor(120, 120, 120);
    metrics.push(("video angular momentum".to_string(), video(1), grey));
    for (i, set) in report.sets.iter().enumerate() {
        let name = format!("{} angular momentum", set.name);
        metrics.push((name, column(set, 3), COLOURS[(i + 2) % 6]));
    }
    let mut errors = Vec::new();
    for (i, set) in report.sets.iter().enumerate() {
        let density = format!("{} density error", set.name);
        errors.push((density, column(set, 0), COLOURS[(2 * i) % 6]));
        let velocity = format!("{} velocity error", set.name);
        errors.push((velocity, column(set, 1), COLOURS[(2 * i + 1) % 6]));
    }
    let title = "emergent measures (held-out frames)";
    chart(&out.path("metrics.png"), title, "value", &metrics)?;
    let title = "coarse-grid errors (held-out frames)";
    chart(&out.path("errors.png"), title, "relative error", &errors)?;
    for set in &report.sets {
        crate::plot::heat_map(
            &out.path(&format!("error-map-{}.png", set.name)),
            &format!("{}: mean |ρ' − ρ| per coarse cell (agents)", set.name),
            &set.error_map,
        )?;
    }
    Ok(())
}

/// `count.png`: the animals in view over the held-out frames, the video's and each set's.
fn count_plot(report: &Report, video: &[f64], out: &AtomicDir) -> Result<()> {
    let start = report.run.frames[0];
    let line = |v: &[f64]| -> Vec<(f64, f64)> {
        v.iter()
            .enumerate()
            .map(|(k, c)| ((start + k) as f64, *c))
            .collect()
    };
    let mut lines = vec![("video".to_string(), line(video), RGBColor(0, 0, 0))];
    for (i, set) in report.sets.iter().enumerate() {
        if let Some(p) = &set.population {
            lines.push((set.name.clone(), line(&p.count), COLOURS[i % 6]));
        }
    }
    let title = "animals in view (held-out frames, open boundary)";
    chart(&out.path("count.png"), title, "animals", &lines)
}

/// A named line of (frame, value) points and its colour.
type Line = (String, Vec<(f64, f64)>, RGBColor);

/// A line chart of [`Line`]s over the held-out frames.
fn chart(path: &Path, title: &str, y: &str, lines: &[Line]) -> Result<()> {
    let series: Vec<Series> = lines
        .iter()
        .map(|(name, points, colour)| Series {
            name,
            points: points.clone(),
            colour: *colour,
        })
        .collect();
    crate::plot::line_chart(path, title, "frame", y, &series)
}
