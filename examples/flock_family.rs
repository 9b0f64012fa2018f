//! The shape family of animated flocks (issue #50): for the shipped V, U, J and line examples
//! (`examples/flocks/`), N = 14 and 41 birds and seeds 1–5, the whole animation (initiation,
//! hand-over, F steady frames; no files) and, per run: the example's own worst deviation from its
//! sides' curves, the animation's over the key shapes and the steady frames (`flock::family`,
//! longitudinal, wingspans), their ratio, the hand-over's peak acceleration against its bound, the
//! fraction of steady (frame, bird) savings ξ inside Step 2's ranges, the flock's mean
//! induced-power saving and wing-tip spacing, and the wall time of the run.
//!
//! `cargo run --release --example flock_family -- [FRAMES] [SEEDS]` (defaults 250, 5).

use herdfit::flock::animate::{self, AnimateConfig};
use herdfit::flock::extract::{self, ExtractConfig};
use herdfit::progress::NoProgress;
use rayon::prelude::*;
use std::time::Instant;

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let frames: usize = args.first().map_or(250, |a| a.parse().expect("FRAMES"));
    let seeds: u64 = args.get(1).map_or(5, |a| a.parse().expect("SEEDS"));
    let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut cases = Vec::new();
    for stem in ["v", "u", "j", "line"] {
        for n in [14usize, 41] {
            for seed in 1..=seeds {
                cases.push((stem, n, seed));
            }
        }
    }
    let rows: Vec<_> = cases
        .par_iter()
        .map(|&(stem, n, seed)| {
            let path = root.join(format!("examples/flocks/{stem}.csv"));
            let p = extract::extract_file(&path, &ExtractConfig::default()).expect("example");
            let cfg = AnimateConfig {
                birds: Some(n),
                frames,
                seed,
                video: false,
                ..AnimateConfig::default()
            };
            let t0 = Instant::now();
            let a = animate::animate(&p, stem, &cfg, &mut NoProgress).expect("animation");
            (stem, n, seed, a.report, t0.elapsed().as_secs_f64())
        })
        .collect();
    println!(
        "example  N seed  example_worst  keys_worst  steady_worst  ratio  hand_over_accel/bound  \
         xi_in_range  saving  WTS  converged  keys  s"
    );
    let mut worst_ratio: f64 = 0.0;
    let mut worst_accel: f64 = 0.0;
    for (stem, n, seed, r, secs) in &rows {
        let f = &r.shape_family;
        worst_ratio = worst_ratio.max(f.ratio);
        worst_accel = worst_accel.max(r.max_accel_hand_over / r.accel_bound);
        println!(
            "{stem:5} {n:3} {seed:3}  {:12.3}  {:10.3}  {:12.3}  {:5.2}  {:8.3}/{:.1}  {:11.4}  \
             {:5.1}%  {:+.3}  {:>9}  {:4}  {secs:.1}",
            f.example_worst,
            f.keys_worst,
            f.steady_worst,
            f.ratio,
            r.max_accel_hand_over,
            r.accel_bound,
            r.xi_in_range_steady,
            100.0 * r.flock_mean_saving,
            r.mean_wing_tip_spacing,
            r.initiation
                .as_ref()
                .and_then(|i| i.converged_after)
                .map_or("no".to_string(), |t| format!("{t:.1} s")),
            r.keys.len(),
        );
    }
    println!(
        "{} runs: worst steady/example ratio {worst_ratio:.3} (target ≤ 1.5); worst hand-over \
         acceleration / bound {worst_accel:.3} (target ≤ 1)",
        rows.len()
    );
}
