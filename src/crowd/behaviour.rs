//! High-level behaviour (§6.1): rule-based labelling of the training data (§3 and §7's ants:
//! slow agents staying within a distance of each other for long enough interact; everything else
//! is locomotion) and the control parameters the finite-state machine takes from the data: mean
//! durations, group size, interpersonal distance and how often an interaction starts.

use super::features::{Scene, V2};
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::collections::BTreeMap;

/// Behaviour names used by the labels, the models and the layout's regions.
pub const LOCOMOTION: &str = "locomotion";
pub const INTERACTION: &str = "interaction";
pub const LINE: &str = "line";

/// The labelling rules (speed and distance thresholds, as the paper's ants).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct LabelConfig {
    /// Agents slower than this (units/s) may be interacting.
    pub slow_speed: f64,
    /// …with another slow agent nearer than this (units)…
    pub near_distance: f64,
    /// …for at least this long (s).
    pub min_duration: f64,
}

impl Default for LabelConfig {
    fn default() -> Self {
        LabelConfig {
            slow_speed: 0.3,
            near_distance: 1.5,
            min_duration: 2.0,
        }
    }
}

impl LabelConfig {
    /// Checks the values; errors name the key.
    pub fn check(&self) -> Result<()> {
        for (v, k) in [
            (self.slow_speed, "slow_speed"),
            (self.near_distance, "near_distance"),
            (self.min_duration, "min_duration"),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!("labels.{k} = {v} must be ≥ 0")));
            }
        }
        Ok(())
    }
}

/// Speed (units/s) of segment `k` at its index `j` (the step into `j`; index 0 takes step 1).
pub fn speed_at(scene: &Scene, k: usize, j: usize) -> f64 {
    let p = &scene.segments[k].pos;
    if p.len() < 2 {
        return 0.0;
    }
    let j = j.max(1);
    (p[j][0] - p[j - 1][0]).hypot(p[j][1] - p[j - 1][1]) / scene.dt
}

/// Per segment and index: whether the agent interacts (the rules of [`LabelConfig`]).
pub fn label(scene: &Scene, cfg: &LabelConfig) -> Vec<Vec<bool>> {
    let min_frames = (cfg.min_duration / scene.dt).ceil().max(1.0) as usize;
    scene
        .segments
        .iter()
        .enumerate()
        .map(|(k, s)| {
            let cand: Vec<bool> = (0..s.pos.len())
                .map(|j| {
                    let f = s.start + j;
                    speed_at(scene, k, j) < cfg.slow_speed
                        && scene.at_frame[f].iter().any(|&o| {
                            o != k && {
                                let os = &scene.segments[o];
                                let q = os.at(f).expect("present at its frame");
                                let p = s.pos[j];
                                (p[0] - q[0]).hypot(p[1] - q[1]) < cfg.near_distance
                                    && speed_at(scene, o, f - os.start) < cfg.slow_speed
                            }
                        })
                })
                .collect();
            keep_long_runs(&cand, min_frames)
        })
        .collect()
}

/// `flags` with every run of `true` shorter than `min` set to `false`.
fn keep_long_runs(flags: &[bool], min: usize) -> Vec<bool> {
    let mut out = vec![false; flags.len()];
    let mut j = 0;
    while j < flags.len() {
        if flags[j] {
            let a = j;
            while j < flags.len() && flags[j] {
                j += 1;
            }
            if j - a >= min {
                out[a..j].iter_mut().for_each(|v| *v = true);
            }
        } else {
            j += 1;
        }
    }
    out
}

/// Control parameters of the behaviour machine, measured from labelled data (§6.1).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FsmStats {
    /// Mean duration (s) of an uninterrupted stay in each behaviour.
    pub mean_duration: BTreeMap<String, f64>,
    /// Mean number of agents in an interacting group (connected within `near_distance`).
    pub group_size: f64,
    /// Mean distance (units) between linked members of a group.
    pub interpersonal: f64,
    /// Interactions started per agent-second of locomotion.
    pub start_rate: f64,
    /// Fraction of agent-frames labelled interaction.
    pub interaction_fraction: f64,
}

impl Default for FsmStats {
    fn default() -> Self {
        FsmStats {
            mean_duration: BTreeMap::new(),
            group_size: 2.0,
            interpersonal: 1.0,
            start_rate: 0.0,
            interaction_fraction: 0.0,
        }
    }
}

/// Measures [`FsmStats`] over scenes and their labels.
pub fn measure(scenes: &[(&Scene, &[Vec<bool>])], cfg: &LabelConfig) -> FsmStats {
    let mut runs: BTreeMap<&str, (f64, usize)> = BTreeMap::new();
    let (mut starts, mut loco_time, mut inter_frames, mut frames) = (0usize, 0.0, 0usize, 0usize);
    let (mut groups, mut members, mut links, mut link_len) = (0usize, 0usize, 0usize, 0.0);
    for (scene, labels) in scenes {
        for l in labels.iter() {
            let mut j = 0;
            while j < l.len() {
                let a = j;
                while j < l.len() && l[j] == l[a] {
                    j += 1;
                }
                let name = if l[a] { INTERACTION } else { LOCOMOTION };
                let e = runs.entry(name).or_default();
                e.0 += (j - a) as f64 * scene.dt;
                e.1 += 1;
                if l[a] && a > 0 {
                    starts += 1;
                }
            }
            loco_time += l.iter().filter(|v| !**v).count() as f64 * scene.dt;
            inter_frames += l.iter().filter(|v| **v).count();
            frames += l.len();
        }
        for f in 0..scene.frames() {
            let pts: Vec<V2> = scene.at_frame[f]
                .iter()
                .filter(|&&k| labels[k][f - scene.segments[k].start])
                .map(|&k| scene.segments[k].at(f).expect("present"))
                .collect();
            for comp in components(&pts, cfg.near_distance) {
                groups += 1;
                members += comp.len();
            }
            for i in 0..pts.len() {
                for j in i + 1..pts.len() {
                    let d = (pts[i][0] - pts[j][0]).hypot(pts[i][1] - pts[j][1]);
                    if d < cfg.near_distance {
                        links += 1;
                        link_len += d;
                    }
                }
            }
        }
    }
    FsmStats {
        mean_duration: runs
            .into_iter()
            .map(|(k, (t, n))| (k.to_string(), t / n.max(1) as f64))
            .collect(),
        group_size: if groups > 0 {
            members as f64 / groups as f64
        } else {
            2.0
        },
        interpersonal: if links > 0 {
            link_len / links as f64
        } else {
            cfg.near_distance * 0.5
        },
        start_rate: if loco_time > 0.0 {
            starts as f64 / loco_time
        } else {
            0.0
        },
        interaction_fraction: inter_frames as f64 / frames.max(1) as f64,
    }
}

/// Connected components of points linked when nearer than `r` (each a list of indices, in
/// ascending order of their smallest member).
pub fn components(pts: &[V2], r: f64) -> Vec<Vec<usize>> {
    let mut comp = vec![usize::MAX; pts.len()];
    let mut out = Vec::new();
    for s in 0..pts.len() {
        if comp[s] != usize::MAX {
            continue;
        }
        let id = out.len();
        let mut stack = vec![s];
        comp[s] = id;
        let mut members = Vec::new();
        while let Some(i) = stack.pop() {
            members.push(i);
            for j in 0..pts.len() {
                if comp[j] == usize::MAX && (pts[i][0] - pts[j][0]).hypot(pts[i][1] - pts[j][1]) < r
                {
                    comp[j] = id;
                    stack.push(j);
                }
            }
        }
        members.sort_unstable();
        out.push(members);
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn short_runs_are_dropped() {
        let f = [true, true, false, true, true, true, false, true];
        assert_eq!(
            keep_long_runs(&f, 3),
            vec![false, false, false, true, true, true, false, false]
        );
    }

    #[test]
    fn components_link_chains() {
        let p = [[0.0, 0.0], [0.9, 0.0], [1.8, 0.0], [5.0, 5.0]];
        assert_eq!(components(&p, 1.0), vec![vec![0, 1, 2], vec![3]]);
    }
}
