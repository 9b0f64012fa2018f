//! The track objective's gradient (issue #49) against finite differences in f64: a window of a
//! synthetic herd's tracks, rolled out both ways (neighbours replayed, and free), its loss
//! differentiated by burn's autodiff through the fused force op, and differenced with the
//! decisions of the autodiff run replayed (so both see the same lists, roles, branches and noise).
//! This binary runs in f64 only (burn fixes a process's float type).

mod common;
use common::small_clip;
use herdfit::backend::{cpu_device, Precision};
use herdfit::herd::params::{Params, N_PARAMS};
use herdfit::herd::sim::{read_vec, theta_tensor, Decide, ForceTensors, Recording};
use herdfit::herd::track_fit::{
    load_input, prepare, window_loss, Leaders, Rollout, Scoring, Speeds, TrackClip, TrackFitConfig,
    Window,
};
use rand::SeedableRng;

/// The loss of window `w` at `theta` on `device`, with the decisions of `rec` (replayed) or live
/// (recorded into `rec`); with the gradient when `grad`.
fn loss(
    clip: &TrackClip,
    w: &Window,
    how: &Scoring,
    theta: &[f64; N_PARAMS],
    device: &burn::tensor::Device,
    rec: &mut Recording,
    live: bool,
) -> (f64, Option<Vec<f64>>) {
    let th = theta_tensor(theta, device);
    let th = if live { th.require_grad() } else { th };
    let forces = ForceTensors::new(&th, &clip.model.params.constants);
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(9);
    let decide = match live {
        true => Decide::Live {
            rng: &mut rng,
            record: Some(rec),
        },
        false => Decide::Replay(rec),
    };
    let l = window_loss(clip, w, how, &forces, device, decide)
        .unwrap()
        .expect("the window scores animals");
    assert!(
        how.spacing_weight == 0.0 || l.n_spacing > 0,
        "the spacing term compared no distance"
    );
    let value = read_vec(&l.loss.clone().detach()).unwrap()[0];
    let g = live.then(|| {
        let grads = l.loss.backward();
        read_vec(&th.grad(&grads).expect("θ has a gradient")).unwrap()
    });
    (value, g)
}

#[test]
fn the_track_loss_gradient_matches_finite_differences_in_f64() {
    let dir = tempfile::tempdir().unwrap();
    let path = small_clip(dir.path(), 60, 24, 5);
    let device = cpu_device(Precision::F64).unwrap();
    let ad = device.clone().autodiff();
    // An interior point away from θ*, so every force acts with a gradient of its own.
    let theta = [
        0.42, 0.55, 0.63, 0.58, 0.31, 0.47, 0.52, 0.44, 0.61, 0.66, 0.37, 0.58,
    ];
    let start = Params::default().with_vec(&theta);
    let mut clips = vec![load_input(&path, None, 0..0, (Leaders::Field, 0.0), &start).unwrap()];
    let cfg = TrackFitConfig {
        precision: Precision::F64,
        ..TrackFitConfig::default()
    };
    prepare(&mut clips, &start, &cfg).unwrap();
    let clip = &clips[0];
    let w = clip.windows(0, 10, 10, 2)[0];
    // The spacing term (sorted nearest-neighbour distances) on in two of the four.
    let cases = [
        (Rollout::Conditioned, Speeds::Noisy, 2.0),
        (Rollout::Conditioned, Speeds::Tracks, 0.0),
        (Rollout::Free, Speeds::Noisy, 2.0),
        (Rollout::Free, Speeds::Tracks, 0.0),
    ];
    for (rollout, speeds, spacing_weight) in cases {
        let how = Scoring {
            rollout,
            speeds,
            heading_weight: 1.0,
            min_speed: 0.1,
            spacing_weight,
        };
        let nf = clip.starters(w.start).len();
        let mut rec = Recording::new(nf);
        let (_, g) = loss(clip, &w, &how, &theta, &ad, &mut rec, true);
        let g = g.unwrap();
        let h = 1e-4;
        let fd: Vec<f64> = (0..N_PARAMS)
            .map(|j| {
                let mut at = |d: f64| {
                    let mut t = theta;
                    t[j] += d;
                    loss(clip, &w, &how, &t, &device, &mut rec, false).0
                };
                (-at(2.0 * h) + 8.0 * at(h) - 8.0 * at(-h) + at(-2.0 * h)) / (12.0 * h)
            })
            .collect();
        let scale = fd.iter().fold(0.0f64, |m, x| m.max(x.abs()));
        assert!(
            scale > 1e-6,
            "{rollout}/{speeds}: the loss depends on θ ({fd:?})"
        );
        for j in 0..N_PARAMS {
            let rel = (g[j] - fd[j]).abs() / fd[j].abs().max(1e-3 * scale);
            assert!(
                rel <= 1e-6,
                "{rollout}/{speeds}, parameter {j}: autodiff {} vs differences {} (relative {rel:e})",
                g[j],
                fd[j]
            );
        }
    }
}
