//! Criterion benchmarks of LIFT (issue #21): the thesis's frame-by-frame method and the
//! whole-sequence optimisation on a synthetic boids flock seen by its ground observer, at the
//! thesis's scale (200 frames × 5 birds, "< 1 s", §1), at 300 × 20, and at the 1000 frames
//! × 200 birds (frame by frame ≤ 2 s, whole sequence ≤ 30 s).
//!
//! The whole sequence runs with the hand-derived gradient (`analytic`, the default) and, in the
//! same run, with the previous implementation, burn reverse-mode autodiff in f32 (`autodiff`, the
//! reference): whole runs at 200 × 5 and 300 × 20 (at 1000 × 200 one autodiff run takes over
//! 300 s, BENCHMARKS.md), one energy + gradient evaluation at every size.
//!
//! `cargo bench --bench lift` (all, ≈ 15 min on 2 quiet cores); one group:
//! `cargo bench --bench lift -- lift/whole_sequence`.

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use herdfit::lift::boids::{synth_flock, BoidsConfig};
use herdfit::lift::frame::frame_by_frame;
use herdfit::lift::sequence::{whole_sequence, Energy, Gradient, Structure};
use herdfit::lift::{demo_config, LiftConfig, Observations};
use herdfit::progress::NoProgress;
use std::time::Duration;

/// (frames, birds) of each case, and whether the autodiff whole sequence is run on it.
const CASES: [(usize, usize, bool); 3] = [(200, 5, true), (300, 20, true), (1000, 200, false)];

fn problem(frames: usize, birds: usize) -> (Observations, LiftConfig) {
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

fn with(cfg: &LiftConfig, how: Gradient) -> LiftConfig {
    let mut c = cfg.clone();
    c.sequence.gradient = how;
    c
}

const HOWS: [(&str, Gradient); 2] = [
    ("analytic", Gradient::Analytic),
    ("autodiff", Gradient::Autodiff),
];

fn lift(c: &mut Criterion) {
    let mut g = c.benchmark_group("lift");
    g.sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5));
    for (frames, birds, autodiff_whole) in CASES {
        let (obs, cfg) = problem(frames, birds);
        let id = format!("{frames}x{birds}");
        g.bench_with_input(BenchmarkId::new("frame_by_frame", &id), &id, |b, _| {
            b.iter(|| frame_by_frame(&obs, &cfg, &mut NoProgress).unwrap())
        });
        let init = frame_by_frame(&obs, &cfg, &mut NoProgress).unwrap();
        let u: Vec<f64> = init.iter().map(|d| d.ln()).collect();
        let s = Structure::new(&obs, cfg.sequence.neighbours);
        for (name, how) in HOWS {
            let c = with(&cfg, how);
            let mut e = Energy::new(&obs, &s, &c).unwrap();
            let mut grad = vec![0.0; u.len()];
            g.bench_with_input(
                BenchmarkId::new(format!("energy_gradient/{name}"), &id),
                &id,
                |b, _| b.iter(|| e.eval(&u, Some(&mut grad)).unwrap()),
            );
        }
        for (name, how) in HOWS {
            if how == Gradient::Autodiff && !autodiff_whole {
                continue;
            }
            let c = with(&cfg, how);
            g.bench_with_input(
                BenchmarkId::new(format!("whole_sequence/{name}"), &id),
                &id,
                |b, _| b.iter(|| whole_sequence(&obs, &init, &c, &mut NoProgress).unwrap()),
            );
        }
    }
    g.finish();
}

criterion_group!(benches, lift);
criterion_main!(benches);
