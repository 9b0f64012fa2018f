//! The bad-input suite of issue #14 through the binary. Each case asserts (see `harness`):
//! non-zero exit, one `error: …` line naming the file or key, no panic text, the folder listing
//! (hidden files included) and every input's bytes unchanged.

#[path = "bad_input/harness.rs"]
mod harness;

use harness::{case, case_in, workdir};

// ---- Data loss and damage: outputs onto devices, symlinks, FIFOs and inputs ----

#[test]
fn simulate_onto_a_device_is_refused() {
    case(
        &[
            "simulate",
            "--agents",
            "5",
            "--steps",
            "2",
            "--out",
            "/dev/null",
        ],
        "/dev/null",
    );
    use std::os::unix::fs::FileTypeExt;
    let m = std::fs::symlink_metadata("/dev/null").unwrap();
    assert!(
        m.file_type().is_char_device(),
        "/dev/null is still a device"
    );
}

#[test]
fn simulate_onto_dev_stdout_is_refused() {
    case(
        &[
            "simulate",
            "--agents",
            "5",
            "--steps",
            "2",
            "--out",
            "/dev/stdout",
        ],
        "/dev/stdout",
    );
    assert!(std::fs::symlink_metadata("/dev/stdout")
        .unwrap()
        .file_type()
        .is_symlink());
}

#[test]
fn simulate_onto_a_symlink_is_refused() {
    let t = workdir();
    std::fs::write(t.path().join("real.csv"), "keep me").unwrap();
    std::os::unix::fs::symlink("real.csv", t.path().join("link.csv")).unwrap();
    case_in(
        t.path(),
        &[
            "simulate", "--agents", "5", "--steps", "2", "--out", "link.csv",
        ],
        "link.csv",
    );
}

#[test]
fn simulate_onto_a_dangling_symlink_is_refused() {
    let t = workdir();
    std::os::unix::fs::symlink("nowhere.csv", t.path().join("link.csv")).unwrap();
    case_in(
        t.path(),
        &[
            "simulate", "--agents", "5", "--steps", "2", "--out", "link.csv",
        ],
        "link.csv",
    );
}

#[test]
fn simulate_onto_a_fifo_is_refused_without_blocking() {
    let t = workdir();
    let st = std::process::Command::new("mkfifo")
        .arg(t.path().join("out.csv"))
        .status()
        .unwrap();
    assert!(st.success());
    case_in(
        t.path(),
        &[
            "simulate", "--agents", "5", "--steps", "2", "--out", "out.csv",
        ],
        "out.csv",
    );
}

#[test]
fn fit_log_onto_a_device_is_refused() {
    case(
        &[
            "fit",
            "clip",
            "--out",
            "q.json",
            "--epochs",
            "1",
            "--log",
            "/dev/null",
        ],
        "/dev/null",
    );
}

#[test]
fn fit_plot_onto_a_device_is_refused() {
    case(
        &[
            "fit",
            "clip",
            "--out",
            "q.json",
            "--epochs",
            "1",
            "--plot",
            "/dev/zero",
        ],
        "/dev/zero",
    );
}

#[test]
fn fields_info_json_onto_a_device_is_refused() {
    case(&["fields-info", "clip", "--json", "/dev/full"], "/dev/full");
}

#[test]
fn fit_out_onto_the_clips_metadata_is_refused() {
    case(
        &["fit", "clip", "--out", "clip/clip.json", "--epochs", "1"],
        "clip/clip.json",
    );
}

#[test]
fn fit_out_onto_its_start_is_refused() {
    case(
        &[
            "fit", "clip", "--start", "p.json", "--out", "p.json", "--epochs", "1",
        ],
        "p.json",
    );
}

#[test]
fn fit_log_onto_its_start_is_refused() {
    case(
        &[
            "fit", "clip", "--start", "p.json", "--out", "q.json", "--log", "p.json",
        ],
        "p.json",
    );
}

#[test]
fn fit_out_into_the_clip_folder_is_refused() {
    case(
        &["fit", "clip", "--out", "clip/new.json", "--epochs", "1"],
        "clip/new.json",
    );
}

#[test]
fn validate_out_onto_its_clip_keeps_the_clip() {
    case(
        &["validate", "clip", "--params", "p.json", "--out", "clip"],
        "clip",
    );
}

#[test]
fn validate_out_onto_a_folder_holding_its_inputs_is_refused() {
    case(
        &["validate", "clip", "--params", "p.json", "--out", "."],
        ".: contains an input",
    );
}

#[test]
fn validate_out_through_a_symlink_to_the_clip_is_refused() {
    let t = workdir();
    std::os::unix::fs::symlink("clip", t.path().join("report")).unwrap();
    case_in(
        t.path(),
        &["validate", "clip", "--params", "p.json", "--out", "report"],
        "report",
    );
}

#[test]
fn validate_out_onto_its_params_is_refused() {
    case(
        &["validate", "clip", "--params", "p.json", "--out", "p.json"],
        "p.json",
    );
}

#[test]
fn fields_info_json_onto_the_clips_metadata_is_refused() {
    case(
        &["fields-info", "clip", "--json", "clip/clip.json"],
        "clip/clip.json",
    );
}

#[test]
fn fields_info_json_through_dotdot_onto_the_clip_is_refused() {
    case(
        &["fields-info", "clip", "--json", "clip/../clip/fields.npz"],
        "fields.npz",
    );
}

#[test]
fn simulate_out_onto_its_init_is_refused() {
    case(
        &[
            "simulate", "--init", "init.csv", "--steps", "2", "--out", "init.csv",
        ],
        "init.csv",
    );
}

#[test]
fn simulate_out_onto_its_params_is_refused() {
    case(
        &[
            "simulate", "--params", "p.json", "--agents", "3", "--steps", "1", "--out", "p.json",
        ],
        "p.json",
    );
}

#[test]
fn simulate_record_onto_its_init_is_refused() {
    case(
        &[
            "simulate", "--init", "init.csv", "--steps", "2", "--out", "t.csv", "--record",
            "init.csv",
        ],
        "init.csv",
    );
}

#[test]
fn simulate_out_onto_a_folder_is_refused() {
    case(
        &["simulate", "--agents", "3", "--steps", "1", "--out", "clip"],
        "clip",
    );
}

#[test]
fn synth_out_onto_a_users_folder_is_refused() {
    let t = workdir();
    std::fs::create_dir(t.path().join("thesis")).unwrap();
    std::fs::write(t.path().join("thesis/main.tex"), "…").unwrap();
    case_in(
        t.path(),
        &[
            "synth",
            "--agents",
            "5",
            "--frame-count",
            "3",
            "--grid-size",
            "4x4",
            "--cell-size",
            "2",
            "--out",
            "thesis",
        ],
        "thesis",
    );
}

#[test]
fn synth_out_onto_its_params_is_refused() {
    case(
        &[
            "synth",
            "--params",
            "p.json",
            "--agents",
            "5",
            "--frame-count",
            "3",
            "--grid-size",
            "4x4",
            "--cell-size",
            "2",
            "--out",
            "p.json",
        ],
        "p.json",
    );
}
