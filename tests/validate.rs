//! `herdfit validate` and `herdfit demo`: the report's numbers, its files, and bad input.

mod common;
use common::{herdfit, ok, s};

/// `herdfit synth` into `dir/clip` on 3-BL cells.
fn synth_clip(
    dir: &std::path::Path,
    agents: &str,
    frames: &str,
    grid: &str,
    seed: &str,
) -> std::path::PathBuf {
    let clip = dir.join("clip");
    ok(&[
        "synth",
        "--agents",
        agents,
        "--frames",
        frames,
        "--grid",
        grid,
        "--cell-size",
        "3",
        "--seed",
        seed,
        "--out",
        s(&clip),
    ]);
    clip
}

/// The clip's truth with no cohesion, no alignment and the strongest avoidance, written to
/// `path`: a parameter set that is genuinely wrong.
fn disordered_start(clip: &std::path::Path, path: &std::path::Path) {
    let mut bad: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(clip.join("truth.json")).unwrap()).unwrap();
    bad["forces"]["cohesion"]["weight"] = 0.0.into();
    bad["forces"]["alignment"]["weight"] = 0.0.into();
    bad["forces"]["avoidance"]["weight"] = 1.0.into();
    bad.as_object_mut().unwrap().remove("physical");
    std::fs::write(path, bad.to_string()).unwrap();
}

/// Asserts that report.md prints set `set`'s error of every measure as report.json holds it.
fn assert_report_prints(r: &serde_json::Value, md: &str, set: usize) {
    for m in 0..6 {
        let row = &r["sets"][set]["rows"][m];
        let cell = format!(
            "{:.4} ± {:.4}",
            row["error"]["mean"].as_f64().unwrap(),
            row["error"]["std"].as_f64().unwrap()
        );
        assert!(md.contains(&cell), "{cell} not in report.md");
    }
}

#[test]
fn true_parameters_beat_a_disordered_baseline_and_the_report_prints_its_numbers() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = synth_clip(d, "200", "60", "12x8", "7");
    // Baseline: no cohesion, no alignment, strong avoidance.
    let bad_path = d.join("bad.json");
    disordered_start(&clip, &bad_path);
    let out = d.join("report");
    let printed = ok(&[
        "validate",
        s(&clip),
        "--params",
        s(&clip.join("truth.json")),
        "--baseline",
        s(&bad_path),
        "--seeds",
        "2",
        "--out",
        s(&out),
    ]);
    for f in [
        "report.json",
        "report.md",
        "metrics.png",
        "errors.png",
        "error-map-fitted.png",
        "error-map-baseline.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    #[cfg(feature = "video")]
    assert!(out.join("side-by-side.avi").is_file());
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(r["frames"], serde_json::json!([30, 60]));
    let err = |set: usize, m: usize| r["sets"][set]["rows"][m]["error"]["mean"].as_f64().unwrap();
    // density error, velocity error, polarization error: the truth wins.
    for m in 0..3 {
        assert!(
            err(0, m) < err(1, m),
            "measure {m}: truth {} vs baseline {}",
            err(0, m),
            err(1, m)
        );
    }
    // The Markdown report opens with the comparison table and prints these very numbers.
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert!(md.starts_with("# herdfit validation"));
    let first_table = md
        .lines()
        .position(|l| l.starts_with("| measure |"))
        .unwrap();
    assert!(first_table < 5);
    assert_report_prints(&r, &md, 0);
    assert!(printed.contains("| measure |"));
}

/// `herdfit validate CLIP --params P [args…] --no-video --out OUT`: report.json and the printed text.
fn validate_json(
    clip: &std::path::Path,
    params: &std::path::Path,
    args: &[&str],
    out: &std::path::Path,
) -> (serde_json::Value, String) {
    let mut all = vec!["validate", s(clip), "--params", s(params)];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--no-video", "--out", s(out)]);
    let printed = ok(&all);
    let text = std::fs::read_to_string(out.join("report.json")).unwrap();
    (serde_json::from_str(&text).unwrap(), printed)
}

/// The per-seed differences of a report's first set against its second, measure `m` (6: the sum
/// of the four emergent measures), recomputed from `seed_errors`.
fn seed_differences(r: &serde_json::Value, m: usize) -> Vec<f64> {
    let seeds = |k: usize| r["sets"][k]["seed_errors"].as_array().unwrap().clone();
    let e = |row: &serde_json::Value, i: usize| row[i].as_f64().unwrap();
    let value = |row: &serde_json::Value| match m {
        6 => (2..6).map(|i| e(row, i)).sum::<f64>(),
        _ => e(row, m),
    };
    let (a, b) = (seeds(0), seeds(1));
    a.iter().zip(&b).map(|(x, y)| value(x) - value(y)).collect()
}

#[test]
fn the_report_says_whether_a_difference_is_beyond_the_seeds_noise() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = synth_clip(d, "200", "60", "12x8", "7");
    let bad = d.join("bad.json");
    disordered_start(&clip, &bad);
    let truth = clip.join("truth.json");
    let validate = |params: &std::path::Path, out: &str| {
        let args = ["--baseline", s(params), "--seeds", "6"];
        validate_json(&clip, &truth, &args, &d.join(out))
    };
    // A set against itself: every per-seed difference is exactly 0.
    let (same, _) = validate(&truth, "same");
    let rows = same["paired"][0]["rows"].as_array().unwrap();
    assert_eq!(rows.len(), 7);
    for row in rows {
        assert_eq!(row["difference"].as_f64(), Some(0.0), "{row}");
        assert_eq!(row["verdict"], "same", "{row}");
    }
    // The truth against the disordered set: six seeds each, the rows recomputed from the
    // per-seed errors, and the verdicts from the t-interval (t 2.571 at 5 degrees of freedom).
    let (r, printed) = validate(&bad, "bad");
    assert_eq!(r["paired"][0]["set"], "fitted");
    assert_eq!(r["paired"][0]["against"], "baseline");
    assert_eq!(r["paired"][0]["seeds"], 6);
    assert_eq!(r["sets"][0]["seed_errors"].as_array().unwrap().len(), 6);
    for m in 0..7 {
        let row = &r["paired"][0]["rows"][m];
        let d = seed_differences(&r, m);
        let mean = d.iter().sum::<f64>() / 6.0;
        let sd = (d.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / 5.0).sqrt();
        let se = sd / 6f64.sqrt();
        assert!(
            (row["difference"].as_f64().unwrap() - mean).abs() < 1e-12,
            "{row}"
        );
        assert!(
            (row["standard_error"].as_f64().unwrap() - se).abs() < 1e-12,
            "{row}"
        );
        let verdict = if mean + 2.571 * se < 0.0 {
            "better"
        } else if mean - 2.571 * se > 0.0 {
            "worse"
        } else {
            "within noise"
        };
        assert_eq!(row["verdict"], verdict, "{row}");
        if m < 6 {
            // The per-seed means average to the row's error (every frame's value is finite here).
            let rows = &r["sets"][0]["rows"][m]["error"]["mean"];
            let seeds = r["sets"][0]["seed_errors"].as_array().unwrap();
            let avg = seeds.iter().map(|e| e[m].as_f64().unwrap()).sum::<f64>() / 6.0;
            assert!((avg - rows.as_f64().unwrap()).abs() < 1e-9, "measure {m}");
        }
    }
    // The truth keeps the herd's density and momentum far better than the disordered set does,
    // beyond the seeds' noise.
    for m in 0..2 {
        assert_eq!(
            r["paired"][0]["rows"][m]["verdict"], "better",
            "measure {m}"
        );
    }
    assert!(printed.contains("## fitted against baseline, seed by seed"));
    let density = &r["paired"][0]["rows"][0];
    let line = format!(
        "| density_error | {:+.4} | {:.4} | better |",
        density["difference"].as_f64().unwrap(),
        density["standard_error"].as_f64().unwrap()
    );
    assert!(printed.contains(&line), "{line} not printed");
}

#[test]
fn a_horizon_draws_the_herd_afresh_from_the_clip() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = synth_clip(d, "200", "60", "12x8", "7");
    let truth = clip.join("truth.json");
    let report = |horizon: &str| {
        let out = d.join(format!("h{horizon}"));
        validate_json(&clip, &truth, &["--seeds", "2", "--horizon", horizon], &out)
    };
    let (one_run, _) = report("0");
    // A horizon as long as the held-out part (frames 30..60) is one run: the same numbers.
    let (whole, _) = report("30");
    assert_eq!(one_run["sets"], whole["sets"]);
    assert_eq!(whole["horizon"], 30);
    assert!(one_run.get("horizon").is_none());
    // Drawn afresh every 5 frames, the herd stays closer to the clip than one run does.
    let (short, printed) = report("5");
    let err = |r: &serde_json::Value, m: usize| {
        r["sets"][0]["rows"][m]["error"]["mean"].as_f64().unwrap()
    };
    for m in 0..2 {
        assert!(
            err(&short, m) < err(&one_run, m),
            "measure {m}: every 5 frames {} vs one run {}",
            err(&short, m),
            err(&one_run, m)
        );
    }
    assert_eq!(short["frames"], serde_json::json!([30, 60]));
    assert!(printed.contains("the herd drawn afresh from the clip every 5 frames"));
    // One frame holds no motion.
    let e = common::fails(&[
        "validate",
        s(&clip),
        "--params",
        s(&truth),
        "--horizon",
        "1",
        "--out",
        s(&d.join("h1")),
    ]);
    assert!(e.contains("--horizon"), "{e}");
    assert!(!d.join("h1").exists());
}

#[test]
fn bad_validation_input_fails_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = d.join("clip");
    ok(&[
        "synth",
        "--agents",
        "40",
        "--frames",
        "10",
        "--grid",
        "8x8",
        "--cell-size",
        "2",
        "--out",
        s(&clip),
    ]);
    let out = d.join("report");
    for (args, needle) in [
        (
            vec![
                "validate",
                s(&clip),
                "--params",
                s(&d.join("none.json")),
                "--out",
                s(&out),
            ],
            "none.json",
        ),
        (
            vec![
                "validate",
                s(&clip),
                "--params",
                s(&clip.join("truth.json")),
                "--split",
                "1.5",
                "--out",
                s(&out),
            ],
            "--split",
        ),
        (
            vec![
                "validate",
                s(&clip),
                "--params",
                s(&clip.join("truth.json")),
                "--seeds",
                "0",
                "--out",
                s(&out),
            ],
            "--seeds",
        ),
        (
            vec![
                "validate",
                s(&clip),
                "--params",
                s(&clip.join("truth.json")),
                "--guidance-scale",
                "-2",
                "--out",
                s(&out),
            ],
            "--guidance-scale",
        ),
    ] {
        let o = herdfit(&args);
        assert_eq!(o.status.code(), Some(1), "{args:?}");
        let e = String::from_utf8_lossy(&o.stderr).into_owned();
        assert_eq!(e.trim().lines().count(), 1, "{e}");
        assert!(e.contains(needle), "{e}");
        assert!(!out.exists());
    }
}

#[test]
fn demo_runs_the_whole_chain() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("demo");
    let text = ok(&["demo", "--out", s(&out)]);
    assert!(text.contains("mean |θ − θ*| per parameter"));
    // The start is clearly wrong (no cohesion, no alignment, the strongest avoidance) and the
    // fitted set beats it on the held-out half: density and velocity errors and the measures.
    let start = herdfit::herd::params::Params::load(&out.join("start.json")).unwrap();
    let v = start.to_vec();
    assert_eq!((v[0], v[3], v[6]), (0.0, 1.0, 0.0));
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report/report.json")).unwrap())
            .unwrap();
    let err = |set: usize, m: usize| r["sets"][set]["rows"][m]["error"]["mean"].as_f64().unwrap();
    let sums = |set: usize| (2..6).map(|m| err(set, m)).sum::<f64>();
    assert_eq!(r["sets"][1]["name"], "baseline");
    for (k, (fit, start)) in [
        (err(0, 0), err(1, 0)),
        (err(0, 1), err(1, 1)),
        (sums(0), sums(1)),
    ]
    .iter()
    .enumerate()
    {
        assert!(
            fit < start,
            "held-out measure {k}: fitted {fit} vs start {start}"
        );
        // The printed line carries these numbers, and the report's seed-by-seed verdict.
        let row = &r["paired"][0]["rows"][[0, 1, 6][k]];
        let seedwise = format!(
            "; seed by seed {:+.3} ± {:.3}: {}",
            row["difference"].as_f64().unwrap(),
            row["standard_error"].as_f64().unwrap(),
            row["verdict"].as_str().unwrap()
        );
        assert!(text.contains(&format!("{start:.3} → {fit:.3}")), "{text}");
        assert!(text.contains(&seedwise), "{seedwise} not in {text}");
    }
    assert!(
        text.contains("held-out frames 60..120, start → fitted"),
        "{text}"
    );
    // The files name the folder the user gave, never the temporary one they were written in
    // (which is gone): the fitted set's clip is `<out>/clip` (or `<out>/synthetic` without
    // OpenCV), and it exists.
    let params = std::fs::read_to_string(out.join("params.json")).unwrap();
    assert!(!params.contains(".herdfit-"), "{params}");
    let clip_named = [out.join("clip"), out.join("synthetic")]
        .into_iter()
        .find(|c| params.contains(&format!("\"{}\"", c.display())))
        .unwrap_or_else(|| panic!("no clip of {} named in {params}", out.display()));
    assert!(clip_named.join("clip.json").is_file());
    for f in ["report/report.md", "report/report.json", "clip/clip.json"] {
        if let Ok(t) = std::fs::read_to_string(out.join(f)) {
            assert!(!t.contains(".herdfit-"), "{f}: {t}");
        }
    }
    for f in [
        "truth.json",
        "start.json",
        "params.json",
        "fit.log.csv",
        "report/report.md",
        "report/report.json",
        "crowd/model.json",
        "crowd/hall.csv",
        "crowd/hall.png",
        "crowd/compare.json",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    assert!(text.contains("crowd: picture"), "{text}");
    #[cfg(feature = "video")]
    {
        assert!(out.join("herd.avi").is_file());
        assert!(out.join("report/side-by-side.avi").is_file());
        assert!(text.contains("side-by-side video (clip | fitted simulation): "));
        assert!(out.join("clip/clip.json").is_file());
    }
    herdfit::herd::params::Params::load(&out.join("params.json")).unwrap();
}

#[test]
fn a_warm_up_starts_earlier_and_reports_the_same_frames() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = synth_clip(d, "80", "24", "8x6", "5");
    let run = |warmup: &str| -> serde_json::Value {
        let out = d.join(format!("r{warmup}"));
        ok(&[
            "validate",
            s(&clip),
            "--params",
            s(&clip.join("truth.json")),
            "--seeds",
            "1",
            "--warmup",
            warmup,
            "--no-video",
            "--out",
            s(&out),
        ]);
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap()
    };
    let (a, b, c) = (run("0"), run("6"), run("12"));
    for r in [&a, &b, &c] {
        assert_eq!(r["frames"], serde_json::json!([12, 24]));
        assert_eq!(r["sets"][0]["per_frame"].as_array().unwrap().len(), 12);
    }
    // Another start, another herd; the whole training part (12 frames) starts at frame 0.
    assert_ne!(a["sets"][0]["per_frame"], b["sets"][0]["per_frame"]);
    assert_ne!(b["sets"][0]["per_frame"], c["sets"][0]["per_frame"]);
    // A warm-up reaching before the clip is refused (issue #14: no silent clamping), in one line.
    let err = common::fails(&[
        "validate",
        s(&clip),
        "--params",
        s(&clip.join("truth.json")),
        "--warmup",
        "500",
        "--no-video",
        "--out",
        s(&d.join("r500")),
    ]);
    assert!(
        err.contains("--warmup") && err.contains("frame 12"),
        "{err}"
    );
    assert!(!d.join("r500").exists());
}

#[test]
fn ensemble_mean_validation_scores_the_seeds_mean_prediction() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = synth_clip(d, "120", "40", "10x6", "5");
    let report = |name: &str, seeds: &str, ensemble: bool| {
        let out = d.join(name);
        let truth = clip.join("truth.json");
        let mut args = vec![
            "validate",
            s(&clip),
            "--params",
            s(&truth),
            "--seeds",
            seeds,
            "--no-video",
            "--out",
            s(&out),
        ];
        if ensemble {
            args.push("--ensemble-mean");
        }
        ok(&args);
        let r: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap())
                .unwrap();
        assert_eq!(r["ensemble_mean"], ensemble);
        let md = std::fs::read_to_string(out.join("report.md")).unwrap();
        assert_eq!(md.contains("the seeds' mean prediction"), ensemble);
        (0..6)
            .map(|m| r["sets"][0]["rows"][m]["error"]["mean"].as_f64().unwrap())
            .collect::<Vec<f64>>()
    };
    // One seed: the mean prediction is that seed's run, so both modes give the same numbers.
    let (one, one_ens) = (report("p1", "1", false), report("e1", "1", true));
    for m in 0..6 {
        assert!(
            (one[m] - one_ens[m]).abs() < 1e-12,
            "measure {m}: {one:?} vs {one_ens:?}"
        );
    }
    // Three seeds: |mean(n') − n| ≤ mean |n' − n| cell by cell and frame by frame, and the same
    // for each measure, so the density error and the measures' errors of the mean prediction can
    // only be smaller; they are strictly smaller when the seeds' runs differ.
    let (per_run, ens) = (report("p3", "3", false), report("e3", "3", true));
    for m in [0, 2, 3, 4, 5] {
        assert!(
            ens[m] <= per_run[m] + 1e-12,
            "measure {m}: {ens:?} vs {per_run:?}"
        );
    }
    assert!(ens[0] < per_run[0], "density: {ens:?} vs {per_run:?}");
}

/// Issue 6's acceptance on a synthetic clip: fitted on the first half from a disordered start (no
/// cohesion, no alignment, the strongest avoidance), the fitted set beats that start on the
/// held-out half on the density and velocity errors and on every measure's error, and the report
/// prints the numbers asserted here. (On the demo's clip, whose generic start is force-free, even
/// the generating parameters cannot: RESULTS.md §1, held-out validation.)
#[test]
fn a_fit_beats_its_disordered_start_on_every_held_out_measure() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let clip = synth_clip(d, "300", "120", "16x10", "11");
    let start = d.join("start.json");
    disordered_start(&clip, &start);
    let fitted = d.join("fitted.json");
    ok(&[
        "fit",
        s(&clip),
        "--frames",
        "0..60",
        "--init",
        s(&start),
        "--loss",
        "fields",
        "--optimizer",
        "normalized",
        "--window",
        "16",
        "--epochs",
        "6",
        "--seed",
        "1",
        "--out",
        s(&fitted),
    ]);
    let out = d.join("report");
    ok(&[
        "validate",
        s(&clip),
        "--params",
        s(&fitted),
        "--baseline",
        s(&start),
        "--seeds",
        "4",
        "--no-video",
        "--out",
        s(&out),
    ]);
    let r: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("report.json")).unwrap()).unwrap();
    assert_eq!(r["frames"], serde_json::json!([60, 120]));
    for m in 0..6 {
        let sets = &r["sets"];
        let err = |set: usize| sets[set]["rows"][m]["error"]["mean"].as_f64().unwrap();
        assert!(
            err(0) < err(1),
            "{}: fitted {} vs start {}",
            sets[0]["rows"][m]["measure"],
            err(0),
            err(1)
        );
    }
    let md = std::fs::read_to_string(out.join("report.md")).unwrap();
    assert_report_prints(&r, &md, 0);
    assert_report_prints(&r, &md, 1);
}
