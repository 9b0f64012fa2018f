//! k-means of the k nearest samples' actions into output possibilities (§5.1): a deterministic
//! Lloyd iteration on 2-D points with k-means++ seeding from the agent's own generator
//! (cross-checked against linfa-clustering in `tests/crowd.rs`).

use super::action::d2;
use super::features::V2;
use rand::Rng;

/// k-means (Lloyd, k-means++ seeding from `rng`) of 2-D points into at most `k` clusters; fills
/// `assign` with each point's cluster and returns the means. Clusters left empty are dropped.
pub fn kmeans(
    pts: &[V2],
    k: usize,
    iters: usize,
    rng: &mut impl Rng,
    assign: &mut Vec<usize>,
) -> Vec<V2> {
    let mut centres = Vec::new();
    kmeans_into(
        pts,
        k,
        iters,
        rng,
        assign,
        &mut centres,
        &mut Vec::new(),
        &mut Vec::new(),
    );
    centres
}

/// [`kmeans`] with the means written to `centres` and the buffers `dmin`, `sum` reused.
#[allow(clippy::too_many_arguments)]
pub(super) fn kmeans_into(
    pts: &[V2],
    k: usize,
    iters: usize,
    rng: &mut impl Rng,
    assign: &mut Vec<usize>,
    centres: &mut Vec<V2>,
    dmin: &mut Vec<f64>,
    sum: &mut Vec<[f64; 3]>,
) {
    assign.clear();
    assign.resize(pts.len(), 0);
    centres.clear();
    if pts.is_empty() {
        centres.push([0.0, 0.0]);
        return;
    }
    centres.push(pts[rng.gen_range(0..pts.len())]);
    dmin.clear();
    dmin.extend(pts.iter().map(|p| d2(*p, centres[0])));
    while centres.len() < k {
        let total: f64 = dmin.iter().sum();
        if total <= 0.0 {
            break;
        }
        let u = rng.gen::<f64>() * total;
        let mut acc = 0.0;
        let j = dmin
            .iter()
            .position(|d| {
                acc += d;
                u < acc
            })
            .unwrap_or(pts.len() - 1);
        centres.push(pts[j]);
        for (d, p) in dmin.iter_mut().zip(pts) {
            *d = d.min(d2(*p, pts[j]));
        }
    }
    sum.clear();
    sum.resize(centres.len(), [0.0, 0.0, 0.0]);
    let (cs, sum, assign) = (&mut centres[..], &mut sum[..], &mut assign[..]);
    for it in 0..iters {
        let mut changed = it == 0;
        for (a, p) in assign.iter_mut().zip(pts) {
            let mut best = 0;
            let mut best_d = d2(*p, cs[0]);
            for (c, m) in cs.iter().enumerate().skip(1) {
                let dc = d2(*p, *m);
                if dc < best_d {
                    best = c;
                    best_d = dc;
                }
            }
            changed |= *a != best;
            *a = best;
        }
        if !changed {
            break;
        }
        // Per cluster, a masked sum over all points: no chain of loads and stores through
        // one accumulator in memory, and the points are still added in their order.
        for (c, s) in sum.iter_mut().enumerate() {
            let mut t = [0.0, 0.0, 0.0];
            for (a, p) in assign.iter().zip(pts) {
                let m = f64::from(u8::from(*a == c));
                t[0] += m * p[0];
                t[1] += m * p[1];
                t[2] += m;
            }
            *s = t;
        }
        for (m, s) in cs.iter_mut().zip(sum.iter()) {
            if s[2] > 0.0 {
                *m = [s[0] / s[2], s[1] / s[2]];
            }
        }
    }
    // Drop empty clusters, renumbering the assignment (at most a handful of clusters).
    let mut kept = 0;
    for c in 0..centres.len() {
        if !assign.contains(&c) {
            continue;
        }
        if kept != c {
            centres.swap(kept, c);
            assign
                .iter_mut()
                .filter(|a| **a == c)
                .for_each(|a| *a = kept);
        }
        kept += 1;
    }
    centres.truncate(kept);
}
