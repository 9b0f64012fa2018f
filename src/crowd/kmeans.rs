//! k-means of the k nearest samples' actions into output possibilities (§5.1): a deterministic
//! Lloyd iteration on 2-D points with k-means++ seeding from the agent's own generator
//! (cross-checked against linfa-clustering in `tests/crowd.rs`).

use super::features::{d2, V2};
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
#[inline(always)]
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
    let (cs, assign) = (&mut centres[..], &mut assign[..]);
    match cs.len() {
        1 => lloyd_n::<1>(pts, cs, assign, iters),
        2 => lloyd_n::<2>(pts, cs, assign, iters),
        3 => lloyd_n::<3>(pts, cs, assign, iters),
        4 => lloyd_n::<4>(pts, cs, assign, iters),
        _ => {
            sum.clear();
            sum.resize(cs.len(), [0.0, 0.0, 0.0]);
            for it in 0..iters {
                let changed = assign_nearest(pts, cs, assign) || it == 0;
                if !changed {
                    break;
                }
                cluster_sums(assign, pts, sum);
                update_means(cs, sum);
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

/// A mean moves to its cluster's centroid; an empty cluster's stays.
#[inline(always)]
fn update_means(cs: &mut [V2], sum: &[[f64; 3]]) {
    for (m, s) in cs.iter_mut().zip(sum) {
        if s[2] > 0.0 {
            *m = [s[0] / s[2], s[1] / s[2]];
        }
    }
}

/// Lloyd's iteration for exactly `N` centres (up to four), the centres and every sum held in
/// registers; the same passes, comparisons and sums, in the same order, as the general loop.
#[inline(always)]
fn lloyd_n<const N: usize>(pts: &[V2], cs: &mut [V2], assign: &mut [usize], iters: usize) {
    let mut m = [[0.0f64; 2]; N];
    m.copy_from_slice(cs);
    for it in 0..iters {
        let changed = assign_nearest_n(pts, &m, assign) || it == 0;
        if !changed {
            break;
        }
        let sum = cluster_sums_n::<N>(assign, pts);
        update_means(&mut m, &sum);
    }
    cs.copy_from_slice(&m);
}

/// Assigns each point to its nearest of `N` centres (the first of equally near ones), each
/// choice made without branches; whether any assignment changed.
#[inline(always)]
fn assign_nearest_n<const N: usize>(pts: &[V2], m: &[V2; N], assign: &mut [usize]) -> bool {
    let mut changed = false;
    for (a, p) in assign.iter_mut().zip(pts) {
        let mut best = 0;
        let mut best_d = d2(*p, m[0]);
        for (c, mc) in m.iter().enumerate().skip(1) {
            let dc = d2(*p, *mc);
            let nearer = dc < best_d;
            best = if nearer { c } else { best };
            best_d = if nearer { dc } else { best_d };
        }
        changed |= *a != best;
        *a = best;
    }
    changed
}

/// Each of `N` clusters' sums (x, y, count) of its points, added in the points' order, in one
/// pass with every sum in a register: each point adds its coordinates to its own cluster's sums
/// and 0 to the others' (a sum starts at +0 and so never becomes −0, and x + 0 = x for every
/// other x, so the sums are those of the points alone). No chain of loads and stores through
/// one accumulator in memory.
#[inline(always)]
fn cluster_sums_n<const N: usize>(assign: &[usize], pts: &[V2]) -> [[f64; 3]; N] {
    let mut t = [[0.0f64; 3]; N];
    for (&a, p) in assign.iter().zip(pts) {
        for (c, tc) in t.iter_mut().enumerate() {
            let m = a == c;
            tc[0] += if m { p[0] } else { 0.0 };
            tc[1] += if m { p[1] } else { 0.0 };
            tc[2] += if m { 1.0 } else { 0.0 };
        }
    }
    t
}

/// Assigns each point to its nearest centre (the first of equally near ones); whether any
/// assignment changed. Any number of centres (more than four: see [`lloyd_n`] for fewer).
#[inline(always)]
fn assign_nearest(pts: &[V2], cs: &[V2], assign: &mut [usize]) -> bool {
    let mut changed = false;
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
    changed
}

/// Each cluster's sums (x, y, count) of its points, added in the points' order (any number
/// of clusters).
#[inline(always)]
fn cluster_sums(assign: &[usize], pts: &[V2], sum: &mut [[f64; 3]]) {
    for (c, s) in sum.iter_mut().enumerate() {
        let mut t = [0.0, 0.0, 0.0];
        for (_, p) in assign.iter().zip(pts).filter(|(a, _)| **a == c) {
            t[0] += p[0];
            t[1] += p[1];
            t[2] += 1.0;
        }
        *s = t;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// The general loop (any number of centres), as the specialised ones must reproduce it.
    fn general(pts: &[V2], cs: &mut [V2], assign: &mut [usize], iters: usize) {
        let mut sum = vec![[0.0; 3]; cs.len()];
        for it in 0..iters {
            if !(assign_nearest(pts, cs, assign) || it == 0) {
                break;
            }
            cluster_sums(assign, pts, &mut sum);
            update_means(cs, &sum);
        }
    }

    #[test]
    fn specialised_lloyd_equals_the_general_loop_bit_for_bit() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for n in 1..=4 {
            for trial in 0..50 {
                let pts: Vec<V2> = (0..60 + trial)
                    .map(|_| [rng.gen_range(-2.0..2.0), rng.gen_range(-1.0..3.0)])
                    .collect();
                let start: Vec<V2> = pts[..n].to_vec();
                let iters = 1 + trial % 20;
                let (mut a, mut b) = (start.clone(), start);
                let (mut aa, mut ab) = (vec![0; pts.len()], vec![0; pts.len()]);
                general(&pts, &mut a, &mut aa, iters);
                match n {
                    1 => lloyd_n::<1>(&pts, &mut b, &mut ab, iters),
                    2 => lloyd_n::<2>(&pts, &mut b, &mut ab, iters),
                    3 => lloyd_n::<3>(&pts, &mut b, &mut ab, iters),
                    _ => lloyd_n::<4>(&pts, &mut b, &mut ab, iters),
                }
                assert_eq!(aa, ab, "{n} centres, trial {trial}");
                let bits = |v: &[V2]| v.iter().flatten().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(&a), bits(&b), "{n} centres, trial {trial}");
            }
        }
    }
}
