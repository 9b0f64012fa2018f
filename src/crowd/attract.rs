//! §5.3 attraction: the regression's output kept within the chosen cluster's spread, then
//! perturbed toward the nearest sample of the cluster in the joint (state, action) space.

use super::features::{d2, V2};

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
    let spread = [c * sd_v, c * sd_a];
    grid_best(
        out,
        grid.max(1),
        [v0, a0],
        spread,
        (lo_v, hi_v),
        clamp_a,
        score,
    )
}

/// §5.3's search: `start`, then the `steps` × `steps` candidates of speed v0 + spread₀·t
/// (clamped to `speeds`) and direction `clamp_a`(a0 + spread₁·t), t from −1 to 1, each scored by
/// `score(candidate, best score so far)`; the first candidate of least score.
#[inline(always)]
fn grid_best(
    start: V2,
    steps: usize,
    [v0, a0]: [f64; 2],
    spread: [f64; 2],
    (lo_v, hi_v): (f64, f64),
    clamp_a: impl Fn(f64) -> f64,
    score: impl Fn(V2, f64) -> f64,
) -> V2 {
    let mut best = (score(start, f64::INFINITY), start);
    for iv in 0..steps {
        for ia in 0..steps {
            let t = |i: usize| {
                if steps == 1 {
                    0.0
                } else {
                    2.0 * i as f64 / (steps - 1) as f64 - 1.0
                }
            };
            let v = (v0 + spread[0] * t(iv)).clamp(lo_v, hi_v);
            let a = clamp_a(a0 + spread[1] * t(ia));
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
    use rand::{Rng, SeedableRng};
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
        let spread = [c * sd_v, c * sd_a];
        grid_best(out, grid, [v0, a0], spread, (lo_v, hi_v), clamp_a, score)
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
