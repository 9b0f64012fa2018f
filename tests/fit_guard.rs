//! The fit-loss guard of issue #14: a clip whose velocity field turns NaN part-way (a clip that
//! `ClipFields::load` would refuse, built in memory to reach the loss) stops the fit with one
//! message naming the epoch and the window, and the checkpoint of the last finished epoch is kept
//! byte for byte.

mod common;

use common::{ok, s};
use herdfit::data::ClipFields;
use herdfit::herd::fit::{fit_clips, CheckpointDir, FitConfig};
use herdfit::herd::params::Params;

#[test]
fn a_nan_loss_stops_the_fit_naming_epoch_and_window_and_keeps_the_checkpoint() {
    let t = tempfile::tempdir().unwrap();
    let dir = t.path().join("clip");
    #[rustfmt::skip]
    ok(&["synth", "--agents", "40", "--frame-count", "9", "--grid-size", "8x8", "--cell-size",
         "2", "--seed", "5", "--out", s(&dir)]);
    let clip = ClipFields::load(&dir).unwrap();
    let init = Params::default();
    let cfg = FitConfig {
        frames: 0..9,
        epochs: 2,
        window: 4,
        ..FitConfig::default()
    };
    let ckpt = CheckpointDir {
        dir: t.path().join("ck"),
        resume: false,
    };
    std::fs::create_dir_all(&ckpt.dir).unwrap();
    // A run "killed" in its second epoch (the progress callback panics): epoch 0's checkpoint.
    let killed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        fit_clips(&[&clip], &init, &cfg, Some(&ckpt), |epoch, _, _, _| {
            assert!(epoch < 1, "killed in epoch 1");
        })
    }));
    assert!(killed.is_err());
    let good = std::fs::read(ckpt.file()).unwrap();
    let k: serde_json::Value = serde_json::from_slice(&good).unwrap();
    assert_eq!(k["epochs_done"], 1);

    // The same clip with NaN velocities from frame 5 on: the first window (frames 0..4) is
    // finite, the second (4..8) targets NaN.
    let mut bad = clip.clone();
    for f in 5..bad.frames() {
        bad.velocity
            .slice_mut(ndarray::s![f, .., .., ..])
            .fill(f32::NAN);
    }
    let resume = CheckpointDir {
        dir: ckpt.dir.clone(),
        resume: true,
    };
    let mut windows = Vec::new();
    let e = fit_clips(&[&bad], &init, &cfg, Some(&resume), |epoch, frame, _, _| {
        windows.push((epoch, frame))
    })
    .expect_err("a NaN loss must stop the fit")
    .to_string();
    assert!(
        e.contains("epoch 1") && e.contains("window frames 4..8") && e.contains("not finite"),
        "{e}"
    );
    assert!(e.contains("likely cause"), "{e}");
    assert_eq!(e.lines().count(), 1, "{e}");
    // Resumed at epoch 1: its first window ran, the second stopped before the optimiser step.
    assert_eq!(windows, vec![(1, 4)]);
    assert_eq!(
        std::fs::read(ckpt.file()).unwrap(),
        good,
        "the last good checkpoint is kept"
    );
}
