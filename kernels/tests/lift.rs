//! The whole-sequence lifting kernel: its gradient against central finite differences, and its
//! blocked parallel passes against one sequential pass and across thread counts.

use herdfit_kernels::lift::*;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

type Problem = (
    Vec<[f64; 3]>,
    Vec<(usize, usize)>,
    Vec<(usize, usize)>,
    Vec<f64>,
);

/// Three birds over five frames, the third leaving after frame 3; every term active.
fn problem() -> Problem {
    flock(5, 3, 7, |b, f| b == 2 && f > 3)
}

/// `birds` birds over `frames` frames, bird b absent where `gone(b, f)`; every same-frame pair a
/// neighbour pair; frame-major observations, as herdfit builds them.
fn flock(frames: usize, birds: usize, seed: u64, gone: impl Fn(usize, usize) -> bool) -> Problem {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut ray = Vec::new();
    let mut at = Vec::new();
    for f in 0..frames {
        for b in 0..birds {
            if gone(b, f) {
                continue;
            }
            ray.push([
                0.02 * b as f64 + 0.01 * f as f64 + rng.gen_range(-0.003..0.003),
                1.0,
                0.01 * b as f64 - 0.004 * f as f64,
            ]);
            at.push((f, b));
        }
    }
    let find = |f: usize, b: usize| at.iter().position(|&x| x == (f, b));
    let mut vel = Vec::new();
    for (i, &(f, b)) in at.iter().enumerate() {
        if f > 0 {
            if let Some(p) = find(f - 1, b) {
                vel.push((p, i));
            }
        }
    }
    let mut pairs = Vec::new();
    for (i, &(f, _)) in at.iter().enumerate() {
        for (j, &(g, _)) in at.iter().enumerate().skip(i + 1) {
            if f == g {
                pairs.push((i, j));
            }
        }
    }
    // Depths around 30 with ~1 apart: some pairs inside d_sep.
    let u = (0..at.len())
        .map(|_| (30.0 + rng.gen_range(-1.0..1.0f64)).ln())
        .collect();
    (ray, vel, pairs, u)
}

fn weights(n: usize) -> SeqWeights {
    SeqWeights {
        accel: 100.0,
        speed: 1.0,
        align: 0.3,
        cohesion: 1.0,
        separation: 100.0,
        level: 1.0,
        scale: 1.0 / n as f64,
        v_target: 0.5,
        d_sep: 1.5,
    }
}

type Lists = [Vec<(usize, usize)>; 4];

/// vel, acc, pairs, align of `problem`.
fn lists() -> (Vec<[f64; 3]>, Lists, Vec<f64>) {
    lists_of(problem())
}

/// vel, acc, pairs, align of a problem.
fn lists_of((ray, vel, pairs, u): Problem) -> (Vec<[f64; 3]>, Lists, Vec<f64>) {
    let acc: Vec<(usize, usize)> = (0..vel.len())
        .flat_map(|b| (0..vel.len()).map(move |a| (a, b)))
        .filter(|&(a, b)| vel[b].0 == vel[a].1)
        .collect();
    let vel_of = |i: usize| vel.iter().position(|v| v.1 == i);
    let align: Vec<(usize, usize)> = pairs
        .iter()
        .filter_map(|&(i, j)| Some((vel_of(i)?, vel_of(j)?)))
        .collect();
    (ray, [vel, acc, pairs, align], u)
}

fn structure<'a>(ray: &'a [[f64; 3]], l: &'a Lists) -> SeqStructure<'a> {
    SeqStructure {
        ray,
        vel: &l[0],
        acc: &l[1],
        pairs: &l[2],
        align: &l[3],
    }
}

#[test]
fn the_gradient_matches_central_finite_differences() {
    let (ray, l, u) = lists();
    assert!(l[1].len() >= 6 && l[3].len() >= 6, "{l:?}");
    let st = structure(&ray, &l);
    let plan = SeqPlan::new(&st);
    let w = weights(u.len());
    let mut ws = SeqWorkspace::default();
    let mut g = vec![0.0; u.len()];
    let t = sequence_energy(&st, &plan, &w, &u, Some(&mut g), &mut ws);
    assert!(t.separation > 0.0, "some pair inside d_sep: {t:?}");
    assert!(t.accel > 0.0 && t.align > 0.0 && t.level > 0.0 && t.cohesion > 0.0);
    // The value without the gradient is the same.
    assert_eq!(sequence_energy(&st, &plan, &w, &u, None, &mut ws), t);
    let h = 1e-6;
    let mut e = |u: &[f64]| sequence_energy(&st, &plan, &w, u, None, &mut ws).total();
    for i in 0..u.len() {
        let mut up = u.clone();
        up[i] += h;
        let mut dn = u.clone();
        dn[i] -= h;
        let fd = (e(&up) - e(&dn)) / (2.0 * h);
        let tol = 1e-6 * (1.0 + fd.abs().max(g[i].abs()));
        assert!(
            (fd - g[i]).abs() < tol,
            "u[{i}]: analytic {} vs fd {fd}",
            g[i]
        );
    }
}

/// Energy and gradient of `st` at `u` with `plan` on a pool of `threads`.
fn run(st: &SeqStructure, plan: &SeqPlan, u: &[f64], threads: usize) -> (SeqTerms, Vec<f64>) {
    let w = weights(u.len());
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap();
    pool.install(|| {
        let mut g = vec![0.0; u.len()];
        let t = sequence_energy(st, plan, &w, u, Some(&mut g), &mut Default::default());
        (t, g)
    })
}

#[test]
fn tiled_chunked_sweeps_match_the_sequential_pass_and_ignore_the_thread_count() {
    // Birds entering and leaving at random frames: velocities, accelerations and pairs of every
    // kind cross the tile and chunk cuts.
    let mut rng = ChaCha8Rng::seed_from_u64(3);
    let life: Vec<(usize, usize)> = (0..7)
        .map(|_| {
            let a = rng.gen_range(0..30);
            (a, rng.gen_range(a + 2..=40))
        })
        .collect();
    for (ray, l, u) in [
        lists(),
        lists_of(flock(40, 7, 11, |b, f| f < life[b].0 || f >= life[b].1)),
    ] {
        let st = structure(&ray, &l);
        let one = SeqPlan::with_sizes(&st, usize::MAX, usize::MAX);
        assert_eq!(one.cuts(), [1, 1]);
        let (t1, g1) = run(&st, &one, &u, 1);
        // Each entry's contributions arrive in list order whatever the cuts: the same gradient
        // bits; the energy's partial sums are grouped by chunk.
        for (tile, chunk) in [(1, 1), (1, 3), (4, 9), (1, usize::MAX), (10, 20)] {
            let plan = SeqPlan::with_sizes(&st, tile, chunk);
            let [tiles, chunks] = plan.cuts();
            if tile == 1 {
                assert!(tiles >= 5, "tile {tile}: {tiles} tiles");
            }
            if chunk <= 3 {
                assert!(chunks >= 2, "chunk {chunk}: {chunks} chunks");
            }
            let (t, g) = run(&st, &plan, &u, 3);
            assert!(
                (t.total() - t1.total()).abs() < 1e-12 * t1.total(),
                "{tile}/{chunk}: {t:?} vs {t1:?}"
            );
            assert_eq!(g, g1, "tile {tile}, chunk {chunk}");
            for threads in [1, 2, 4] {
                assert_eq!(
                    run(&st, &plan, &u, threads),
                    (t, g.clone()),
                    "{threads} threads"
                );
            }
            // Without the gradient, the same terms.
            let w = weights(u.len());
            let bare = sequence_energy(&st, &plan, &w, &u, None, &mut Default::default());
            assert_eq!(bare, t);
        }
    }
}

#[test]
fn lists_out_of_tile_order_run_as_one_tile_with_the_same_result() {
    let (ray, l, u) = lists();
    let st = structure(&ray, &l);
    let (t1, g1) = run(&st, &SeqPlan::with_sizes(&st, 1, 3), &u, 2);
    let mut rev = l.clone();
    rev[2].reverse();
    let st_rev = structure(&ray, &rev);
    let plan_rev = SeqPlan::with_sizes(&st_rev, 1, 3);
    assert_eq!(plan_rev.cuts(), [1, 1]);
    let (t, g) = run(&st_rev, &plan_rev, &u, 2);
    assert!((t.total() - t1.total()).abs() < 1e-12 * t1.total());
    for (a, b) in g.iter().zip(&g1) {
        assert!((a - b).abs() < 1e-12 * (1.0 + a.abs()), "{a} vs {b}");
    }
}
