//! The action model of §5: the k nearest samples of a query state (§5.1), k-means of their actions
//! into output possibilities, one cluster chosen by eq. 2, locally weighted linear regression
//! within it (eq. 3) and the attraction toward the nearest sample (§5.3).
//!
//! An action is the next step's velocity in the agent's frame, `(forward, left)` in units/s: its
//! length is the speed and its angle the turn (§4). Clustering and regression work on this vector
//! rather than on (speed, angle), which has no wrap-around at ±π.

pub use super::attract::{attract, attract_by, polar, AttractConfig, AttractScratch, Polar};
use super::features::{d2, V2};
pub use super::kmeans::kmeans;
use super::kmeans::kmeans_into;
use super::knn::StateTree;
pub use super::lwr::{lwr, lwr_by, LwrScratch};
use crate::error::{Error, Result};
use rand::Rng;
use serde::{Deserialize, Serialize};

/// How a cluster is picked among the output possibilities.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ClusterChoice {
    /// At random with eq. 2's probabilities p_i ∝ 1/‖m_i − m_prev‖ (the paper).
    Sample,
    /// The most probable cluster of eq. 2 (the one nearest m_prev): a deterministic predictor.
    Nearest,
}

/// What the action model outputs within the chosen cluster.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ActionOutput {
    #[default]
    /// Eq. 3's regression, kept within the cluster's spread and attracted toward the nearest
    /// sample (§5.2–5.3; the paper).
    Regression,
    /// The action of one of the cluster's samples, drawn with eq. 3's Gaussian weights
    /// exp(−d²/2h²) of its state distance: the output is always a step some real individual
    /// took in a state like this one, so the learnt crowd walks straight, stands still and turns
    /// as often as the real one did (a regression's average of many steps does none of these).
    Sample,
    /// The action of the cluster's nearest sample.
    Nearest,
}

/// Settings of the action model (§5, §7: k = 100, 3 clusters, bandwidth = 5th neighbour).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ActionConfig {
    /// Nearest samples per query.
    pub k: usize,
    /// k-means clusters of their actions.
    pub clusters: usize,
    /// The regression's Gaussian bandwidth is the distance to this neighbour (1-based)…
    pub bandwidth_neighbour: usize,
    /// …times this factor.
    pub bandwidth_scale: f64,
    /// Ridge penalty on the regression's slopes, relative to the mean weighted variance of the
    /// states (0: eq. 3 as written; a few effective samples in 8–12 dimensions make it unstable).
    pub ridge: f64,
    /// Half-width of the attraction's perturbation range in standard deviations of the cluster's
    /// speed and direction (§5.3); 0 turns attraction off.
    pub attraction: f64,
    /// Candidate outputs per axis (speed, direction) within that range.
    pub attraction_grid: usize,
    /// Outputs are kept within the chosen cluster's mean speed and direction ± this many of its
    /// standard deviations (§5.3: "to avoid excessive extrapolations").
    pub max_deviation: f64,
    pub choice: ClusterChoice,
    /// Lloyd iterations of k-means at most.
    pub kmeans_iterations: usize,
    /// Inertia λ ∈ [0, 1] of the step (a departure, ARCHITECTURE.md): the planned velocity is
    /// (1 − λ)·(the action in world coordinates) + λ·(the agent's last step / dt). 0 (the
    /// default, not written) is §5's action as it is; 1 is constant velocity.
    #[serde(skip_serializing_if = "super::features::is_zero")]
    pub inertia: f64,
    /// The output within the chosen cluster (default: eq. 3's regression).
    #[serde(skip_serializing_if = "is_regression")]
    pub output: ActionOutput,
    /// Continuation (a departure, ARCHITECTURE.md; motion matching's rule): with a sampled
    /// output, the sample that follows the agent's last one in its own real track is taken when
    /// it is among the query's `continuation` nearest samples and in the chosen cluster, so that
    /// an agent keeps walking one real track's steps (its jitter, its rhythm, its turns) while the
    /// situation stays like that track's. 0 (the default, not written): every step drawn afresh.
    #[serde(skip_serializing_if = "is_zero_usize")]
    pub continuation: usize,
}

fn is_zero_usize(v: &usize) -> bool {
    *v == 0
}

fn is_regression(o: &ActionOutput) -> bool {
    *o == ActionOutput::Regression
}

impl Default for ActionConfig {
    fn default() -> Self {
        ActionConfig {
            k: 100,
            clusters: 3,
            bandwidth_neighbour: 5,
            bandwidth_scale: 1.0,
            ridge: 0.0,
            attraction: 0.5,
            attraction_grid: 5,
            max_deviation: 2.0,
            choice: ClusterChoice::Sample,
            kmeans_iterations: 20,
            inertia: 0.0,
            output: ActionOutput::Regression,
            continuation: 0,
        }
    }
}

impl ActionConfig {
    /// Checks the values; errors name the key.
    pub fn check(&self) -> Result<()> {
        let bad = |k: &str, m: String| Err(Error::invalid(format!("action.{k} {m}")));
        if self.k == 0 {
            return bad("k", "must be ≥ 1".into());
        }
        if self.clusters == 0 || self.clusters > self.k {
            return bad("clusters", format!("= {} must be in 1..=k", self.clusters));
        }
        if self.bandwidth_neighbour == 0 || self.bandwidth_neighbour > self.k {
            return bad(
                "bandwidth_neighbour",
                format!("= {} must be in 1..=k", self.bandwidth_neighbour),
            );
        }
        if !(self.attraction.is_finite() && self.attraction >= 0.0) {
            return bad("attraction", format!("= {} must be ≥ 0", self.attraction));
        }
        // Standard deviations: beyond 100 the perturbation leaves any learnt range.
        crate::limits::within("action.attraction", self.attraction, 0.0, 100.0)?;
        crate::limits::within("action.bandwidth_scale", self.bandwidth_scale, 0.0, 1e6)?;
        if self.k > 100_000 {
            return bad("k", format!("= {} must be at most 100000", self.k));
        }
        if self.continuation > 100_000 {
            return bad(
                "continuation",
                format!("= {} must be at most 100000", self.continuation),
            );
        }
        if !(self.bandwidth_scale.is_finite() && self.bandwidth_scale > 0.0) {
            return bad(
                "bandwidth_scale",
                format!("= {} must be > 0", self.bandwidth_scale),
            );
        }
        if !(self.ridge.is_finite() && self.ridge >= 0.0) {
            return bad("ridge", format!("= {} must be ≥ 0", self.ridge));
        }
        if !(self.max_deviation.is_finite() && self.max_deviation >= 0.0) {
            return bad(
                "max_deviation",
                format!("= {} must be ≥ 0", self.max_deviation),
            );
        }
        if self.attraction_grid == 0 {
            return bad("attraction_grid", "must be ≥ 1".into());
        }
        if !(0.0..=1.0).contains(&self.inertia) {
            return bad("inertia", format!("= {} must be in [0, 1]", self.inertia));
        }
        if self.kmeans_iterations == 0 {
            return bad("kmeans_iterations", "must be ≥ 1".into());
        }
        Ok(())
    }
}

/// Samples of one behaviour: PCA states (row-major, `dims` columns) and their actions.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ActionSamples {
    pub dims: usize,
    pub states: Vec<f64>,
    pub actions: Vec<V2>,
    /// For each sample, the index of the sample one frame later in the same track ([`NO_NEXT`]
    /// where there is none); learnt only for [`ActionConfig::continuation`], otherwise empty
    /// (and not written).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub next: Vec<u32>,
}

/// [`ActionSamples::next`] of a sample whose track has no next sample.
pub const NO_NEXT: u32 = u32::MAX;

impl ActionSamples {
    pub fn len(&self) -> usize {
        self.actions.len()
    }
    pub fn is_empty(&self) -> bool {
        self.actions.is_empty()
    }
}

/// Samples and their kd-tree.
pub struct ActionModel {
    pub samples: ActionSamples,
    tree: StateTree,
    /// The samples' actions in the tree's order: a query reads the states and actions of its
    /// neighbours from memory the search has just touched.
    tree_actions: Vec<V2>,
    /// Each of those actions in polar form ([`polar`]), computed once rather than per query.
    tree_polar: Vec<Polar>,
    /// [`ActionSamples::next`] in the tree's order (positions, not sample indices); empty when
    /// the samples have none.
    tree_next: Vec<u32>,
    /// The instruction set the query's loops after the search are compiled for (chosen at run
    /// time, as the kd-tree's leaf distances are).
    arch: pulp::Arch,
}

/// Scratch buffers of one query (reused across queries of a thread: a query allocates nothing
/// once they have grown).
#[derive(Default)]
pub struct Scratch {
    nn: Vec<(f64, u32)>,
    acts: Vec<V2>,
    assign: Vec<usize>,
    members: Vec<usize>,
    centres: Vec<V2>,
    dmin: Vec<f64>,
    sums: Vec<[f64; 3]>,
    probs: Vec<f64>,
    lwr: LwrScratch,
    attract: AttractScratch,
}

/// The outcome of one query.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Decision {
    /// The action (local velocity, units/s).
    pub action: V2,
    /// The chosen cluster's mean action: m_prev of the next query (eq. 2).
    pub cluster_mean: V2,
    /// The tree position of the sample whose action was output ([`ActionOutput::Sample`],
    /// `Nearest`), for the next query's continuation; [`NO_NEXT`] for a regression.
    pub sample: u32,
}

impl ActionModel {
    /// Builds the kd-tree over `samples`.
    pub fn new(samples: ActionSamples) -> Result<ActionModel> {
        if samples.is_empty() {
            return Err(Error::invalid("an action model needs at least one sample"));
        }
        if samples.states.len() != samples.len() * samples.dims {
            return Err(Error::invalid(format!(
                "samples: {} state values for {} actions of {} dimensions",
                samples.states.len(),
                samples.len(),
                samples.dims
            )));
        }
        if samples
            .states
            .iter()
            .chain(samples.actions.iter().flatten())
            .any(|v| !v.is_finite())
        {
            return Err(Error::invalid("samples: values are not finite"));
        }
        let n = samples.len();
        if !samples.next.is_empty()
            && (samples.next.len() != n
                || samples
                    .next
                    .iter()
                    .any(|&j| j != NO_NEXT && j as usize >= n))
        {
            return Err(Error::invalid(format!(
                "samples: next must hold, per sample, the index of its track's next sample (< {n}) \
                 or {NO_NEXT} for none"
            )));
        }
        let tree = StateTree::build(&samples.states, samples.dims)?;
        let tree_actions: Vec<V2> = tree
            .order()
            .iter()
            .map(|&i| samples.actions[i as usize])
            .collect();
        let tree_polar = tree_actions.iter().map(|&a| polar(a)).collect();
        let tree_next = if samples.next.is_empty() {
            Vec::new()
        } else {
            let mut position = vec![0u32; n];
            for (pos, &i) in tree.order().iter().enumerate() {
                position[i as usize] = pos as u32;
            }
            tree.order()
                .iter()
                .map(|&i| match samples.next[i as usize] {
                    NO_NEXT => NO_NEXT,
                    j => position[j as usize],
                })
                .collect()
        };
        Ok(ActionModel {
            samples,
            tree,
            tree_actions,
            tree_polar,
            tree_next,
            arch: pulp::Arch::new(),
        })
    }

    /// The action for PCA state `s` given the previously chosen cluster's mean `m_prev`.
    pub fn decide(
        &self,
        s: &[f64],
        m_prev: V2,
        cfg: &ActionConfig,
        rng: &mut impl Rng,
        sc: &mut Scratch,
    ) -> Decision {
        self.decide_after(s, m_prev, NO_NEXT, cfg, rng, sc)
    }

    /// [`ActionModel::decide`] for an agent whose last output was the sample at tree position
    /// `last` ([`Decision::sample`]; [`NO_NEXT`]: none), for [`ActionConfig::continuation`].
    pub fn decide_after(
        &self,
        s: &[f64],
        m_prev: V2,
        last: u32,
        cfg: &ActionConfig,
        rng: &mut impl Rng,
        sc: &mut Scratch,
    ) -> Decision {
        let k = cfg.k.min(self.samples.len());
        self.tree.nearest_pos(s, k, &mut sc.nn);
        let follow = match self.tree_next.get(last as usize) {
            Some(&next) if cfg.continuation > 0 && cfg.output == ActionOutput::Sample => next,
            _ => NO_NEXT,
        };
        // The rest inlined into one function compiled for the CPU's widest instruction set
        // (AVX2 where there is one): wider lanes for the same operations in the same order
        // (no fused multiply-adds are formed), so the same bits as the baseline build.
        self.arch
            .dispatch(|| self.decide_among_neighbours(s, m_prev, follow, cfg, rng, sc))
    }

    /// [`ActionModel::decide`] once `sc.nn` holds the query's neighbours.
    #[inline(always)]
    fn decide_among_neighbours(
        &self,
        s: &[f64],
        m_prev: V2,
        follow: u32,
        cfg: &ActionConfig,
        rng: &mut impl Rng,
        sc: &mut Scratch,
    ) -> Decision {
        sc.acts.clear();
        sc.acts
            .extend(sc.nn.iter().map(|&(_, i)| self.tree_actions[i as usize]));
        kmeans_into(
            &sc.acts,
            cfg.clusters,
            cfg.kmeans_iterations,
            rng,
            &mut sc.assign,
            &mut sc.centres,
            &mut sc.dmin,
            &mut sc.sums,
        );
        cluster_probabilities_into(&sc.centres, m_prev, &mut sc.probs);
        let probs = &sc.probs;
        let c = match cfg.choice {
            ClusterChoice::Nearest => argmax(probs),
            ClusterChoice::Sample => {
                let u: f64 = rng.gen();
                let mut acc = 0.0;
                probs
                    .iter()
                    .position(|p| {
                        acc += p;
                        u < acc
                    })
                    .unwrap_or(probs.len() - 1)
            }
        };
        sc.members.clear();
        sc.members
            .extend((0..sc.nn.len()).filter(|&j| sc.assign[j] == c));
        let h2 = bandwidth2(&sc.nn, cfg.bandwidth_neighbour) * cfg.bandwidth_scale.powi(2);
        if cfg.output != ActionOutput::Regression {
            // Continuation: the next step of the agent's last sample's track, when it is among
            // the nearest `continuation` samples and in the chosen cluster.
            // (No tree position is NO_NEXT, so an agent without a last sample never matches.)
            let near = cfg.continuation.min(sc.nn.len());
            let (action, j) = match sc.nn[..near].iter().position(|n| n.1 == follow) {
                Some(j) if sc.assign[j] == c => (sc.acts[j], j),
                _ => pick_sample(&sc.nn, &sc.acts, &sc.members, h2, cfg.output, rng),
            };
            return Decision {
                action,
                cluster_mean: sc.centres[c],
                sample: sc.nn.get(j).map_or(NO_NEXT, |n| n.1),
            };
        }
        let (nn, acts, members) = (&sc.nn, &sc.acts, &sc.members);
        let (points, dims) = (self.tree.points(), self.samples.dims);
        let row = |r: usize| {
            let j = members[r];
            let (d2, i) = nn[j];
            let i = i as usize;
            (&points[i * dims..(i + 1) * dims], acts[j], d2)
        };
        let lwr_out = lwr_by(s, members.len(), row, h2, cfg.ridge, &mut sc.lwr);
        let tree_polar = &self.tree_polar;
        let action = attract_by(
            lwr_out,
            members.len(),
            |r| {
                let (_, a, d2) = row(r);
                (a, d2)
            },
            |r| tree_polar[nn[members[r]].1 as usize],
            h2,
            &AttractConfig {
                c: cfg.attraction,
                grid: cfg.attraction_grid,
                limit: cfg.max_deviation,
            },
            &mut sc.attract,
        );
        Decision {
            action,
            cluster_mean: sc.centres[c],
            sample: NO_NEXT,
        }
    }
}

/// The action of one member of the chosen cluster ([`ActionOutput::Sample`], `Nearest`):
/// `nn` holds (squared state distance, index) nearest first, `acts` their actions.
fn pick_sample(
    nn: &[(f64, u32)],
    acts: &[V2],
    members: &[usize],
    h2: f64,
    output: ActionOutput,
    rng: &mut impl Rng,
) -> (V2, usize) {
    let Some(&first) = members.first() else {
        return ([0.0, 0.0], 0);
    };
    if output == ActionOutput::Nearest {
        return (acts[first], first);
    }
    let h2 = if h2.is_finite() && h2 > 0.0 { h2 } else { 1.0 };
    // Weights relative to the nearest member's, so the nearest always weighs 1.
    let d0 = nn[first].0;
    let w = |j: usize| (-(nn[j].0 - d0) / (2.0 * h2)).exp();
    let total: f64 = members.iter().map(|&j| w(j)).sum();
    let mut u = rng.gen::<f64>() * total;
    for &j in members {
        u -= w(j);
        if u < 0.0 {
            return (acts[j], j);
        }
    }
    let j = *members.last().expect("members");
    (acts[j], j)
}

#[inline(always)]
fn argmax(p: &[f64]) -> usize {
    let mut best = 0;
    for (i, v) in p.iter().enumerate() {
        if *v > p[best] {
            best = i;
        }
    }
    best
}

/// Squared bandwidth: the squared distance to the `nth` neighbour (1-based), or the largest
/// positive one before it when that is zero; 1 when every neighbour coincides with the query.
#[inline(always)]
fn bandwidth2(nn: &[(f64, u32)], nth: usize) -> f64 {
    let i = nth.min(nn.len()).saturating_sub(1);
    if let Some(&(d, _)) = nn.get(i) {
        if d > 0.0 {
            return d;
        }
    }
    nn.iter().map(|n| n.0).find(|&d| d > 0.0).unwrap_or(1.0)
}

/// Eq. 2: p_i = (1/‖m_i − m_prev‖) / Σ_j 1/‖m_j − m_prev‖. A cluster whose mean is m_prev gets
/// probability 1 (shared when several do).
pub fn cluster_probabilities(means: &[V2], m_prev: V2) -> Vec<f64> {
    let mut p = Vec::with_capacity(means.len());
    cluster_probabilities_into(means, m_prev, &mut p);
    p
}

/// [`cluster_probabilities`] into `p`.
#[inline(always)]
fn cluster_probabilities_into(means: &[V2], m_prev: V2, p: &mut Vec<f64>) {
    p.clear();
    p.extend(means.iter().map(|m| d2(*m, m_prev).sqrt()));
    let zero = p.iter().filter(|&&d| d <= 1e-12).count();
    if zero > 0 {
        p.iter_mut()
            .for_each(|d| *d = if *d <= 1e-12 { 1.0 / zero as f64 } else { 0.0 });
        return;
    }
    p.iter_mut().for_each(|d| *d = 1.0 / *d);
    let s: f64 = p.iter().sum();
    p.iter_mut().for_each(|v| *v /= s);
}
