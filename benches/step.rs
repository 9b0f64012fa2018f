//! Criterion benchmarks of the hot paths on the standard random herd (one agent per 2 BL²,
//! occlusion on, f32): the perception kernel, one simulation step, and forward + backward through
//! T = 10 unrolled steps (reported per iteration; divide by 10 for per-step figures), each with
//! the fused force op (`fused/N`) and the tensor-op reference (`reference/N`); and the same
//! forward + backward replaying decisions recorded once outside the timed loop
//! (`forward_backward_10_steps_replay`), as `fit` does after its plan and as the JAX peer does.
//!
//! `neighbour_skin/S/N` perceives the 20 steps of an N-agent run with Verlet lists of skin S BL
//! (`fresh/N` searches the grid every step): the sweep behind `NEIGHBOUR_SKIN`.
//!
//! `cargo bench --bench step` (set `HERDFIT_BENCH_LARGE=1` to add the 100,000-agent cases).

use criterion::{criterion_group, criterion_main, BenchmarkId, Criterion};
use herdfit::backend::{cpu_device, Precision};
use herdfit::herd::gradcheck::objective;
use herdfit::herd::scenario::bench_model;
use herdfit::herd::sim::{theta_tensor, Decide, ForceKernel, HerdState};
use herdfit_kernels::{perceive, NeighbourLists};
use rand::SeedableRng;
use std::time::Duration;

fn sizes(base: &[usize]) -> Vec<usize> {
    let mut v = base.to_vec();
    if std::env::var_os("HERDFIT_BENCH_LARGE").is_some() {
        v.push(100_000);
    }
    v
}

/// Every size with the fused op, then with the tensor-op reference.
fn kernels(sizes: &[usize]) -> Vec<(ForceKernel, usize)> {
    [ForceKernel::Fused, ForceKernel::Reference]
        .iter()
        .flat_map(|&k| sizes.iter().map(move |&n| (k, n)))
        .collect()
}

fn name(k: ForceKernel) -> &'static str {
    match k {
        ForceKernel::Fused => "fused",
        ForceKernel::Reference => "reference",
    }
}

fn perception(c: &mut Criterion) {
    let device = cpu_device(Precision::F32).unwrap();
    let mut g = c.benchmark_group("perception_kernel");
    g.sample_size(10).measurement_time(Duration::from_secs(3));
    for n in sizes(&[1500, 10_000]) {
        let (model, init) = bench_model(n, 1).unwrap();
        let snap = HerdState::from_rows(&init, &device).snapshot().unwrap();
        let cfg = model.perception_config();
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| perceive(&snap.pos, &snap.head, None, &cfg))
        });
    }
    g.finish();
}

fn sim_step(c: &mut Criterion) {
    let device = cpu_device(Precision::F32).unwrap();
    let mut g = c.benchmark_group("sim_step");
    g.sample_size(10).measurement_time(Duration::from_secs(3));
    for (kernel, n) in kernels(&sizes(&[500, 1500, 5000])) {
        let (mut model, init) = bench_model(n, 1).unwrap();
        model.force_kernel = kernel;
        let theta = theta_tensor(&model.params.to_vec(), &device);
        let state = HerdState::from_rows(&init, &device);
        g.bench_with_input(BenchmarkId::new(name(kernel), n), &n, |b, _| {
            let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
            b.iter(|| {
                let s = model
                    .rollout(
                        &theta,
                        state.clone(),
                        1,
                        Decide::Live {
                            rng: &mut rng,
                            record: None,
                        },
                        |_, _, _| Ok(()),
                    )
                    .unwrap();
                s.x.into_data()
            })
        });
    }
    g.finish();
}

fn grad_window(c: &mut Criterion) {
    grad_group(c, "forward_backward_10_steps", false);
}

/// Forward + backward through 10 steps replaying the decisions (perception with occlusion, roles,
/// noise) of one no-gradient run recorded before timing.
fn grad_window_replay(c: &mut Criterion) {
    grad_group(c, "forward_backward_10_steps_replay", true);
}

/// Forward + backward through 10 unrolled steps for every kernel and size, with each step's
/// decisions made live inside the timed pass or (`replay`) recorded once before timing.
fn grad_group(c: &mut Criterion, group: &str, replay: bool) {
    let device = cpu_device(Precision::F32).unwrap();
    let ad = device.clone().autodiff();
    let mut g = c.benchmark_group(group);
    g.sample_size(10).measurement_time(Duration::from_secs(5));
    for (kernel, n) in kernels(&[500, 1500, 5000]) {
        let (mut model, init) = bench_model(n, 1).unwrap();
        model.force_kernel = kernel;
        let theta_v = model.params.to_vec();
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let rec = replay.then(|| {
            let th = theta_tensor(&theta_v, &device);
            model.record(&th, &init, 10, &mut rng).unwrap()
        });
        g.bench_with_input(BenchmarkId::new(name(kernel), n), &n, |b, _| {
            b.iter(|| {
                let th = theta_tensor(&theta_v, &ad).require_grad();
                let decide = match &rec {
                    Some(rec) => Decide::Replay(rec),
                    None => Decide::Live {
                        rng: &mut rng,
                        record: None,
                    },
                };
                let s = HerdState::from_rows(&init, &ad);
                let end = model.rollout(&th, s, 10, decide, |_, _, _| Ok(())).unwrap();
                let grads = objective(&end, 4.0).backward();
                th.grad(&grads).unwrap().into_data()
            })
        });
    }
    g.finish();
}

/// Perception over the 20 steps of a live run of N agents (the positions and headings recorded
/// once): a fresh grid search every step (`fresh/N`) against Verlet lists of skin S BL (`S/N`).
fn neighbour_skin(c: &mut Criterion) {
    let device = cpu_device(Precision::F32).unwrap();
    let mut g = c.benchmark_group("neighbour_skin");
    g.sample_size(10).measurement_time(Duration::from_secs(4));
    for n in sizes(&[1500]) {
        let (model, init) = bench_model(n, 1).unwrap();
        let theta = theta_tensor(&model.params.to_vec(), &device);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(2);
        let start = HerdState::from_rows(&init, &device);
        let mut steps = vec![start.snapshot().unwrap()];
        let decide = Decide::Live {
            rng: &mut rng,
            record: None,
        };
        model
            .rollout(&theta, start, 20, decide, |_, _, s| {
                steps.push(s.snapshot()?);
                Ok(())
            })
            .unwrap();
        let cfg = model.perception_config();
        g.bench_with_input(BenchmarkId::new("fresh", n), &n, |b, _| {
            b.iter(|| {
                for s in &steps {
                    perceive(&s.pos, &s.head, None, &cfg);
                }
            })
        });
        for skin in [0.1, 0.25, 0.5, 1.0, 2.0] {
            g.bench_with_input(BenchmarkId::new(skin.to_string(), n), &skin, |b, &skin| {
                b.iter(|| {
                    let mut lists = NeighbourLists::new(skin);
                    for s in &steps {
                        lists.perceive(&s.pos, &s.head, None, &cfg);
                    }
                })
            });
        }
    }
    g.finish();
}

criterion_group!(
    benches,
    neighbour_skin,
    perception,
    sim_step,
    grad_window,
    grad_window_replay,
    fit_frames
);
criterion_main!(benches);

/// One epoch of `fit` (W = 1, the paper's per-frame scheme, split gradients: two forward+backward
/// passes per frame) over 10 frames of a synthetic clip, per agent count.
fn fit_frames(c: &mut Criterion) {
    use herdfit::data::Grid;
    use herdfit::herd::fit::{fit, FitConfig};
    use herdfit::herd::params::Params;
    use herdfit::herd::synth::{synthesise, SynthConfig};
    let device = cpu_device(Precision::F32).unwrap();
    let mut g = c.benchmark_group("fit_epoch_10_frames");
    g.sample_size(10).measurement_time(Duration::from_secs(8));
    for n in [500, 1000, 1500] {
        let side = ((n as f64 * 2.0).sqrt() / 4.0).ceil() as usize * 2 + 2;
        let cfg = SynthConfig {
            params: Params::default(),
            agents: n,
            frame_count: 11,
            fps: 25.0,
            grid: Grid {
                origin: [0.0, 0.0],
                cell_size: 4.0,
                nx: side,
                ny: side,
            },
            obstacles: ndarray::Array2::zeros((side, side)),
            seed: 1,
            heading_deg: 0.0,
            precision: Precision::F32,
            density: 0.5,
            random_headings: false,
        };
        let clip = synthesise(&cfg, &device, || {}).unwrap().clip;
        let fc = FitConfig {
            window: 1,
            epochs: 1,
            frames: 0..11,
            ..FitConfig::default()
        };
        g.bench_with_input(BenchmarkId::from_parameter(n), &n, |b, _| {
            b.iter(|| fit(&clip, &Params::neutral(), &fc, None, |_, _, _, _| {}).unwrap())
        });
    }
    g.finish();
}
