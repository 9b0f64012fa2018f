//! Rejection sampling with plain eq. 2 draws (Klotsman & Tal §5 Step 3): how many independent
//! per-bird box draws (projected onto Σ ξ̂ = 1, `steady::draw_xi`) Levenberg–Marquardt can
//! reproduce at all. For each N of `flock_keys`, from the first key shape on its own lateral
//! layout, `DRAWS` draws are each solved directly from the key's positions and, failing that, by
//! the straight-line continuation (`keys::continuation`); a draw counts as reachable when either
//! reaches it to `solve_tol`. The measured acceptance is why `keys::next_key` samples the eq. 2
//! box restricted to the reachable set instead (RESULTS.md §3, ARCHITECTURE.md).
//!
//! `cargo run --release --example flock_reach -- [DRAWS]` (default 20).

use herdfit::flock::solve::{self, PositionProblem};
use herdfit::flock::{keys, steady, synth};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

fn main() {
    let draws: usize = std::env::args()
        .nth(1)
        .map_or(20, |a| a.parse().expect("DRAWS"));
    let cases = synth::key_shape_cases();
    let out: Vec<(usize, usize, f64, f64)> = cases
        .par_iter()
        .map(|(ex, n)| {
            let cfg = steady::SteadyConfig::default();
            let mut rng = ChaCha8Rng::seed_from_u64(11 + *n as u64);
            let (init, range, _, _) =
                synth::key_shape_setup(ex, *n, &cfg, &mut rng).expect("key-shape set-up");
            let prev = steady::first_key(&init.shapes[0]).expect("first key");
            let x: Vec<f64> = prev.pos.iter().map(|p| p[0] - prev.pos[0][0]).collect();
            let y0: Vec<f64> = prev.pos.iter().map(|p| p[1] - prev.pos[0][1]).collect();
            let mut drng = ChaCha8Rng::seed_from_u64(500 + *n as u64);
            let (mut ok, mut reach_sum, mut best_err) = (0, 0.0, f64::INFINITY);
            for _ in 0..draws {
                let (draw, _) = steady::draw_xi(&prev.xi_target, &range, &cfg, &mut drng);
                let s = solve::solve(
                    PositionProblem::new(x.clone(), draw.clone(), 0, y0.clone()),
                    cfg.solve_evaluations,
                );
                best_err = best_err.min(s.max_relative_error);
                if s.max_relative_error <= cfg.solve_tol {
                    ok += 1;
                    reach_sum += 1.0;
                    continue;
                }
                let (t, ..) = keys::continuation(&x, &x, &prev.xi_target, &draw, y0.clone(), &cfg);
                reach_sum += t;
                if t >= 1.0 {
                    ok += 1;
                }
            }
            (*n, ok, reach_sum / draws as f64, best_err)
        })
        .collect();
    println!("N   draws  reachable  mean fraction of the way  best direct max|ξ−ξ̂|/ξ̂");
    for (n, ok, reach, best) in out {
        println!("{n:>2}  {draws:>5}  {ok:>9}  {reach:>24.3}  {best:>24.2e}");
    }
}
