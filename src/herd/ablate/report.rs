//! The ablation report: `ablation.json` (`herdfit.ablation/1`), `ablation.md` (the paper's
//! Table 4 for every switch, and which switches help on which measures), the plots and each
//! variant's fitted parameter set.

use super::{density_term, AblateConfig, Variant};
use crate::data::atomic::AtomicDir;
use crate::error::{Error, Result};
use crate::herd::validate::{MeasureRow, Report, Stat, MEASURES};
use crate::plot::{Series, PALETTE};
use serde::Serialize;

/// Schema tag of `ablation.json`.
pub const ABLATION_SCHEMA: &str = "herdfit.ablation/1";

/// One variant in the report.
#[derive(Clone, Debug, Serialize)]
pub struct VariantReport {
    /// `full`, or `no-<switch>`.
    pub name: String,
    /// The switch turned off (none for the full model).
    pub switch: Option<String>,
    /// The fitted 12 parameters.
    pub params: [f64; 12],
    pub occlusion: bool,
    /// Wall time of the fit (s).
    pub fit_seconds: f64,
    /// Each measure's held-out error (and the simulation's value), as `validate` reports it.
    pub rows: Vec<MeasureRow>,
    /// Per held-out frame, seed-averaged: the six measures of [`MEASURES`] of the simulation.
    pub per_frame: Vec<[f64; 6]>,
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct AblationReport {
    /// [`ABLATION_SCHEMA`].
    pub schema: String,
    pub clip: String,
    /// Frames fitted (`[start, end)`).
    pub fit_frames: [usize; 2],
    /// Frames held out for validation.
    pub heldout_frames: [usize; 2],
    pub settings: AblateConfig,
    /// The video's mean ± STD of each emergent measure over the held-out frames (none for the
    /// density and velocity errors, which are cumulative).
    pub video: Vec<Option<Stat>>,
    /// The video's per-frame measures: [polarization, ang. momentum centroid, frame centre,
    /// aspect ratio].
    pub video_per_frame: Vec<[f64; 4]>,
    pub variants: Vec<VariantReport>,
}

impl AblationReport {
    /// The report of `variants` (the full model first) validated as `validation` describes.
    pub fn new(
        clip: &str,
        cfg: &AblateConfig,
        variants: &[Variant],
        validation: &Report,
    ) -> AblationReport {
        let video = variants
            .first()
            .map(|v| v.validation.rows.iter().map(|r| r.video).collect())
            .unwrap_or_default();
        AblationReport {
            schema: ABLATION_SCHEMA.into(),
            clip: clip.to_string(),
            fit_frames: [0, validation.run.frames[0]],
            heldout_frames: validation.run.frames,
            settings: cfg.clone(),
            video,
            video_per_frame: validation.video_per_frame.clone(),
            variants: variants
                .iter()
                .map(|v| VariantReport {
                    name: v.name.clone(),
                    switch: v.switch.map(|s| s.to_string()),
                    params: v.params.to_vec(),
                    occlusion: v.params.constants.occlusion,
                    fit_seconds: v.fit_seconds,
                    rows: v.validation.rows.clone(),
                    per_frame: v.validation.per_frame.clone(),
                })
                .collect(),
        }
    }

    /// The mean held-out error of `measure` (index into [`MEASURES`]) for variant `v`.
    pub fn error(&self, v: usize, measure: usize) -> f64 {
        self.variants[v].rows[measure].error.mean
    }

    /// For each switched-off variant: the measures on which the full model's error is lower
    /// (the switch helps) and those on which it is not.
    pub fn verdicts(&self) -> Vec<(String, Vec<&'static str>, Vec<&'static str>)> {
        self.variants
            .iter()
            .enumerate()
            .skip(1)
            .map(|(v, var)| {
                let (mut helps, mut not) = (Vec::new(), Vec::new());
                for (m, name) in MEASURES.iter().enumerate() {
                    match self.error(0, m) < self.error(v, m) {
                        true => helps.push(*name),
                        false => not.push(*name),
                    }
                }
                (var.switch.clone().unwrap_or_default(), helps, not)
            })
            .collect()
    }
}

/// The report as Markdown: the settings, Table 4 (video STD, the full model's error and each
/// switched-off variant's), the verdicts and the fitted parameters.
pub fn markdown(r: &AblationReport) -> String {
    let f = &r.settings.fit;
    let v = &r.settings.validate;
    let mut s = format!(
        "# herdfit ablation\n\nClip `{}`: fitted on frames {}..{} (`{}` objective, {} epochs of {}-step windows, lr {}, β {}, λ_var {}, {} replica(s), seed {}), validated on frames {}..{} ({} seed(s), {}×{} coarse grid). Density term off: {}.\n\n",
        r.clip,
        r.fit_frames[0],
        r.fit_frames[1],
        f.loss,
        f.epochs,
        f.window,
        f.lr,
        f.beta,
        f.var_weight,
        f.replicas,
        f.seed,
        r.heldout_frames[0],
        r.heldout_frames[1],
        v.seeds,
        v.coarse_grid,
        v.coarse_grid,
        density_term(f.loss),
    );
    s.push_str("| measure | video STD |");
    for var in &r.variants {
        s.push_str(&format!(" {} error |", heading(&var.name)));
    }
    s.push_str("\n|---|---:|");
    for _ in &r.variants {
        s.push_str("---:|");
    }
    s.push('\n');
    for (m, name) in MEASURES.iter().enumerate() {
        let video = r
            .video
            .get(m)
            .and_then(|x| x.as_ref())
            .map_or("N/A".to_string(), |st| format!("{:.4}", st.std));
        s.push_str(&format!("| {name} | {video} |"));
        let best = (0..r.variants.len())
            .map(|v| r.error(v, m))
            .fold(f64::INFINITY, f64::min);
        for v in 0..r.variants.len() {
            let e = r.error(v, m);
            match e == best {
                true => s.push_str(&format!(" **{e:.4}** |")),
                false => s.push_str(&format!(" {e:.4} |")),
            }
        }
        s.push('\n');
    }
    s.push_str("\nErrors are held-out means over frames (and seeds); density and velocity errors are relative coarse-grid errors, the others |simulation − video| per frame (as `herdfit validate`). Bold: the lowest of the row.\n\n");
    for (switch, helps, not) in r.verdicts() {
        s.push_str(&format!(
            "- **{switch}** helps (full model lower) on {} of {}: {}{}\n",
            helps.len(),
            MEASURES.len(),
            if helps.is_empty() {
                "none".to_string()
            } else {
                helps.join(", ")
            },
            if not.is_empty() {
                format!("; not on {}", not.join(", "))
            } else {
                String::new()
            }
        ));
    }
    s.push_str("\n| parameter |");
    for var in &r.variants {
        s.push_str(&format!(" {} |", var.name));
    }
    s.push_str("\n|---|");
    for _ in &r.variants {
        s.push_str("---:|");
    }
    s.push('\n');
    for (i, n) in crate::herd::params::param_names().iter().enumerate() {
        s.push_str(&format!("| {n} |"));
        for var in &r.variants {
            s.push_str(&format!(" {:.4} |", var.params[i]));
        }
        s.push('\n');
    }
    s.push_str("| fit wall s |");
    for var in &r.variants {
        s.push_str(&format!(" {:.1} |", var.fit_seconds));
    }
    s.push('\n');
    s
}

/// "full" → "with all (full)", "no-x" → "without x".
fn heading(name: &str) -> String {
    match name.strip_prefix("no-") {
        Some(x) => format!("without {x}"),
        None => "full model".to_string(),
    }
}

/// Writes `ablation.json`, each variant's parameter set and the plots into `dir`.
pub(super) fn write(r: &AblationReport, variants: &[Variant], dir: &AtomicDir) -> Result<()> {
    let json = serde_json::to_string_pretty(r).map_err(|e| Error::Internal(e.to_string()))?;
    dir.write("ablation.json", format!("{json}\n").as_bytes())?;
    for v in variants {
        v.params
            .save(&dir.path(&format!("params-{}.json", v.name)))?;
    }
    let at = |k: usize| (r.heldout_frames[0] + k) as f64;
    let lines = |m: usize| -> Vec<(String, Vec<(f64, f64)>)> {
        r.variants
            .iter()
            .map(|v| {
                let pts = v.per_frame.iter().enumerate();
                (v.name.clone(), pts.map(|(k, x)| (at(k), x[m])).collect())
            })
            .collect()
    };
    let density = lines(0);
    let mut polar = lines(2);
    let video = r.video_per_frame.iter().enumerate();
    polar.insert(
        0,
        ("video".into(), video.map(|(k, x)| (at(k), x[0])).collect()),
    );
    chart(
        &dir.path("density-error.png"),
        "held-out density error per variant",
        "relative error",
        "frame",
        &density,
        false,
    )?;
    chart(
        &dir.path("polarization.png"),
        "held-out polarization per variant",
        "polarization",
        "frame",
        &polar,
        true,
    )?;
    // Every variant's error of each measure relative to the full model's (1 = the same; x =
    // measure index), so that differences of a few per cent show.
    let table: Vec<(String, Vec<(f64, f64)>)> = (0..r.variants.len())
        .map(|v| {
            let pts = (0..MEASURES.len())
                .map(|m| (m as f64, r.error(v, m) / r.error(0, m)))
                .filter(|p| p.1.is_finite())
                .collect();
            (r.variants[v].name.clone(), pts)
        })
        .collect();
    chart(
        &dir.path("errors.png"),
        "held-out error relative to the full model",
        "error / full model's error",
        "measure (0 density, 1 velocity, 2 polarization, 3-4 ang. momentum, 5 aspect ratio)",
        &table,
        false,
    )
}

/// A line chart of named lines (the first black when `first_black`).
pub(super) fn chart(
    path: &std::path::Path,
    title: &str,
    y: &str,
    x: &str,
    lines: &[(String, Vec<(f64, f64)>)],
    first_black: bool,
) -> Result<()> {
    let series: Vec<Series> = lines
        .iter()
        .enumerate()
        .map(|(i, (name, points))| Series {
            name,
            points: points.clone(),
            colour: match (first_black, i) {
                (true, 0) => plotters::style::RGBColor(0, 0, 0),
                (true, i) => PALETTE[(i - 1) % PALETTE.len()],
                (false, i) => PALETTE[i % PALETTE.len()],
            },
        })
        .collect();
    crate::plot::line_chart(path, title, x, y, &series)
}
