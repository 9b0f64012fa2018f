//! The fit's global phase (issue #15 item 3): the multi-start's first candidate is the plain fit
//! on the refinement frames, the candidates are ranked by the objective on the held-out frames
//! with common random numbers, the choice never scores worse than the plain fit there, and bad
//! settings fail cleanly. (The two-basin case is `optim::multistart`'s unit test; kill-and-resume
//! identity with the phase is in tests/fit.rs.)

mod common;
use common::{fails, ok, s};
use herdfit::data::ClipFields;
use herdfit::herd::fit::global::{candidate_starts, objective, split_frames};
use herdfit::herd::fit::{fit_clips, fit_global, loss_of, FitConfig, GlobalPhase};
use herdfit::herd::params::Params;
use std::path::Path;

fn clip(d: &Path) -> std::path::PathBuf {
    let out = d.join("clip");
    ok(&[
        "synth",
        "--agents",
        "120",
        "--frame-count",
        "40",
        "--grid-size",
        "10x6",
        "--cell-size",
        "3",
        "--seed",
        "5",
        "--out",
        s(&out),
    ]);
    out
}

#[test]
fn the_global_phase_ranks_refined_candidates_on_held_out_frames() {
    let dir = tempfile::tempdir().unwrap();
    let c = ClipFields::load(&clip(dir.path())).unwrap();
    let cfg = FitConfig {
        window: 4,
        epochs: 3,
        frames: 0..40,
        seed: 2,
        global: GlobalPhase {
            starts: 3,
            holdout: 0.25,
        },
        ..FitConfig::default()
    };
    let init = Params::neutral();
    let (res, rep) = fit_global(&[&c], &init, &cfg, None, |_, _, _, _| {}).unwrap();
    let rep = rep.expect("the phase ran");
    assert_eq!(
        (rep.refine_frames.clone(), rep.holdout_frames.clone()),
        (0..30, 30..40)
    );
    assert_eq!(rep.candidates.len(), 3);
    // Candidate 0 starts at the given start; the others are the Latin hypercube, inside the box.
    assert_eq!(rep.candidates[0].start, init.to_vec().to_vec());
    assert_eq!(
        rep.candidates
            .iter()
            .map(|k| k.start.clone())
            .collect::<Vec<_>>(),
        candidate_starts(&init.to_vec(), &cfg.global, cfg.seed)
    );
    for k in &rep.candidates[1..] {
        assert!(k.start.iter().all(|&x| (0.05..=0.95).contains(&x)));
        assert_ne!(k.start, rep.candidates[0].start);
    }
    // Candidate 0 is exactly the plain fit on the refinement frames.
    let plain_cfg = FitConfig {
        frames: 0..30,
        global: GlobalPhase::default(),
        ..cfg.clone()
    };
    let plain = fit_clips(&[&c], &init, &plain_cfg, None, |_, _, _, _| {}).unwrap();
    assert_eq!(rep.candidates[0].end, plain.params.to_vec().to_vec());
    // Each score is the objective on frames 30..40, recomputed the same (common random numbers).
    let held = FitConfig {
        frames: 30..40,
        ..plain_cfg.clone()
    };
    for k in &rep.candidates {
        let mut th = [0.0; 12];
        th.copy_from_slice(&k.end);
        let again = objective(&held, loss_of(&[&c], &init.with_vec(&th), &held).unwrap());
        assert_eq!(again, k.score);
        assert!(k.score.is_finite() && k.score > 0.0);
    }
    // The choice: the lowest held-out score, never above the plain fit's; the result is its set.
    let best = &rep.candidates[rep.chosen];
    assert!(rep.candidates.iter().all(|k| best.score <= k.score));
    assert!(best.score <= rep.candidates[0].score);
    assert_eq!(res.params.to_vec().to_vec(), best.end);
    assert_eq!(res.start, init.to_vec());
    // The held-out frames were not trained on: every log row is inside the refinement frames.
    assert!(
        res.log.iter().all(|r| r.frame < 30),
        "log reaches past frame 30"
    );
}

#[test]
fn the_frame_split_holds_enough_frames_on_each_side() {
    let g = GlobalPhase {
        starts: 2,
        holdout: 0.25,
    };
    assert_eq!(split_frames(&(10..50), &g).unwrap(), (10..40, 40..50));
    // 6 frames: 2 held out, 4 refined; 4 frames: 1 held out is too few.
    assert_eq!(split_frames(&(0..6), &g).unwrap(), (0..4, 4..6));
    assert!(split_frames(&(0..4), &g).is_err());
}

#[test]
fn bad_global_settings_fail_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let c = clip(dir.path());
    let out = dir.path().join("p.json");
    for (flags, needle) in [
        (vec!["--starts", "0"], "--starts"),
        (vec!["--starts", "65"], "--starts"),
        (vec!["--starts", "2", "--holdout", "1.5"], "--holdout"),
        (vec!["--starts", "2", "--holdout", "NaN"], "--holdout"),
        (
            vec!["--starts", "2", "--holdout", "0.01", "--frames", "0..20"],
            "--holdout",
        ),
    ] {
        let mut a = vec!["fit", s(&c), "--out", s(&out), "--epochs", "1"];
        a.extend(flags);
        let e = fails(&a);
        assert!(e.contains(needle), "{a:?}: {e}");
        assert!(!out.exists(), "{a:?} wrote its output");
    }
}
