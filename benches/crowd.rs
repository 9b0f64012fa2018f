//! Crowd simulation throughput (agent-steps per second) with k = 100 and ≥ 5,000 training samples,
//! on both cores and on one thread, and its parts against peers in the same run: our kd-tree vs
//! kiddo's and brute-force kNN, our 2-D k-means vs linfa-clustering's KMeans on the same 100
//! actions.
//!
//! `cargo bench --bench crowd`

use criterion::{criterion_group, criterion_main, BatchSize, BenchmarkId, Criterion, Throughput};
use herdfit::crowd::action::{kmeans, ActionModel, Scratch};
use herdfit::crowd::knn::brute_force;
use herdfit::crowd::model::{learn, CrowdModel, LearnConfig};
use herdfit::crowd::sim::{entries_from_layout, typical_speed};
use herdfit::crowd::step::{advance, plan, Agent};
use herdfit::crowd::synth::{corridor, SynthConfig};
use herdfit::progress::NoProgress;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;

/// The synthetic corridor crowd the model learns from (120 s).
fn source() -> herdfit::data::tracks::Tracks {
    corridor(&SynthConfig {
        duration: 120.0,
        ..SynthConfig::default()
    })
    .unwrap()
}

fn model() -> CrowdModel {
    let src = source();
    let cfg = LearnConfig {
        max_samples: 6000,
        ..LearnConfig::default()
    };
    let m = learn(&[src], &cfg, &mut NoProgress).unwrap();
    assert!(
        m.behaviours[0].model.samples.len() >= 5000,
        "≥ 5,000 samples"
    );
    assert_eq!(m.config.action.k, 100);
    m
}

/// `n` agents spread over a 40 × 40 m square walking in random directions.
fn agents(m: &CrowdModel, n: usize) -> Vec<Agent> {
    let mut layout = herdfit::crowd::layout::Layout::default();
    let side = (n as f64).sqrt().ceil() as usize;
    for i in 0..n {
        let (x, y) = (
            (i % side) as f64 * 40.0 / side as f64,
            (i / side) as f64 * 40.0 / side as f64,
        );
        layout.spawns.push(herdfit::crowd::layout::Spawn {
            position: [x, y],
            spread: 0.3,
            goal: [40.0 - y, x],
            count: 1,
            start: 0.0,
            interval: 1.0,
        });
    }
    let dt = m.dt;
    entries_from_layout(&layout, dt, typical_speed(m), 0)
        .into_iter()
        .map(|e| {
            let back = [
                e.position[0] - e.velocity[0] * dt,
                e.position[1] - e.velocity[1] * dt,
            ];
            let h = herdfit::crowd::features::unit(e.velocity).unwrap_or([1.0, 0.0]);
            Agent::new(e.id, vec![back, e.position], h, e.goal, 0, dt)
        })
        .collect()
}

/// `n` agents in states like the training ones: the corridor walkers present at frames 50, 87,
/// 124, … of the source crowd (each with its last two positions and its exit as its goal),
/// each frame's group moved 50 m further along y so that the groups do not meet.
fn corridor_agents(m: &CrowdModel, n: usize) -> Vec<Agent> {
    let scene = herdfit::crowd::features::Scene::from_tracks(&source(), 0.0).unwrap();
    let mut out = Vec::new();
    for (copy, f) in (50..scene.at_frame.len()).step_by(37).enumerate() {
        let dy = copy as f64 * 50.0;
        for &si in &scene.at_frame[f] {
            let s = &scene.segments[si];
            let j = f - s.start;
            if j < 1 || j + 1 >= s.pos.len() {
                continue;
            }
            let at = |p: [f64; 2]| [p[0], p[1] + dy];
            let (a, b) = (at(s.pos[j - 1]), at(s.pos[j]));
            let h =
                herdfit::crowd::features::unit([b[0] - a[0], b[1] - a[1]]).unwrap_or([1.0, 0.0]);
            let goal = at(*s.pos.last().unwrap());
            out.push(Agent::new(
                out.len() as u64,
                vec![a, b],
                h,
                Some(goal),
                0,
                m.dt,
            ));
            if out.len() == n {
                return out;
            }
        }
    }
    panic!("the corridor has fewer than {n} walkers at the sampled frames");
}

/// Steps the agents take before the measured step (so the states are mid-simulation ones).
const WARM_UP_STEPS: usize = 10;

fn step(m: &CrowdModel, a: &mut [Agent]) {
    let p = plan(m, a);
    advance(m, a, &p, None, 8);
}

/// One step of `n` agents from the same mid-simulation state each iteration, on the default
/// thread pool (both cores) and on one thread (the peer: the parallel speed-up in the same run).
fn bench_step(c: &mut Criterion) {
    let m = model();
    let one = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let mut g = c.benchmark_group("crowd_step");
    // The corridor's sampled frames hold fewer than 400 walkers: 100 of them.
    for (crowd, n) in [("agents", 100usize), ("agents", 400), ("corridor", 100)] {
        let mut a = if crowd == "agents" {
            agents(&m, n)
        } else {
            corridor_agents(&m, n)
        };
        for _ in 0..WARM_UP_STEPS {
            step(&m, &mut a);
        }
        g.throughput(Throughput::Elements(n as u64));
        g.bench_with_input(BenchmarkId::new(crowd, n), &n, |b, _| {
            b.iter_batched_ref(|| a.clone(), |a| step(&m, a), BatchSize::SmallInput)
        });
        let one_thread = format!("{crowd}_1_thread");
        g.bench_with_input(BenchmarkId::new(one_thread, n), &n, |b, _| {
            b.iter_batched_ref(
                || a.clone(),
                |a| one.install(|| step(&m, a)),
                BatchSize::SmallInput,
            )
        });
    }
    g.finish();
}

fn bench_parts(c: &mut Criterion) {
    let m = model();
    let am: &ActionModel = &m.behaviours[0].model;
    let s = &am.samples;
    let q: Vec<f64> = s.states[123 * s.dims..124 * s.dims].to_vec();
    let mut g = c.benchmark_group("crowd_parts");
    g.bench_function("knn_kdtree_k100", |b| {
        let tree = herdfit::crowd::knn::StateTree::build(&s.states, s.dims).unwrap();
        let mut out = Vec::new();
        b.iter(|| tree.nearest(&q, 100, &mut out))
    });
    g.bench_function("knn_kiddo_k100", |b| {
        let tree = herdfit::crowd::knn::KiddoTree::build(&s.states, s.dims).unwrap();
        let mut out = Vec::new();
        b.iter(|| tree.nearest(&q, 100, &mut out))
    });
    g.bench_function("knn_brute_force_k100", |b| {
        b.iter(|| brute_force(&s.states, s.dims, &q, 100))
    });
    let acts: Vec<[f64; 2]> = s.actions[..100].to_vec();
    g.bench_function("kmeans3_ours", |b| {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut assign = Vec::new();
        b.iter(|| kmeans(&acts, 3, 20, &mut rng, &mut assign))
    });
    g.bench_function("kmeans3_linfa", |b| {
        use linfa::traits::Fit;
        let data = ndarray016::Array2::from_shape_fn((100, 2), |(i, j)| acts[i][j]);
        let ds = linfa::DatasetBase::from(data);
        b.iter(|| {
            linfa_clustering::KMeans::params_with_rng(3, ChaCha8Rng::seed_from_u64(0))
                .max_n_iterations(20)
                .fit(&ds)
                .unwrap()
        })
    });
    g.bench_function("decide_one_query", |b| {
        let mut rng = ChaCha8Rng::seed_from_u64(0);
        let mut sc = Scratch::default();
        b.iter(|| am.decide(&q, [1.2, 0.0], &m.config.action, &mut rng, &mut sc))
    });
    g.finish();
}

criterion_group!(benches, bench_step, bench_parts);
criterion_main!(benches);
