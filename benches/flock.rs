//! Criterion benchmarks of the flock's steady flight (#19): one key shape for 40 birds (eq. 2
//! draw + Levenberg–Marquardt continuation on eq. 4, analytic Jacobian) against the same key shape
//! with the former solver budget of 400 × N evaluations per run (the peer: the same key shape,
//! failed runs taking their full budget), the key shape after it, one solve of eq. 4 with the analytic against a
//! finite-difference Jacobian, e_i of 40 birds by the pair kernel against `power::savings`, and
//! one initiation step of 41 birds (HPR perception for every bird, separation, eq. 5–6).
//!
//! `cargo bench --bench flock`

use criterion::{criterion_group, criterion_main, Criterion};
use herdfit::flock::extract::{extract, ExtractConfig};
use herdfit::flock::initiation::{random_start, Initiation, InitiationConfig, Target};
use herdfit::flock::pairs::Pairs;
use herdfit::flock::solve::PositionProblem;
use herdfit::flock::{power, steady, synth};
use levenberg_marquardt::{LeastSquaresProblem, LevenbergMarquardt};
use nalgebra::{DMatrix, DVector, Dyn, Owned};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::time::Duration;

struct Setup {
    first: steady::KeyShape,
    nl: usize,
    nr: usize,
    range: Vec<[f64; 2]>,
    gaps: [f64; 2],
    family: herdfit::flock::family::Family,
    target: Vec<[f64; 2]>,
}

fn setup(n: usize) -> Setup {
    let ex = synth::synth(&synth::SynthConfig {
        birds: 41,
        seed: 3,
        ..synth::SynthConfig::default()
    })
    .unwrap();
    let p = extract(&ex, "bench", &ExtractConfig::default()).unwrap();
    let cfg = steady::SteadyConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let init = steady::initial_shapes(&p, n, &cfg, &mut rng).unwrap();
    let (_, range) = steady::ranges(&init.shapes).unwrap();
    let m: Vec<f64> = p.frames.iter().map(|f| f.mean_gap).collect();
    Setup {
        first: steady::first_key(&init.shapes[0]).unwrap(),
        nl: init.nl,
        nr: init.nr,
        range,
        gaps: [
            m.iter().cloned().fold(f64::INFINITY, f64::min),
            m.iter().cloned().fold(f64::NEG_INFINITY, f64::max),
        ],
        family: herdfit::flock::family::Family::of_example(&p, &init),
        target: init.shapes[0].clone(),
    }
}

/// The same problem with a central-difference Jacobian.
struct Fd(PositionProblem);

impl LeastSquaresProblem<f64, Dyn, Dyn> for Fd {
    type ResidualStorage = Owned<f64, Dyn>;
    type JacobianStorage = Owned<f64, Dyn, Dyn>;
    type ParameterStorage = Owned<f64, Dyn>;
    fn set_params(&mut self, p: &DVector<f64>) {
        self.0.set_params(p)
    }
    fn params(&self) -> DVector<f64> {
        self.0.params()
    }
    fn residuals(&self) -> Option<DVector<f64>> {
        self.0.residuals()
    }
    fn jacobian(&self) -> Option<DMatrix<f64>> {
        let p0 = self.0.params();
        let n = self.0.x.len();
        let mut j = DMatrix::zeros(n, p0.len());
        let mut q = self.0.clone();
        for k in 0..p0.len() {
            let h = 1e-6;
            let mut p = p0.clone();
            p[k] += h;
            q.set_params(&p);
            let a = q.residuals()?;
            p[k] -= 2.0 * h;
            q.set_params(&p);
            let b = q.residuals()?;
            j.set_column(k, &((a - b) / (2.0 * h)));
        }
        Some(j)
    }
}

fn key_shape(c: &mut Criterion) {
    let s = setup(40);
    let cfg = steady::SteadyConfig::default();
    let mut g = c.benchmark_group("flock_key_shape_40");
    g.sample_size(20).measurement_time(Duration::from_secs(8));
    g.bench_function("analytic_jacobian", |b| {
        b.iter(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            steady::next_key(
                &s.first, s.nl, s.nr, &s.range, s.gaps, &s.family, &cfg, &mut rng,
            )
        })
    });
    let old = steady::SteadyConfig {
        solve_evaluations: 400 * 40,
        ..cfg.clone()
    };
    g.bench_function("analytic_jacobian_budget_400n", |b| {
        b.iter(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            steady::next_key(
                &s.first, s.nl, s.nr, &s.range, s.gaps, &s.family, &old, &mut rng,
            )
        })
    });
    // One solve of the key shape's final equations from the previous positions.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let k = steady::next_key(
        &s.first, s.nl, s.nr, &s.range, s.gaps, &s.family, &cfg, &mut rng,
    );
    // The key shape after it (from a key shape on a uniform layout, as every later one is).
    g.bench_function("second_key_shape", |b| {
        b.iter(|| {
            let mut rng = ChaCha8Rng::seed_from_u64(8);
            steady::next_key(&k, s.nl, s.nr, &s.range, s.gaps, &s.family, &cfg, &mut rng)
        })
    });
    let x: Vec<f64> = k.pos.iter().map(|p| p[0]).collect();
    let y0: Vec<f64> = s
        .first
        .pos
        .iter()
        .map(|p| p[1] - s.first.pos[0][1])
        .collect();
    let lm = LevenbergMarquardt::new()
        .with_ftol(1e-15)
        .with_xtol(1e-15)
        .with_gtol(1e-15)
        .with_patience(400);
    g.bench_function("one_solve_analytic", |b| {
        b.iter(|| {
            lm.minimize(PositionProblem::new(
                x.clone(),
                k.xi_target.clone(),
                0,
                y0.clone(),
            ))
        })
    });
    g.bench_function("one_solve_finite_differences", |b| {
        b.iter(|| {
            lm.minimize(Fd(PositionProblem::new(
                x.clone(),
                k.xi_target.clone(),
                0,
                y0.clone(),
            )))
        })
    });
    g.finish();
    let pos: Vec<[f64; 2]> = k.pos.clone();
    let mut g = c.benchmark_group("flock_savings");
    g.bench_function("e_i_40_birds", |b| {
        b.iter(|| power::savings_unchecked(&pos))
    });
    let xs: Vec<f64> = pos.iter().map(|p| p[0]).collect();
    let ys: Vec<f64> = pos.iter().map(|p| p[1]).collect();
    let pairs = Pairs::new(&xs);
    let (mut e, mut dg) = (vec![0.0; xs.len()], Vec::new());
    g.bench_function("e_i_and_dg_40_birds_pairs", |b| {
        b.iter(|| pairs.eval(&ys, &mut e, &mut dg))
    });
    g.finish();
}

fn initiation_step(c: &mut Criterion) {
    let s = setup(41);
    let cfg = InitiationConfig::default();
    let target = Target {
        pos: s.target.clone(),
        nl: s.nl,
        nr: s.nr,
    };
    let mut rng = ChaCha8Rng::seed_from_u64(2);
    let start = random_start(41, &cfg, &mut rng);
    let mut g = c.benchmark_group("flock_initiation");
    g.sample_size(20).measurement_time(Duration::from_secs(5));
    g.bench_function("step_41_birds", |b| {
        let mut sim = Initiation::new(cfg.clone(), target.clone(), start.clone()).unwrap();
        b.iter(|| sim.step())
    });
    g.finish();
}

criterion_group!(benches, key_shape, initiation_step);
criterion_main!(benches);
