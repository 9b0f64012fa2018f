//! Line-formation flocks (issue #19): Munk's theorem, extraction, the eq. 4 solver, N ≠ N̂,
//! initiation from random starts, the animation's files and bad input.

mod common;

use common::{fails, ok, s};
use herdfit::flock::extract::{self, ExtractConfig, ShapeKind, Side};
use herdfit::flock::initiation::{self, Initiation, InitiationConfig, Target};
use herdfit::flock::{animate, power, steady, synth};
use herdfit::progress::NoProgress;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::Path;

fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

#[test]
fn munk_total_saving_is_invariant_under_longitudinal_displacements() {
    let mut rng = ChaCha8Rng::seed_from_u64(19);
    let mut worst: f64 = 0.0;
    let mut worst_printed: f64 = 0.0;
    let mut worst_unsigned: f64 = 0.0;
    for n in 2..=41 {
        // Lateral positions with gaps of 0.85–1.6 b; any longitudinal positions.
        let mut x = 0.0;
        let xs: Vec<f64> = (0..n)
            .map(|_| {
                x += rng.gen_range(0.85..1.6);
                x
            })
            .collect();
        let ys: Vec<f64> = (0..n).map(|_| rng.gen_range(-10.0..10.0)).collect();
        let pos = |dy: &[f64]| -> Vec<[f64; 2]> {
            xs.iter()
                .zip(ys.iter().zip(dy))
                .map(|(&a, (&b, &d))| [a, b + d])
                .collect()
        };
        let total = |p: &[[f64; 2]], g: &dyn Fn(f64, f64) -> f64| -> f64 {
            let mut s = 0.0;
            for i in 0..p.len() {
                for j in 0..p.len() {
                    if i != j {
                        s += g((p[j][0] - p[i][0]).abs(), p[j][1] - p[i][1]);
                    }
                }
            }
            s
        };
        let zero = vec![0.0; n];
        let e0 = power::savings(&pos(&zero)).unwrap().iter().sum::<f64>();
        let abreast = power::total_abreast(&xs);
        assert!(
            (e0 - abreast).abs() <= 1e-12 * abreast,
            "n {n}: {e0} vs {abreast}"
        );
        let p0 = total(&pos(&zero), &power::g_printed);
        let u0 = total(&pos(&zero), &|x, t| power::g_printed(x, t.abs()));
        for _ in 0..20 {
            let dy: Vec<f64> = (0..n).map(|_| rng.gen_range(-30.0..30.0)).collect();
            let p = pos(&dy);
            let e = power::savings(&p).unwrap().iter().sum::<f64>();
            worst = worst.max((e - e0).abs() / e0);
            worst_printed = worst_printed.max((total(&p, &power::g_printed) - p0).abs() / p0);
            let u = total(&p, &|x, t| power::g_printed(x, t.abs()));
            worst_unsigned = worst_unsigned.max((u - u0).abs() / u0);
        }
    }
    println!(
        "Munk, N = 2..41, 20 displacements each: max relative change of Σe {worst:.2e} (stable \
         form), {worst_printed:.2e} (printed formula, signed y), {worst_unsigned:.2e} (printed, \
         y read as a distance |y|)"
    );
    assert!(worst <= 1e-9, "{worst}");
    assert!(worst_printed <= 1e-9, "{worst_printed}");
    // Reading y_ij as an unsigned distance breaks the theorem: the sign is essential.
    assert!(worst_unsigned > 1e-2, "{worst_unsigned}");
}

/// Outlier precision and recall over (bird, frame) pairs against the synthetic truth.
fn outlier_scores(t: &herdfit::data::tracks::Tracks, p: &extract::ShapeParams) -> (f64, f64) {
    let (mut tp, mut fp, mut fneg) = (0usize, 0usize, 0usize);
    for f in &p.frames {
        for b in &f.birds {
            let truth = t
                .rows
                .iter()
                .find(|r| r.frame == f.frame && r.id == b.id)
                .and_then(|r| r.role.clone())
                .unwrap();
            match (truth == "outlier", b.outlier) {
                (true, true) => tp += 1,
                (false, true) => fp += 1,
                (true, false) => fneg += 1,
                _ => {}
            }
        }
    }
    (
        tp as f64 / (tp + fp).max(1) as f64,
        tp as f64 / (tp + fneg).max(1) as f64,
    )
}

#[test]
fn extraction_recovers_a_synthetic_v() {
    // 9 birds (4 per side, 1–2 of them outliers) are reported in RESULTS.md, not held to this.
    for (birds, seed) in [(21usize, 5u64), (41, 7)] {
        let cfg = synth::SynthConfig {
            birds,
            frames: 20,
            seed,
            ..synth::SynthConfig::default()
        };
        assert_eq!(
            (cfg.half_angle_deg, cfg.outlier_fraction, cfg.noise),
            (30.0, 0.2, 0.1)
        );
        let t = synth::synth(&cfg).unwrap();
        let p = extract::extract(&t, "synthetic", &ExtractConfig::default()).unwrap();
        assert_eq!(p.kind, ShapeKind::V, "{birds} birds");
        assert_eq!(p.birds, birds);
        let mut worst: f64 = 0.0;
        for f in &p.frames {
            assert_eq!(f.leader, 0, "the apex bird leads");
            for s in [Side::Left, Side::Right] {
                worst = worst.max((f.side(s).unwrap().angle_deg - 30.0).abs());
            }
        }
        let (precision, recall) = outlier_scores(&t, &p);
        println!(
            "V of {birds}: worst side-angle error {worst:.2}°, outlier precision {precision:.3}, \
             recall {recall:.3}"
        );
        assert!(worst <= 2.0, "{birds} birds: angle off by {worst}°");
        assert!(precision >= 0.9 && recall >= 0.9, "{precision} {recall}");
        // Lateral gaps: mean near the truth (1 b).
        let g = p.frames.iter().map(|f| f.mean_gap).sum::<f64>() / p.frames.len() as f64;
        assert!((g - 1.0).abs() < 0.1, "mean gap {g}");
    }
}

#[test]
fn shipped_examples_regenerate_byte_for_byte_and_classify() {
    let dir = tempfile::tempdir().unwrap();
    let written = synth::write_examples(dir.path()).unwrap();
    assert_eq!(written.len(), 4);
    for p in &written {
        for ext in ["csv", "json"] {
            let name = p.with_extension(ext);
            let name = name.file_name().unwrap();
            let shipped = repo().join("examples/flocks").join(name);
            assert_eq!(
                std::fs::read(&shipped).unwrap_or_else(|e| panic!("{}: {e}", shipped.display())),
                std::fs::read(dir.path().join(name)).unwrap(),
                "{} differs from a fresh `herdfit flock synth --examples`",
                shipped.display()
            );
        }
    }
    for (stem, want) in [
        ("v", ShapeKind::V),
        ("u", ShapeKind::U),
        ("j", ShapeKind::J),
        ("line", ShapeKind::Line),
    ] {
        let path = repo().join(format!("examples/flocks/{stem}.csv"));
        let p = extract::extract_file(&path, &ExtractConfig::default()).unwrap();
        assert_eq!(p.kind, want, "{stem}");
        let t = herdfit::data::tracks::Tracks::load(&path).unwrap();
        let (precision, recall) = outlier_scores(&t, &p);
        println!("{stem}: outlier precision {precision:.3}, recall {recall:.3}");
    }
}

/// Steady flight keys for `n` birds from an example; checks every key shape against its own
/// drawn ξ̂ and range. Returns the worst relative error and the rejected draws.
fn check_keys(example: &synth::SynthConfig, n: usize, keys: usize, seed: u64) -> (f64, usize) {
    let cfg = steady::SteadyConfig::default();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (init, range, gr, fam) = synth::key_shape_setup(example, n, &cfg, &mut rng).unwrap();
    assert_eq!(init.shapes[0].len(), n);
    assert_eq!(init.nl + init.nr + 1, n);
    let first = steady::first_key(&init.shapes[0]).unwrap();
    let mut prev = steady::settle(first, &range, &fam, &cfg, &mut rng);
    let (mut worst, mut rejected) = (0.0f64, 0);
    for key in 0..keys {
        let k = steady::next_key(&prev, init.nl, init.nr, &range, gr, &fam, &cfg, &mut rng);
        assert!(k.reproduced, "N = {n} key {key}: no draw reproduced");
        assert_eq!(k.xi_target, k.xi_draw, "N = {n} key {key}");
        // ξ of the solved positions against the drawn targets.
        for (a, b) in k.xi.iter().zip(&k.xi_draw) {
            worst = worst.max((a - b).abs() / b);
        }
        // The draw moved: not the previous key's ξ (eq. 2's box has room on every bird).
        let moved = k
            .xi_draw
            .iter()
            .zip(&prev.xi_target)
            .map(|(a, b)| (a - b).abs() / b)
            .fold(0.0, f64::max);
        assert!(
            moved > 1e-3,
            "N = {n} key {key}: the draw stayed put ({moved})"
        );
        for (i, (v, r)) in k.xi.iter().zip(&range).enumerate() {
            let (lo, hi) = ((1.0 - cfg.epsilon) * r[0], (1.0 + cfg.epsilon) * r[1]);
            assert!(
                *v >= lo * (1.0 - 1e-6) && *v <= hi * (1.0 + 1e-6),
                "bird {i}: {v} ∉ [{lo}, {hi}]"
            );
        }
        rejected += k.draws_rejected;
        prev = k;
    }
    (worst, rejected)
}

#[test]
fn levenberg_marquardt_reproduces_every_key_shape() {
    let cases = synth::key_shape_cases();
    let out: Vec<(usize, f64, usize)> = cases
        .par_iter()
        .map(|(ex, n)| {
            // 1 key shape per N (N = 41 takes ~0.1 s, RESULTS.md §3); the sweep is `cargo run --release --example flock_keys`
            // (RESULTS.md §3).
            let (w, r) = check_keys(ex, *n, 1, 11 + *n as u64);
            (*n, w, r)
        })
        .collect();
    let ns: Vec<usize> = out.iter().map(|o| o.0).collect();
    assert_eq!(ns, vec![9, 14, 16, 28, 41]);
    for (n, worst, rejected) in out {
        println!(
            "N = {n}: worst |ξ − ξ̂|/ξ̂ over 1 key shape {worst:.2e}, {rejected} draws rejected"
        );
        assert!(worst <= 1e-6, "N = {n}: {worst}");
    }
}

#[test]
fn n_differs_from_the_example_and_every_xi_stays_in_its_range() {
    // 9 → 14 and 16 → 28 through the whole animation (no initiation, no files).
    for (stem, n) in [("v", 14usize), ("u", 28)] {
        let p = extract::extract_file(
            &repo().join(format!("examples/flocks/{stem}.csv")),
            &ExtractConfig::default(),
        )
        .unwrap();
        let cfg = animate::AnimateConfig {
            birds: Some(n),
            frames: 300,
            initiation: false,
            video: false,
            seed: 2,
            ..animate::AnimateConfig::default()
        };
        let a = animate::animate(&p, stem, &cfg, &mut NoProgress).unwrap();
        let r = &a.report;
        assert_eq!((r.birds, r.example_birds), (n, p.birds));
        assert!(r.keys.len() >= 3, "{} keys", r.keys.len());
        let eps = cfg.steady.epsilon;
        for (k, key) in r.keys.iter().enumerate() {
            for i in 0..n {
                let (lo, hi) = (
                    (1.0 - eps) * r.xi_range[i][0],
                    (1.0 + eps) * r.xi_range[i][1],
                );
                let v = key.xi[i];
                assert!(
                    v >= lo * (1.0 - 1e-6) && v <= hi * (1.0 + 1e-6),
                    "{stem} key {k} bird {i}"
                );
            }
            assert!(key.reproduced, "{stem} key {k}: draw not reproduced");
            for (a, b) in key.xi.iter().zip(&key.xi_draw) {
                assert!(
                    (a - b).abs() <= 1e-6 * b,
                    "{stem} key {k}: {a} vs drawn {b}"
                );
            }
        }
        // The correspondence keeps the example's leader and adds birds.
        assert_eq!(r.example_bird[0], Some(p.frames[0].leader));
        assert_eq!(
            r.example_bird.iter().filter(|b| b.is_some()).count(),
            p.birds
        );
        assert!(
            r.max_accel_steady <= r.accel_bound * 1.01,
            "{} > {}",
            r.max_accel_steady,
            r.accel_bound
        );
        assert_eq!(a.tracks.rows.len(), n * 300);
    }
}

/// Initiation runs from `runs` seeded random starts (seeds 1000 + k) towards the first initial
/// shape for `n` birds of the shipped V; checks the issue's conditions on the converged runs and
/// returns how many converged.
fn initiation_runs(n: usize, runs: u64) -> usize {
    let p = extract::extract_file(
        &repo().join("examples/flocks/v.csv"),
        &ExtractConfig::default(),
    )
    .unwrap();
    let mut rng = ChaCha8Rng::seed_from_u64(n as u64);
    let scfg = steady::SteadyConfig::default();
    let setup = animate::steady_setup(&p, n, &scfg, &mut rng).unwrap();
    let init = &setup.init;
    let target = Target {
        pos: setup.first.pos.clone(),
        nl: init.nl,
        nr: init.nr,
    };
    let cfg = InitiationConfig::default();
    let runs_out: Vec<_> = (0..runs)
        .into_par_iter()
        .map(|seed| {
            let mut rng = ChaCha8Rng::seed_from_u64(1000 + seed);
            let start = initiation::random_start(n, &cfg, &mut rng);
            initiation::run(Initiation::new(cfg.clone(), target.clone(), start).unwrap())
        })
        .collect();
    let ok_runs: Vec<_> = runs_out
        .iter()
        .filter(|r| r.converged_after.is_some())
        .collect();
    let times: Vec<f64> = ok_runs.iter().filter_map(|r| r.converged_after).collect();
    let worst_pair = ok_runs
        .iter()
        .map(|r| r.min_pair_distance)
        .fold(f64::INFINITY, f64::min);
    let most_followers = ok_runs.iter().map(|r| r.max_followers).max().unwrap_or(0);
    println!(
        "N = {n}: {} of {runs} converged within {} s; time median {:.1} s, max {:.1} s; closest \
         pair after convergence {worst_pair:.2} b; most followers of a non-leader {most_followers}",
        ok_runs.len(),
        cfg.max_time,
        median(&times),
        times.iter().cloned().fold(0.0, f64::max)
    );
    // The target shape's own closest pair (Step 1 keeps pairs `min_pair` = 1.05 b apart): the
    // issue's bound is 1 b between converged birds.
    let mut target_pair = f64::INFINITY;
    for (a, p) in target.pos.iter().enumerate() {
        for q in &target.pos[a + 1..] {
            target_pair = target_pair.min((p[0] - q[0]).hypot(p[1] - q[1]));
        }
    }
    println!("N = {n}: closest pair of the target shape itself {target_pair:.2} b");
    assert!(worst_pair >= 1.0, "N = {n}: birds {worst_pair} b apart");
    assert!(most_followers <= 1, "N = {n}: {most_followers}");
    for r in &ok_runs {
        assert!(r.final_mean_error.unwrap() <= cfg.converge_distance);
    }
    ok_runs.len()
}

#[test]
fn initiation_converges_from_random_starts() {
    // A modest sample (seconds); the issue's 100-start sweep is the example
    // `cargo run --release --example flock_initiation -- 14 100` (and `-- 41 100`), RESULTS.md §3.
    let ok = initiation_runs(14, 20);
    assert!(ok >= 19, "N = 14: {ok} of 20 converged");
    let ok = initiation_runs(41, 4);
    assert!(ok >= 4, "N = 41: {ok} of 4 converged");
}

#[test]
fn animated_flocks_keep_the_examples_shape_family_and_the_hand_over_its_bound() {
    // Issue #50: before, a 14-bird V's key shapes put the last bird 36–43 b behind the leader
    // (worst bird 9.0 b off its side's line against the example's own 2.6 b) and the hand-over
    // peaked at 0.649 b/s² against its bound of 0.5. The sweep over 4 examples × N = 14, 41 × 5
    // seeds is `cargo run --release --example flock_family` (RESULTS).
    let cases = [
        ("v", 14usize),
        ("u", 14),
        ("j", 14),
        ("line", 14),
        ("v", 41),
    ];
    let reports: Vec<_> = cases
        .par_iter()
        .map(|&(stem, n)| {
            let p = extract::extract_file(
                &repo().join(format!("examples/flocks/{stem}.csv")),
                &ExtractConfig::default(),
            )
            .unwrap();
            let cfg = animate::AnimateConfig {
                birds: Some(n),
                frames: 250,
                seed: 1,
                video: false,
                ..animate::AnimateConfig::default()
            };
            (
                stem,
                n,
                animate::animate(&p, stem, &cfg, &mut NoProgress)
                    .unwrap()
                    .report,
            )
        })
        .collect();
    for (stem, n, r) in reports {
        let f = &r.shape_family;
        println!(
            "{stem} N = {n}: worst bird {:.3} b off its side's curve over the steady frames, \
             example's own {:.3} b ({:.2}×); hand-over peak {:.3} b/s²; ξ in range {:.4}",
            f.steady_worst, f.example_worst, f.ratio, r.max_accel_hand_over, r.xi_in_range_steady
        );
        assert!(f.example_worst > 0.5, "{stem}: the example has outliers");
        assert!(f.ratio <= 1.5, "{stem} N = {n}: {f:?}");
        assert!(
            f.keys_worst <= 1.5 * f.example_worst,
            "{stem} N = {n}: {f:?}"
        );
        assert!(r.max_accel_hand_over <= r.accel_bound, "{stem} N = {n}");
        assert!(r.max_accel_steady <= r.accel_bound * 1.01, "{stem} N = {n}");
        assert_eq!(r.xi_in_range_steady, 1.0, "{stem} N = {n}");
        assert!(
            r.initiation.as_ref().unwrap().converged_after.is_some(),
            "{stem} N = {n}"
        );
    }
}

fn median(v: &[f64]) -> f64 {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    if v.is_empty() {
        f64::NAN
    } else {
        v[v.len() / 2]
    }
}

#[test]
fn animate_writes_tracks_savings_report_and_plots_deterministically() {
    let dir = tempfile::tempdir().unwrap();
    let ex = repo().join("examples/flocks/v.csv");
    let shape = dir.path().join("shape.json");
    let out = ok(&["flock", "extract", s(&ex), "--out", s(&shape)]);
    assert!(out.contains("shape v"), "{out}");
    let mut bytes = Vec::new();
    for k in 0..2 {
        let o = dir.path().join(format!("anim{k}"));
        // A short initiation (4 s), then the hand-over and 60 steady frames.
        let cfg = dir.path().join("cfg.json");
        std::fs::write(&cfg, r#"{"init": {"max_time": 4.0}}"#).unwrap();
        let out = ok(&[
            "flock",
            "animate",
            s(&shape),
            "--birds",
            "12",
            "--frames",
            "60",
            "--seed",
            "4",
            "--config",
            s(&cfg),
            "--out",
            s(&o),
        ]);
        assert!(
            out.contains("12 birds") && out.contains("initiation"),
            "{out}"
        );
        let mut names: Vec<String> = std::fs::read_dir(&o)
            .unwrap()
            .map(|e| e.unwrap().file_name().into_string().unwrap())
            .collect();
        names.sort();
        let mut want = vec![
            "report.json",
            "savings.csv",
            "savings.json",
            "savings.png",
            "shapes.png",
            "tracks.csv",
            "tracks.json",
        ];
        if cfg!(feature = "video") {
            want.push("flock.avi");
            want.sort();
        }
        assert_eq!(names, want);
        bytes.push(
            ["tracks.csv", "savings.csv", "report.json"].map(|f| std::fs::read(o.join(f)).unwrap()),
        );
        let t = herdfit::data::tracks::Tracks::load(&o.join("tracks.csv")).unwrap();
        assert_eq!(t.meta.dimension, 3);
        assert!(
            t.rows.iter().all(|r| (r.pos[2] - 100.0).abs() < 1.0),
            "altitude about 100 m"
        );
        let rep: serde_json::Value =
            serde_json::from_slice(&std::fs::read(o.join("report.json")).unwrap()).unwrap();
        assert_eq!(rep["schema"], "herdfit.flock-animation/1");
        let init = rep["initiation_frames"].as_u64().unwrap() as usize;
        assert_eq!(init, 100, "4 s of initiation at 25 fps");
        let hand = rep["hand_over_frames"].as_u64().unwrap() as usize;
        assert_eq!(t.frames().len(), init + hand + 60);
        let sav = std::fs::read_to_string(o.join("savings.csv")).unwrap();
        assert!(sav.starts_with("frame,time,id,e,xi\n"));
        assert_eq!(sav.lines().count(), 1 + 60 * 12);
        // The 60 frames come after the hand-over, so every bird flies in formation: no e < 0
        // (before the fix, frames of the hand-over gave e from −32.6 to +33.4). e above 1 is
        // Hummel's model itself at overlapping wing tips (this example's gaps are 0.88–1.03 b,
        // i.e. up to 0.12 b of overlap, where an inner bird's e reaches 1.11; RESULTS.md §3).
        for l in sav.lines().skip(1) {
            let e: f64 = l.split(',').nth(3).unwrap().parse().unwrap();
            assert!((0.0..=1.5).contains(&e), "{l}");
        }
        let first: u64 = sav
            .lines()
            .nth(1)
            .unwrap()
            .split(',')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let hand = rep["hand_over_frames"].as_u64().unwrap();
        assert_eq!(
            first,
            init as u64 + hand,
            "savings start after the hand-over"
        );
        let side: serde_json::Value =
            serde_json::from_slice(&std::fs::read(o.join("savings.json")).unwrap()).unwrap();
        assert_eq!(side["schema"], "herdfit.flock-savings/1");
        // e is named for what it is (issue #50): induced power, in units of a lone bird's, not a
        // fraction of the flight power (it exceeds 1 where wing tips overlap).
        let e = side["columns"]["e"].as_str().unwrap();
        assert!(e.starts_with("induced-power saving"), "{e}");
        assert!(
            e.contains("no ceiling") && e.contains("not the fraction"),
            "{e}"
        );
        // The flock-level figure to compare with field estimates, and the wing-tip spacing.
        assert!(rep["flock_mean_saving"].as_f64().unwrap() > 0.0);
        assert!(rep["mean_wing_tip_spacing"].as_f64().unwrap().abs() < 0.5);
    }
    assert!(bytes[0] == bytes[1], "same seed, same bytes");
}

#[test]
fn bad_input_gets_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let write = |name: &str, csv: &str, side: &str| {
        let p = d.join(format!("{name}.csv"));
        std::fs::write(&p, csv).unwrap();
        std::fs::write(d.join(format!("{name}.json")), side).unwrap();
        p
    };
    let side = r#"{"schema":"herdfit.tracks/1","units":"m","fps":2,"dimension":2,"provenance":{"wingspan":1.5}}"#;
    let two = write(
        "two",
        "frame,time,id,x,y\n0,0,0,0,0\n0,0,1,1,-1\n1,0.5,0,0,5\n1,0.5,1,1,4\n",
        side,
    );
    let abreast = write(
        "abreast",
        "frame,time,id,x,y\n0,0,0,0,0\n0,0,1,1.5,0\n0,0,2,3,0\n1,0.5,0,0,7\n1,0.5,1,1.5,7\n1,0.5,2,3,7\n",
        side,
    );
    let nan = write(
        "nan",
        "frame,time,id,x,y\n0,0,0,0,0\n0,0,1,NaN,-1\n0,0,2,3,-2\n",
        side,
    );
    let good = write(
        "good",
        "frame,time,id,x,y\n0,0,0,0,0\n0,0,1,1.5,-2\n0,0,2,-1.5,-2\n1,0.5,0,0,7\n1,0.5,1,1.5,5\n1,0.5,2,-1.5,5\n",
        side,
    );
    let out = d.join("shape.json");
    let cases: [(&[&str], &str); 5] = [
        (
            &["flock", "extract", s(&two), "--out", s(&out)],
            "at least 3",
        ),
        (
            &["flock", "extract", s(&abreast), "--out", s(&out)],
            "abreast",
        ),
        (&["flock", "extract", s(&nan), "--out", s(&out)], "x is NaN"),
        (
            &[
                "flock",
                "extract",
                s(&good),
                "--wingspan",
                "0",
                "--out",
                s(&out),
            ],
            "--wingspan",
        ),
        (
            &[
                "flock",
                "extract",
                s(&good),
                "--wingspan",
                "-2",
                "--out",
                s(&out),
            ],
            "must be > 0",
        ),
    ];
    let before: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    for (args, want) in cases {
        let e = fails(args);
        assert!(e.contains(want), "{args:?}: {e}");
    }
    // The good file extracts; animating 2 birds is refused before anything is written.
    ok(&["flock", "extract", s(&good), "--out", s(&out)]);
    let anim = d.join("anim");
    let e = fails(&[
        "flock",
        "animate",
        s(&out),
        "--birds",
        "2",
        "--out",
        s(&anim),
    ]);
    assert!(e.contains("--birds") && e.contains("3"), "{e}");
    assert!(!anim.exists());
    let mut after: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    after.retain(|n| n != "shape.json");
    assert_eq!(before.len(), after.len(), "nothing half-written: {after:?}");
    // A wingspan ≤ 0 in the sidecar names the file.
    let zero = write(
        "zero",
        "frame,time,id,x,y\n0,0,0,0,0\n0,0,1,1.5,-2\n0,0,2,-1.5,-2\n",
        &side.replace("1.5", "0"),
    );
    let e = fails(&[
        "flock",
        "extract",
        s(&zero),
        "--heading",
        "90",
        "--out",
        s(&out),
    ]);
    assert!(e.contains("zero.csv") && e.contains("wingspan = 0"), "{e}");
}
