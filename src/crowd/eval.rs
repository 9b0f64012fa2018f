//! Leave-one-scene-out forecasting on ETH/UCY: train on the other scenes, observe 8 steps,
//! predict 12, ADE/FDE in metres beside the constant-velocity baseline (the last observed
//! displacement) computed from the same windows, and the collision rate of each.
//!
//! Windows: every complete 20-step window of every pedestrian (no overlap filter). At the end of
//! the observation of frame f, every pedestrian present at f and f − 1 is rolled out jointly by the
//! learnt model for 12 steps from its own observed past (≤ 8 frames; intended direction from past
//! frames only), so neighbours are predictions too, never future ground truth; the pedestrians
//! with a complete window ending its observation at f are scored.

use super::behaviour::LOCOMOTION;
use super::features::{formation, headings, Scene, V2};
use super::model::{learn, read_tracks, BehaviourSpec, CrowdModel, LearnConfig};
use super::sim::SEPARATION_PASSES;
use super::step::{advance, plan, separate, Agent};
use super::tune::{inner_scores, training, with, Candidate, TuningConfig};
use crate::data::tracks::Tracks;
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
    /// Hard minimum distance (m) between rolled-out pedestrians after each predicted step
    /// (`crowd::step::separate`); 0: off. Fixed a priori (the simulation's 0.3 m), not tuned.
    pub min_distance: f64,
    /// Hyper-parameters chosen per test scene inside its training scenes.
    pub tuning: TuningConfig,
}

impl Default for EvalConfig {
    /// The forecasting configuration measured best in RESULTS.md §4: the kinematic features
    /// (speed, intended direction; formation weight 0) in 4 PCA dimensions, tracks smoothed with
    /// σ = 3 frames, eq. 3 over all k = 100 neighbours with 3 × the 5th neighbour's distance as
    /// bandwidth, no clustering or attraction (both raised the error on every fold tried).
    /// One behaviour learnt from every sample: a forecast runs no behaviour machine, so every
    /// pedestrian is predicted by the locomotion model, which must then have seen the ones who
    /// stand and talk too (§6.1's split leaves them to an interaction model).
    fn default() -> Self {
        let mut learn = LearnConfig {
            behaviours: vec![BehaviourSpec {
                name: LOCOMOTION.into(),
                weights: None,
                pivot: None,
            }],
            ..LearnConfig::default()
        };
        learn.action.choice = super::action::ClusterChoice::Nearest;
        learn.action.clusters = 1;
        learn.action.attraction = 0.0;
        learn.action.max_deviation = 100.0;
        learn.action.bandwidth_scale = 3.0;
        learn.features.weights.formation = 0.0;
        learn.pca_dims = 4;
        learn.smoothing = 3.0;
        // A forecast has no goal or time to leave: the paper's intent and eq. 3, whatever
        // `LearnConfig`'s defaults become.
        learn.features.intent = super::features::IntentWindow::Centred;
        learn.action.output = super::action::ActionOutput::Regression;
        EvalConfig {
            learn,
            data: PathBuf::from("../shared/data/pedestrians/eth-ucy"),
            scenes: vec![],
            observe: 8,
            predict: 12,
            collision_distance: 0.2,
            seed: 0,
            min_distance: 0.3,
            tuning: TuningConfig::default(),
        }
    }
}

impl EvalConfig {
    /// Checks every value; errors name the key.
    pub fn check(&self) -> Result<()> {
        self.learn.check()?;
        self.tuning.check()?;
        if self.observe < 2 || self.predict == 0 {
            return Err(Error::invalid("observe must be ≥ 2 and predict ≥ 1"));
        }
        if !(self.min_distance.is_finite() && self.min_distance >= 0.0) {
            return Err(Error::invalid("min_distance must be ≥ 0"));
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

/// The model's collisions split by cause, as fractions of all scored pairs (they sum to the
/// model's collision rate).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct CollisionCauses {
    /// Pairs within [`NEAR`] at the observation's end (walking together or passing close).
    pub near_at_start: f64,
    /// Pairs farther apart whose predicted paths met.
    pub converging: f64,
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
    pub model_collision_causes: CollisionCauses,
    /// Every candidate's inner score, and the one chosen ([`TuningConfig`]; empty for the
    /// average).
    pub candidates: Vec<Candidate>,
    pub chosen: Option<usize>,
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
pub(crate) struct Acc {
    pub(crate) windows: usize,
    pub(crate) pairs: usize,
    pub(crate) ade: [f64; 2],
    pub(crate) fde: [f64; 2],
    pub(crate) coll: [usize; 3],
    /// Model collisions of pairs within [`NEAR`] of each other at the observation's end, and
    /// of the others.
    pub(crate) cause: [usize; 2],
}

/// Pairs closer than this (m) at the end of their observation count as walking together
/// (the training data's mean interpersonal distance in groups is 0.82 m, RESULTS.md §4).
pub const NEAR: f64 = 1.0;

impl Acc {
    pub(crate) fn add(&mut self, o: &Acc) {
        self.windows += o.windows;
        self.pairs += o.pairs;
        for i in 0..2 {
            self.ade[i] += o.ade[i];
            self.fde[i] += o.fde[i];
        }
        for i in 0..3 {
            self.coll[i] += o.coll[i];
        }
        for i in 0..2 {
            self.cause[i] += o.cause[i];
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
        separate(&mut agents, cfg.min_distance, SEPARATION_PASSES, None);
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
        for (t, &p) in paths[i].iter().enumerate() {
            acc.ade[0] += dist(p, truth(k, t)) / pred as f64;
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
            let m = hit(&|t| (paths[i][t], paths[j][t]));
            acc.coll[0] += usize::from(m);
            if m {
                let now = |k: usize| scene.segments[k].pos[f - scene.segments[k].start];
                acc.cause[usize::from(dist(now(k), now(l)) >= NEAR)] += 1;
            }
            acc.coll[1] += usize::from(hit(&|t| (cv(k, t), cv(l, t))));
            acc.coll[2] += usize::from(hit(&|t| (truth(k, t), truth(l, t))));
        }
    }
    acc
}

/// Scores `model` on one scene's frames (parallel over observation ends, summed in frame order).
pub(crate) fn score_scene(
    model: &CrowdModel,
    scene: &Scene,
    cfg: &EvalConfig,
    stride: usize,
) -> Acc {
    let ends: Vec<usize> = (1..scene.frames()).step_by(stride).collect();
    let per: Vec<Acc> = ends
        .into_par_iter()
        .map(|f| forecast_frame(model, scene, f, cfg))
        .collect();
    let mut acc = Acc::default();
    per.iter().for_each(|a| acc.add(a));
    acc
}

fn read(dir: &Path, name: &str, fps: f64) -> Result<Tracks> {
    read_tracks(&dir.join(name), fps)
}

/// Runs the leave-one-scene-out evaluation, hyper-parameters chosen per test scene inside its
/// training scenes ([`TuningConfig`]).
pub fn evaluate(cfg: &EvalConfig, progress: &mut dyn Progress) -> Result<EvalReport> {
    cfg.check()?;
    let fps = cfg.learn.eth_fps;
    let mut files = Vec::new();
    for (name, fs) in SCENES.iter() {
        let mut v = Vec::new();
        for f in fs.iter() {
            v.push(read(&cfg.data, f, fps)?);
        }
        files.push((*name, v));
    }
    let extra = TRAIN_ONLY
        .iter()
        .map(|f| read(&cfg.data, f, fps))
        .collect::<Result<Vec<_>>>()?;
    let tests: Vec<&str> = SCENES
        .iter()
        .map(|(n, _)| *n)
        .filter(|n| cfg.scenes.is_empty() || cfg.scenes.iter().any(|s| s == n))
        .collect();
    let tuned = cfg.tuning.lists(&cfg.learn).iter().any(|l| l.len() > 1);
    let inner = if tuned {
        inner_scores(&files, &extra, &tests, cfg, progress)?
    } else {
        vec![vec![]; tests.len()]
    };
    let mut folds = Vec::new();
    for (ti, name) in tests.iter().enumerate() {
        let chosen = (!inner[ti].is_empty()).then(|| {
            let cost = |c: &Candidate| c.inner_ade + c.inner_fde;
            (0..inner[ti].len())
                .min_by(|&a, &b| cost(&inner[ti][a]).total_cmp(&cost(&inner[ti][b])))
                .expect("candidates")
        });
        let lcfg = match chosen {
            Some(c) => {
                let c = &inner[ti][c];
                with(
                    &cfg.learn,
                    [c.smoothing, c.formation, c.bandwidth_scale, c.inertia],
                )
            }
            None => cfg.learn.clone(),
        };
        let model = learn(&training(&files, &extra, &[name]), &lcfg, progress)?;
        let fs = &files.iter().find(|(n, _)| n == name).expect("scene").1;
        progress.start(&format!("evaluate {name}"), fs.len() as u64);
        let mut acc = Acc::default();
        for (t, f) in fs.iter().zip(
            SCENES
                .iter()
                .find(|(n, _)| n == name)
                .expect("scene")
                .1
                .iter(),
        ) {
            let scene = Scene::from_tracks(t, 0.0).map_err(|e| e.in_file(cfg.data.join(f)))?;
            acc.add(&score_scene(&model, &scene, cfg, 1));
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
            model_collision_causes: CollisionCauses {
                near_at_start: acc.cause[0] as f64 / np,
                converging: acc.cause[1] as f64 / np,
            },
            candidates: inner[ti].clone(),
            chosen,
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
        model_collision_causes: CollisionCauses {
            near_at_start: m(&|f| f.model_collision_causes.near_at_start),
            converging: m(&|f| f.model_collision_causes.converging),
        },
        candidates: vec![],
        chosen: None,
    })
}

impl std::fmt::Display for EvalReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{:<8} {:>7} {:>13} {:>11} {:>9} {:>9} {:>9} {:>15}",
            "scene",
            "windows",
            "model ADE/FDE",
            "CV ADE/FDE",
            "coll",
            "CV coll",
            "data coll",
            "coll near/far"
        )?;
        for x in self.folds.iter().chain(self.average.as_ref()) {
            writeln!(
                f,
                "{:<8} {:>7} {:>6.3}/{:<6.3} {:>5.3}/{:<5.3} {:>9.4} {:>9.4} {:>9.4} {:>7.4}/{:<7.4}",
                x.scene,
                x.windows,
                x.model.ade,
                x.model.fde,
                x.constant_velocity.ade,
                x.constant_velocity.fde,
                x.model.collision_rate,
                x.constant_velocity.collision_rate,
                x.data_collision_rate,
                x.model_collision_causes.near_at_start,
                x.model_collision_causes.converging
            )?;
        }
        for x in &self.folds {
            if let Some(c) = x.chosen.map(|i| &x.candidates[i]) {
                writeln!(
                    f,
                    "{}: chosen in its training scenes: smoothing {}, formation weight {}, \
                     bandwidth × {}{} (inner ADE/FDE {:.3}/{:.3} of {} candidates)",
                    x.scene,
                    c.smoothing,
                    c.formation,
                    c.bandwidth_scale,
                    if c.inertia > 0.0 {
                        format!(", inertia {}", c.inertia)
                    } else {
                        String::new()
                    },
                    c.inner_ade,
                    c.inner_fde,
                    x.candidates.len()
                )?;
            }
        }
        Ok(())
    }
}
