//! The spacing term of a track fit (issue #49): how far each rolled-out animal is from its
//! nearest neighbour, as a distribution, against the tracks'.
//!
//! The position and heading error of [`super::rollout::window_loss`] score each animal on its
//! own path; a set that switches the interactions off (radial widths of eq. 3–5 near 0) walks
//! every animal straight and can score well there while its free runs lose the tracked spacing.
//! The spacing term compares, at each step, the nearest-neighbour distances of the scored animals
//! as simulated with those of the same animals as tracked, as two samples: the squared 1-D
//! Wasserstein-2 distance, Σ_k (d_(k) − r_(k))² over the sorted values (the optimal coupling of
//! two equal-size samples on a line pairs them in order). Which neighbour is nearest and the
//! sorting order are decided without gradient; the gradient reaches θ through the distances.
//!
//! Neighbours: in a free rollout the other scored animals (simulated for d, tracked for r); in a
//! neighbour-conditioned rollout the tracked scene of the step's frame, each animal's own twin
//! left out (the same constants for d and r).

use crate::error::Result;
use crate::herd::sim::read_vec;
use burn::tensor::{Int, Tensor, TensorData};
use herdfit_kernels::P2;

/// Guard (BL²) under the square root of a distance, so that two animals at one point have a
/// finite gradient.
const DIST_EPS: f64 = 1e-9;

/// Where the neighbours of a scored animal are.
pub enum Neighbours<'a> {
    /// The other scored animals (a free rollout).
    Scored,
    /// A tracked scene (positions, ids) and the scored animals' ids (a conditioned rollout).
    Scene {
        pos: &'a [P2],
        ids: &'a [u64],
        own: &'a [u64],
    },
}

fn dist(a: P2, b: P2) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// The nearest of `cands` (index, distance) to `p`, skipping `skip`.
fn nearest(
    p: P2,
    cands: impl Iterator<Item = (usize, P2)>,
    skip: impl Fn(usize) -> bool,
) -> Option<(usize, f64)> {
    cands
        .filter(|&(j, _)| !skip(j))
        .map(|(j, q)| (j, dist(p, q)))
        .min_by(|a, b| a.1.total_cmp(&b.1))
}

/// Σ_k (d_(k) − r_(k))² over the sorted nearest-neighbour distances of the scored animals (those
/// with a tracked position in `tracked`), simulated at (`x`, `y`) and tracked, and how many were
/// compared; `None` where fewer than two animals (free) or no scene neighbour (conditioned).
pub fn spacing_sq(
    x: &Tensor<1>,
    y: &Tensor<1>,
    tracked: &[Option<P2>],
    around: &Neighbours<'_>,
) -> Result<Option<(Tensor<1>, usize)>> {
    let (xs, ys) = (read_vec(x)?, read_vec(y)?);
    let scored: Vec<usize> = (0..tracked.len())
        .filter(|&i| tracked[i].is_some())
        .collect();
    let sim = |i: usize| [xs[i], ys[i]];
    let real = |i: usize| tracked[i].unwrap_or([0.0, 0.0]);
    // Per scored animal: the simulated neighbour (a scored row, or a scene point) and the
    // tracked nearest distance.
    let mut pairs: Vec<(usize, Result<usize, P2>, f64)> = Vec::new();
    for &i in &scored {
        let found = match around {
            Neighbours::Scored => {
                let others = || scored.iter().copied();
                let s = nearest(sim(i), others().map(|j| (j, sim(j))), |j| j == i);
                let r = nearest(real(i), others().map(|j| (j, real(j))), |j| j == i);
                s.zip(r).map(|((j, _), (_, r))| (Ok(j), r))
            }
            Neighbours::Scene { pos, ids, own } => {
                let me = own[i];
                let cands = || pos.iter().copied().enumerate();
                let s = nearest(sim(i), cands(), |j| ids[j] == me);
                let r = nearest(real(i), cands(), |j| ids[j] == me);
                s.zip(r).map(|((j, _), (_, r))| (Err(pos[j]), r))
            }
        };
        if let Some((j, r)) = found {
            pairs.push((i, j, r));
        }
    }
    if pairs.is_empty() {
        return Ok(None);
    }
    let device = x.device();
    let n = pairs.len();
    let ints = |v: Vec<i64>| Tensor::<1, Int>::from_data(TensorData::new(v, [n]), &device);
    let floats = |v: Vec<f64>| Tensor::<1>::from_data(TensorData::new(v, [n]), &device);
    let me = ints(pairs.iter().map(|p| p.0 as i64).collect());
    // The neighbour's coordinates: a simulated row (gathered) or a scene constant, one vector
    // each way; rows index into the state, constants take a placeholder row 0 masked out.
    let row: Vec<i64> = pairs
        .iter()
        .map(|p| *p.1.as_ref().unwrap_or(&0) as i64)
        .collect();
    let is_row: Vec<f64> = pairs.iter().map(|p| p.1.is_ok() as u8 as f64).collect();
    let fixed = |c: usize| -> Vec<f64> {
        pairs
            .iter()
            .map(|p| p.1.map_or_else(|q| q[c], |_| 0.0))
            .collect()
    };
    let (row, is_row) = (ints(row), floats(is_row));
    let other = |t: &Tensor<1>, c: usize| {
        t.clone().select(0, row.clone()) * is_row.clone() + floats(fixed(c))
    };
    let dx = x.clone().select(0, me.clone()) - other(x, 0);
    let dy = y.clone().select(0, me) - other(y, 1);
    let d = (dx.square() + dy.square()).add_scalar(DIST_EPS).sqrt();
    let dv = read_vec(&d.clone().detach())?;
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| dv[a].total_cmp(&dv[b]).then(a.cmp(&b)));
    let mut r: Vec<f64> = pairs.iter().map(|p| p.2).collect();
    r.sort_by(f64::total_cmp);
    let sorted = d.select(0, ints(order.iter().map(|&k| k as i64).collect()));
    Ok(Some(((sorted - floats(r)).square().sum(), n)))
}
