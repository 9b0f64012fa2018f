//! Issue #47's probe, case by case: each command that broke a promise, as a regression test named
//! after what it pins. Every refusal is checked by the bad-input harness: non-zero exit, one
//! `error:` line naming the file or flag, no panic, the folder (hidden files included) and every
//! input byte-identical.

#[path = "whole_cli/fixture.rs"]
mod fixture;
#[path = "bad_input/harness.rs"]
#[allow(dead_code)]
mod harness;

use harness::{case_full_disk, case_in};
use std::path::Path;

/// A fresh folder with the whole-CLI fixture (tracks with sidecars, a crowd model, a camera, …).
fn folder() -> tempfile::TempDir {
    let t = tempfile::tempdir().unwrap();
    copy(fixture::fixture(), t.path());
    t
}

fn copy(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let (p, q) = (e.path(), to.join(e.file_name()));
        if p.is_dir() {
            copy(&p, &q);
        } else {
            std::fs::copy(&p, &q).unwrap();
        }
    }
}

fn refused(args: &[&str], names: &str) {
    let t = folder();
    case_in(t.path(), args, names);
}

// ---- An output written onto an input's JSON sidecar (the input destroyed, exit 0) ----

#[test]
fn flock_extract_onto_its_inputs_sidecar_is_refused() {
    refused(&["flock", "extract", "f.csv", "--out", "f.json"], "f.json");
}

#[test]
fn crowd_learn_onto_its_inputs_sidecar_is_refused() {
    refused(&["crowd", "learn", "t.csv", "--out", "t.json"], "t.json");
}

#[test]
fn lift_run_report_onto_its_inputs_sidecar_is_refused() {
    refused(
        &[
            "lift", "run", "t2.csv", "--camera", "cam.json", "--out", "o.csv", "--report",
            "t2.json",
        ],
        "t2.json",
    );
}

#[test]
fn crowd_simulate_compare_onto_the_entries_sidecar_is_refused() {
    refused(
        &[
            "crowd",
            "simulate",
            "model.json",
            "--entries",
            "t.csv",
            "--steps",
            "5",
            "--compare",
            "t.json",
            "--out",
            "s.csv",
        ],
        "t.json",
    );
}

#[test]
fn export_gltf_onto_its_inputs_sidecar_is_refused() {
    refused(&["export-gltf", "t3.csv", "--out", "t3.json"], "t3.json");
}

#[test]
fn crowd_compare_json_onto_an_inputs_sidecar_is_refused() {
    refused(
        &["crowd", "compare", "t.csv", "u.csv", "--json", "t.json"],
        "t.json",
    );
}

// ---- A refused run leaves its CSV behind (the output's sidecar would overwrite an input) ----

#[test]
fn crowd_simulate_whose_sidecar_is_the_model_writes_nothing() {
    refused(
        &[
            "crowd",
            "simulate",
            "model.json",
            "--entries",
            "t.csv",
            "--steps",
            "5",
            "--out",
            "model.csv",
        ],
        "model.json",
    );
}

#[test]
fn lift_run_whose_sidecar_is_the_camera_writes_nothing() {
    refused(
        &[
            "lift", "run", "t2.csv", "--camera", "cam.json", "--out", "cam.csv",
        ],
        "cam.json",
    );
}

#[test]
fn lift_project_whose_sidecar_is_the_camera_writes_nothing() {
    refused(
        &[
            "lift", "project", "t3.csv", "--camera", "cam.json", "--out", "cam.csv",
        ],
        "cam.json",
    );
}

#[test]
fn flock_synth_whose_sidecar_is_its_config_writes_nothing() {
    refused(
        &[
            "flock",
            "synth",
            "--config",
            "fsyn.json",
            "--out",
            "fsyn.csv",
        ],
        "fsyn.json",
    );
}

// ---- A full disk (a file-size limit: every write past it fails, as on a full disk) ----

#[test]
fn lift_run_video_on_a_full_disk_is_refused_not_truncated() {
    let t = folder();
    case_full_disk(
        t.path(),
        &[
            "lift", "run", "t2.csv", "--camera", "cam.json", "--out", "o.csv", "--video", "v.avi",
        ],
        "",
        20_000,
    );
}

#[test]
fn crowd_simulate_video_on_a_full_disk_is_refused_not_truncated() {
    let t = folder();
    case_full_disk(
        t.path(),
        &[
            "crowd",
            "simulate",
            "model.json",
            "--layout",
            "layout.json",
            "--video",
            "v.avi",
            "--out",
            "s.csv",
        ],
        "",
        20_000,
    );
}

#[test]
fn flock_animate_video_on_a_full_disk_is_refused_not_truncated() {
    let t = folder();
    case_full_disk(
        t.path(),
        &[
            "flock",
            "animate",
            "shape.json",
            "--birds",
            "5",
            "--frames",
            "40",
            "--out",
            "fa",
        ],
        "",
        60_000,
    );
}

#[test]
fn fit_zones_loss_curve_on_a_full_disk_fails_the_run_and_claims_nothing() {
    let t = folder();
    // The bundle and the log fit under the limit; the loss curve (a PNG of tens of kB) does not.
    case_full_disk(
        t.path(),
        &[
            "fit",
            "clip",
            "--zones",
            "zones.json",
            "--epochs",
            "1",
            "--window",
            "2",
            "--no-uncertainty",
            "--out",
            "s.json",
        ],
        "",
        12_000,
    );
}

// ---- Aborts: sizes checked before anything is allocated ----

#[test]
fn bench_with_a_billion_agents_is_refused_up_front() {
    refused(
        &["bench", "--agents", "1000000000", "--json", "b.json"],
        "--agents",
    );
}

#[test]
fn gradcheck_with_a_billion_agents_is_refused_up_front() {
    refused(
        &[
            "gradcheck",
            "--agents",
            "1000000000",
            "--steps",
            "2",
            "--json",
            "g.json",
        ],
        "--agents",
    );
}

#[test]
fn a_crowd_layout_spawning_a_billion_is_refused_up_front() {
    let t = folder();
    std::fs::write(
        t.path().join("big.json"),
        r#"{"schema": "herdfit.crowd-layout/1", "spawns": [{"position": [0, 0],
            "goal": [10, 0], "count": 1000000000}]}"#,
    )
    .unwrap();
    case_in(
        t.path(),
        &[
            "crowd",
            "simulate",
            "model.json",
            "--layout",
            "big.json",
            "--out",
            "s.csv",
        ],
        "big.json",
    );
}

#[test]
fn an_npy_header_declaring_a_trillion_points_is_refused_up_front() {
    let t = folder();
    let head = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000, 1000000, 2), }";
    let mut h = head.to_string();
    while (h.len() + 11) % 64 != 0 {
        h.push(' ');
    }
    h.push('\n');
    let mut bytes = b"\x93NUMPY\x01\x00".to_vec();
    bytes.extend((h.len() as u16).to_le_bytes());
    bytes.extend(h.as_bytes());
    bytes.extend([0u8; 64]);
    std::fs::write(t.path().join("big.npy"), bytes).unwrap();
    case_in(
        t.path(),
        &[
            "import-tracks",
            "big.npy",
            "--fps",
            "25",
            "--body-length-px",
            "10",
            "--out",
            "c",
        ],
        "big.npy",
    );
}

// ---- A panic: a shape file out of range ----

#[test]
fn a_flock_shape_file_with_a_huge_mean_gap_is_refused_without_a_panic() {
    let t = folder();
    let text = std::fs::read_to_string(t.path().join("shape.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["frames"][0]["mean_gap"] = serde_json::json!(1e300);
    std::fs::write(t.path().join("huge.json"), v.to_string()).unwrap();
    case_in(
        t.path(),
        &["flock", "animate", "huge.json", "--out", "fa"],
        "huge.json",
    );
}

// ---- 1e300 turned into NaN or inf output ----

/// `t.csv`'s sibling with its first x set to 1e300 (and the same sidecar).
fn huge_tracks(dir: &Path, src: &str, name: &str) {
    let text = std::fs::read_to_string(dir.join(format!("{src}.csv"))).unwrap();
    let mut lines: Vec<String> = text.lines().map(str::to_string).collect();
    let head: Vec<&str> = lines[0].split(',').collect();
    let xi = head.iter().position(|h| *h == "x").unwrap();
    let mut row: Vec<String> = lines[1].split(',').map(str::to_string).collect();
    row[xi] = "1e300".into();
    lines[1] = row.join(",");
    std::fs::write(dir.join(format!("{name}.csv")), lines.join("\n") + "\n").unwrap();
    std::fs::copy(
        dir.join(format!("{src}.json")),
        dir.join(format!("{name}.json")),
    )
    .unwrap();
}

#[test]
fn flock_extract_of_a_huge_coordinate_is_refused_not_written_as_null() {
    let t = folder();
    huge_tracks(t.path(), "f", "fh");
    case_in(
        t.path(),
        &["flock", "extract", "fh.csv", "--out", "s.json"],
        "fh.csv",
    );
}

#[test]
fn export_gltf_of_a_huge_coordinate_is_refused_not_written_as_infinity() {
    let t = folder();
    huge_tracks(t.path(), "t3", "th");
    case_in(
        t.path(),
        &["export-gltf", "th.csv", "--out", "e.glb"],
        "th.csv",
    );
}

#[test]
fn export_gltf_with_a_huge_scale_is_refused_not_written_as_infinity() {
    refused(
        &[
            "export-gltf",
            "t3.csv",
            "--scale",
            "1e300",
            "--out",
            "e.glb",
        ],
        "--scale",
    );
}

// ---- Lesser lapses: absurd values, limits up front, the flag or file named ----

#[test]
fn flock_synth_absurd_noise_is_refused() {
    refused(
        &["flock", "synth", "--noise", "1e300", "--out", "s.csv"],
        "--noise",
    );
}

#[test]
fn flock_extract_absurd_wingspan_is_refused() {
    refused(
        &[
            "flock",
            "extract",
            "f.csv",
            "--wingspan",
            "1e300",
            "--out",
            "s.json",
        ],
        "--wingspan",
    );
}

#[test]
fn flock_animate_absurd_altitude_is_refused() {
    let t = folder();
    std::fs::write(t.path().join("alt.json"), r#"{"altitude_m": 1e300}"#).unwrap();
    case_in(
        t.path(),
        &[
            "flock",
            "animate",
            "shape.json",
            "--config",
            "alt.json",
            "--out",
            "fa",
        ],
        "alt.json",
    );
}

#[test]
fn a_crowd_model_with_an_absurd_time_step_is_refused() {
    let t = folder();
    let text = std::fs::read_to_string(t.path().join("model.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["dt"] = serde_json::json!(1e300);
    std::fs::write(t.path().join("dt.json"), v.to_string()).unwrap();
    case_in(
        t.path(),
        &[
            "crowd",
            "simulate",
            "dt.json",
            "--layout",
            "layout.json",
            "--out",
            "s.csv",
        ],
        "dt.json",
    );
}

#[test]
fn lift_run_absurd_v_target_is_refused() {
    refused(
        &[
            "lift",
            "run",
            "t2.csv",
            "--camera",
            "cam.json",
            "--v-target",
            "1e300",
            "--out",
            "o.csv",
        ],
        "--v-target",
    );
}

#[test]
fn validate_absurd_coarse_grid_is_refused() {
    refused(
        &[
            "validate",
            "clip",
            "--params",
            "p.json",
            "--coarse-grid",
            "1000000000",
            "--out",
            "v",
        ],
        "--coarse-grid",
    );
}

#[test]
fn validate_a_billion_seeds_is_refused_up_front() {
    refused(
        &[
            "validate",
            "clip",
            "--params",
            "p.json",
            "--seeds",
            "1000000000",
            "--out",
            "v",
        ],
        "--seeds",
    );
}

#[test]
fn crowd_simulate_a_billion_steps_is_refused_up_front_naming_the_flag() {
    refused(
        &[
            "crowd",
            "simulate",
            "model.json",
            "--layout",
            "layout.json",
            "--steps",
            "1000000000",
            "--out",
            "s.csv",
        ],
        "--steps",
    );
}

#[test]
fn a_crowd_layout_lasting_forever_is_refused_up_front() {
    let t = folder();
    let text = std::fs::read_to_string(t.path().join("layout.json")).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["duration"] = serde_json::json!(1e12);
    std::fs::write(t.path().join("long.json"), v.to_string()).unwrap();
    case_in(
        t.path(),
        &[
            "crowd",
            "simulate",
            "model.json",
            "--layout",
            "long.json",
            "--out",
            "s.csv",
        ],
        "long.json",
    );
}

#[test]
fn crowd_learn_errors_name_the_flag_not_the_config_key() {
    let t = folder();
    let e = refused_line(
        t.path(),
        &["crowd", "learn", "t.csv", "--radius=-1", "--out", "m.json"],
    );
    assert!(
        e.contains("--radius") && !e.contains("features.radius"),
        "{e}"
    );
}

#[test]
fn a_bad_sidecar_value_names_the_sidecar_not_the_csv() {
    let t = folder();
    let side = t.path().join("t.json");
    let text = std::fs::read_to_string(&side).unwrap();
    let mut v: serde_json::Value = serde_json::from_str(&text).unwrap();
    v["fps"] = serde_json::json!(-3);
    std::fs::write(&side, v.to_string()).unwrap();
    let e = refused_line(t.path(), &["crowd", "learn", "t.csv", "--out", "m.json"]);
    assert!(e.starts_with("error: t.json: ") && e.contains("fps"), "{e}");
}

/// Runs a refused case in `dir` and returns its error line.
fn refused_line(dir: &Path, args: &[&str]) -> String {
    let before = harness::snapshot(dir);
    let o = harness::bin().args(args).current_dir(dir).output().unwrap();
    harness::check(args, &o, "", dir, &before);
    String::from_utf8_lossy(&o.stderr).trim().to_string()
}
