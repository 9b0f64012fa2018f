//! `herdfit validate --params BUNDLE.json`: the held-out validation of a zone fit's parameter-set
//! bundle (paper §7.2.4), each agent with its zone's set and the zones' fixed speeds, against an
//! optional baseline (another bundle, or one set played in every zone under the same zones and
//! speeds). The report folder holds `report.json` (`herdfit.zone-validation/1`), `report.md`
//! (whole-grid and per-zone tables) and `zones.png` (the zones of the clip's cells).

use super::report::ValidateJob;
use super::zones::{validate_zones, ZoneSetReport};
use super::HeldOut;
use crate::data::atomic::AtomicDir;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::params::Params;
use crate::herd::sets::{ParamSets, PARAM_SETS_SCHEMA};
use crate::herd::zoned::ZoneSets;
use crate::progress::Progress;
use serde::Serialize;
use std::path::Path;

/// Schema tag of a zone validation report.
pub const ZONE_VALIDATION_SCHEMA: &str = "herdfit.zone-validation/1";

/// A zone validation report (`report.json`).
#[derive(Clone, Debug, Serialize)]
pub struct ZoneReport {
    #[serde(flatten)]
    pub run: HeldOut,
    /// The zones' emergent measures are those of the seeds' mean prediction
    /// ([`super::ValidateConfig::ensemble_mean`]). Not written when false.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    pub ensemble_mean: bool,
    /// Per zone: its name, its cells and its fixed speed (BL/s), if any.
    pub zones: Vec<ZoneInfo>,
    pub sets: Vec<ZoneSetReport>,
}

/// One zone of the report.
#[derive(Clone, Debug, Serialize)]
pub struct ZoneInfo {
    pub name: String,
    pub cells: usize,
    pub speed: Option<f64>,
}

/// Runs a validation job whatever its parameter file holds: a zone fit's bundle
/// (`herdfit.param-sets/1`) zone by zone ([`run_bundle`]), one set as [`super::run`]; returns the
/// report's Markdown (what the CLI prints).
pub fn run_either(job: &ValidateJob, progress: &mut dyn Progress) -> Result<String> {
    if is_bundle(&job.params) {
        run_bundle(job, progress).map(|r| r.1)
    } else {
        super::run(job, progress).map(|r| r.1)
    }
}

/// Whether `path` holds a parameter-set bundle (its `schema` says so); unreadable files are
/// left to the parameter-set reader's message.
pub fn is_bundle(path: &Path) -> bool {
    let Ok(text) = std::fs::read_to_string(path) else {
        return false;
    };
    serde_json::from_str::<serde_json::Value>(&text)
        .ok()
        .and_then(|v| v.get("schema").and_then(|s| s.as_str()).map(str::to_owned))
        .is_some_and(|s| s == PARAM_SETS_SCHEMA)
}

/// Runs the zone validation of `job.params` (a bundle) and writes the report folder.
pub fn run_bundle(job: &ValidateJob, progress: &mut dyn Progress) -> Result<(ZoneReport, String)> {
    job.check()?;
    let clip = ClipFields::load(&job.clip)?;
    let grid = clip.grid();
    let of = |path: &Path| -> Result<ZoneSets> {
        ZoneSets::of_bundle(&ParamSets::load(path)?, path, &grid, &clip.obstacles)
    };
    let fitted = of(&job.params)?;
    let mut sets = vec![("fitted".to_string(), fitted.clone())];
    if let Some(b) = &job.baseline {
        let base = if is_bundle(b) {
            of(b)?
        } else {
            let p = Params::load(b)?;
            ZoneSets {
                sets: vec![p; fitted.sets.len()],
                ..fitted.clone()
            }
        };
        if base.zones.cell_zone != fitted.zones.cell_zone {
            return Err(Error::file(
                b,
                "its zones are not the validated bundle's: compare bundles of the same zones",
            ));
        }
        sets.push(("baseline".to_string(), base));
    }
    let out = AtomicDir::create(&job.out)?;
    progress.start("validate", (sets.len() * job.config.seeds) as u64);
    let reports = validate_zones(&clip, &sets, &job.config, || {
        progress.inc(1);
        progress.check()
    })
    .map_err(|e| e.in_file(&job.clip))?;
    progress.finish();
    let z = &fitted.zones;
    let nf = clip.frames();
    let report = ZoneReport {
        run: HeldOut {
            schema: ZONE_VALIDATION_SCHEMA.into(),
            clip: job.clip.display().to_string(),
            frames: [job.config.held_out_start(nf), nf],
            split: job.config.split,
            grid: job.config.coarse_grid,
            seeds: job.config.seeds,
            horizon: 0,
            tracks: job.config.tracks.as_ref().map(|t| t.display().to_string()),
            device: job.config.device,
        },
        ensemble_mean: job.config.ensemble_mean,
        zones: z
            .specs
            .iter()
            .enumerate()
            .map(|(k, s)| ZoneInfo {
                name: s.name.clone(),
                cells: z.cell_zone.iter().filter(|c| **c == Some(k)).count(),
                speed: s.speed,
            })
            .collect(),
        sets: reports,
    };
    let json = serde_json::to_string_pretty(&report).map_err(|e| Error::Internal(e.to_string()))?;
    out.write("report.json", format!("{json}\n").as_bytes())?;
    let md = markdown(&report);
    out.write("report.md", md.as_bytes())?;
    let map: Vec<Vec<f64>> = (0..grid.ny)
        .map(|iy| {
            (0..grid.nx)
                .map(|ix| z.cell_zone[iy * grid.nx + ix].map_or(f64::NAN, |k| (k + 1) as f64))
                .collect()
        })
        .collect();
    let names: Vec<String> = z
        .specs
        .iter()
        .enumerate()
        .map(|(k, s)| format!("{} = {}", k + 1, s.name))
        .collect();
    crate::plot::heat_map(
        &out.path("zones.png"),
        &format!("zones of the clip's cells ({})", names.join(", ")),
        &map,
    )?;
    out.commit()?;
    Ok((report, md))
}

/// The zone report as Markdown: the whole grid's errors per set, then every zone's.
pub fn markdown(r: &ZoneReport) -> String {
    let mut s = format!(
        "# herdfit zone validation\n\n{} (whole grid); each agent plays its zone's set.\n\n| zone | cells | fixed speed (BL/s) |\n|---|---:|---:|\n",
        r.run.summary()
    );
    for z in &r.zones {
        let v = z.speed.map_or("—".into(), |v| format!("{v}"));
        s.push_str(&format!("| {} | {} | {v} |\n", z.name, z.cells));
    }
    s.push_str("\n| set | density error | velocity error |\n|---|---:|---:|\n");
    for set in &r.sets {
        s.push_str(&format!(
            "| {} | {:.4} ± {:.4} | {:.4} ± {:.4} |\n",
            set.name,
            set.density_error.mean,
            set.density_error.std,
            set.velocity_error.mean,
            set.velocity_error.std
        ));
    }
    s.push_str("\n| set | zone | density error | polarization error | angular momentum error | aspect ratio error |\n|---|---|---:|---:|---:|---:|\n");
    for set in &r.sets {
        for z in &set.zones {
            s.push_str(&format!(
                "| {} | {} | {:.4} | {:.4} | {:.4} | {:.4} |\n",
                set.name,
                z.zone,
                z.density_error.mean,
                z.polarization_error.mean,
                z.angular_momentum_error.mean,
                z.aspect_ratio_error.mean
            ));
        }
    }
    s.push_str("\nZone errors: the zone's relative density error on its cells and the emergent measures (eq. 12–13) of the fields inside the zone, mean over the held-out frames and seeds. `zones.png` shows which zone each cell belongs to.\n");
    s
}
