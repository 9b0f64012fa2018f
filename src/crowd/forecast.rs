//! Forecasts scored (`crowd evaluate`): the pedestrians observed at a frame are rolled out jointly
//! by a learnt model and scored against the truth, beside the constant-velocity baseline (ADE,
//! FDE, collisions). Shared by the evaluation ([`super::eval`]) and the choice of its
//! hyper-parameters ([`super::tune`]).

use super::features::{formation, headings, Scene, V2};
use super::model::CrowdModel;
use super::sim::SEPARATION_PASSES;
use super::step::{advance, plan, separate, Agent};
use crate::data::tracks::Tracks;
use crate::error::Result;
use rayon::prelude::*;

/// What a forecast rollout needs of `crowd evaluate`'s settings ([`super::eval::EvalConfig`]).
#[derive(Clone, Copy, Debug)]
pub(crate) struct Forecast {
    /// Observed steps.
    pub(crate) observe: usize,
    /// Predicted steps.
    pub(crate) predict: usize,
    /// Pairs closer than this (m) at a predicted frame collide.
    pub(crate) collision_distance: f64,
    pub(crate) seed: u64,
    /// Hard minimum distance (m) between rolled-out pedestrians after each predicted step.
    pub(crate) min_distance: f64,
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
fn forecast_frame(model: &CrowdModel, scene: &Scene, f: usize, cfg: &Forecast) -> Acc {
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
pub(crate) fn score_scene(model: &CrowdModel, scene: &Scene, cfg: &Forecast, stride: usize) -> Acc {
    let ends: Vec<usize> = (1..scene.frames()).step_by(stride).collect();
    let per: Vec<Acc> = ends
        .into_par_iter()
        .map(|f| forecast_frame(model, scene, f, cfg))
        .collect();
    let mut acc = Acc::default();
    per.iter().for_each(|a| acc.add(a));
    acc
}

pub(crate) fn score_files(
    model: &CrowdModel,
    tracks: &[Tracks],
    cfg: &Forecast,
    stride: usize,
) -> Result<Acc> {
    let mut acc = Acc::default();
    for t in tracks {
        let scene = Scene::from_tracks(t, 0.0)?;
        acc.add(&score_scene(model, &scene, cfg, stride));
    }
    Ok(acc)
}
