//! The fused force op of eq. 3–5 as CubeCL kernels (`--device gpu`) against the ndarray fused
//! op and the tensor-op reference on the CPU: forces and gradients (positions, headings, and θ
//! through the coefficients) on recorded steps of a small herd, in f32, on lavapipe in CI (a
//! module of `tests/gpu.rs`: its device, no test binary of its own to link).

use super::{gpu, one_at_a_time};
use burn::tensor::{Device, Tensor};
use herdfit::backend::{cpu_device, Precision};
use herdfit::herd::scenario::Scenario;
use herdfit::herd::sim::{
    cube_op_passes, theta_tensor, Decide, ForceKernel, ForceTensors, HerdState, Snapshot,
    StepDecisions,
};
use herdfit_kernels::perception::BRANCH_BEHIND;
use rand::{Rng, SeedableRng};

/// Forces and gradients of the CubeCL op within this of the CPU's, relative to the largest
/// magnitude of each compared quantity (f32 on both sides; the GPU's atan2 and exp round
/// differently from the CPU kernel's, which computes in f64 and rounds once).
const OP_TOL: f64 = 1e-5;

/// 60 agents of the gradcheck scene (obstacles inside the herd, occlusion on; the default force
/// kernel), the last moved far from the others, so it has no neighbours.
fn scene(seed: u64) -> Scenario {
    let mut sc = super::scene(60, seed, ForceKernel::Fused);
    let last = sc.init.len() - 1;
    sc.init[last].x += 500.0;
    sc.init[last].y += 500.0;
    sc
}

/// The states and decisions of `steps` live steps on the CPU.
fn steps(sc: &Scenario, steps: usize, seed: u64) -> Vec<(Snapshot, StepDecisions)> {
    let dev = cpu_device(Precision::F32).unwrap();
    let theta = theta_tensor(&sc.model.params.to_vec(), &dev);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let mut out = Vec::new();
    let mut prev = HerdState::from_rows(&sc.init, &dev).snapshot().unwrap();
    sc.model
        .rollout(
            &theta,
            HerdState::from_rows(&sc.init, &dev),
            steps,
            Decide::Live {
                rng: &mut rng,
                record: None,
            },
            |_, dec, s| {
                out.push((prev.clone(), dec.clone()));
                prev = s.snapshot()?;
                Ok(())
            },
        )
        .unwrap();
    out
}

fn values<const D: usize>(t: Tensor<D>) -> Vec<f64> {
    let d = t.into_data().convert::<f32>();
    d.try_to_vec::<f32>()
        .unwrap()
        .into_iter()
        .map(f64::from)
        .collect()
}

/// The op's forces `[F_x…, F_y…]` and the gradients of L = Σ_i (a_i F_x,i + b_i F_y,i) (fixed
/// random a, b) with respect to x, y, hx, hy and θ, on the autodiff device `dev`. With
/// `per_agent` the fused op gets one coefficient row per agent (the shared row scaled by random
/// factors in [0.5, 1.5]; the tensor ops still read the shared values).
fn forces_and_gradients(
    sc: &Scenario,
    kernel: ForceKernel,
    (snap, dec): &(Snapshot, StepDecisions),
    dev: &Device,
    per_agent: bool,
) -> [Vec<f64>; 6] {
    let mut model = sc.model.clone();
    model.force_kernel = kernel;
    let theta = theta_tensor(&model.params.to_vec(), dev).require_grad();
    let mut f = ForceTensors::new(&theta, &model.params.constants);
    let n = snap.pos.len();
    if per_agent {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
        let v: Vec<f32> = (0..n * 12).map(|_| rng.gen_range(0.5..1.5)).collect();
        let scale = Tensor::<2>::from_data(burn::tensor::TensorData::new(v, [n, 12]), dev);
        f.coef = f.coef.repeat_dim(0, n) * scale;
    }
    let s = HerdState::from_snapshot(snap, dev).require_grad();
    let (fx, fy) = model.forces(&f, &s, dec);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
    let w = |rng: &mut rand_chacha::ChaCha8Rng| {
        let v: Vec<f32> = (0..n).map(|_| rng.gen_range(-1.0..1.0)).collect();
        Tensor::<2>::from_data(burn::tensor::TensorData::new(v, [n, 1]), dev)
    };
    let (a, b) = (w(&mut rng), w(&mut rng));
    let loss = (fx.clone() * a + fy.clone() * b).sum();
    let grads = loss.backward();
    let g = |t: &Tensor<1>| values(t.grad(&grads).expect("a gradient"));
    let mut forces = values(fx);
    forces.extend(values(fy));
    [forces, g(&s.x), g(&s.y), g(&s.hx), g(&s.hy), g(&theta)]
}

/// Worst difference of `got` from `want`, relative to the largest magnitude of `want`.
fn worst(got: &[f64], want: &[f64], what: &str) -> f64 {
    assert_eq!(got.len(), want.len(), "{what}: lengths");
    let scale = want.iter().fold(0.0f64, |m, v| m.max(v.abs())).max(1e-12);
    let mut w: f64 = 0.0;
    for (i, (g, c)) in got.iter().zip(want).enumerate() {
        assert!(g.is_finite(), "{what}[{i}]: {g}");
        let e = (g - c).abs() / scale;
        assert!(
            e <= OP_TOL,
            "{what}[{i}]: GPU {g} vs CPU {c} ({e:.2e} of the largest > {OP_TOL:.0e})"
        );
        w = w.max(e);
    }
    w
}

const NAMES: [&str; 6] = ["F", "∂L/∂x", "∂L/∂y", "∂L/∂hx", "∂L/∂hy", "∂L/∂θ"];

#[test]
fn cube_force_op_forces_and_gradients_match_the_ndarray_op_and_the_reference() {
    let (g, c) = (
        gpu().autodiff(),
        cpu_device(Precision::F32).unwrap().autodiff(),
    );
    let _turn = one_at_a_time();
    let sc = scene(5);
    assert!(sc.model.perception_config().occlusion, "occlusion is on");
    let radius = sc.model.perception_config().radius;
    let recorded = steps(&sc, 3, 5);
    // The lists exercise every branch of the kernels: pairs behind the agent, obstacle points,
    // an agent without neighbours and pairs within the radius left out (occluded or over K).
    let (mut behind, mut obstacles, mut lonely, mut hidden) = (0, 0, 0, 0);
    for (snap, dec) in &recorded {
        let p = &dec.perception;
        for i in 0..p.n {
            let row = i * p.k..(i + 1) * p.k;
            let listed = row.clone().filter(|&e| p.neighbour_mask[e] != 0).count();
            behind += row
                .filter(|&e| p.neighbour_mask[e] != 0 && p.neighbour_branch[e] & BRANCH_BEHIND != 0)
                .count();
            obstacles += p.obstacle_mask[i * p.ko..(i + 1) * p.ko]
                .iter()
                .filter(|&&m| m != 0)
                .count();
            lonely += usize::from(listed == 0);
            let near = (0..p.n)
                .filter(|&j| {
                    let d = [
                        snap.pos[j][0] - snap.pos[i][0],
                        snap.pos[j][1] - snap.pos[i][1],
                    ];
                    j != i && d[0] * d[0] + d[1] * d[1] < radius * radius
                })
                .count();
            hidden += usize::from(listed < near);
        }
    }
    assert!(
        behind > 0 && obstacles > 0 && lonely > 0 && hidden > 0,
        "behind {behind}, obstacle points {obstacles}, lonely {lonely}, hidden {hidden}"
    );
    for step in &recorded {
        let before = cube_op_passes();
        let on_gpu = forces_and_gradients(&sc, ForceKernel::Fused, step, &g, false);
        let after = cube_op_passes();
        assert!(
            after.0 > before.0 && after.1 > before.1,
            "the CubeCL op ran forward and backward: {before:?} → {after:?}"
        );
        let fused = forces_and_gradients(&sc, ForceKernel::Fused, step, &c, false);
        let reference = forces_and_gradients(&sc, ForceKernel::Reference, step, &c, false);
        for k in 0..6 {
            let a = worst(&on_gpu[k], &fused[k], NAMES[k]);
            let b = worst(&on_gpu[k], &reference[k], NAMES[k]);
            println!(
                "{}: GPU − ndarray op {a:.1e}, GPU − reference {b:.1e} of the largest",
                NAMES[k]
            );
        }
        // Same inputs, same bytes: the backward pass gathers without atomics.
        let again = forces_and_gradients(&sc, ForceKernel::Fused, step, &g, false);
        assert_eq!(
            again, on_gpu,
            "a re-run of the CubeCL op changed its results"
        );
        // One coefficient row per agent (behaviour regions): the GPU op against the ndarray op.
        let on_gpu = forces_and_gradients(&sc, ForceKernel::Fused, step, &g, true);
        let fused = forces_and_gradients(&sc, ForceKernel::Fused, step, &c, true);
        for k in 0..6 {
            let a = worst(&on_gpu[k], &fused[k], NAMES[k]);
            println!(
                "{} (per-agent coefficients): GPU − ndarray op {a:.1e}",
                NAMES[k]
            );
        }
    }
}

#[test]
fn force_kernel_reference_on_the_gpu_bypasses_the_cube_op() {
    let g = gpu().autodiff();
    let _turn = one_at_a_time();
    let sc = scene(6);
    let recorded = steps(&sc, 1, 6);
    let before = cube_op_passes();
    let reference = forces_and_gradients(&sc, ForceKernel::Reference, &recorded[0], &g, false);
    assert_eq!(cube_op_passes(), before, "Reference ran the CubeCL op");
    let fused = forces_and_gradients(&sc, ForceKernel::Fused, &recorded[0], &g, false);
    assert!(cube_op_passes().0 > before.0);
    for k in 0..6 {
        worst(&fused[k], &reference[k], NAMES[k]);
    }
    // Another computation, not the CubeCL op's bytes under another name.
    assert_ne!(
        fused[0], reference[0],
        "Reference forces equal the CubeCL op's bit for bit"
    );
}
