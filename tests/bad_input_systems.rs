//! Issue #14's bad-input promises for the verbs of the newer systems (`import-tracks`,
//! `export-gltf`, `flock extract`), through the binary with the same harness as
//! `tests/bad_input.rs`: non-zero exit, one `error:` line naming the file or flag, no panic, the
//! folder listing and every file's bytes unchanged.

// The shared harness; this file uses part of it.
#[path = "bad_input/harness.rs"]
#[allow(dead_code)]
mod harness;

use harness::{bin, case_in, workdir};

/// A fresh folder with a small tracks file `t.csv` (TRAJ.csv written by `simulate`).
fn with_tracks() -> tempfile::TempDir {
    let t = workdir();
    let o = bin()
        .args([
            "simulate", "--agents", "5", "--steps", "3", "--out", "t.csv",
        ])
        .current_dir(t.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    t
}

fn tracks_case(args: &[&str], names: &str) {
    let t = with_tracks();
    case_in(t.path(), args, names);
}

#[test]
fn import_tracks_onto_a_device_is_refused() {
    tracks_case(
        &["import-tracks", "t.csv", "--out", "/dev/null"],
        "/dev/null",
    );
}

#[test]
fn import_tracks_onto_its_input_is_refused() {
    tracks_case(&["import-tracks", "t.csv", "--out", "t.csv"], "t.csv");
}

#[test]
fn import_tracks_onto_the_folder_holding_its_input_is_refused() {
    tracks_case(&["import-tracks", "t.csv", "--out", "."], "input");
}

#[test]
fn import_tracks_onto_a_symlink_is_refused() {
    let t = with_tracks();
    std::os::unix::fs::symlink("clip", t.path().join("link")).unwrap();
    case_in(
        t.path(),
        &["import-tracks", "t.csv", "--out", "link"],
        "link",
    );
    assert!(
        t.path().join("clip/clip.json").is_file(),
        "the clip survives"
    );
}

#[test]
fn import_tracks_rejects_nan_and_out_of_range_settings() {
    let t = with_tracks();
    let d = t.path();
    case_in(
        d,
        &["import-tracks", "t.csv", "--out", "c", "--fps", "NaN"],
        "--fps",
    );
    case_in(
        d,
        &["import-tracks", "t.csv", "--out", "c", "--fps", "1e-9"],
        "--fps",
    );
    case_in(
        d,
        &["import-tracks", "t.csv", "--out", "c", "--grid", "100000"],
        "--grid",
    );
    case_in(
        d,
        &[
            "import-tracks",
            "t.csv",
            "--out",
            "c",
            "--body-length-px",
            "0",
        ],
        "--body-length-px",
    );
}

#[test]
fn import_tracks_refuses_a_grid_beyond_the_cell_limit() {
    let t = with_tracks();
    for c in ["1e-12", "1e-300"] {
        case_in(
            t.path(),
            &["import-tracks", "t.csv", "--out", "c", "--cell-size", c],
            "--cell-size",
        );
    }
}

#[test]
fn export_gltf_onto_its_input_or_a_device_is_refused() {
    let t = with_tracks();
    case_in(
        t.path(),
        &["export-gltf", "t.csv", "--out", "t.csv"],
        "t.csv",
    );
    case_in(
        t.path(),
        &["export-gltf", "t.csv", "--out", "/dev/null"],
        "/dev/null",
    );
    case_in(
        t.path(),
        &["export-gltf", "t.csv", "--out", "o.glb", "--scale", "NaN"],
        "--scale",
    );
}

#[test]
fn flock_extract_without_a_wingspan_names_the_file() {
    tracks_case(&["flock", "extract", "t.csv", "--out", "s.json"], "t.csv");
}
