//! `herdfit ablate CLIP --zones ZONES.json`: the paper's ablations (§7.2.1–7.2.5) of a per-zone
//! fit (§7.2.4's seals: one parameter set per zone). Each variant — the full model, then each
//! switch off in turn — learns one set per zone jointly (as `fit --zones`) on the frames before
//! the held-out part and is validated zone by zone (as `validate --params BUNDLE.json`): the
//! whole grid's density and velocity errors and, in every zone, its density, polarization,
//! angular momentum and aspect-ratio errors.

use super::{AblateConfig, AblateJob};
use crate::data::atomic::AtomicDir;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::fit::run::fit_zones;
use crate::herd::params::Params;
use crate::herd::validate::zones::{validate_zones, ZoneSetReport};
use crate::herd::zoned::ZoneSets;
use crate::herd::zones::Zones;
use crate::progress::Progress;
use serde::Serialize;

/// Schema tag of a zone ablation's `ablation.json`.
pub const ZONE_ABLATION_SCHEMA: &str = "herdfit.zone-ablation/1";

/// One zone's fitted set in a variant.
#[derive(Clone, Debug, Serialize)]
pub struct ZoneParams {
    pub zone: String,
    pub params: [f64; 12],
    pub occlusion: bool,
}

/// One variant of a zone ablation.
#[derive(Clone, Debug, Serialize)]
pub struct ZoneVariantReport {
    /// `full`, or `no-<switch>`.
    pub name: String,
    pub switch: Option<String>,
    pub sets: Vec<ZoneParams>,
    /// Wall time of the fit (s).
    pub fit_seconds: f64,
    /// The held-out errors, the whole grid's and each zone's.
    pub validation: ZoneSetReport,
}

/// The whole report.
#[derive(Clone, Debug, Serialize)]
pub struct ZoneAblationReport {
    /// [`ZONE_ABLATION_SCHEMA`].
    pub schema: String,
    pub clip: String,
    pub zones: String,
    /// Frames fitted (`[start, end)`) and held out.
    pub fit_frames: [usize; 2],
    pub heldout_frames: [usize; 2],
    pub settings: AblateConfig,
    pub variants: Vec<ZoneVariantReport>,
}

impl ZoneAblationReport {
    /// The table's rows: (name, each variant's mean held-out error).
    pub fn rows(&self) -> Vec<(String, Vec<f64>)> {
        let Some(first) = self.variants.first() else {
            return Vec::new();
        };
        let mut names = vec![
            "density error (whole grid)".to_string(),
            "velocity error (whole grid)".to_string(),
        ];
        for z in &first.validation.zones {
            for m in [
                "density",
                "polarization",
                "angular momentum",
                "aspect ratio",
            ] {
                names.push(format!("{}: {m} error", z.zone));
            }
        }
        let values = |v: &ZoneVariantReport| -> Vec<f64> {
            let r = &v.validation;
            let mut x = vec![r.density_error.mean, r.velocity_error.mean];
            for z in &r.zones {
                x.extend([
                    z.density_error.mean,
                    z.polarization_error.mean,
                    z.angular_momentum_error.mean,
                    z.aspect_ratio_error.mean,
                ]);
            }
            x
        };
        let per_variant: Vec<Vec<f64>> = self.variants.iter().map(values).collect();
        names
            .into_iter()
            .enumerate()
            .map(|(k, n)| (n, per_variant.iter().map(|v| v[k]).collect()))
            .collect()
    }
}

/// A variant's report and its fitted zone sets.
pub type Fitted = (ZoneVariantReport, ZoneSets);

/// Fits every variant's zone sets on the frames before the held-out part of `clip` and
/// validates them zone by zone; `progress` sees one unit per fit window and validation seed.
pub fn ablate_zones(
    clip: &ClipFields,
    zones: &Zones,
    start: &Params,
    cfg: &AblateConfig,
    progress: &mut dyn Progress,
) -> Result<(Vec<Fitted>, [usize; 2])> {
    cfg.check()?;
    let nf = clip.frames();
    let held = cfg.validate.held_out_start(nf);
    zones.check_agents(clip, 0..held)?;
    let (fit_cfg, runs) = super::plan(clip, cfg, "ablate --zones", progress)?;
    let mut out = Vec::with_capacity(runs.len());
    for switch in runs {
        let (name, s, c, k) = super::variant(switch, start, &fit_cfg, clip);
        progress.message(&name);
        let t0 = std::time::Instant::now();
        let starts = vec![s; zones.len()];
        let res = fit_zones(&k, &starts, &c, zones, None, |_, _, _, _| {
            progress.inc(1);
            progress.check()
        })?;
        let fit_seconds = t0.elapsed().as_secs_f64();
        let sets = ZoneSets {
            zones: zones.clone(),
            sets: res.sets,
            grid: k.grid(),
        };
        let named = [(name.clone(), sets)];
        let mut reports = validate_zones(&k, &named, &cfg.validate, || {
            progress.inc(1);
            progress.check()
        })?;
        let [(_, sets)] = named;
        let report = ZoneVariantReport {
            name,
            switch: switch.map(|s| s.to_string()),
            sets: zones
                .specs
                .iter()
                .zip(&sets.sets)
                .map(|(z, p)| ZoneParams {
                    zone: z.name.clone(),
                    params: p.to_vec(),
                    occlusion: p.constants.occlusion,
                })
                .collect(),
            fit_seconds,
            validation: reports.remove(0),
        };
        out.push((report, sets));
    }
    progress.finish();
    Ok((out, [held, nf]))
}

/// Runs an ablation job: zone by zone when `job.zones` is set ([`run`]), else on one parameter set
/// ([`super::run`]); returns the report's Markdown (what the CLI prints).
pub fn run_either(job: &AblateJob, progress: &mut dyn Progress) -> Result<String> {
    match job.zones {
        Some(_) => run(job, progress).map(|r| r.1),
        None => super::run(job, progress).map(|r| r.1),
    }
}

/// Runs a zone ablation job (`job.zones` set): loads the clip, the zones and the start, runs
/// [`ablate_zones`] and writes the report folder atomically — `ablation.json`, `ablation.md`,
/// `errors.png` and each variant's bundle `params-<variant>.json` (`herdfit.param-sets/1`, which
/// `author` scenes and `validate --params` read); returns the report and its Markdown.
pub fn run(job: &AblateJob, progress: &mut dyn Progress) -> Result<(ZoneAblationReport, String)> {
    job.config.check()?;
    let Some(zpath) = &job.zones else {
        return Err(Error::config("zones", "no zones file given"));
    };
    let clip = super::load_clip(&job.clip)?;
    let zones = Zones::load(zpath, &clip)?;
    let start = match &job.start {
        Some(p) => Params::load(p)?,
        None => Params::neutral(),
    };
    let dir = AtomicDir::create(&job.out)?;
    let (variants, [held, nf]) = ablate_zones(&clip, &zones, &start, &job.config, progress)
        .map_err(|e| e.in_file(&job.clip))?;
    let report = ZoneAblationReport {
        schema: ZONE_ABLATION_SCHEMA.into(),
        clip: job.clip.display().to_string(),
        zones: zpath.display().to_string(),
        fit_frames: [0, held],
        heldout_frames: [held, nf],
        settings: job.config.clone(),
        variants: variants.iter().map(|(r, _)| r.clone()).collect(),
    };
    let json = serde_json::to_string_pretty(&report).map_err(|e| Error::Internal(e.to_string()))?;
    dir.write("ablation.json", format!("{json}\n").as_bytes())?;
    for (r, sets) in &variants {
        let prov = serde_json::json!({
            "source": "ablate --zones",
            "clip": report.clip,
            "zones": report.zones,
            "variant": r.name,
            "fit_frames": report.fit_frames,
        });
        sets.bundle(Some(prov))
            .save(&dir.path(&format!("params-{}.json", r.name)))?;
    }
    errors_chart(&report, &dir)?;
    let md = markdown(&report);
    dir.write("ablation.md", md.as_bytes())?;
    dir.commit()?;
    Ok((report, md))
}

/// Every variant's error of each row relative to the full model's (1 = the same).
fn errors_chart(r: &ZoneAblationReport, dir: &AtomicDir) -> Result<()> {
    let rows = r.rows();
    let lines: Vec<(String, Vec<(f64, f64)>)> = r
        .variants
        .iter()
        .enumerate()
        .map(|(v, var)| {
            let pts = rows
                .iter()
                .enumerate()
                .map(|(k, (_, e))| (k as f64, e[v] / e[0]))
                .filter(|p| p.1.is_finite())
                .collect();
            (var.name.clone(), pts)
        })
        .collect();
    super::report::chart(
        &dir.path("errors.png"),
        "held-out error relative to the full model, per zone",
        "error / full model's error",
        "row of ablation.md's table (0-1 whole grid, then 4 per zone)",
        &lines,
        false,
    )
}

/// The report as Markdown: the settings, the table (the whole grid's errors and every zone's,
/// each variant's mean held-out error), the verdicts and each zone's fitted parameters.
pub fn markdown(r: &ZoneAblationReport) -> String {
    let f = &r.settings.fit;
    let v = &r.settings.validate;
    let mut s = format!(
        "# herdfit ablation, one parameter set per zone\n\nClip `{}`, zones `{}`: fitted on frames {}..{} (`{}` objective, {} epochs of {}-step windows, lr {}, seed {}), validated on frames {}..{} ({} seed(s), {}×{} coarse grid).\n\n| held-out error |",
        r.clip, r.zones, r.fit_frames[0], r.fit_frames[1], f.loss, f.epochs, f.window, f.lr,
        f.seed, r.heldout_frames[0], r.heldout_frames[1], v.seeds, v.coarse_grid, v.coarse_grid,
    );
    for var in &r.variants {
        s.push_str(&format!(" {} |", var.name));
    }
    s.push_str("\n|---|");
    s.push_str(&"---:|".repeat(r.variants.len()));
    s.push('\n');
    let rows = r.rows();
    for (name, e) in &rows {
        let best = e.iter().copied().fold(f64::INFINITY, f64::min);
        s.push_str(&format!("| {name} |"));
        for x in e {
            match *x == best {
                true => s.push_str(&format!(" **{x:.4}** |")),
                false => s.push_str(&format!(" {x:.4} |")),
            }
        }
        s.push('\n');
    }
    s.push_str("\nDensity and velocity errors of the whole grid are relative coarse-grid errors; a zone's density error is Σ|ρ' − ρ| / Σρ over its cells, the others |simulation − video| of the measure inside the zone, per frame (as `validate --params BUNDLE.json`). Bold: the lowest of the row.\n\n");
    for (k, var) in r.variants.iter().enumerate().skip(1) {
        let helps: Vec<&str> = rows
            .iter()
            .filter(|(_, e)| e[0] < e[k])
            .map(|(n, _)| n.as_str())
            .collect();
        s.push_str(&format!(
            "- **{}** helps (full model lower) on {} of {} rows{}\n",
            var.switch.as_deref().unwrap_or(&var.name),
            helps.len(),
            rows.len(),
            if helps.is_empty() {
                String::new()
            } else {
                format!(": {}", helps.join(", "))
            }
        ));
    }
    let names = crate::herd::params::param_names();
    for (z, set) in r.variants[0].sets.iter().enumerate() {
        s.push_str(&format!("\n| zone `{}` parameter |", set.zone));
        for var in &r.variants {
            s.push_str(&format!(" {} |", var.name));
        }
        s.push_str("\n|---|");
        s.push_str(&"---:|".repeat(r.variants.len()));
        s.push('\n');
        for (i, n) in names.iter().enumerate() {
            s.push_str(&format!("| {n} |"));
            for var in &r.variants {
                s.push_str(&format!(" {:.4} |", var.sets[z].params[i]));
            }
            s.push('\n');
        }
    }
    s.push_str("\n| fit wall s |");
    for var in &r.variants {
        s.push_str(&format!(" {:.1} |", var.fit_seconds));
    }
    s.push('\n');
    s
}
