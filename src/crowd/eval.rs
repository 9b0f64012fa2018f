//! Leave-one-scene-out forecasting on ETH/UCY: train on the other scenes, observe 8 steps,
//! predict 12, ADE/FDE in metres beside the constant-velocity baseline (the last observed
//! displacement) computed from the same windows, and the collision rate of each.
//!
//! Windows: every complete 20-step window of every pedestrian (no overlap filter). At the end of
//! the observation of frame f, every pedestrian present at f and f − 1 is rolled out jointly by the
//! learnt model for 12 steps from its own observed past (≤ 8 frames; intended direction from past
//! frames only), so neighbours are predictions too, never future ground truth; the pedestrians
//! with a complete window ending its observation at f are scored.

use super::features::{formation, headings, Scene, V2};
use super::model::{learn, read_tracks, CrowdModel, LearnConfig};
use super::step::{advance, plan, Agent};
use crate::error::{Error, Result};
use crate::progress::Progress;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

/// Schema tag of evaluation reports.
pub const EVAL_SCHEMA: &str = "herdfit.crowd-eval/1";

/// The five test scenes and their files, then the training-only files.
pub const SCENES: [(&str, &[&str]); 5] = [
    ("ETH", &["biwi_eth.txt"]),
    ("HOTEL", &["biwi_hotel.txt"]),
    ("UNIV", &["students001.txt", "students003.txt"]),
    ("ZARA1", &["crowds_zara01.txt"]),
    ("ZARA2", &["crowds_zara02.txt"]),
];
pub const TRAIN_ONLY: [&str; 2] = ["uni_examples.txt", "crowds_zara03.txt"];

/// Settings of `crowd evaluate`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct EvalConfig {
    /// How each fold's model is learnt.
    pub learn: LearnConfig,
    /// Folder of the ETH/UCY text files.
    pub data: PathBuf,
    /// Test scenes (names of [`SCENES`]); empty: all five.
    pub scenes: Vec<String>,
    /// Observed steps.
    pub observe: usize,
    /// Predicted steps.
    pub predict: usize,
    /// Pairs closer than this (m) at a predicted frame collide.
    pub collision_distance: f64,
    pub seed: u64,
}

impl Default for EvalConfig {
    /// The forecasting configuration measured best in RESULTS.md §3: the kinematic features
    /// (speed, intended direction; formation weight 0) in 4 PCA dimensions, tracks smoothed with
    /// σ = 3 frames, eq. 3 over all k = 100 neighbours with 3 × the 5th neighbour's distance as
    /// bandwidth, no clustering or attraction (both raised the error on every fold tried).
    fn default() -> Self {
        let mut learn = LearnConfig::default();
        learn.action.choice = super::action::ClusterChoice::Nearest;
        learn.action.clusters = 1;
        learn.action.attraction = 0.0;
        learn.action.max_deviation = 100.0;
        learn.action.bandwidth_scale = 3.0;
        learn.features.weights.formation = 0.0;
        learn.pca_dims = 4;
        learn.smoothing = 3.0;
        EvalConfig {
            learn,
            data: PathBuf::from("../shared/data/pedestrians/eth-ucy"),
            scenes: vec![],
            observe: 8,
            predict: 12,
            collision_distance: 0.2,
            seed: 0,
        }
    }
}

impl EvalConfig {
    /// Checks every value; errors name the key.
    pub fn check(&self) -> Result<()> {
        self.learn.check()?;
        if self.observe < 2 || self.predict == 0 {
            return Err(Error::invalid("observe must be ≥ 2 and predict ≥ 1"));
        }
        if !(self.collision_distance.is_finite() && self.collision_distance >= 0.0) {
            return Err(Error::invalid("collision_distance must be ≥ 0"));
        }
        for s in &self.scenes {
            if !SCENES.iter().any(|(n, _)| n == s) {
                return Err(Error::invalid(format!(
                    "scenes: '{s}' is not one of ETH, HOTEL, UNIV, ZARA1, ZARA2"
                )));
            }
        }
        Ok(())
    }
}

/// Errors and collisions of one predictor on one fold.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct Scores {
    /// Average displacement error (m).
    pub ade: f64,
    /// Final displacement error (m).
    pub fde: f64,
    /// Fraction of scored pairs (same observation end) closer than `collision_distance` at some
    /// predicted frame.
    pub collision_rate: f64,
}

/// One test scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Fold {
    pub scene: String,
    pub windows: usize,
    pub pairs: usize,
    pub train_samples: usize,
    pub model: Scores,
    pub constant_velocity: Scores,
    /// The ground truth's own collision rate over the same pairs.
    pub data_collision_rate: f64,
}

/// The report of `crowd evaluate`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct EvalReport {
    pub schema: String,
    pub config: EvalConfig,
    pub folds: Vec<Fold>,
    /// Means over the folds (each scene weighs the same, as the literature averages).
    pub average: Option<Fold>,
}

#[derive(Default, Clone)]
struct Acc {
    windows: usize,
    pairs: usize,
    ade: [f64; 2],
    fde: [f64; 2],
    coll: [usize; 3],
}

impl Acc {
    fn add(&mut self, o: &Acc) {
        self.windows += o.windows;
        self.pairs += o.pairs;
        for i in 0..2 {
            self.ade[i] += o.ade[i];
            self.fde[i] += o.fde[i];
        }
        for i in 0..3 {
            self.coll[i] += o.coll[i];
        }
    }
}

fn dist(a: V2, b: V2) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Rolls out the agents observed at frame `f` and scores those with complete windows.
fn forecast_frame(model: &CrowdModel, scene: &Scene, f: usize, cfg: &EvalConfig) -> Acc {
    let (obs, pred) = (cfg.observe, cfg.predict);
    let fc = &model.config.features;
    let mut agents = Vec::new();
    let mut scored = Vec::new(); // (agent index, segment)
    for &k in &scene.at_frame[f] {
        let s = &scene.segments[k];
        if f == s.start {
            continue;
        }
        let a0 = s.start.max((f + 1).saturating_sub(obs));
        let hist: Vec<V2> = s.pos[a0 - s.start..=f - s.start].to_vec();
        let heads = headings(&hist, fc.still_speed * scene.dt);
        let h = *heads.last().expect("history");
        let mut a = Agent::new(
            s.id,
            hist.clone(),
            h,
            None,
            cfg.seed ^ ((f as u64) << 20),
            scene.dt,
        );
        let hp = heads[heads.len() - 2];
        a.prev_formation = formation(hist[hist.len() - 2], hp, scene.others(f - 1, k), fc.radius);
        if a0 + obs == f + 1 && s.end() > f + pred {
            scored.push((agents.len(), k));
        }
        agents.push(a);
    }
    let mut acc = Acc::default();
    if scored.is_empty() {
        return acc;
    }
    let keep = fc.intent_window + 2;
    let mut paths = vec![Vec::with_capacity(pred); agents.len()];
    for _ in 0..pred {
        let plans = plan(model, &mut agents);
        advance(model, &mut agents, &plans, None, keep);
        for (p, a) in paths.iter_mut().zip(&agents) {
            p.push(a.pos);
        }
    }
    let cv = |k: usize, t: usize| {
        let s = &scene.segments[k];
        let (p, q) = (s.pos[f - s.start - 1], s.pos[f - s.start]);
        let m = (t + 1) as f64;
        [q[0] + m * (q[0] - p[0]), q[1] + m * (q[1] - p[1])]
    };
    let truth = |k: usize, t: usize| scene.segments[k].pos[f + 1 + t - scene.segments[k].start];
    for &(i, k) in &scored {
        acc.windows += 1;
        for t in 0..pred {
            acc.ade[0] += dist(paths[i][t], truth(k, t)) / pred as f64;
            acc.ade[1] += dist(cv(k, t), truth(k, t)) / pred as f64;
        }
        acc.fde[0] += dist(paths[i][pred - 1], truth(k, pred - 1));
        acc.fde[1] += dist(cv(k, pred - 1), truth(k, pred - 1));
    }
    let r = cfg.collision_distance;
    for (x, &(i, k)) in scored.iter().enumerate() {
        for &(j, l) in &scored[x + 1..] {
            acc.pairs += 1;
            let hit = |g: &dyn Fn(usize) -> (V2, V2)| {
                (0..pred).any(|t| {
                    let (a, b) = g(t);
                    dist(a, b) < r
                })
            };
            acc.coll[0] += usize::from(hit(&|t| (paths[i][t], paths[j][t])));
            acc.coll[1] += usize::from(hit(&|t| (cv(k, t), cv(l, t))));
            acc.coll[2] += usize::from(hit(&|t| (truth(k, t), truth(l, t))));
        }
    }
    acc
}

/// Scores `model` on one scene's frames (parallel over observation ends, summed in frame order).
fn score_scene(model: &CrowdModel, scene: &Scene, cfg: &EvalConfig) -> Acc {
    let per: Vec<Acc> = (1..scene.frames())
        .into_par_iter()
        .map(|f| forecast_frame(model, scene, f, cfg))
        .collect();
    let mut acc = Acc::default();
    per.iter().for_each(|a| acc.add(a));
    acc
}

fn read(dir: &Path, name: &str, fps: f64) -> Result<crate::data::tracks::Tracks> {
    read_tracks(&dir.join(name), fps)
}

/// Runs the leave-one-scene-out evaluation.
pub fn evaluate(cfg: &EvalConfig, progress: &mut dyn Progress) -> Result<EvalReport> {
    cfg.check()?;
    let fps = cfg.learn.eth_fps;
    let mut folds = Vec::new();
    let tests: Vec<&(&str, &[&str])> = SCENES
        .iter()
        .filter(|(n, _)| cfg.scenes.is_empty() || cfg.scenes.iter().any(|s| s == n))
        .collect();
    for (name, files) in tests {
        let mut train = Vec::new();
        for (other, ofiles) in SCENES.iter() {
            if other != name {
                for f in ofiles.iter() {
                    train.push(read(&cfg.data, f, fps)?);
                }
            }
        }
        for f in TRAIN_ONLY {
            train.push(read(&cfg.data, f, fps)?);
        }
        let model = learn(&train, &cfg.learn, progress)?;
        progress.start(&format!("evaluate {name}"), files.len() as u64);
        let mut acc = Acc::default();
        for f in files.iter() {
            let t = read(&cfg.data, f, fps)?;
            let scene = Scene::from_tracks(&t, 0.0).map_err(|e| e.in_file(cfg.data.join(f)))?;
            acc.add(&score_scene(&model, &scene, cfg));
            progress.inc(1);
        }
        progress.finish();
        let n = acc.windows.max(1) as f64;
        let np = acc.pairs.max(1) as f64;
        folds.push(Fold {
            scene: name.to_string(),
            windows: acc.windows,
            pairs: acc.pairs,
            train_samples: model.samples(),
            model: Scores {
                ade: acc.ade[0] / n,
                fde: acc.fde[0] / n,
                collision_rate: acc.coll[0] as f64 / np,
            },
            constant_velocity: Scores {
                ade: acc.ade[1] / n,
                fde: acc.fde[1] / n,
                collision_rate: acc.coll[1] as f64 / np,
            },
            data_collision_rate: acc.coll[2] as f64 / np,
        });
    }
    let average = average(&folds);
    Ok(EvalReport {
        schema: EVAL_SCHEMA.into(),
        config: cfg.clone(),
        folds,
        average,
    })
}

fn average(folds: &[Fold]) -> Option<Fold> {
    if folds.len() < 2 {
        return None;
    }
    let n = folds.len() as f64;
    let m = |g: &dyn Fn(&Fold) -> f64| folds.iter().map(g).sum::<f64>() / n;
    Some(Fold {
        scene: "average".into(),
        windows: folds.iter().map(|f| f.windows).sum(),
        pairs: folds.iter().map(|f| f.pairs).sum(),
        train_samples: 0,
        model: Scores {
            ade: m(&|f| f.model.ade),
            fde: m(&|f| f.model.fde),
            collision_rate: m(&|f| f.model.collision_rate),
        },
        constant_velocity: Scores {
            ade: m(&|f| f.constant_velocity.ade),
            fde: m(&|f| f.constant_velocity.fde),
            collision_rate: m(&|f| f.constant_velocity.collision_rate),
        },
        data_collision_rate: m(&|f| f.data_collision_rate),
    })
}

impl std::fmt::Display for EvalReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{:<8} {:>7} {:>11} {:>11} {:>9} {:>9} {:>9}",
            "scene", "windows", "model ADE/FDE", "CV ADE/FDE", "coll", "CV coll", "data coll"
        )?;
        for x in self.folds.iter().chain(self.average.as_ref()) {
            writeln!(
                f,
                "{:<8} {:>7} {:>6.3}/{:<6.3} {:>5.3}/{:<6.3} {:>9.4} {:>9.4} {:>9.4}",
                x.scene,
                x.windows,
                x.model.ade,
                x.model.fde,
                x.constant_velocity.ade,
                x.constant_velocity.fde,
                x.model.collision_rate,
                x.constant_velocity.collision_rate,
                x.data_collision_rate
            )?;
        }
        Ok(())
    }
}
