//! The fused force op (`sim::fused`) against the tensor-op reference (`Model::reference_forces`)
//! in f64: forces and gradients (all 12 parameters and the initial state) on random scenes with
//! obstacles, leaders and padded list entries, through checkpointed autodiff too, and gradcheck
//! through the fused op at 10 and 50 steps (DESIGN §7).

use burn::tensor::{Device, Tensor};
use herdfit::backend::{cpu_device, Compute, Precision};
use herdfit::herd::gradcheck::{gradcheck, record};
use herdfit::herd::params::Params;
use herdfit::herd::scenario::{default_scenario, objective, Scenario};
use herdfit::herd::sim::{
    fused_forces, read_vec, theta_tensor, Decide, ForceKernel, ForceTensors, HerdState, Model,
    Recording, StepDecisions,
};
use rand::{Rng, SeedableRng};

fn device() -> Device {
    cpu_device(Precision::F64).unwrap()
}

/// The gradcheck scene (obstacle blocks inside the herd, uniform guidance so the leader rule
/// acts) with random parameters and headings spread all round, so bearings take every branch.
fn scene(agents: usize, seed: u64) -> Scenario {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let theta: [f64; 12] = std::array::from_fn(|_| rng.gen_range(0.15..0.95));
    let mut params = Params::default().with_vec(&theta);
    params.constants.max_neighbours = 12;
    let mut sc = default_scenario(params, agents, seed).unwrap();
    for r in &mut sc.init {
        let a: f64 = rng.gen_range(-3.2..3.2);
        let s = (r.vx * r.vx + r.vy * r.vy).sqrt();
        r.vx = s * a.cos();
        r.vy = s * a.sin();
    }
    sc
}

fn with_kernel(sc: &Scenario, k: ForceKernel) -> Model {
    Model {
        force_kernel: k,
        ..sc.model.clone()
    }
}

/// What a scene must exercise: padding, obstacle points and leaders.
fn assert_exercises_everything(dec: &StepDecisions) {
    let p = &dec.perception;
    let real = p.neighbour_mask.iter().filter(|&&m| m == 1).count();
    assert!(real > 0 && real < p.n * p.k, "no padded neighbour entries");
    assert!(p.obstacle_mask.contains(&1), "no obstacle points");
    assert!(p.obstacle_mask.contains(&0), "no padded obstacle entries");
    assert!(dec.leader.contains(&true), "no leaders");
}

fn close(a: &[f64], b: &[f64], tol: f64, what: &str) {
    assert_eq!(a.len(), b.len(), "{what}: lengths");
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        assert!(x.is_finite() && y.is_finite(), "{what}[{i}]: {x} vs {y}");
        assert!(
            (x - y).abs() <= tol * (1.0 + y.abs()),
            "{what}[{i}]: fused {x} vs reference {y}"
        );
    }
}

fn column(t: Tensor<2>) -> Vec<f64> {
    let n = t.dims()[0];
    read_vec(&t.reshape([n])).unwrap()
}

#[test]
fn fused_forces_equal_the_tensor_ops_on_random_scenes() {
    let dev = device();
    for seed in 0..3 {
        let sc = scene(300, seed);
        let state = HerdState::from_rows(&sc.init, &dev);
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let dec = sc.model.decide(&state.snapshot().unwrap(), &mut rng);
        assert_exercises_everything(&dec);
        let f = ForceTensors::new(
            &theta_tensor(&sc.model.params.to_vec(), &dev),
            &sc.model.params.constants,
        );
        let (fx, fy) = fused_forces(&f, &state, &dec).expect("ndarray has the fused op");
        let (rx, ry) = Model::reference_forces(&f, &state, &dec);
        let (fx, rx) = (column(fx), column(rx));
        close(&fx, &rx, 1e-10, "F_x");
        close(&column(fy), &column(ry), 1e-10, "F_y");
        // Forces of this size move the herd (not all zero).
        assert!(fx.iter().map(|v| v.abs()).sum::<f64>() > 0.1 * fx.len() as f64);
    }
}

#[test]
fn fused_forces_equal_the_tensor_ops_with_per_agent_parameters() {
    let dev = device();
    let sc = scene(200, 7);
    let state = HerdState::from_rows(&sc.init, &dev);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let dec = sc.model.decide(&state.snapshot().unwrap(), &mut rng);
    let thetas: Vec<[f64; 12]> = (0..sc.init.len())
        .map(|_| std::array::from_fn(|_| rng.gen_range(0.1..1.0)))
        .collect();
    let f = ForceTensors::per_agent(&thetas, &sc.model.params.constants, &dev);
    let (fx, fy) = fused_forces(&f, &state, &dec).unwrap();
    let (rx, ry) = Model::reference_forces(&f, &state, &dec);
    close(&column(fx), &column(rx), 1e-10, "F_x");
    close(&column(fy), &column(ry), 1e-10, "F_y");
}

/// J of `steps` replayed steps from `sc.init`; gradients of all 12 parameters and of the initial
/// positions and headings.
fn gradients(model: &Model, sc: &Scenario, rec: &Recording, steps: usize, ad: &Device) -> Vec<f64> {
    let theta = theta_tensor(&model.params.to_vec(), ad).require_grad();
    let s = HerdState::from_rows(&sc.init, ad);
    // The fused path really is taken on this (autodiff) device.
    let f = ForceTensors::new(&theta, &model.params.constants);
    assert!(fused_forces(&f, &s, &rec.steps[0]).is_some());
    let s = s.require_grad();
    let end = model
        .rollout::<rand_chacha::ChaCha8Rng>(
            &theta,
            s.clone(),
            steps,
            Decide::Replay(rec),
            |_, _, _| Ok(()),
        )
        .unwrap();
    let grads = objective(&end, 4.0).backward();
    let mut out = read_vec(&theta.grad(&grads).expect("θ gradient")).unwrap();
    for t in [&s.x, &s.y, &s.hx, &s.hy] {
        out.extend(read_vec(&t.grad(&grads).expect("state gradient")).unwrap());
    }
    out
}

#[test]
fn fused_gradients_equal_the_tensor_ops_through_ten_steps() {
    let dev = device();
    for seed in [11, 12] {
        let sc = scene(250, seed);
        let rec = record(&sc, 10, seed, &dev).unwrap();
        assert_exercises_everything(&rec.steps[0]);
        let ad = dev.clone().autodiff();
        let fused = gradients(&with_kernel(&sc, ForceKernel::Fused), &sc, &rec, 10, &ad);
        let reference = gradients(
            &with_kernel(&sc, ForceKernel::Reference),
            &sc,
            &rec,
            10,
            &ad,
        );
        close(&fused[..12], &reference[..12], 1e-10, "∂J/∂θ");
        close(&fused[12..], &reference[12..], 1e-10, "∂J/∂(x, y, hx, hy)");
        assert!(
            fused[..12].iter().all(|g| g.abs() > 1e-9),
            "{:?}",
            &fused[..12]
        );
    }
}

#[test]
fn fused_gradients_are_the_same_under_gradient_checkpointing() {
    let dev = device();
    let sc = scene(150, 21);
    let rec = record(&sc, 8, 21, &dev).unwrap();
    let plain = dev.clone().autodiff();
    let ckpt = dev.clone().autodiff().gradient_checkpointing();
    let fused = with_kernel(&sc, ForceKernel::Fused);
    let a = gradients(&fused, &sc, &rec, 8, &plain);
    let b = gradients(&fused, &sc, &rec, 8, &ckpt);
    let r = gradients(
        &with_kernel(&sc, ForceKernel::Reference),
        &sc,
        &rec,
        8,
        &ckpt,
    );
    close(&b, &a, 1e-12, "checkpointed vs plain");
    close(&b, &r, 1e-10, "checkpointed fused vs reference");
}

#[test]
fn gradcheck_passes_through_the_fused_op_at_10_and_50_steps() {
    let dev = device();
    let sc = default_scenario(Params::default(), 120, 3).unwrap();
    assert_eq!(sc.model.force_kernel, ForceKernel::Fused, "the default");
    for steps in [10, 50] {
        let rec = record(&sc, steps, 3, &dev).unwrap();
        let r = gradcheck(
            &sc,
            steps,
            (Compute::Cpu, Precision::F64),
            1e-4,
            &rec,
            || {},
        )
        .unwrap();
        assert_eq!(r.parameters.len(), 12);
        assert!(r.max_rel_err <= 1e-6, "{steps} steps: {r:?}");
        assert!(
            r.parameters.iter().all(|p| p.autodiff.abs() > 1e-8),
            "{r:?}"
        );
    }
}

#[path = "fused_step/body.rs"]
mod body;

/// The plain simulation step (`sim::plain_step`) has the bytes of the tensor-op step around the
/// fused forces, in f64 (f32: `tests/fused_step_f32.rs`).
#[test]
fn plain_step_has_the_bytes_of_the_tensor_ops_in_f64() {
    body::plain_step_has_the_bytes_of_the_tensor_ops(Precision::F64);
}
