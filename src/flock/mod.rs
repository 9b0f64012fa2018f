//! Line-formation flocks (Klotsman & Tal, "Animation of Flocks Flying in Line Formations"): V, U,
//! J and line shapes learnt from a short marked example, animated for any number of birds with
//! the example's pattern of energy savings (§5), after an initiation phase that converges from
//! any start to the first steady shape (§6).
//!
//! Stages, one file each: [`synth`] (synthetic examples with known truth), [`extract`] (§4:
//! ordering, gaps, leader, RANSAC side fits in [`ransac`]), [`power`] (§5 Step 2: Hummel's g_ij,
//! Munk's theorem), [`steady`] (Algorithm 1, with the eq. 4 solver in [`solve`]), [`hpr`] and
//! [`initiation`] (§6), [`animate`] (the whole animation and its files), [`figures`] and
//! `render` (feature `video`).

pub mod animate;
pub mod extract;
pub mod family;
pub mod figures;
mod frames;
pub mod hpr;
pub mod initiation;
pub mod keys;
pub mod pairs;
pub mod power;
pub mod ransac;
#[cfg(feature = "video")]
pub mod render;
pub mod solve;
pub mod steady;
pub mod synth;

use crate::error::Result;
use crate::progress::Progress;
use std::path::{Path, PathBuf};

/// What [`demo`] did, printed for a newcomer.
#[derive(Clone, Debug)]
pub struct DemoSummary {
    pub folder: PathBuf,
    pub example_birds: usize,
    pub kind: extract::ShapeKind,
    pub angles: [Option<f64>; 2],
    pub outliers_found: usize,
    pub outliers_true: usize,
    pub birds: usize,
    pub keys: usize,
    pub converged_after: Option<f64>,
    pub flock_mean_saving: f64,
    pub least_saving: f64,
    pub most_saving: f64,
    pub seconds: f64,
}

impl std::fmt::Display for DemoSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let a = |v: Option<f64>| v.map_or("-".to_string(), |x| format!("{x:.1}°"));
        writeln!(
            f,
            "flock: a synthetic {}-bird V (30° sides, 20 % outliers, noise 0.1 b) → extracted as {}, \
             side angles {} / {}, {} of {} outlier marks found",
            self.example_birds,
            self.kind.as_str().to_uppercase(),
            a(self.angles[0]),
            a(self.angles[1]),
            self.outliers_found,
            self.outliers_true
        )?;
        writeln!(
            f,
            "flock: animated as {} birds: initiation from a random start {}, then {} key shapes \
             with the example's saving pattern",
            self.birds,
            match self.converged_after {
                Some(t) => format!("converged in {t:.1} s"),
                None => "did not converge".into(),
            },
            self.keys
        )?;
        write!(
            f,
            "flock: induced-power saving {:.0} % on average ({:.0}–{:.0} % per bird); {} ({:.0} s)",
            100.0 * self.flock_mean_saving,
            100.0 * self.least_saving,
            100.0 * self.most_saving,
            self.folder.display(),
            self.seconds
        )
    }
}

/// The flock walk-through: a synthetic V example → extraction → a 14-bird animation with
/// initiation, in `out/flock/` (`example.csv`, `shape.json`, `animation/`).
pub fn demo(out: &Path, progress: &mut dyn Progress) -> Result<DemoSummary> {
    let t0 = std::time::Instant::now();
    let dir = out.join("flock");
    std::fs::create_dir_all(&dir)
        .map_err(|e| crate::Error::file(&dir, format!("cannot create folder: {e}")))?;
    let scfg = synth::SynthConfig {
        seed: 1,
        ..synth::SynthConfig::default()
    };
    let example = synth::synth(&scfg)?;
    let ex_path = dir.join("example.csv");
    example.save(&ex_path)?;
    let shape = extract::extract(
        &example,
        &ex_path.display().to_string(),
        &extract::ExtractConfig::default(),
    )?;
    let shape_path = dir.join("shape.json");
    shape.save(&shape_path)?;
    let outliers_true = example
        .rows
        .iter()
        .filter(|r| r.role.as_deref() == Some("outlier"))
        .count();
    let outliers_found = shape
        .frames
        .iter()
        .flat_map(|f| &f.birds)
        .filter(|b| b.outlier)
        .count();
    let mut cfg = animate::AnimateConfig {
        birds: Some(14),
        frames: 250,
        seed: 3,
        ..animate::AnimateConfig::default()
    };
    cfg.init.max_time = 20.0;
    let anim_dir = dir.join("animation");
    let rep = animate::animate_file(&shape_path, &anim_dir, &cfg, progress)?;
    let fold = |f: fn(f64, f64) -> f64, init: f64| rep.mean_saving.iter().cloned().fold(init, f);
    Ok(DemoSummary {
        folder: anim_dir,
        example_birds: shape.birds,
        kind: shape.kind,
        angles: [
            shape.mean_angle(extract::Side::Left),
            shape.mean_angle(extract::Side::Right),
        ],
        outliers_found,
        outliers_true,
        birds: rep.birds,
        keys: rep.keys.len(),
        converged_after: rep.initiation.as_ref().and_then(|r| r.converged_after),
        flock_mean_saving: rep.flock_mean_saving,
        least_saving: fold(f64::min, f64::INFINITY),
        most_saving: fold(f64::max, f64::NEG_INFINITY),
        seconds: t0.elapsed().as_secs_f64(),
    })
}
