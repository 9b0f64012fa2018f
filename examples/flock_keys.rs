//! Key shapes of the steady flight (Klotsman & Tal Algorithm 1, eq. 2–4) for N = 9, 14, 16, 28,
//! 41: how exactly Levenberg–Marquardt reproduces each key shape's targets ξ̂, and how far the
//! continuation gets towards the eq. 2 draw. The 5-key sweep behind RESULTS.md §3 (the test
//! `levenberg_marquardt_reproduces_every_key_shape` checks 2 keys per N).
//!
//! `cargo run --release --example flock_keys -- [KEYS]` (default 5).

use herdfit::flock::{steady, synth};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

fn main() {
    let keys: usize = std::env::args()
        .nth(1)
        .map_or(5, |a| a.parse().expect("KEYS"));
    let cases = synth::key_shape_cases();
    let out: Vec<(usize, f64, f64)> = cases
        .par_iter()
        .map(|(ex, n)| {
            let cfg = steady::SteadyConfig::default();
            let mut rng = ChaCha8Rng::seed_from_u64(11 + *n as u64);
            let (init, range, gr) =
                synth::key_shape_setup(ex, *n, &cfg, &mut rng).expect("key-shape set-up");
            let mut prev = steady::first_key(&init.shapes[0]).expect("first key");
            let (mut worst, mut reached) = (0.0f64, 0.0);
            for _ in 0..keys {
                let k = steady::next_key(&prev, init.nl, init.nr, &range, gr, &cfg, &mut rng);
                for (a, b) in k.xi.iter().zip(&k.xi_target) {
                    worst = worst.max((a - b).abs() / b);
                }
                reached += k.reached;
                prev = k;
            }
            (*n, worst, reached / keys as f64)
        })
        .collect();
    for (n, worst, reached) in out {
        println!(
            "N = {n}: worst |ξ − ξ̂|/ξ̂ over {keys} key shapes {worst:.2e}, mean fraction of the way \
             to the eq. 2 draw reached {reached:.2}"
        );
    }
}
