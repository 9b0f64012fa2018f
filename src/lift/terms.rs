//! What the whole-sequence energy of [`super::sequence`] is made of, shared by its hand-derived
//! gradient and its autodiff reference (`lift::autodiff`): the index lists of its terms
//! ([`Structure`], fixed by the tracks alone) and the terms' values at one point
//! ([`EnergyTerms`]).

use super::observe::Observations;
use serde::{Deserialize, Serialize};

/// Index lists of the energy's terms, fixed by the tracks alone.
#[derive(Clone, Debug, Default)]
pub struct Structure {
    /// Velocities: (observation at f − 1, observation at f).
    pub vel: Vec<(usize, usize)>,
    /// Accelerations: consecutive velocities of one bird (indices into `vel`).
    pub acc: Vec<(usize, usize)>,
    /// Same-frame image-neighbour pairs (i < j).
    pub pairs: Vec<(usize, usize)>,
    /// Pairs whose two birds both have a velocity (indices into `vel`).
    pub align: Vec<(usize, usize)>,
}

impl Structure {
    /// The index lists of `obs` with `k` image neighbours per bird and frame.
    pub fn new(obs: &Observations, k: usize) -> Self {
        let n = obs.len();
        let mut vel_of = vec![usize::MAX; n];
        let mut vel = Vec::new();
        for (i, slot) in vel_of.iter_mut().enumerate() {
            if let Some(p) = obs.prev[i] {
                *slot = vel.len();
                vel.push((p, i));
            }
        }
        let acc = vel
            .iter()
            .enumerate()
            .filter(|&(_, &(p, _))| vel_of[p] != usize::MAX)
            .map(|(v, &(p, _))| (vel_of[p], v))
            .collect();
        let mut pairs = Vec::new();
        for (_, r) in &obs.frames {
            let idx: Vec<usize> = r.clone().collect();
            let mut near: Vec<(f64, usize)> = Vec::with_capacity(idx.len());
            for &i in &idx {
                near.clear();
                let p = obs.pixel[i];
                near.extend(idx.iter().filter(|&&j| j != i).map(|&j| {
                    let q = obs.pixel[j];
                    ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2), j)
                }));
                let take = k.min(near.len());
                if take == 0 {
                    continue;
                }
                near.select_nth_unstable_by(take - 1, |a, b| {
                    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
                });
                for &(_, j) in &near[..take] {
                    pairs.push((i.min(j), i.max(j)));
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        let align = pairs
            .iter()
            .filter(|&&(i, j)| vel_of[i] != usize::MAX && vel_of[j] != usize::MAX)
            .map(|&(i, j)| (vel_of[i], vel_of[j]))
            .collect();
        Structure {
            vel,
            acc,
            pairs,
            align,
        }
    }
}

/// The terms of the energy at one point (each already weighted and divided by T).
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct EnergyTerms {
    pub accel: f64,
    pub speed: f64,
    pub align: f64,
    pub cohesion: f64,
    pub separation: f64,
    pub level: f64,
    pub total: f64,
}
