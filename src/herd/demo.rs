//! The herd's walk-through (`herdfit demo`): a synthetic herd with the built-in parameters,
//! rendered to video, extracted to fields (when built with OpenCV), fitted on the first half of
//! the clip from a clearly wrong start ([`wrong_start`]: no cohesion, no alignment, the strongest
//! avoidance — not the all-0.5 start, which even the generating parameters cannot beat on this
//! clip, RESULTS.md §1), and validated against that start on the second half: the printed
//! start → fitted held-out errors show what the fit earns.

use crate::backend::Precision;
use crate::data::ClipFields;
use crate::error::Result;
use crate::herd::fit::{
    fit, identify, write_log, FitConfig, LossKind, Optimizer, Settle, UncertaintyConfig,
    GUIDANCE_SCALE,
};
use crate::herd::params::{param_names, Params};
use crate::herd::synth::{write_clip, SynthJob, SynthVideo};
use crate::herd::uncertainty::summary;
use crate::herd::validate::{self, Report, ValidateConfig, ValidateJob};
use crate::progress::Progress;
use std::path::{Path, PathBuf};

/// What the demo did, printed by `herdfit demo`: each stage's summary, the true, start and
/// fitted parameters and the held-out errors of the fitted set and the start.
#[derive(Clone, Debug)]
pub struct DemoSummary {
    /// The summaries of the synthetic clip and of the extraction (none without OpenCV).
    pub synth: String,
    pub extract: Option<String>,
    /// The validation report and its Markdown.
    pub report: Report,
    pub report_md: String,
    pub report_dir: PathBuf,
    pub truth: Params,
    pub start: Params,
    pub fitted: Params,
    /// The identifiability summary of the fitted set (issue #15 item 2), printed after the
    /// held-out errors when present.
    pub identifiability: Option<String>,
    /// The side-by-side video of the clip and the fitted set's simulation (with OpenCV).
    pub video: Option<PathBuf>,
    /// Wall time of the whole demo (s).
    pub seconds: f64,
}

/// Runs the demo into `out` (created if missing).
pub fn demo(out: &Path, progress: &mut dyn Progress) -> Result<DemoSummary> {
    crate::data::atomic::make_dir(out)?;
    let t0 = std::time::Instant::now();
    let truth = Params::default();
    let truth_path = out.join("truth.json");
    truth.save(&truth_path)?;
    // 1. A synthetic herd with known parameters, rendered to video when OpenCV is available.
    let synth_dir = out.join("synthetic");
    let video = out.join("herd.avi");
    let with_video = cfg!(feature = "video");
    let synth_job = SynthJob {
        params: Some(truth_path.clone()),
        agents: 300,
        frame_count: 120,
        fps: 25.0,
        grid_size: (16, 10),
        cell_size: 3.0,
        obstacles: None,
        heading_deg: 0.0,
        seed: 7,
        precision: Precision::F32,
        out: synth_dir.clone(),
        video: with_video.then(|| {
            let v = SynthVideo {
                px_per_bl: 12.0,
                body_colour: [235, 235, 225],
                camera_motion: false,
            };
            (video.clone(), v)
        }),
        zone_sets: None,
        ..SynthJob::default()
    };
    let syn = write_clip(&synth_job, progress)?;
    let synth = syn.summary(&synth_job);
    // 2. Fields from the video (or the synthetic fields without OpenCV).
    let (clip_dir, extract) = fields_of(out, &video, &synth_dir, progress)?;
    let clip = ClipFields::load(&clip_dir)?;
    // 3. Fit on the first half from a clearly wrong start.
    let half = clip.frames() / 2;
    let start = wrong_start(&truth);
    let start_path = out.join("start.json");
    start.save(&start_path)?;
    // Field matching through 16-step windows: on this clip it beats the paper's losses on the
    // held-out measures (RESULTS.md §1).
    let cfg = FitConfig {
        window: 16,
        epochs: 6,
        frames: 0..half,
        seed: 1,
        loss: LossKind::Fields,
        optimizer: Optimizer::Normalized,
        ..FitConfig::default()
    };
    progress.start("fit", (cfg.epochs * (half - 1).div_ceil(cfg.window)) as u64);
    let res = fit(&clip, &start, &cfg, None, |_, _, e, _| {
        progress.message(&format!("E_mean {e:.3}"));
        progress.inc(1);
    })?;
    progress.finish();
    // What the clip determines at the fitted point (issue #15 item 2), as `herdfit fit` reports it.
    let ucfg = UncertaintyConfig::default();
    let uncertainty = identify(
        &[&clip],
        &start.with_vec(&res.params.to_vec()),
        &cfg,
        &ucfg,
        progress,
    )?;
    let identifiability = summary(&uncertainty, &res.params.to_vec());
    let params_path = out.join("params.json");
    let mut fitted = res.params.clone();
    fitted.uncertainty = Some(uncertainty);
    fitted.provenance = Some(serde_json::json!({
        "source": "demo fit",
        "clip": clip_dir.display().to_string(),
        "frames": [0, half],
        "settings": cfg,
    }));
    fitted.save(&params_path)?;
    write_log(&out.join("fit.log.csv"), &res.log)?;
    // 4. Validation on the second half, fitted vs the generic start.
    let report_dir = out.join("report");
    let (report, report_md) = validate::run(
        &ValidateJob {
            clip: clip_dir.clone(),
            params: params_path.clone(),
            baseline: Some(start_path),
            out: report_dir.clone(),
            video: true,
            config: ValidateConfig {
                split: 0.5,
                coarse_grid: 10,
                seeds: 3,
                settle: Settle::default(),
                warmup: 0,
                guidance_scale: GUIDANCE_SCALE,
                ensemble_mean: false,
                horizon: 0,
                tracks: None,
                boundary: Default::default(),
                frames: None,
                measures: Default::default(),
                device: Default::default(),
            },
        },
        progress,
    )?;
    let video = cfg!(feature = "video").then(|| report_dir.join("side-by-side.avi"));
    Ok(DemoSummary {
        synth,
        extract,
        report,
        report_md,
        report_dir,
        truth,
        start,
        fitted: res.params,
        identifiability: Some(identifiability),
        video,
        seconds: t0.elapsed().as_secs_f64(),
    })
}

/// The demo's start: `truth` with no cohesion, no alignment and the strongest avoidance
/// (cohesion.weight 0, alignment.weight 0, avoidance.weight 1) — a herd that scatters.
pub fn wrong_start(truth: &Params) -> Params {
    let mut v = truth.to_vec();
    v[0] = 0.0;
    v[3] = 1.0;
    v[6] = 0.0;
    truth.with_vec(&v)
}

/// Held-out (fitted, start) values of the density error, the velocity error and the sum of the
/// four emergent-measure errors (polarization, the two angular momenta, aspect ratio).
pub fn held_out(report: &Report) -> [(f64, f64); 3] {
    let (fit, start) = (&report.sets[0], &report.sets[1]);
    let sum = |s: &crate::herd::validate::SetReport| {
        [
            "polarization",
            "angular_momentum_centroid",
            "angular_momentum_frame_centre",
            "aspect_ratio",
        ]
        .iter()
        .map(|m| s.error(m))
        .sum::<f64>()
    };
    [
        (fit.error("density_error"), start.error("density_error")),
        (fit.error("velocity_error"), start.error("velocity_error")),
        (sum(fit), sum(start)),
    ]
}

/// The clip the demo fits: extracted from its video with OpenCV (preview PNGs too), the
/// synthetic fields without.
#[cfg(feature = "video")]
fn fields_of(
    out: &Path,
    video: &Path,
    _synth_dir: &Path,
    progress: &mut dyn Progress,
) -> Result<(PathBuf, Option<String>)> {
    use crate::video::extract::{run, ExtractConfig, ExtractJob};
    let d = out.join("clip");
    let job = ExtractJob {
        video: video.to_path_buf(),
        out: d.clone(),
        preview: Some(out.join("preview")),
        preview_every: 60,
        config: ExtractConfig {
            grid: Some(16),
            body_length_px: Some(12.0),
            body_colour: Some([235, 235, 225]),
            ..ExtractConfig::default()
        },
    };
    let ex = run(&job, progress)?;
    Ok((d.clone(), Some(ex.summary(&d))))
}

#[cfg(not(feature = "video"))]
fn fields_of(
    _out: &Path,
    _video: &Path,
    synth_dir: &Path,
    _progress: &mut dyn Progress,
) -> Result<(PathBuf, Option<String>)> {
    Ok((synth_dir.to_path_buf(), None))
}

/// The demo's header line (printed before it runs).
pub const DEMO_HEADER: &str =
    "herdfit demo: synthetic herd → video → fields → fit (first half) → validation (second half)";

impl std::fmt::Display for DemoSummary {
    /// Each stage's summary, the parameter table and the held-out errors.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "{}", self.synth)?;
        if let Some(e) = &self.extract {
            writeln!(f, "{e}")?;
        }
        write!(f, "{}", self.report_md)?;
        writeln!(f, "wrote {}", self.report_dir.display())?;
        writeln!(f)?;
        writeln!(
            f,
            "{:<20} {:>8} {:>8} {:>8}",
            "parameter", "true", "start", "fitted"
        )?;
        let (t, s, x) = (
            self.truth.to_vec(),
            self.start.to_vec(),
            self.fitted.to_vec(),
        );
        for (i, n) in param_names().iter().enumerate() {
            writeln!(f, "{n:<20} {:>8.3} {:>8.3} {:>8.3}", t[i], s[i], x[i])?;
        }
        let mean_abs =
            |v: [f64; 12]| v.iter().zip(t).map(|(a, b)| (a - b).abs()).sum::<f64>() / 12.0;
        writeln!(
            f,
            "mean |θ − θ*| per parameter: start {:.3}, fitted {:.3}",
            mean_abs(s),
            mean_abs(x)
        )?;
        writeln!(
            f,
            "held-out frames {}..{}, start → fitted (change):",
            self.report.run.frames[0], self.report.run.frames[1]
        )?;
        // Each printed number with its paired row (fitted against the start, seed by seed).
        let names = [
            ("density error", "density_error"),
            ("velocity error", "velocity_error"),
            (
                "Σ 4 measure errors",
                crate::herd::validate::paired::SUM_OF_FOUR,
            ),
        ];
        let paired = self.report.paired.first().map(|p| &p.rows);
        for ((n, row), (fit, start)) in names.iter().zip(held_out(&self.report)) {
            let seedwise = paired
                .and_then(|rows| rows.iter().find(|r| r.measure == *row))
                .map_or(String::new(), |r| {
                    let se = r.standard_error.map_or("—".into(), |x| format!("{x:.3}"));
                    format!("; seed by seed {:+.3} ± {se}: {}", r.difference, r.verdict)
                });
            writeln!(
                f,
                "  {n:<20} {start:.3} → {fit:.3} ({:+.0} %{seedwise})",
                100.0 * (fit - start) / start
            )?;
        }
        if let Some(id) = &self.identifiability {
            writeln!(f, "{id}")?;
        }
        if let Some(v) = &self.video {
            writeln!(
                f,
                "side-by-side video (clip | fitted simulation): {}",
                v.display()
            )?;
        }
        writeln!(
            f,
            "report: {} (report.md opens with the comparison table); {:.0} s",
            self.report_dir.join("report.md").display(),
            self.seconds
        )
    }
}
