//! Can Levenberg–Marquardt reach the *drawn* ξ̂ of a key shape (Klotsman & Tal eq. 2 and 4)?
//! For the key shapes of `flock_keys` (same seeds, the same draws) this re-draws each key's ξ̂
//! and lateral gap exactly as `steady::next_key` does, then:
//!
//! - solves eq. 4 for the draw directly (no continuation) from the previous key's y and from
//!   `STARTS` random V-like starts, with a large evaluation budget: the smallest max |ξ − ξ̂|/ξ̂;
//! - follows the continuation path of `next_key` and records the smallest singular value of the
//!   relative Jacobian (∂ξ/∂y, `PositionProblem::jacobian_matrix`) and the largest |y| as the
//!   path approaches where it stops: a singular value → 0 with y growing marks the boundary of the
//!   set of ξ that positions can give (a fold of y ↦ ξ), so the draw beyond it is unreachable.
//!
//! `cargo run --release --example flock_reach -- [KEYS] [STARTS]` (defaults 3, 8).

use herdfit::flock::solve::{self, PositionProblem};
use herdfit::flock::{steady, synth};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

fn layout(nl: usize, nr: usize, gap: f64) -> Vec<f64> {
    let mut x = vec![0.0];
    x.extend((1..=nl).map(|k| -(k as f64) * gap));
    x.extend((1..=nr).map(|k| k as f64 * gap));
    x
}

fn sigma_min(p: &PositionProblem) -> f64 {
    let j = p.jacobian_matrix();
    j.singular_values()
        .iter()
        .cloned()
        .fold(f64::INFINITY, f64::min)
}

struct KeyReport {
    n: usize,
    key: usize,
    reached: f64,
    direct_prev: f64,
    direct_best: f64,
    sigma_start: f64,
    sigma_end: f64,
    ymax_end: f64,
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let keys: usize = args.first().map_or(3, |a| a.parse().expect("KEYS"));
    let starts: usize = args.get(1).map_or(8, |a| a.parse().expect("STARTS"));
    let cases = synth::key_shape_cases();
    let out: Vec<Vec<KeyReport>> = cases
        .par_iter()
        .map(|(ex, n)| {
            let n = *n;
            let cfg = steady::SteadyConfig::default();
            let mut rng = ChaCha8Rng::seed_from_u64(11 + n as u64);
            let (init, range, gr) =
                synth::key_shape_setup(ex, n, &cfg, &mut rng).expect("key-shape set-up");
            let mut prev = steady::first_key(&init.shapes[0]).expect("first key");
            let mut rows = Vec::new();
            for key in 1..=keys {
                // The same draw as next_key: draw_xi, then the gap, from the same stream.
                let mut r2 = rng.clone();
                let (draw, _) = steady::draw_xi(&prev.xi_target, &range, &cfg, &mut r2);
                let gap = if gr[1] > gr[0] {
                    r2.gen_range(gr[0]..=gr[1])
                } else {
                    gr[0]
                }
                .max(cfg.min_gap);
                let k = steady::next_key(&prev, init.nl, init.nr, &range, gr, &cfg, &mut rng);
                let x = layout(init.nl, init.nr, gap);
                let y0: Vec<f64> = prev.pos.iter().map(|q| q[1] - prev.pos[0][1]).collect();
                let budget = 5000;
                let direct_prev = solve::solve(
                    PositionProblem::new(x.clone(), draw.clone(), 0, y0.clone()),
                    budget,
                )
                .max_relative_error;
                let mut srng = ChaCha8Rng::seed_from_u64(7 + key as u64 + 100 * n as u64);
                let mut direct_best = direct_prev;
                for _ in 0..starts {
                    let depth = srng.gen_range(0.2..2.0);
                    let ys: Vec<f64> = x
                        .iter()
                        .map(|xx| -depth * xx.abs() + srng.gen_range(-1.0..1.0))
                        .collect();
                    let s =
                        solve::solve(PositionProblem::new(x.clone(), draw.clone(), 0, ys), budget);
                    direct_best = direct_best.min(s.max_relative_error);
                }
                // The continuation's path at its start and where it stopped.
                let x0: Vec<f64> = prev.pos.iter().map(|q| q[0] - prev.pos[0][0]).collect();
                let xi_at = |t: f64| -> Vec<f64> {
                    prev.xi_target
                        .iter()
                        .zip(&draw)
                        .map(|(a, b)| a + t * (b - a))
                        .collect()
                };
                let x_at = |t: f64| -> Vec<f64> {
                    x0.iter().zip(&x).map(|(a, b)| a + t * (b - a)).collect()
                };
                let start = PositionProblem::new(x_at(0.0), xi_at(0.0), 0, y0.clone());
                let kend: Vec<f64> = k.pos.iter().map(|q| q[1] - k.pos[0][1]).collect();
                let end = PositionProblem::new(x_at(k.reached), xi_at(k.reached), 0, kend.clone());
                rows.push(KeyReport {
                    n,
                    key,
                    reached: k.reached,
                    direct_prev,
                    direct_best,
                    sigma_start: sigma_min(&start),
                    sigma_end: sigma_min(&end),
                    ymax_end: kend.iter().map(|v| v.abs()).fold(0.0, f64::max),
                });
                prev = k;
            }
            rows
        })
        .collect();
    println!(
        "N  key  reached  direct-from-prev  best-of-{starts}-starts  σmin(start)  σmin(stop)  max|y| at stop (b)"
    );
    for r in out.iter().flatten() {
        println!(
            "{:>2} {:>4}  {:>7.3}  {:>16.2e}  {:>17.2e}  {:>11.3e}  {:>10.3e}  {:>8.2}",
            r.n,
            r.key,
            r.reached,
            r.direct_prev,
            r.direct_best,
            r.sigma_start,
            r.sigma_end,
            r.ymax_end
        );
    }
}
