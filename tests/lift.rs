//! LIFT (issue #21): 3D flocks from 2D tracks, the glTF export, and their bad inputs.

mod common;

use common::{fails, ok, s};
use herdfit::data::camera::Camera;
use herdfit::data::gltf::read_glb;
use herdfit::data::jackdaw::read_jackdaw;
use herdfit::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
use herdfit::lift::boids::{synth_flock, BoidsConfig};
use herdfit::lift::eval::{evaluate, EvalReport};
use herdfit::lift::LiftConfig;
use herdfit::progress::NoProgress;
use std::path::{Path, PathBuf};
use std::process::Command;

/// `../shared/data` as the team brief resolves it: `HERDFIT_SHARED_DATA`, else beside the
/// repository, else `/work/shared/data`.
fn shared_data() -> PathBuf {
    if let Ok(p) = std::env::var("HERDFIT_SHARED_DATA") {
        return PathBuf::from(p);
    }
    let beside = Path::new(env!("CARGO_MANIFEST_DIR")).join("../shared/data");
    if beside.is_dir() {
        return beside;
    }
    PathBuf::from("/work/shared/data")
}

fn synth_to(dir: &Path) -> PathBuf {
    let out = dir.join("syn");
    ok(&[
        "lift",
        "synth",
        "--out",
        s(&out),
        "--birds",
        "12",
        "--frames",
        "150",
    ]);
    out
}

fn listing(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

#[test]
fn lifted_tracks_project_onto_the_input_tracks_within_1e_6_px() {
    let dir = tempfile::tempdir().unwrap();
    let syn = synth_to(dir.path());
    let out = dir.path().join("lifted.csv");
    let text = ok(&[
        "lift",
        "run",
        s(&syn.join("tracks2d.csv")),
        "--camera",
        s(&syn.join("camera.json")),
        "--out",
        s(&out),
        "--v-target",
        "0.333333",
        "--d-near",
        "20",
        "--d-far",
        "400",
        "--iterations",
        "60",
    ]);
    assert!(text.contains("reprojection"), "{text}");
    let input = Tracks::load(&syn.join("tracks2d.csv")).unwrap();
    let lifted = Tracks::load(&out).unwrap();
    let cam = Camera::load(&syn.join("camera.json")).unwrap();
    assert_eq!(lifted.meta.dimension, 3);
    assert_eq!(lifted.meta.units, Units::Metres);
    assert_eq!(
        lifted.rows.len(),
        input.rows.len(),
        "one 3D point per tracked point"
    );
    let mut worst: f64 = 0.0;
    for (a, b) in input.rows.iter().zip(&lifted.rows) {
        assert_eq!((a.frame, a.id), (b.frame, b.id));
        let (p, d) = cam.project(b.pos).expect("in front of the camera");
        assert!((20.0..=400.0).contains(&d), "depth {d} within the bounds");
        worst = worst.max((p[0] - a.pos[0]).hypot(p[1] - a.pos[1]));
    }
    assert!(worst < 1e-6, "reprojection error {worst} px");
    let report: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.path().join("lifted.report.json")).unwrap(),
    )
    .unwrap();
    assert_eq!(report["schema"], "herdfit.lift-report/2");
    assert!(
        report["whole_sequence"]["reprojection_max_px"]
            .as_f64()
            .unwrap()
            < 1e-6
    );
    // The same inputs give the same bytes.
    let again = dir.path().join("again.csv");
    ok(&[
        "lift",
        "run",
        s(&syn.join("tracks2d.csv")),
        "--camera",
        s(&syn.join("camera.json")),
        "--out",
        s(&again),
        "--v-target",
        "0.333333",
        "--d-near",
        "20",
        "--d-far",
        "400",
        "--iterations",
        "60",
    ]);
    assert_eq!(std::fs::read(&out).unwrap(), std::fs::read(&again).unwrap());
}

fn scores(r: &EvalReport) -> [(f64, f64); 4] {
    let mut out = [(0.0, 0.0); 4];
    for (k, name) in [
        "true_mean_depth",
        "constant_median",
        "frame_by_frame",
        "whole_sequence",
    ]
    .iter()
    .enumerate()
    {
        let m = r.methods.iter().find(|m| m.name == *name).unwrap();
        out[k] = (m.depth_rmse_relative, m.position_rmse);
    }
    out
}

#[test]
fn whole_sequence_beats_the_baselines_on_a_synthetic_flock_with_entries_and_exits() {
    let b = BoidsConfig::demo();
    let syn = synth_flock(&b, &mut NoProgress).unwrap();
    assert!(
        syn.tracks.rows.len() < syn.truth.rows.len(),
        "some points leave the view"
    );
    let cfg = herdfit::lift::demo_config(&b);
    let ev = evaluate(&syn.truth, &syn.camera, &cfg, true, &mut NoProgress).unwrap();
    let [_, constant, fbf, seq] = scores(&ev.report);
    assert!(
        seq.0 < constant.0 && seq.0 < fbf.0,
        "{:?}",
        ev.report.methods
    );
    assert!(seq.1 < constant.1 && seq.1 < fbf.1);
    let w = ev
        .report
        .methods
        .iter()
        .find(|m| m.name == "whole_sequence")
        .unwrap();
    assert_eq!(
        w.checks.pairs_below_half_d_sep, 0,
        "no two birds closer than d_sep / 2"
    );
    assert!(w.checks.reprojection_max_px < 1e-6);
    for r in w.speed_change_ratio {
        assert!(
            (0.5..=2.0).contains(&r),
            "speed changes within 2× the truth's: {:?}",
            w.speed_change_ratio
        );
    }
}

/// The virtual ground observers of RESULTS.md: 60 m south of each flight's centroid, 5 m below
/// its lowest bird, looking at the centroid; 1920 × 1080, 60° horizontal field of view.
fn jackdaw_camera(name: &str) -> Camera {
    let (pos, at) = match name {
        "transit_05" => ([3.6, -65.1, -16.8], [3.6, -5.1, -0.7]),
        _ => ([-7.3, -59.5, -17.9], [-7.3, 0.6, 3.9]),
    };
    Camera::look_at(Units::Metres, 1920, 1080, 60.0, pos, at, [0.0, 0.0, 1.0]).unwrap()
}

#[test]
fn on_both_jackdaw_flights_the_whole_sequence_beats_constant_depth_and_frame_by_frame() {
    for name in ["transit_05", "mob_10"] {
        let truth = read_jackdaw(&shared_data().join(format!("jackdaws/{name}.csv"))).unwrap();
        let cfg = LiftConfig {
            v_target: Some(9.0 / 60.0),
            d_near: Some(10.0),
            d_far: Some(150.0),
            ..LiftConfig::default()
        };
        let ev = evaluate(&truth, &jackdaw_camera(name), &cfg, false, &mut NoProgress).unwrap();
        let [_, constant, fbf, seq] = scores(&ev.report);
        assert!(
            seq.0 < constant.0 && seq.0 < fbf.0,
            "{name}: {:?}",
            ev.report.methods
        );
        assert!(seq.1 < constant.1 && seq.1 < fbf.1, "{name}");
        assert_eq!(ev.report.observations, truth.rows.len());
    }
}

fn validate_gltf(files: &[&Path]) -> String {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    assert!(
        root.join(".ci/node_modules/gltf-validator/package.json")
            .is_file(),
        "the Khronos glTF validator is not installed: run scripts/setup-debian.sh"
    );
    let o = Command::new("node")
        .arg(root.join("scripts/validate-gltf.js"))
        .args(files)
        .output()
        .expect("node runs (scripts/setup-debian.sh installs it)");
    let text = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{text}{}",
        String::from_utf8_lossy(&o.stderr)
    );
    text
}

#[test]
fn exported_gltf_files_pass_the_khronos_validator_and_replay_the_tracks() {
    let dir = tempfile::tempdir().unwrap();
    let syn = synth_to(dir.path());
    // 3D (synthetic truth, birds always present), 2D px (birds leave and enter), 2D metres (ETH).
    let eth = shared_data().join("pedestrians/eth-ucy/biwi_eth.txt");
    let eth_tracks = herdfit::data::tracks::read_eth_ucy(&eth, 2.5).unwrap();
    let eth_csv = dir.path().join("eth.csv");
    eth_tracks.save(&eth_csv).unwrap();
    let cases = [
        (syn.join("truth3d.csv"), dir.path().join("truth.glb")),
        (syn.join("tracks2d.csv"), dir.path().join("px.glb")),
        (eth_csv.clone(), dir.path().join("eth.glb")),
    ];
    for (t, g) in &cases {
        let text = ok(&["export-gltf", s(t), "--out", s(g)]);
        assert!(text.contains("nodes"), "{text}");
    }
    let files: Vec<&Path> = cases.iter().map(|c| c.1.as_path()).collect();
    let report = validate_gltf(&files);
    assert_eq!(report.matches(": 0 errors").count(), 3, "{report}");
    // Read back: one node per bird; at a key time every present bird sits at its track point
    // (z-up (x, y, z) → y-up (x, z, −y)) and absent ones are hidden.
    let truth = Tracks::load(&syn.join("truth3d.csv")).unwrap();
    let g = read_glb(&cases[0].1).unwrap();
    assert_eq!(g.root.nodes.len(), truth.ids().len());
    let frame = 40;
    let t = truth.rows.iter().find(|r| r.frame == frame).unwrap().time;
    let nodes = g.sample(t).unwrap();
    for r in truth.rows.iter().filter(|r| r.frame == frame) {
        let (_, tr, _, sc) = nodes
            .iter()
            .find(|n| n.0 == format!("bird {}", r.id))
            .unwrap();
        let want = [r.pos[0], r.pos[2], -r.pos[1]];
        for k in 0..3 {
            assert!(
                (tr[k] - want[k]).abs() < 1e-3 * (1.0 + want[k].abs()),
                "{tr:?} vs {want:?}"
            );
        }
        assert_eq!(*sc, [1.0; 3]);
    }
    let px = Tracks::load(&syn.join("tracks2d.csv")).unwrap();
    let gp = read_glb(&cases[1].1).unwrap();
    let last = px.rows.last().unwrap();
    let hidden = gp
        .sample(last.time)
        .unwrap()
        .iter()
        .filter(|n| n.3 == [0.0; 3])
        .count();
    let present = px.rows.iter().filter(|r| r.frame == last.frame).count();
    assert_eq!(
        hidden,
        px.ids().len() - present,
        "birds out of view are hidden"
    );
    // The preview renders the exported file.
    let png = dir.path().join("preview.png");
    let text = ok(&[
        "export-gltf",
        s(&syn.join("truth3d.csv")),
        "--out",
        s(&cases[0].1),
        "--preview",
        s(&png),
        "--preview-camera",
        s(&syn.join("camera.json")),
    ]);
    assert!(text.contains("preview: 12 birds"), "{text}");
    assert!(std::fs::metadata(&png).unwrap().len() > 1000);
}

fn write_tracks(path: &Path, rows: &[(u64, u64, f64, f64)]) {
    let rows = rows
        .iter()
        .map(|&(frame, id, x, y)| TrackRow {
            frame,
            time: frame as f64 / 30.0,
            id,
            pos: [x, y, 0.0],
            vel: None,
            role: None,
        })
        .collect();
    Tracks::new(TracksMeta::new(Units::Pixels, 30.0, 2), rows)
        .unwrap()
        .save(path)
        .unwrap();
}

#[test]
fn bad_inputs_fail_with_one_line_and_leave_nothing_behind() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cam = Camera::look_at(
        Units::Metres,
        640,
        480,
        60.0,
        [0.0, -50.0, 1.0],
        [0.0, 0.0, 10.0],
        [0.0, 0.0, 1.0],
    )
    .unwrap();
    cam.save(&d.join("cam.json")).unwrap();
    let mut zero = cam.clone();
    zero.fx = 0.0;
    std::fs::write(d.join("zero.json"), serde_json::to_string(&zero).unwrap()).unwrap();
    let good: Vec<(u64, u64, f64, f64)> = (0..5)
        .flat_map(|f| {
            [
                (f, 1, 300.0 + f as f64, 200.0),
                (f, 2, 340.0, 210.0 - f as f64),
            ]
        })
        .collect();
    write_tracks(&d.join("good.csv"), &good);
    let mut outside = good.clone();
    outside[3].2 = 700.0;
    write_tracks(&d.join("outside.csv"), &outside);
    let single: Vec<_> = good.iter().filter(|r| r.1 == 1).copied().collect();
    write_tracks(&d.join("single.csv"), &single);
    std::fs::write(
        d.join("nan.csv"),
        "frame,time,id,x,y\n0,0,1,300,200\n0,0,2,NaN,210\n1,0.0333,1,301,200\n1,0.0333,2,340,209\n",
    )
    .unwrap();
    std::fs::write(
        d.join("nan.json"),
        r#"{"schema":"herdfit.tracks/1","units":"px","fps":30,"dimension":2}"#,
    )
    .unwrap();
    let before = listing(d);
    let out = d.join("out.csv");
    let run = |tracks: &str, cam: &str| {
        fails(&[
            "lift",
            "run",
            s(&d.join(tracks)),
            "--camera",
            s(&d.join(cam)),
            "--out",
            s(&out),
        ])
    };
    let e = run("good.csv", "zero.json");
    assert!(
        e.contains("zero.json") && e.contains("fx = 0 must be > 0"),
        "{e}"
    );
    let e = run("outside.csv", "cam.json");
    assert!(
        e.contains("outside.csv") && e.contains("outside the 640 × 480 image"),
        "{e}"
    );
    let e = run("single.csv", "cam.json");
    assert!(
        e.contains("single.csv") && e.contains("only one bird"),
        "{e}"
    );
    let e = run("nan.csv", "cam.json");
    assert!(e.contains("nan.csv") && e.contains("x is NaN"), "{e}");
    let e = fails(&[
        "lift",
        "run",
        s(&d.join("good.csv")),
        "--camera",
        s(&d.join("cam.json")),
        "--out",
        s(&out),
        "--d-near",
        "50",
        "--d-far",
        "10",
    ]);
    assert!(
        e.contains("--d-near: d_near = 50 must be below d_far = 10"),
        "{e}"
    );
    let e = fails(&[
        "export-gltf",
        s(&d.join("nan.csv")),
        "--out",
        s(&d.join("x.glb")),
    ]);
    assert!(e.contains("nan.csv") && e.contains("x is NaN"), "{e}");
    let e = fails(&[
        "lift",
        "project",
        s(&d.join("good.csv")),
        "--camera",
        s(&d.join("cam.json")),
        "--out",
        s(&out),
    ]);
    assert!(
        e.contains("good.csv") && e.contains("needs 3D tracks"),
        "{e}"
    );
    // Five frames are too few to estimate v_target from how the birds turn: the user is told to
    // give it.
    let e = run("good.csv", "cam.json");
    assert!(
        e.contains("good.csv") && e.contains("v_target not given") && e.contains("give v_target"),
        "{e}"
    );
    assert_eq!(listing(d), before, "nothing new on disk");
    // The good input works with v_target and the bounds given.
    ok(&[
        "lift",
        "run",
        s(&d.join("good.csv")),
        "--camera",
        s(&d.join("cam.json")),
        "--out",
        s(&out),
        "--iterations",
        "5",
        "--v-target",
        "0.1",
        "--d-near",
        "1",
        "--d-far",
        "100",
    ]);
    assert!(out.is_file());
}

#[test]
fn the_demo_section_scores_the_four_estimates_and_writes_a_valid_glb() {
    let dir = tempfile::tempdir().unwrap();
    let t0 = std::time::Instant::now();
    let summary = herdfit::lift::demo(dir.path(), &mut NoProgress).unwrap();
    let secs = t0.elapsed().as_secs_f64();
    let text = summary.to_string();
    eprintln!("{text}\n(lift demo: {secs:.1} s)");
    assert_eq!(summary.scores.len(), 4);
    assert!(
        text.contains("3D RMSE (m)") && text.contains("flock.glb"),
        "{text}"
    );
    let lift = dir.path().join("lift");
    for f in [
        "tracks2d.csv",
        "truth3d.csv",
        "lifted3d.csv",
        "eval.json",
        "top.png",
        "side.png",
        "flock.glb",
        "flock_render.png",
    ] {
        assert!(lift.join(f).is_file(), "{f} written");
    }
    let report = validate_gltf(&[&lift.join("flock.glb")]);
    assert!(report.contains(": 0 errors"), "{report}");
    // The whole-sequence lift is the demo's result: better than the constant baseline.
    let s = &summary.scores;
    assert!(s[3].position_rmse < s[1].position_rmse, "{text}");
}
