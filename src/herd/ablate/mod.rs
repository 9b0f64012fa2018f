//! The paper's ablations as one run (§7.2.1–7.2.5): the same clip fitted on its first part and
//! validated on the held-out rest with the full model, then with each switch off in turn —
//! occlusion (§7.2.1), angular perception (Φ held at π, §7.2.2), the density term (β = 0 in
//! eq. 11, or no density term in the field objectives, §7.2.3), direction-variance matching
//! (E_var of eq. 8, §7.2.4) and the speed–density table (§7.2.5) — and the paper's Table 4 for
//! all of them: the video's STD of each measure and each variant's held-out error.

use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::fit::{fit_clips, FitConfig, LossKind};
use crate::herd::params::{param_names, Params};
use crate::herd::validate::{validate, SetReport, ValidateConfig};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};
use std::path::PathBuf;

mod report;
pub mod zoned;

pub use report::{markdown, AblationReport, VariantReport, ABLATION_SCHEMA};

/// One of the paper's switches, turned off in an ablation.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Switch {
    /// Perceptual occlusion by closer agents (§7.2.1): `constants.occlusion` off.
    Occlusion,
    /// Angular perception (§7.2.2): the four angular ranges held at 1 (Φ_F = π) and not fitted.
    Angular,
    /// Density matching (§7.2.3): β = 0 in eq. 11, and the field objectives' density term 0.
    Density,
    /// Direction-variance matching (§7.2.4): λ_var = 0, every parameter (alignment too) follows
    /// the remaining objective.
    DirVariance,
    /// The speed–density table (§7.2.5): v_μ is the clip's mean speed at every density.
    SpeedDensity,
}

enum_names!(Switch {
    Occlusion = "occlusion",
    Angular = "angular",
    Density = "density",
    DirVariance = "dir-variance",
    SpeedDensity = "speed-density",
});

/// Every switch, in the paper's order.
pub const SWITCHES: [Switch; 5] = [
    Switch::Occlusion,
    Switch::Angular,
    Switch::Density,
    Switch::DirVariance,
    Switch::SpeedDensity,
];

impl Switch {
    /// The variant's name in the report (`no-occlusion`, …).
    pub fn variant(self) -> String {
        format!("no-{self}")
    }

    /// Turns the switch off in a start, a fit's settings and the clip's speed model.
    pub fn apply(self, start: &mut Params, cfg: &mut FitConfig, clip: &mut ClipFields) {
        match self {
            Switch::Occlusion => start.constants.occlusion = false,
            Switch::Angular => {
                let mut v = start.to_vec();
                let names = param_names();
                for g in 0..4 {
                    v[3 * g + 2] = 1.0;
                    cfg.frozen.push(names[3 * g + 2].clone());
                }
                *start = start.with_vec(&v);
            }
            Switch::Density => {
                cfg.beta = 0.0;
                cfg.density_weight = 0.0;
            }
            Switch::DirVariance => {
                cfg.var_weight = 0.0;
                cfg.split_gradients = false;
            }
            Switch::SpeedDensity => clip.meta.speed.density_table.clear(),
        }
    }
}

/// Settings of an ablation: the fit of every variant, the validation of every variant, and
/// the switches turned off in turn.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AblateConfig {
    /// The fit of every variant (`frames` is set from `validate.split`: the frames before the
    /// held-out part).
    pub fit: FitConfig,
    /// The held-out validation (`split` divides the clip).
    pub validate: ValidateConfig,
    /// The switches, each turned off in one variant (the full model is always run first).
    pub switches: Vec<Switch>,
}

impl Default for AblateConfig {
    fn default() -> Self {
        AblateConfig {
            // The paper's switches are ablated on the paper's objective (as `herdfit ablate`).
            fit: FitConfig {
                loss: LossKind::Paper,
                ..FitConfig::default()
            },
            validate: ValidateConfig::default(),
            switches: SWITCHES.to_vec(),
        }
    }
}

impl AblateConfig {
    /// Checks the settings on their own; errors name the key.
    pub fn check(&self) -> Result<()> {
        self.validate.check()?;
        if self.validate.split <= 0.0 {
            return Err(Error::config(
                "split",
                "0 leaves no frames to fit: give a fraction in (0, 1)",
            ));
        }
        FitConfig {
            frames: 0..2,
            ..self.fit.clone()
        }
        .check()?;
        if self.fit.loss == LossKind::Auto {
            return Err(Error::config(
                "loss",
                "the ablations compare one objective's fits: give fields, paper or ensemble",
            ));
        }
        if !self.fit.global.is_off() {
            return Err(Error::config(
                "global.starts",
                "an ablation fits each variant from the same start: set 1",
            ));
        }
        for (i, s) in self.switches.iter().enumerate() {
            if self.switches[..i].contains(s) {
                return Err(Error::config("switches", format!("'{s}' is given twice")));
            }
        }
        Ok(())
    }
}

/// An ablation with its files.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct AblateJob {
    pub clip: PathBuf,
    /// Starting parameters of every variant; the generic start (every value 0.5) when absent.
    pub start: Option<PathBuf>,
    /// The report folder: `ablation.json`, `ablation.md`, the plots and each variant's fitted
    /// parameter set (`params-<variant>.json`).
    pub out: PathBuf,
    /// Zones (`herdfit.zones/1`): one parameter set per zone in every variant ([`zoned::run`]).
    pub zones: Option<PathBuf>,
    pub config: AblateConfig,
}

impl Default for AblateJob {
    fn default() -> Self {
        AblateJob {
            clip: PathBuf::from("clip"),
            start: None,
            out: PathBuf::from("ablation"),
            zones: None,
            config: AblateConfig::default(),
        }
    }
}

/// One variant's fit and validation.
pub struct Variant {
    pub name: String,
    pub switch: Option<Switch>,
    pub params: Params,
    pub fit_seconds: f64,
    pub validation: SetReport,
}

/// Fits and validates the full model and each variant on `clip`; `progress` sees one unit per
/// fit window and per validation seed. Returns the variants and the held-out frames, and the
/// fit's frames.
pub fn ablate(
    clip: &ClipFields,
    clip_name: &str,
    start: &Params,
    cfg: &AblateConfig,
    progress: &mut dyn Progress,
) -> Result<(Vec<Variant>, crate::herd::validate::Report)> {
    let (fit_cfg, runs) = plan(clip, cfg, "ablate", progress)?;
    let mut out = Vec::with_capacity(runs.len());
    let mut first_report = None;
    for switch in runs {
        let (name, s, c, k) = variant(switch, start, &fit_cfg, clip);
        progress.message(&name);
        let t0 = std::time::Instant::now();
        let res = fit_clips(&[&k], &s, &c, None, |_, _, _, _| {
            progress.inc(1);
            progress.check()
        })?;
        let fit_seconds = t0.elapsed().as_secs_f64();
        let sets = [(name.clone(), res.params.clone())];
        let (mut report, _) = validate(&k, clip_name, &sets, &cfg.validate, || {
            progress.inc(1);
            progress.check()
        })?;
        let validation = report.sets.remove(0);
        first_report.get_or_insert(report);
        out.push(Variant {
            name,
            switch,
            params: res.params,
            fit_seconds,
            validation,
        });
    }
    progress.finish();
    let report = first_report.ok_or_else(|| Error::Internal("no variant ran".into()))?;
    Ok((out, report))
}

/// The fit settings of every variant (the frames before the held-out part, checked against
/// `clip`) and the runs (the full model, then each switch off); starts `progress` with one unit
/// per fit window and validation seed of every run.
fn plan(
    clip: &ClipFields,
    cfg: &AblateConfig,
    label: &str,
    progress: &mut dyn Progress,
) -> Result<(FitConfig, Vec<Option<Switch>>)> {
    cfg.check()?;
    let held = cfg.validate.held_out_start(clip.frames());
    let fit_cfg = FitConfig {
        frames: 0..held,
        ..cfg.fit.clone()
    };
    fit_cfg.check_clip(clip)?;
    let windows = (held - 1).div_ceil(fit_cfg.window) * fit_cfg.epochs;
    let runs: Vec<Option<Switch>> = std::iter::once(None)
        .chain(cfg.switches.iter().copied().map(Some))
        .collect();
    progress.start(label, (runs.len() * (windows + cfg.validate.seeds)) as u64);
    Ok((fit_cfg, runs))
}

/// A run's name (`full` or `no-<switch>`) and its start, fit settings and clip with the switch
/// off.
fn variant(
    switch: Option<Switch>,
    start: &Params,
    fit_cfg: &FitConfig,
    clip: &ClipFields,
) -> (String, Params, FitConfig, ClipFields) {
    let (mut s, mut c, mut k) = (start.clone(), fit_cfg.clone(), clip.clone());
    if let Some(sw) = switch {
        sw.apply(&mut s, &mut c, &mut k);
    }
    let name = switch.map_or_else(|| "full".to_string(), Switch::variant);
    (name, s, c, k)
}

/// Runs an ablation job: loads the clip and the start, runs [`ablate`] and writes the report
/// folder atomically; returns the report and its Markdown.
pub fn run(job: &AblateJob, progress: &mut dyn Progress) -> Result<(AblationReport, String)> {
    job.config.check()?;
    if job.zones.is_some() {
        return Err(Error::Internal(
            "a zone ablation runs through ablate::zoned::run".into(),
        ));
    }
    let clip = load_clip(&job.clip)?;
    let start = match &job.start {
        Some(p) => Params::load(p)?,
        None => Params::neutral(),
    };
    let dir = crate::data::atomic::AtomicDir::create(&job.out)?;
    let name = job.clip.display().to_string();
    let (variants, validation) =
        ablate(&clip, &name, &start, &job.config, progress).map_err(|e| e.in_file(&job.clip))?;
    let report = AblationReport::new(&name, &job.config, &variants, &validation);
    report::write(&report, &variants, &dir)?;
    let md = markdown(&report);
    dir.write("ablation.md", md.as_bytes())?;
    dir.commit()?;
    Ok((report, md))
}

/// The clip of an ablation: a video clip (a still has no held-out half).
fn load_clip(path: &std::path::Path) -> Result<ClipFields> {
    let clip = ClipFields::load(path)?;
    if clip.frames() == 1 {
        return Err(Error::file(
            path,
            "is a still (one frame): the ablations fit and validate on halves of a clip; fit a \
             still with `herdfit fit` (with and without E_var: --var-weight 0)",
        ));
    }
    Ok(clip)
}

/// Whether the loss kind has a density term the ablation of density matching removes: β of
/// eq. 11 for the paper's objective, the density part of the field objectives otherwise.
pub fn density_term(loss: LossKind) -> &'static str {
    match loss {
        LossKind::Paper => "β = 0 in eq. 11",
        // (`auto` is refused by the ablation's check.)
        LossKind::Fields | LossKind::Ensemble | LossKind::Auto => {
            "no density term in the field objective"
        }
    }
}
