//! Tests of the force kernel: finite differences, kept terms, per-agent coefficients, threads.

use super::*;
use crate::perception::tests::scene;
use crate::perception::{perceive, PerceptionConfig};
use crate::Capsule;
use rand::{Rng, SeedableRng};

/// The perception settings of these tests, with the list caps given.
fn config(max_neighbours: usize, max_obstacles: usize) -> PerceptionConfig {
    PerceptionConfig {
        radius: 4.0,
        capsule: Capsule {
            half_length: 0.3,
            radius: 0.2,
        },
        occlusion: true,
        max_neighbours,
        max_obstacles,
        front_cone: 1.0,
    }
}

fn setup(seed: u64, n: usize) -> (PairLists, [Vec<f64>; 4], Vec<f64>) {
    let (pos, head, map) = scene(seed, n);
    let cfg = config(12, 8);
    let p = perceive(&pos, &head, Some(&map), &cfg);
    let lists = PairLists::from_perception(&p);
    let s = [
        pos.iter().map(|p| p[0]).collect(),
        pos.iter().map(|p| p[1]).collect(),
        head.iter().map(|h| h[0]).collect(),
        head.iter().map(|h| h[1]).collect(),
    ];
    let mut coef = vec![0.0; N_COEF];
    for g in 0..4 {
        coef[g] = 1.0 + 0.7 * g as f64;
        coef[4 + g] = -0.5 / (1.5 + 0.4 * g as f64).powi(2);
        coef[8 + g] = -0.5 / (1.2 + 0.5 * g as f64).powi(2);
    }
    (lists, s, coef)
}

fn loss(lists: &PairLists, s: &[Vec<f64>; 4], coef: &[f64], w: &[f64]) -> f64 {
    let mut out = vec![0.0; 2 * lists.n];
    let a = AgentsRef {
        x: &s[0],
        y: &s[1],
        hx: &s[2],
        hy: &s[3],
    };
    forces_forward(lists, a, Coefficients(coef), &mut out);
    out.iter().zip(w).map(|(f, w)| f * w).sum()
}

/// Every gradient of `L = Σ w·F` against 4-point central differences of the forward pass.
#[test]
fn backward_matches_central_differences() {
    let (lists, s, coef) = setup(3, 120);
    assert!(lists.pairs() > 200 && !lists.ob_point.is_empty());
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    let w: Vec<f64> = (0..2 * lists.n).map(|_| rng.gen_range(-1.0..1.0)).collect();
    let a = AgentsRef {
        x: &s[0],
        y: &s[1],
        hx: &s[2],
        hy: &s[3],
    };
    let g = forces_backward(&lists, a, Coefficients(&coef), &w, None);
    let h = 1e-5;
    let fd =
        |f: &dyn Fn(f64) -> f64| (8.0 * (f(h) - f(-h)) - (f(2.0 * h) - f(-2.0 * h))) / (12.0 * h);
    let mut worst = 0.0f64;
    let mut check = |got: f64, want: f64| {
        worst = worst.max((got - want).abs() / want.abs().max(1.0));
    };
    for c in 0..N_COEF {
        let want = fd(&|d| {
            let mut k = coef.clone();
            k[c] += d;
            loss(&lists, &s, &k, &w)
        });
        check(g.coef[c], want);
    }
    let grads = [&g.x, &g.y, &g.hx, &g.hy];
    for (v, gv) in grads.iter().enumerate() {
        for i in (0..lists.n).step_by(7) {
            let want = fd(&|d| {
                let mut t = s.clone();
                t[v][i] += d;
                loss(&lists, &t, &coef, &w)
            });
            check(gv[i], want);
        }
    }
    assert!(worst < 1e-7, "worst relative error {worst:e}");
}

/// The kept pair terms change nothing: the same forces and the same gradients, bit for bit,
/// with obstacles, shared and per-agent coefficients, and agents with no upstream gradient.
#[test]
fn kept_terms_give_the_same_bytes() {
    let (lists, s, coef) = setup(7, 400);
    assert!(!lists.ob_point.is_empty());
    let a = AgentsRef {
        x: &s[0],
        y: &s[1],
        hx: &s[2],
        hy: &s[3],
    };
    let per: Vec<f64> = (0..lists.n)
        .flat_map(|i| coef.iter().map(move |c| c * (1.0 + 0.01 * i as f64)))
        .collect();
    let w: Vec<f64> = (0..2 * lists.n)
        .map(|i| {
            if i % 14 < 2 {
                0.0
            } else {
                (i as f64 * 0.61).cos()
            }
        })
        .collect();
    for k in [&coef, &per] {
        let (mut f1, mut f2) = (vec![0.0; 2 * lists.n], vec![0.0; 2 * lists.n]);
        forces_forward(&lists, a, Coefficients(k), &mut f1);
        let kept = forces_forward_keep(&lists, a, Coefficients(k), &mut f2);
        assert_eq!(f1, f2);
        assert_eq!(kept.nb.len(), lists.pairs());
        assert_eq!(kept.ob.len(), lists.ob_point.len());
        let g1 = forces_backward(&lists, a, Coefficients(k), &w, None);
        let g2 = forces_backward(&lists, a, Coefficients(k), &w, Some(&kept));
        assert_eq!(g1, g2);
    }
}

#[test]
fn per_agent_coefficients_equal_shared_ones() {
    let (lists, s, coef) = setup(4, 200);
    let per: Vec<f64> = (0..lists.n).flat_map(|_| coef.clone()).collect();
    let a = AgentsRef {
        x: &s[0],
        y: &s[1],
        hx: &s[2],
        hy: &s[3],
    };
    let (mut f1, mut f2) = (vec![0.0; 2 * lists.n], vec![0.0; 2 * lists.n]);
    forces_forward(&lists, a, Coefficients(&coef), &mut f1);
    forces_forward(&lists, a, Coefficients(&per), &mut f2);
    assert_eq!(f1, f2);
    let w = vec![0.5; 2 * lists.n];
    let g1 = forces_backward(&lists, a, Coefficients(&coef), &w, None);
    let g2 = forces_backward(&lists, a, Coefficients(&per), &w, None);
    assert_eq!(g1.x, g2.x);
    assert_eq!(g1.hy, g2.hy);
    for c in 0..N_COEF {
        let sum: f64 = (0..lists.n).map(|i| g2.coef[i * N_COEF + c]).sum();
        assert!((sum - g1.coef[c]).abs() <= 1e-9 * (1.0 + g1.coef[c].abs()));
    }
}

#[test]
fn thread_count_does_not_change_forces_or_gradients() {
    let (lists, s, coef) = setup(5, 3000);
    let a = AgentsRef {
        x: &s[0],
        y: &s[1],
        hx: &s[2],
        hy: &s[3],
    };
    let w: Vec<f64> = (0..2 * lists.n).map(|i| (i as f64 * 0.37).sin()).collect();
    let run = |threads: usize| {
        crate::on_threads(threads, || {
            let mut f = vec![0.0; 2 * lists.n];
            forces_forward(&lists, a, Coefficients(&coef), &mut f);
            (f, forces_backward(&lists, a, Coefficients(&coef), &w, None))
        })
    };
    assert_eq!(run(1), run(3));
}

#[test]
fn compact_lists_keep_exactly_the_unmasked_entries() {
    let (pos, head, map) = scene(6, 150);
    let cfg = config(32, 16);
    let p = perceive(&pos, &head, Some(&map), &cfg);
    let l = PairLists::from_perception(&p);
    let real: usize = p.neighbour_mask.iter().map(|&m| m as usize).sum();
    assert_eq!(l.pairs(), real);
    assert!(p.k > 1 && real < p.n * p.k, "the scene must have padding");
    for i in 0..p.n {
        let want: Vec<u32> = (0..p.k)
            .filter(|&s| p.neighbour_mask[i * p.k + s] == 1)
            .map(|s| p.neighbours[i * p.k + s])
            .collect();
        assert_eq!(&l.nb[l.neighbours(i)], &want[..]);
    }
}
