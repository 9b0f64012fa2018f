//! The action model of §5: the k nearest samples of a query state (§5.1), k-means of their actions
//! into output possibilities, one cluster chosen by eq. 2, locally weighted linear regression
//! within it (eq. 3) and the attraction toward the nearest sample (§5.3).
//!
//! An action is the next step's velocity in the agent's frame, `(forward, left)` in units/s: its
//! length is the speed and its angle the turn (§4). Clustering and regression work on this vector
//! rather than on (speed, angle), which has no wrap-around at ±π.

use super::features::V2;
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
}

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
        let tree = StateTree::build(&samples.states, samples.dims)?;
        let tree_actions: Vec<V2> = tree
            .order()
            .iter()
            .map(|&i| samples.actions[i as usize])
            .collect();
        let tree_polar = tree_actions.iter().map(|&a| polar(a)).collect();
        Ok(ActionModel {
            samples,
            tree,
            tree_actions,
            tree_polar,
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
        let k = cfg.k.min(self.samples.len());
        self.tree.nearest_pos(s, k, &mut sc.nn);
        // The rest inlined into one function compiled for the CPU's widest instruction set
        // (AVX2 where there is one): wider lanes for the same operations in the same order
        // (no fused multiply-adds are formed), so the same bits as the baseline build.
        self.arch
            .dispatch(|| self.decide_among_neighbours(s, m_prev, cfg, rng, sc))
    }

    /// [`ActionModel::decide`] once `sc.nn` holds the query's neighbours.
    #[inline(always)]
    fn decide_among_neighbours(
        &self,
        s: &[f64],
        m_prev: V2,
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
        }
    }
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

/// Squared distance of two 2-D points.
pub(super) fn d2(a: V2, b: V2) -> f64 {
    (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2)
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

/// Settings of [`attract`]: half-width `c` of the perturbation range and the output limit
/// `limit`, both in standard deviations, and `grid` candidates per axis.
pub struct AttractConfig {
    pub c: f64,
    pub grid: usize,
    pub limit: f64,
}

/// §5.3 attraction: the regression output is first kept within the cluster's mean speed and
/// direction ± `limit` standard deviations; then candidates on a regular `grid × grid` lattice of
/// speed and direction within ±`c` standard deviations of it (and within that range) compete, and
/// the one nearest to a sample of the cluster in the joint (state, action) space wins, state
/// distances scaled by the bandwidth and action distances by the cluster's action spread.
pub fn attract(
    out: V2,
    rows: &[(&[f64], V2, f64)],
    h2: f64,
    c: f64,
    grid: usize,
    limit: f64,
) -> V2 {
    attract_by(
        out,
        rows.len(),
        |r| (rows[r].1, rows[r].2),
        |r| polar(rows[r].1),
        h2,
        &AttractConfig { c, grid, limit },
        &mut AttractScratch::default(),
    )
}

/// An action `a` in polar form: speed `|a|`, direction `atan2`, and the direction's cosine and
/// sine (as `f64::cos`/`f64::sin` of that angle, not `a / |a|`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Polar {
    pub speed: f64,
    pub angle: f64,
    pub cos: f64,
    pub sin: f64,
}

/// [`Polar`] of `a`.
pub fn polar(a: V2) -> Polar {
    let angle = a[1].atan2(a[0]);
    Polar {
        speed: a[0].hypot(a[1]),
        angle,
        cos: angle.cos(),
        sin: angle.sin(),
    }
}

/// Reusable buffers of [`attract_by`]: the rows in polar form, and each row's state term and
/// action in columns for the candidates' scores.
#[derive(Default)]
pub struct AttractScratch {
    polar: Vec<Polar>,
    e: Vec<f64>,
    ax: Vec<f64>,
    ay: Vec<f64>,
}

/// [`attract`] over `n` rows given by `row(r) = (action, squared state distance)` and
/// `polar_of(r)`, the row's action in polar form, with reusable buffers.
#[inline(always)]
pub fn attract_by(
    out: V2,
    n: usize,
    row: impl Fn(usize) -> (V2, f64),
    polar_of: impl Fn(usize) -> Polar,
    h2: f64,
    cfg: &AttractConfig,
    sc: &mut AttractScratch,
) -> V2 {
    let (c, grid, limit) = (cfg.c, cfg.grid, cfg.limit);
    if n < 2 {
        return if n == 1 { row(0).0 } else { out };
    }
    let polar = &mut sc.polar;
    polar.clear();
    polar.extend((0..n).map(polar_of));
    let nf = n as f64;
    let mean_v = polar.iter().map(|p| p.speed).sum::<f64>() / nf;
    let sd_v = (polar
        .iter()
        .map(|p| (p.speed - mean_v).powi(2))
        .sum::<f64>()
        / nf)
        .sqrt();
    // Circular spread of the directions about their mean.
    let (cs, sn) = polar
        .iter()
        .fold((0.0, 0.0), |(c, s), p| (c + p.cos, s + p.sin));
    let mean_a = sn.atan2(cs);
    let sd_a = (polar
        .iter()
        .map(|p| wrap(p.angle - mean_a).powi(2))
        .sum::<f64>()
        / nf)
        .sqrt();
    let (lo_v, hi_v) = ((mean_v - limit * sd_v).max(0.0), mean_v + limit * sd_v);
    let clamp_a = |a: f64| mean_a + wrap(a - mean_a).clamp(-limit * sd_a, limit * sd_a);
    let v0 = out[0].hypot(out[1]).clamp(lo_v, hi_v);
    let a0 = clamp_a(out[1].atan2(out[0]));
    let out = [v0 * a0.cos(), v0 * a0.sin()];
    if c <= 0.0 {
        return out;
    }
    let h2 = if h2.is_finite() && h2 > 0.0 { h2 } else { 1.0 };
    // Each row's state term and action, in columns.
    let (es, ax, ay) = (&mut sc.e, &mut sc.ax, &mut sc.ay);
    es.clear();
    ax.clear();
    ay.clear();
    let mut sorted = true;
    let mut last = f64::NEG_INFINITY;
    for r in 0..n {
        let (a, dist2) = row(r);
        sorted &= last <= dist2;
        last = dist2;
        es.push(dist2 / h2);
        ax.push(a[0]);
        ay.push(a[1]);
    }
    let (es, ax, ay) = (&es[..n], &ax[..n], &ay[..n]);
    let mean_act = (0..n).fold([0.0, 0.0], |m, r| [m[0] + ax[r] / nf, m[1] + ay[r] / nf]);
    let var_a = (0..n).map(|r| d2([ax[r], ay[r]], mean_act)).sum::<f64>() / nf + 1e-12;
    // A candidate's score: the least over the rows of state term + action term.
    let part = |cand: V2, r: usize| es[r] + d2(cand, [ax[r], ay[r]]) / var_a;
    // Rows come nearest first from the k-nearest query: once a row's state term alone reaches
    // min(best so far, bound), no later row can bring the score below that. Rows are scored
    // four at a time; the few scored past that point are each ≥ it, so they leave a score
    // below `bound` as it was, and one at or above `bound` stays there: the caller, which
    // keeps only scores below `bound`, decides as with a row-by-row exit.
    let score = |cand: V2, bound: f64| {
        let mut best = f64::INFINITY;
        if !sorted {
            return (0..n).fold(best, |b, r| b.min(part(cand, r)));
        }
        let mut r = 0;
        while r < n && es[r] < best.min(bound) {
            let end = (r + 4).min(n);
            best = (r..end).fold(best, |b, j| b.min(part(cand, j)));
            r = end;
        }
        best
    };
    let mut best = (score(out, f64::INFINITY), out);
    let steps = grid.max(1);
    for iv in 0..steps {
        for ia in 0..steps {
            let t = |i: usize| {
                if steps == 1 {
                    0.0
                } else {
                    2.0 * i as f64 / (steps - 1) as f64 - 1.0
                }
            };
            let v = (v0 + c * sd_v * t(iv)).clamp(lo_v, hi_v);
            let a = clamp_a(a0 + c * sd_a * t(ia));
            let cand = [v * a.cos(), v * a.sin()];
            let sc = score(cand, best.0);
            if sc < best.0 {
                best = (sc, cand);
            }
        }
    }
    best.1
}

/// `a` wrapped into [−π, π): `(a + π).rem_euclid(2π) − π`, bit for bit. On the range that
/// angle differences take, without `fmod`: there the exact remainder is `x`, `x − 2π` (exact
/// by Sterbenz's lemma) or, below zero, `x + 2π` as `rem_euclid` rounds it.
#[inline(always)]
fn wrap(a: f64) -> f64 {
    use std::f64::consts::{PI, TAU};
    let x = a + PI;
    let r = if (0.0..TAU).contains(&x) {
        x
    } else if (TAU..2.0 * TAU).contains(&x) {
        x - TAU
    } else if x < 0.0 && x > -TAU {
        x + TAU
    } else {
        x.rem_euclid(TAU)
    };
    r - PI
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use std::f64::consts::{PI, TAU};

    /// §5.3's attraction as first written: polar forms per call, rows scored one at a time.
    fn attract_reference(
        out: V2,
        rows: &[(V2, f64)],
        h2: f64,
        c: f64,
        grid: usize,
        limit: f64,
    ) -> V2 {
        let n = rows.len();
        if n < 2 {
            return if n == 1 { rows[0].0 } else { out };
        }
        let polar: Vec<(f64, f64)> = rows
            .iter()
            .map(|(a, _)| (a[0].hypot(a[1]), a[1].atan2(a[0])))
            .collect();
        let nf = n as f64;
        let mean_v = polar.iter().map(|p| p.0).sum::<f64>() / nf;
        let sd_v = (polar.iter().map(|p| (p.0 - mean_v).powi(2)).sum::<f64>() / nf).sqrt();
        let (cs, sn) = polar
            .iter()
            .fold((0.0, 0.0), |(c, s), p| (c + p.1.cos(), s + p.1.sin()));
        let mean_a = sn.atan2(cs);
        let slow_wrap = |a: f64| (a + PI).rem_euclid(TAU) - PI;
        let sd_a = (polar
            .iter()
            .map(|p| slow_wrap(p.1 - mean_a).powi(2))
            .sum::<f64>()
            / nf)
            .sqrt();
        let (lo_v, hi_v) = ((mean_v - limit * sd_v).max(0.0), mean_v + limit * sd_v);
        let clamp_a = |a: f64| mean_a + slow_wrap(a - mean_a).clamp(-limit * sd_a, limit * sd_a);
        let v0 = out[0].hypot(out[1]).clamp(lo_v, hi_v);
        let a0 = clamp_a(out[1].atan2(out[0]));
        let out = [v0 * a0.cos(), v0 * a0.sin()];
        if c <= 0.0 {
            return out;
        }
        let mean_act = rows
            .iter()
            .fold([0.0, 0.0], |m, (a, _)| [m[0] + a[0] / nf, m[1] + a[1] / nf]);
        let var_a = rows.iter().map(|(a, _)| d2(*a, mean_act)).sum::<f64>() / nf + 1e-12;
        let h2 = if h2.is_finite() && h2 > 0.0 { h2 } else { 1.0 };
        let sorted = (1..n).all(|r| rows[r - 1].1 <= rows[r].1);
        let score = |cand: V2, bound: f64| {
            let mut best = f64::INFINITY;
            for &(a, dist2) in rows {
                let e = dist2 / h2;
                if sorted && e >= best.min(bound) {
                    break;
                }
                best = best.min(e + d2(cand, a) / var_a);
            }
            best
        };
        let mut best = (score(out, f64::INFINITY), out);
        for iv in 0..grid {
            for ia in 0..grid {
                let t = |i: usize| {
                    if grid == 1 {
                        0.0
                    } else {
                        2.0 * i as f64 / (grid - 1) as f64 - 1.0
                    }
                };
                let v = (v0 + c * sd_v * t(iv)).clamp(lo_v, hi_v);
                let a = clamp_a(a0 + c * sd_a * t(ia));
                let cand = [v * a.cos(), v * a.sin()];
                let sc = score(cand, best.0);
                if sc < best.0 {
                    best = (sc, cand);
                }
            }
        }
        best.1
    }

    #[test]
    fn attraction_equals_the_row_by_row_reference_bit_for_bit() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
        for case in 0..3000 {
            let n = rng.gen_range(0..40);
            let mut rows: Vec<(V2, f64)> = (0..n)
                .map(|_| {
                    let (v, a): (f64, f64) = (rng.gen_range(0.0..2.0), rng.gen_range(-3.2..3.2));
                    ([v * a.cos(), v * a.sin()], rng.gen_range(0.0..4.0))
                })
                .collect();
            // Mostly sorted by distance, as the query gives them; some not, and some ties.
            if case % 5 != 0 {
                rows.sort_by(|x, y| x.1.total_cmp(&y.1));
            }
            if case % 7 == 0 && n > 3 {
                rows[2].1 = rows[1].1;
            }
            let out = [rng.gen_range(-1.0..2.0), rng.gen_range(-1.0..1.0)];
            let h2 = [0.5, 1.0, 3.0, f64::INFINITY][case % 4];
            let (c, grid, limit) = (
                [0.0, 0.5, 1.0][case % 3],
                1 + case % 6,
                [1.0, 2.0][case % 2],
            );
            let want = attract_reference(out, &rows, h2, c, grid, limit);
            let refs: Vec<(&[f64], V2, f64)> =
                rows.iter().map(|(a, d)| (&[][..], *a, *d)).collect();
            let got = attract(out, &refs, h2, c, grid, limit);
            assert_eq!(got.map(f64::to_bits), want.map(f64::to_bits), "case {case}");
        }
    }

    #[test]
    fn wrap_equals_rem_euclid_bit_for_bit() {
        let slow = |a: f64| (a + PI).rem_euclid(TAU) - PI;
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let mut xs: Vec<f64> = (0..200_000).map(|_| rng.gen_range(-15.0..15.0)).collect();
        for e in [-3.0, -2.0, -1.0, 0.0, 1.0, 2.0, 3.0] {
            let at = e * TAU - PI;
            xs.extend([at, at.next_up(), at.next_down(), e * PI, (e * PI).next_up()]);
        }
        xs.extend([
            0.0,
            -0.0,
            1e-300,
            -1e-300,
            1e9,
            -1e9,
            f64::MAX,
            f64::INFINITY,
        ]);
        for a in xs {
            assert_eq!(wrap(a).to_bits(), slow(a).to_bits(), "a = {a:e}");
        }
        assert!(wrap(f64::NAN).is_nan());
    }
}
