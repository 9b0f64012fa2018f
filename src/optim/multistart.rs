//! Multi-start global search (issue #15 item 3): K starting points — the caller's own, then a
//! Latin hypercube over the parameter box — each refined by the caller's local method, then the
//! refined points ranked by a score the caller computes on data the refinement did not use.
//!
//! Why multi-start rather than a population method such as CMA-ES: the herd fit's objective is a
//! noisy 12-parameter function whose one evaluation (an epoch of unrolled steps) costs about as
//! much as a gradient, and CMA-ES needs a population of ≈ 4 + 3 ln 12 ≈ 11 evaluations per
//! generation over tens of generations — far beyond the 5-minute budget of a 300-agent clip.
//! Gradient refinement from a handful of well-spread starts uses the gradients the fit already
//! computes, and the held-out choice keeps the selection honest. Model-agnostic: the caller
//! supplies the refinement and the score.

use rand::seq::SliceRandom;
use rand::Rng;

/// One candidate of a multi-start search: where it started, where its refinement ended, and its
/// held-out score (lower is better).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Candidate {
    pub start: Vec<f64>,
    pub end: Vec<f64>,
    pub score: f64,
}

/// `n` points of a Latin hypercube in `[lo, hi]^dim`: each coordinate's range cut into `n`
/// equal strata, every stratum used once per coordinate, the point uniform inside its stratum.
pub fn latin_hypercube(
    n: usize,
    dim: usize,
    lo: f64,
    hi: f64,
    rng: &mut impl Rng,
) -> Vec<Vec<f64>> {
    let mut pts = vec![vec![0.0; dim]; n];
    for d in 0..dim {
        let mut strata: Vec<usize> = (0..n).collect();
        strata.shuffle(rng);
        for (p, s) in pts.iter_mut().zip(strata) {
            let u: f64 = rng.gen();
            p[d] = lo + (hi - lo) * (s as f64 + u) / n as f64;
        }
    }
    pts
}

/// The multi-start search: refines every start with `refine(k, start)` (returning the end point
/// and whatever else the caller keeps, `R`), scores every end with `score(k, &end)`, and returns
/// the candidates in start order with the index of the best (lowest score; the earliest of
/// equals, so a tie keeps the caller's own start). A score that is not finite ranks last.
pub fn multistart<R, E>(
    starts: &[Vec<f64>],
    mut refine: impl FnMut(usize, &[f64]) -> Result<(Vec<f64>, R), E>,
    mut score: impl FnMut(usize, &[f64]) -> Result<f64, E>,
) -> Result<(usize, Vec<Candidate>, Vec<R>), E> {
    let mut cands = Vec::with_capacity(starts.len());
    let mut kept = Vec::with_capacity(starts.len());
    for (k, s) in starts.iter().enumerate() {
        let (end, r) = refine(k, s)?;
        let sc = score(k, &end)?;
        cands.push(Candidate {
            start: s.clone(),
            end,
            score: sc,
        });
        kept.push(r);
    }
    let key = |c: &Candidate| {
        if c.score.is_finite() {
            c.score
        } else {
            f64::INFINITY
        }
    };
    let mut best = 0;
    for (k, c) in cands.iter().enumerate() {
        if key(c) < key(&cands[best]) {
            best = k;
        }
    }
    Ok((best, cands, kept))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::optim::{step, OptState, Optimizer};
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Two basins on [0, 1]: a shallow one at x = 0.2 (value 0.5) and a deep one at x = 0.8
    /// (value 0), the barrier between them at x ≈ 0.45.
    fn two_wells(x: f64) -> f64 {
        let a = 0.5 + 40.0 * (x - 0.2).powi(2);
        let b = 30.0 * (x - 0.8).powi(2);
        a.min(b)
    }

    fn grad(x: f64) -> f64 {
        let h = 1e-6;
        (two_wells(x + h) - two_wells(x - h)) / (2.0 * h)
    }

    fn descend(x0: f64) -> f64 {
        let (mut th, mut st) = (vec![x0], OptState::new(1));
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        for _ in 0..400 {
            let g = [grad(th[0])];
            step(Optimizer::Adam, &mut th, &g, &mut st, 0.01, 0.0, &mut rng);
            th[0] = th[0].clamp(0.0, 1.0);
        }
        th[0]
    }

    #[test]
    fn plain_descent_stays_in_the_shallow_basin_and_the_multistart_finds_the_deep_one() {
        let start = 0.1;
        let plain = descend(start);
        assert!((plain - 0.2).abs() < 0.02, "plain descent ends at {plain}");
        let mut rng = ChaCha8Rng::seed_from_u64(5);
        let mut starts = vec![vec![start]];
        starts.extend(latin_hypercube(3, 1, 0.05, 0.95, &mut rng));
        let (best, cands, _) = multistart::<(), ()>(
            &starts,
            |_, s| Ok((vec![descend(s[0])], ())),
            |_, e| Ok(two_wells(e[0])),
        )
        .unwrap();
        assert_eq!(cands.len(), 4);
        assert_eq!(
            cands[0].end,
            vec![plain],
            "candidate 0 is the plain descent"
        );
        assert!((cands[best].end[0] - 0.8).abs() < 0.02, "{cands:?}");
        assert!(cands[best].score < 0.01 && cands[0].score > 0.49);
    }

    #[test]
    fn latin_hypercube_uses_every_stratum_once() {
        let mut rng = ChaCha8Rng::seed_from_u64(1);
        let p = latin_hypercube(5, 3, 0.0, 1.0, &mut rng);
        for d in 0..3 {
            let mut s: Vec<usize> = p.iter().map(|x| (x[d] * 5.0) as usize).collect();
            s.sort();
            assert_eq!(s, vec![0, 1, 2, 3, 4]);
        }
    }

    #[test]
    fn a_tie_keeps_the_first_start_and_nan_ranks_last() {
        let starts = vec![vec![0.0], vec![1.0], vec![2.0]];
        let scores = [1.0, f64::NAN, 1.0];
        let (best, _, _) =
            multistart::<(), ()>(&starts, |_, s| Ok((s.to_vec(), ())), |k, _| Ok(scores[k]))
                .unwrap();
        assert_eq!(best, 0);
    }
}
