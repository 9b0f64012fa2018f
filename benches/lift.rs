//! Criterion benchmarks of LIFT (issue #21): the thesis's frame-by-frame method and the
//! whole-sequence optimisation on a synthetic boids flock seen by its ground observer, at the
//! thesis's scale (200 frames × 5 birds, "< 1 s", §1) and, frame by frame, at the (1000
//! frames × 200 birds, ≤ 2 s). The whole sequence is benchmarked at 200 × 5 and 300 × 20 only: at
//! 1000 × 200 one run took over 300 s (BENCHMARKS.md), too long for criterion's ten samples.
//!
//! `cargo bench --bench lift`

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use herdfit::lift::boids::{synth_flock, BoidsConfig};
use herdfit::lift::frame::frame_by_frame;
use herdfit::lift::sequence::whole_sequence;
use herdfit::lift::{demo_config, Observations};
use herdfit::progress::NoProgress;
use std::time::Duration;

/// (frames, birds) of each case, and whether the whole sequence is benchmarked on it.
const CASES: [(usize, usize, bool); 3] = [(200, 5, true), (300, 20, true), (1000, 200, false)];

fn problem(frames: usize, birds: usize) -> (Observations, herdfit::lift::LiftConfig) {
    // A wider orbit and a larger flock keep 200 birds apart; every point stays in view.
    let b = BoidsConfig {
        birds,
        frames,
        crop: false,
        hfov: 80.0,
        ..BoidsConfig::default()
    };
    let syn = synth_flock(&b, &mut NoProgress).expect("synthetic flock");
    let obs = Observations::new(&syn.tracks, &syn.camera).expect("observations");
    (obs, demo_config(&b))
}

fn lift(c: &mut Criterion) {
    let mut g = c.benchmark_group("lift");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5));
    for (frames, birds, whole) in CASES {
        let (obs, cfg) = problem(frames, birds);
        let id = format!("{frames}x{birds}");
        g.bench_with_input(BenchmarkId::new("frame_by_frame", &id), &id, |b, _| {
            b.iter(|| frame_by_frame(&obs, &cfg, &mut NoProgress).unwrap())
        });
        if !whole {
            continue;
        }
        let init = frame_by_frame(&obs, &cfg, &mut NoProgress).unwrap();
        g.bench_with_input(BenchmarkId::new("whole_sequence", &id), &id, |b, _| {
            b.iter(|| whole_sequence(&obs, &init, &cfg, &mut NoProgress).unwrap())
        });
    }
    g.finish();
}

criterion_group!(benches, lift);
criterion_main!(benches);
