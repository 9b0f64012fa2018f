//! Shared by `tests/fused.rs` (f64) and `tests/fused_step_f32.rs` (f32): one precision per
//! process (`backend::cpu_device`).

use burn::tensor::Device;
use herdfit::backend::{cpu_device, Precision};
use herdfit::herd::params::Params;
use herdfit::herd::scenario::default_scenario;
use herdfit::herd::sim::{plain_step, theta_tensor, ForceTensors, HerdState, Model};
use herdfit_kernels::P2;
use rand::{Rng, SeedableRng};

/// The bit patterns of a state's values (f32 values widen to f64 exactly).
fn bits(s: &HerdState) -> Vec<u64> {
    let snap = s.snapshot().unwrap();
    snap.pos
        .iter()
        .chain(&snap.head)
        .flatten()
        .chain(&snap.speed)
        .map(|v| v.to_bits())
        .collect()
}

/// Five steps from the gradcheck scene (obstacles inside the herd, uniform guidance so agents
/// lead), each by the plain step on the plain device and by the tensor ops around the fused
/// forces on the autodiff device, with and without an extra force: the same bytes every step.
pub fn plain_step_has_the_bytes_of_the_tensor_ops(precision: Precision) {
    let dev = cpu_device(precision).unwrap();
    let ad: Device = dev.clone().autodiff();
    for seed in 0..3u64 {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let theta: [f64; 12] = std::array::from_fn(|_| rng.gen_range(0.15..0.95));
        let sc = default_scenario(Params::default().with_vec(&theta), 300, seed).unwrap();
        let model: &Model = &sc.model;
        assert!(model.force_kernel.is_fused());
        let n = sc.init.len();
        for with_extra in [false, true] {
            let (mut plain, mut tensor) = (
                HerdState::from_rows(&sc.init, &dev),
                HerdState::from_rows(&sc.init, &ad),
            );
            let fp = ForceTensors::new(&theta_tensor(&theta, &dev), &model.params.constants);
            let fa = ForceTensors::new(&theta_tensor(&theta, &ad), &model.params.constants);
            let mut leaders = 0;
            for t in 0..5 {
                let dec = model.decide(&plain.snapshot().unwrap(), &mut rng);
                leaders += dec.leader.iter().filter(|&&l| l).count();
                let e: Vec<P2> = (0..n)
                    .map(|i| {
                        let a = (i * 7 + t) as f64;
                        [0.3 * a.sin(), 0.2 * a.cos()]
                    })
                    .collect();
                let extra = with_extra.then_some(&e[..]);
                let next = plain_step(model, &fp, &plain, &dec, extra)
                    .expect("the plain ndarray device has the plain step");
                let want = model.step_with(&fa, &tensor, &dec, extra).unwrap();
                assert_eq!(
                    bits(&next),
                    bits(&want),
                    "seed {seed} step {t} extra {with_extra}"
                );
                // The herd moved.
                assert_ne!(bits(&next), bits(&plain), "seed {seed} step {t}");
                (plain, tensor) = (next, want);
            }
            assert!(leaders > 0, "seed {seed}: no leaders");
            // Not on the autodiff device: the caller runs the tensor ops there.
            assert!(plain_step(
                model,
                &fa,
                &tensor,
                &model.decide(&tensor.snapshot().unwrap(), &mut rng),
                None
            )
            .is_none());
        }
    }
}
