//! The `herdfit` binary end to end: simulate, gradcheck and bench, determinism, and bad input
//! (one-line error naming the file, non-zero exit, no panic, no partial output).

mod common;
use common::{fails, fails_with, ok, s};
use std::path::{Path, PathBuf};

fn write(dir: &Path, name: &str, text: &str) -> PathBuf {
    let p = dir.join(name);
    std::fs::write(&p, text).unwrap();
    p
}

const INIT: &str = "id,x,y,vx,vy\n0,0,0,1,0\n1,1.5,0.5,1,0.1\n2,0.5,-1.5,0.9,0\n3,-1,1,1,-0.2\n";

#[test]
fn simulate_writes_the_trajectory_format() {
    let dir = tempfile::tempdir().unwrap();
    let init = write(dir.path(), "init.csv", INIT);
    let out = dir.path().join("traj.csv");
    ok(&[
        "simulate",
        "--init",
        s(&init),
        "--steps",
        "5",
        "--fps",
        "10",
        "--guidance",
        "1,0",
        "--out",
        s(&out),
    ]);
    let text = std::fs::read_to_string(&out).unwrap();
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "frame,time,id,x,y,vx,vy,role");
    assert_eq!(lines.len(), 1 + 6 * 4);
    // Frame 0 is the initial state.
    assert!(lines[1].starts_with("0,0,0,0,0,1,0,"), "{}", lines[1]);
    assert!(lines[4].starts_with("0,0,3,-1,1,1,-0.2,"), "{}", lines[4]);
    let last: Vec<&str> = lines[lines.len() - 1].split(',').collect();
    assert_eq!(last[0], "5");
    assert!((last[1].parse::<f64>().unwrap() - 0.5).abs() < 1e-12);
    assert!(
        text.contains(",leader\n"),
        "the front agents lead along the guidance"
    );
    // A larger herd has both roles.
    let big = dir.path().join("big.csv");
    ok(&[
        "simulate",
        "--agents",
        "80",
        "--steps",
        "2",
        "--guidance",
        "1,0",
        "--out",
        s(&big),
    ]);
    let t = std::fs::read_to_string(&big).unwrap();
    assert!(t.contains(",leader\n") && t.contains(",follower\n"));
    std::fs::remove_file(big).unwrap();
    // Nothing else is left in the folder.
    assert_eq!(std::fs::read_dir(dir.path()).unwrap().count(), 2);
}

#[test]
fn same_seed_same_bytes_and_zero_noise_is_deterministic() {
    let dir = tempfile::tempdir().unwrap();
    let run = |seed: &str, noise: &str, name: &str| -> Vec<u8> {
        let out = dir.path().join(name);
        ok(&[
            "simulate",
            "--agents",
            "60",
            "--steps",
            "8",
            "--seed",
            seed,
            "--speed-noise",
            noise,
            "--out",
            s(&out),
        ]);
        std::fs::read(out).unwrap()
    };
    let a = run("3", "0.3", "a.csv");
    let b = run("3", "0.3", "b.csv");
    assert_eq!(a, b);
    let c = run("4", "0.3", "c.csv");
    assert_ne!(a, c);
    // With v_σ = 0 the noise draws do not matter: two seeds, one initial herd, same bytes.
    let init = write(dir.path(), "init.csv", INIT);
    let run_init = |seed: &str, name: &str| -> Vec<u8> {
        let out = dir.path().join(name);
        ok(&[
            "simulate",
            "--init",
            s(&init),
            "--steps",
            "8",
            "--seed",
            seed,
            "--speed-noise",
            "0",
            "--out",
            s(&out),
        ]);
        std::fs::read(out).unwrap()
    };
    assert_eq!(run_init("1", "d.csv"), run_init("2", "e.csv"));
}

#[test]
fn record_then_replay_gives_identical_trajectories() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let init = write(d, "init.csv", INIT);
    let (a, b, c, rec) = (
        d.join("a.csv"),
        d.join("b.csv"),
        d.join("c.csv"),
        d.join("r.json"),
    );
    let base = [
        "simulate",
        "--init",
        s(&init),
        "--steps",
        "6",
        "--guidance",
        "0,1",
        "--speed-noise",
        "0.5",
    ];
    let run = |extra: &[&str]| {
        let mut v = base.to_vec();
        v.extend_from_slice(extra);
        ok(&v);
    };
    run(&["--seed", "1", "--record", s(&rec), "--out", s(&a)]);
    // Another seed draws other noise ...
    run(&["--seed", "2", "--out", s(&c)]);
    assert_ne!(std::fs::read(&a).unwrap(), std::fs::read(&c).unwrap());
    // ... but replaying the recording reproduces the recorded run byte for byte.
    run(&["--seed", "2", "--replay", s(&rec), "--out", s(&b)]);
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

fn gradcheck_json(args: &[&str]) -> serde_json::Value {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("g.json");
    let mut all = vec!["gradcheck"];
    all.extend_from_slice(args);
    all.extend_from_slice(&["--json", s(&out)]);
    let stdout = ok(&all);
    assert!(stdout.contains("cohesion.weight") && stdout.contains("max rel err"));
    serde_json::from_str(&std::fs::read_to_string(out).unwrap()).unwrap()
}

#[test]
fn gradcheck_f64_within_1e6_at_10_and_50_steps() {
    for steps in ["10", "50"] {
        let g = gradcheck_json(&["--steps", steps]);
        assert_eq!(g["agents"], 200);
        assert_eq!(g["steps"].as_u64().unwrap().to_string(), steps);
        let params = g["parameters"].as_array().unwrap();
        assert_eq!(params.len(), 12);
        assert_eq!(params[9]["name"], "obstacle.weight");
        let max = g["max_rel_err"].as_f64().unwrap();
        assert!(max <= 1e-6, "{steps} steps: max rel err {max}");
        for p in params {
            assert!(p["autodiff"].as_f64().unwrap().abs() > 1e-6, "{p}");
        }
    }
}

#[test]
fn gradcheck_f32_autodiff_matches_f64_within_1e2() {
    let dir = tempfile::tempdir().unwrap();
    let rec = dir.path().join("rec.json");
    let g64 = gradcheck_json(&["--steps", "50", "--record", s(&rec)]);
    let g32 = gradcheck_json(&["--steps", "50", "--precision", "f32", "--replay", s(&rec)]);
    assert_eq!(g32["precision"], "f32");
    for (a, b) in g64["parameters"]
        .as_array()
        .unwrap()
        .iter()
        .zip(g32["parameters"].as_array().unwrap())
    {
        let (a, b) = (
            a["autodiff"].as_f64().unwrap(),
            b["autodiff"].as_f64().unwrap(),
        );
        assert!((a - b).abs() <= 1e-2 * a.abs(), "f64 {a} vs f32 {b}");
    }
}

#[test]
fn bench_reports_its_fields() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("b.json");
    let bench = |args: &[&str]| -> serde_json::Value {
        let mut a = vec!["bench"];
        a.extend_from_slice(args);
        a.extend_from_slice(&["--json", s(&out)]);
        ok(&a);
        serde_json::from_str(&std::fs::read_to_string(&out).unwrap()).unwrap()
    };
    let b = bench(&["--agents", "100", "--steps", "3", "--repeats", "1"]);
    assert_eq!(b["agents"], 100);
    assert!(b["sim_ms_per_step"].as_f64().unwrap() > 0.0);
    assert!(b["grad_ms_per_step"].as_f64().unwrap() > 0.0);
    assert!(b["replay_grad_ms_per_step"].as_f64().unwrap() > 0.0);
    assert!(b["peak_rss_mb"].as_f64().unwrap() > 1.0);
    // Simulation only: no gradient figure of either kind.
    let b = bench(&["--agents", "50", "--steps", "2", "--sim-only"]);
    assert_eq!(b["agents"], 50);
    assert!(b["sim_ms_per_step"].as_f64().unwrap() > 0.0);
    assert!(b["grad_ms_per_step"].is_null());
    assert!(b["replay_grad_ms_per_step"].is_null());
}

#[test]
fn bad_input_fails_cleanly_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("traj.csv");
    let good = write(d, "init.csv", INIT);
    let cases: Vec<(Vec<String>, &str)> = {
        let garbled = write(d, "garbled.csv", "id,x,y,vx,vy\n0,0,0,1,0\n1,oops,0,1,0\n");
        let nan = write(d, "nan.csv", "id,x,y,vx,vy\n0,0,NaN,1,0\n");
        let empty = write(d, "empty.csv", "id,x,y,vx,vy\n");
        let noheader = write(d, "nohead.csv", "0,0,0,1,0\n");
        let params_bad = write(
            d,
            "bad.json",
            "{\"schema\": \"herdfit.params/1\", \"forces\": ",
        );
        let params_range = write(
            d,
            "range.json",
            r#"{"schema": "herdfit.params/1", "forces": {
              "cohesion": {"weight": 0.1, "radial": 0.2, "angular": 0.3},
              "avoidance": {"weight": 1.4, "radial": 0.5, "angular": 0.6},
              "alignment": {"weight": 0.7, "radial": 0.8, "angular": 0.9},
              "obstacle": {"weight": 1.0, "radial": 0.5, "angular": 0.5}}}"#,
        );
        let params_unknown = write(
            d,
            "unknown.json",
            r#"{"schema": "herdfit.params/1", "forces": {
              "cohesion": {"weight": 0.1, "radial": 0.2, "angular": 0.3},
              "avoidance": {"weight": 0.4, "radial": 0.5, "angular": 0.6},
              "alignment": {"weight": 0.7, "radial": 0.8, "angular": 0.9},
              "obstacle": {"weight": 1.0, "radial": 0.5, "angular": 0.5}}, "colour": 3}"#,
        );
        let g = |v: &[&str]| v.iter().map(|x| x.to_string()).collect::<Vec<_>>();
        let o = s(&out);
        vec![
            (
                g(&[
                    "simulate",
                    "--init",
                    s(&d.join("missing.csv")),
                    "--steps",
                    "3",
                    "--out",
                    o,
                ]),
                "missing.csv",
            ),
            (
                g(&[
                    "simulate",
                    "--init",
                    s(&garbled),
                    "--steps",
                    "3",
                    "--out",
                    o,
                ]),
                "line 3",
            ),
            (
                g(&["simulate", "--init", s(&nan), "--steps", "3", "--out", o]),
                "NaN",
            ),
            (
                g(&["simulate", "--init", s(&empty), "--steps", "3", "--out", o]),
                "empty herd",
            ),
            (
                g(&[
                    "simulate",
                    "--init",
                    s(&noheader),
                    "--steps",
                    "3",
                    "--out",
                    o,
                ]),
                "nohead.csv",
            ),
            (
                g(&[
                    "simulate",
                    "--params",
                    s(&params_bad),
                    "--agents",
                    "5",
                    "--steps",
                    "3",
                    "--out",
                    o,
                ]),
                "bad.json",
            ),
            (
                g(&[
                    "simulate",
                    "--params",
                    s(&params_range),
                    "--agents",
                    "5",
                    "--steps",
                    "3",
                    "--out",
                    o,
                ]),
                "avoidance.weight",
            ),
            (
                g(&[
                    "simulate",
                    "--params",
                    s(&params_unknown),
                    "--agents",
                    "5",
                    "--steps",
                    "3",
                    "--out",
                    o,
                ]),
                "colour",
            ),
            (
                g(&["simulate", "--agents", "0", "--steps", "3", "--out", o]),
                "empty",
            ),
            (
                g(&["simulate", "--init", s(&good), "--steps", "0", "--out", o]),
                "--steps",
            ),
            (
                g(&[
                    "simulate",
                    "--init",
                    s(&good),
                    "--steps",
                    "3",
                    "--fps",
                    "0",
                    "--out",
                    o,
                ]),
                "--fps",
            ),
            (
                g(&[
                    "simulate",
                    "--init",
                    s(&good),
                    "--steps",
                    "3",
                    "--speed-noise=-1",
                    "--out",
                    o,
                ]),
                "--speed-noise",
            ),
            (
                g(&[
                    "simulate",
                    "--init",
                    s(&good),
                    "--steps",
                    "3",
                    "--out",
                    s(&d.join("no-such-dir").join("t.csv")),
                ]),
                "no-such-dir",
            ),
            (
                g(&[
                    "simulate",
                    "--init",
                    s(&good),
                    "--steps",
                    "3",
                    "--out",
                    s(d),
                ]),
                "directory",
            ),
            (
                g(&[
                    "simulate",
                    "--init",
                    s(&good),
                    "--steps",
                    "3",
                    "--replay",
                    s(&garbled),
                    "--out",
                    o,
                ]),
                "garbled.csv",
            ),
            (
                g(&[
                    "gradcheck",
                    "--agents",
                    "0",
                    "--steps",
                    "3",
                    "--json",
                    s(&d.join("g.json")),
                ]),
                "empty",
            ),
            (
                g(&["gradcheck", "--steps", "0", "--json", s(&d.join("g.json"))]),
                "--steps",
            ),
            (
                g(&["bench", "--agents", "0", "--json", s(&d.join("b.json"))]),
                "empty",
            ),
        ]
    };
    for (args, needle) in cases {
        let a: Vec<&str> = args.iter().map(String::as_str).collect();
        let msg = fails(&a);
        assert!(msg.contains(needle), "{a:?}: '{msg}' lacks '{needle}'");
        assert!(!out.exists(), "{a:?} left a partial output");
        assert!(!d.join("g.json").exists() && !d.join("b.json").exists());
    }
    // No temporary files are left behind either.
    let leftovers: Vec<_> = std::fs::read_dir(d)
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().starts_with(".herdfit"))
        .collect();
    assert!(leftovers.is_empty());
}

#[test]
fn usage_errors_are_one_line_too() {
    let msg = fails_with(&["simulate", "--steps", "3"], 2);
    assert!(msg.contains("--out"), "{msg}");
    let msg = fails_with(
        &[
            "simulate", "--agents", "5", "--steps", "x", "--out", "t.csv",
        ],
        2,
    );
    assert!(msg.contains("--steps"), "{msg}");
    let msg = fails_with(
        &[
            "simulate",
            "--agents",
            "5",
            "--steps",
            "3",
            "--guidance",
            "0,0",
            "--out",
            "t.csv",
        ],
        2,
    );
    assert!(msg.contains("non-zero"), "{msg}");
    assert!(!std::path::Path::new("t.csv").exists());
}

/// Built without the cargo feature `gpu` (the README's plain build), `--device gpu` says how to
/// get it, in one line, and writes nothing.
#[cfg(not(feature = "gpu"))]
#[test]
fn device_gpu_without_the_feature_says_how_to_build_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("t.csv");
    let e = fails(&[
        "simulate",
        "--agents",
        "30",
        "--steps",
        "5",
        "--device",
        "gpu",
        "--out",
        s(&out),
    ]);
    assert!(e.contains("--features gpu"), "{e}");
    assert!(!out.exists());
}
