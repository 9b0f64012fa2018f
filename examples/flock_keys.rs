//! Key shapes of the steady flight (Klotsman & Tal Algorithm 1, eq. 2–4) for N = 9, 14, 16, 28,
//! 41: how exactly Levenberg–Marquardt reproduces each key shape's *drawn* ξ̂ (eq. 2 restricted to
//! the reachable set, `flock::keys`), how many draws were rejected, and how far the draws move
//! from the previous key shape. The sweep behind RESULTS.md §3 (the test
//! `levenberg_marquardt_reproduces_every_key_shape` checks 2 keys per N).
//!
//! `cargo run --release --example flock_keys -- [KEYS] [N]` (default 5 keys, every N).

use herdfit::flock::{keys, steady, synth};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::time::Instant;

struct Row {
    n: usize,
    worst: f64,
    reproduced: usize,
    rejected: usize,
    acceptance: f64,
    mean_move: f64,
    max_move: f64,
    box_use: f64,
    seconds: f64,
    solves: usize,
    evaluations: usize,
    fingerprint: f64,
}

fn main() {
    let nkeys: usize = std::env::args()
        .nth(1)
        .map_or(5, |a| a.parse().expect("KEYS"));
    let only: Option<usize> = std::env::args().nth(2).map(|a| a.parse().expect("N"));
    let cases: Vec<_> = synth::key_shape_cases()
        .into_iter()
        .filter(|(_, n)| only.is_none_or(|o| o == *n))
        .collect();
    let out: Vec<Row> = cases
        .par_iter()
        .map(|(ex, n)| {
            let cfg = steady::SteadyConfig::default();
            let mut rng = ChaCha8Rng::seed_from_u64(11 + *n as u64);
            let (init, range, gr, fam) =
                synth::key_shape_setup(ex, *n, &cfg, &mut rng).expect("key-shape set-up");
            let mut prev = steady::first_key(&init.shapes[0]).expect("first key");
            let mut r = Row {
                n: *n,
                worst: 0.0,
                reproduced: 0,
                rejected: 0,
                acceptance: 0.0,
                mean_move: 0.0,
                max_move: 0.0,
                box_use: 0.0,
                seconds: 0.0,
                solves: 0,
                evaluations: 0,
                fingerprint: 0.0,
            };
            for _ in 0..nkeys {
                let bx = keys::eq2_box(&prev.xi_target, &range, &cfg);
                let t0 = Instant::now();
                let k = steady::next_key(&prev, init.nl, init.nr, &range, gr, &fam, &cfg, &mut rng);
                r.seconds += t0.elapsed().as_secs_f64();
                for (a, b) in k.xi.iter().zip(&k.xi_draw) {
                    r.worst = r.worst.max((a - b).abs() / b);
                }
                r.reproduced += k.reproduced as usize;
                r.solves += k.solves;
                r.evaluations += k.evaluations;
                // A weighted sum of every key's positions: equal to rounding between two builds
                // exactly when they drew and solved the same key shapes.
                r.fingerprint += k
                    .pos
                    .iter()
                    .enumerate()
                    .map(|(i, p)| (i + 1) as f64 * (p[0] + 0.5 * p[1]))
                    .sum::<f64>();
                r.rejected += k.draws_rejected;
                r.acceptance += k.chain_acceptance / nkeys as f64;
                let mut mv = 0.0;
                let mut used = 0.0;
                for ((d, p), b) in k.xi_draw.iter().zip(&prev.xi_target).zip(&bx) {
                    let m = (d - p).abs() / p;
                    mv += m / *n as f64;
                    r.max_move = r.max_move.max(m);
                    // Where the draw sits in its box: 0 at the previous value, 1 at the face it
                    // moved towards.
                    let face = if d >= p { b[1] } else { b[0] };
                    if (face - p).abs() > 0.0 {
                        used += (d - p) / (face - p) / *n as f64;
                    }
                }
                r.mean_move += mv / nkeys as f64;
                r.box_use += used / nkeys as f64;
                prev = k;
            }
            r
        })
        .collect();
    println!(
        "N   keys  reproduced  worst|ξ−ξ̂|/ξ̂  rejected draws  chain acceptance  mean|Δξ|/ξ  max|Δξ|/ξ  \
         mean box use  s/key  solves/key  evals/key  fingerprint"
    );
    for r in out {
        println!(
            "{:>2}  {:>4}  {:>10}  {:>13.2e}  {:>14}  {:>16.2}  {:>10.3}  {:>9.3}  {:>12.2}  {:>5.3}  {:>10.1}  {:>9.0}  {:.12e}",
            r.n,
            nkeys,
            r.reproduced,
            r.worst,
            r.rejected,
            r.acceptance,
            r.mean_move,
            r.max_move,
            r.box_use,
            r.seconds / nkeys as f64,
            r.solves as f64 / nkeys as f64,
            r.evaluations as f64 / nkeys as f64,
            r.fingerprint
        );
    }
}
