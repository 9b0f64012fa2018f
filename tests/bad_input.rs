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

// ---- Aborts instead of errors: sizes checked before anything is allocated ----

#[test]
fn simulate_a_billion_agents_is_refused() {
    case(
        &[
            "simulate",
            "--agents",
            "1000000000",
            "--steps",
            "2",
            "--out",
            "a.csv",
        ],
        "--agents",
    );
}

#[test]
fn synth_a_huge_grid_is_refused() {
    case(
        &[
            "synth",
            "--agents",
            "10",
            "--frame-count",
            "3",
            "--grid-size",
            "100000x100000",
            "--cell-size",
            "1",
            "--out",
            "s",
        ],
        "--grid-size",
    );
}

#[test]
fn synth_a_billion_agents_is_refused() {
    case(
        &[
            "synth",
            "--agents",
            "1000000000",
            "--frame-count",
            "3",
            "--grid-size",
            "4x4",
            "--cell-size",
            "1",
            "--out",
            "s",
        ],
        "--agents",
    );
}

#[test]
fn synth_more_frames_than_memory_is_refused() {
    case(
        &[
            "synth",
            "--agents",
            "10",
            "--frame-count",
            "100000000",
            "--grid-size",
            "4000x4000",
            "--cell-size",
            "1",
            "--out",
            "s",
        ],
        "--frame-count",
    );
}

#[test]
fn simulate_a_trillion_steps_is_refused() {
    case(
        &[
            "simulate",
            "--agents",
            "5",
            "--steps",
            "1000000000000",
            "--out",
            "a.csv",
        ],
        "--steps",
    );
}

#[test]
fn simulate_an_output_larger_than_the_disk_is_refused_up_front() {
    case(
        &[
            "simulate", "--agents", "100000", "--steps", "90000000", "--out", "a.csv",
        ],
        "free there",
    );
}

#[test]
fn import_reference_a_million_cells_per_side_is_refused() {
    import_reference_with_resolution(1_000_000, &[], "Resolution");
}

/// Found by the 10-minute fuzz run (#14): 4096² cells is within the grid limit, but two frames of
/// them need 537 MB; under a 256 MiB memory limit that is refused before anything is allocated.
#[test]
fn import_reference_more_memory_than_the_limit_is_refused() {
    import_reference_with_resolution(
        4096,
        &[("HERDFIT_MEMORY_LIMIT", "268435456")],
        "needs about",
    );
}

/// Found by the 10-minute fuzz run (#14): a world of 1e300 cells per side wrapped the usize cell
/// count and panicked in ndarray.
#[test]
fn author_a_world_of_1e300_cells_is_refused() {
    let t = with_scene(|v| v["world"]["width"] = serde_json::json!(1e300));
    case_in(t.path(), &["author", "scene.json", "--out", "a"], "world");
}

/// Issue #14's list: a scene with `spawn.count` 1e9 aborted on a failed allocation and left a
/// hidden temporary folder. Both the integer and the float spelling are refused with one line
/// naming the key (`case_in` checks that nothing, hidden files included, is left behind).
#[test]
fn author_a_billion_spawned_agents_is_refused() {
    let t = with_scene(|v| v["spawn"]["count"] = serde_json::json!(1_000_000_000u64));
    case_in(
        t.path(),
        &["author", "scene.json", "--out", "a"],
        "spawn.count",
    );
    let t = with_scene(|v| v["spawn"]["count"] = serde_json::json!(1e9));
    case_in(
        t.path(),
        &["author", "scene.json", "--out", "a"],
        "scene.json",
    );
}

/// Issue #14's list: a scene `duration` of 1e12 s aborted (and left a hidden temporary folder).
#[test]
fn author_a_duration_of_1e12_seconds_is_refused() {
    let t = with_scene(|v| v["duration"] = serde_json::json!(1e12));
    case_in(
        t.path(),
        &["author", "scene.json", "--out", "a"],
        "duration",
    );
}

/// `import-reference` of the test clip with its `Resolution` replaced (errors must name `names`).
fn import_reference_with_resolution(res: usize, env: &[(&str, &str)], names: &str) {
    let t = workdir();
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/reference");
    for e in std::fs::read_dir(&src).unwrap() {
        let e = e.unwrap();
        let text = std::fs::read_to_string(e.path()).unwrap();
        let text = if e.file_name().to_string_lossy().ends_with("_meta.txt") {
            text.lines()
                .map(|l| {
                    if l.starts_with("Resolution") {
                        format!("Resolution {res}")
                    } else {
                        l.to_string()
                    }
                })
                .collect::<Vec<_>>()
                .join("\n")
        } else {
            text
        };
        std::fs::write(t.path().join(e.file_name()), text).unwrap();
    }
    let meta = std::fs::read_dir(t.path())
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .find(|n| n.ends_with("_data_meta.txt"))
        .expect("a reference meta file");
    let prefix = meta.trim_end_matches("_data_meta.txt").to_string();
    harness::case_in_env(
        t.path(),
        &["import-reference", &prefix, "--out", "r"],
        names,
        env,
    );
}

// ---- NaN out, exit 0: huge finite values refused, derived values guarded ----

#[test]
fn simulate_with_a_tiny_fps_is_refused() {
    case(
        &[
            "simulate", "--agents", "5", "--steps", "2", "--fps", "1e-300", "--out", "a.csv",
        ],
        "--fps",
    );
}

#[test]
fn simulate_with_a_huge_fps_is_refused() {
    case(
        &[
            "simulate", "--agents", "5", "--steps", "2", "--fps", "1e300", "--out", "a.csv",
        ],
        "--fps",
    );
}

#[test]
fn synth_with_a_nan_heading_is_refused() {
    case(
        &[
            "synth",
            "--agents",
            "10",
            "--frame-count",
            "3",
            "--grid-size",
            "4x4",
            "--cell-size",
            "2",
            "--heading",
            "NaN",
            "--out",
            "s",
        ],
        "--heading",
    );
}

#[test]
fn synth_with_a_tiny_fps_is_refused() {
    case(
        &[
            "synth",
            "--agents",
            "10",
            "--frame-count",
            "3",
            "--grid-size",
            "4x4",
            "--cell-size",
            "2",
            "--fps",
            "1e-300",
            "--out",
            "s",
        ],
        "--fps",
    );
}

fn edit_json(path: &std::path::Path, f: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

#[test]
fn params_with_huge_speeds_are_refused() {
    let t = workdir();
    edit_json(&t.path().join("p.json"), |v| {
        v["speed"]["mean"] = 1e300.into();
        v["speed"]["max"] = 1e300.into();
    });
    case_in(
        t.path(),
        &[
            "simulate", "--params", "p.json", "--agents", "5", "--steps", "2", "--out", "a.csv",
        ],
        "p.json",
    );
}

#[test]
fn params_with_a_huge_perception_radius_are_refused() {
    let t = workdir();
    edit_json(&t.path().join("p.json"), |v| {
        v["constants"]["perception_radius"] = 1e300.into()
    });
    case_in(
        t.path(),
        &[
            "simulate", "--params", "p.json", "--agents", "5", "--steps", "2", "--out", "a.csv",
        ],
        "perception_radius",
    );
}

#[test]
fn init_with_a_huge_position_is_refused() {
    let t = workdir();
    let p = t.path().join("init.csv");
    let text = std::fs::read_to_string(&p).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let f: Vec<String> = lines[1].split(',').map(String::from).collect();
    lines[1] = format!("{},1e300,{},{},{}", f[0], f[2], f[3], f[4]);
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    case_in(
        t.path(),
        &[
            "simulate", "--init", "init.csv", "--steps", "2", "--out", "a.csv",
        ],
        "init.csv",
    );
}

#[test]
fn init_with_a_huge_speed_is_refused() {
    let t = workdir();
    let p = t.path().join("init.csv");
    let text = std::fs::read_to_string(&p).unwrap();
    let mut lines: Vec<String> = text.lines().map(String::from).collect();
    let f: Vec<String> = lines[1].split(',').map(String::from).collect();
    lines[1] = format!("{},{},{},1e300,{}", f[0], f[1], f[2], f[4]);
    std::fs::write(&p, lines.join("\n") + "\n").unwrap();
    case_in(
        t.path(),
        &[
            "simulate", "--init", "init.csv", "--steps", "2", "--out", "a.csv",
        ],
        "vx",
    );
}

#[test]
fn clip_with_a_tiny_fps_is_refused_by_fit() {
    let t = workdir();
    edit_json(&t.path().join("clip/clip.json"), |v| {
        v["fps"] = 1e-300.into()
    });
    case_in(
        t.path(),
        &["fit", "clip", "--out", "q.json", "--epochs", "1"],
        "fps",
    );
}

#[test]
fn clip_with_a_huge_origin_is_refused_by_fit() {
    let t = workdir();
    edit_json(&t.path().join("clip/clip.json"), |v| {
        v["origin"] = serde_json::json!([1e308, 0.0])
    });
    case_in(
        t.path(),
        &["fit", "clip", "--out", "q.json", "--epochs", "1"],
        "origin",
    );
}

#[test]
fn clip_with_a_huge_cell_size_is_refused_by_fields_info() {
    let t = workdir();
    edit_json(&t.path().join("clip/clip.json"), |v| {
        v["cell_size"] = 1e300.into()
    });
    case_in(t.path(), &["fields-info", "clip"], "cell_size");
}

#[test]
fn clip_with_a_huge_speed_is_refused_by_validate() {
    let t = workdir();
    edit_json(&t.path().join("clip/clip.json"), |v| {
        v["speed"]["mean"] = 1e300.into()
    });
    case_in(
        t.path(),
        &["validate", "clip", "--params", "p.json", "--out", "r"],
        "speed.mean",
    );
}

/// Found by the 10-minute fuzz run (#14): a flipped npy version byte made ndarray-npy allocate a
/// 662 MB header; a header's shape can likewise claim more than the memory there is.
/// The headers are now read first and checked against the memory limit: here 20 kB, between the
/// fixture's 12.3 kB of arrays and the 41 kB its density header claims once (12, 8, 8) reads
/// (99, 9, 9).
#[test]
fn clip_whose_npy_header_claims_more_than_memory_is_refused() {
    let t = workdir();
    let npz = t.path().join("clip").join("fields.npz");
    let mut bytes = std::fs::read(&npz).unwrap();
    let key = b"'shape': (";
    let at = bytes
        .windows(key.len())
        .position(|w| w == key)
        .expect("an npy header")
        + key.len();
    // Every digit of the first array's shape becomes 9: same length, so the archive still opens.
    for b in bytes[at..].iter_mut().take_while(|b| **b != b')') {
        if b.is_ascii_digit() {
            *b = b'9';
        }
    }
    std::fs::write(&npz, &bytes).unwrap();
    harness::case_in_env(
        t.path(),
        &["fields-info", "clip"],
        "fields.npz: reading its arrays needs about",
        &[("HERDFIT_MEMORY_LIMIT", "20000")],
    );
    // The fuzz's own case: the version byte 1 → 3 makes two bytes of the header text part of a
    // u32 header length (hundreds of megabytes), refused before anything is allocated.
    let t = workdir();
    let npz = t.path().join("clip").join("fields.npz");
    let mut bytes = std::fs::read(&npz).unwrap();
    let magic = b"\x93NUMPY";
    let at = bytes
        .windows(6)
        .position(|w| w == magic)
        .expect("npy magic")
        + 6;
    bytes[at] ^= 2;
    std::fs::write(&npz, &bytes).unwrap();
    case_in(t.path(), &["fields-info", "clip"], "its npy header claims");
}

#[test]
fn clip_with_a_huge_density_is_refused() {
    use ndarray::{Array2, Array3, Array4};
    let t = workdir();
    let c = t.path().join("clip");
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(c.join("clip.json")).unwrap()).unwrap();
    let (f, ny, nx) = (
        meta["frames"].as_u64().unwrap() as usize,
        meta["ny"].as_u64().unwrap() as usize,
        meta["nx"].as_u64().unwrap() as usize,
    );
    let mut d = Array3::<f32>::zeros((f, ny, nx));
    d[[0, 1, 1]] = 1e38;
    let mut w = ndarray_npy::NpzWriter::new(std::fs::File::create(c.join("fields.npz")).unwrap());
    w.add_array("density", &d).unwrap();
    w.add_array("velocity", &Array4::<f32>::zeros((f, ny, nx, 2)))
        .unwrap();
    w.add_array("dir_variance", &Array3::<f32>::zeros((f, ny, nx)))
        .unwrap();
    w.add_array("obstacles", &Array2::<u8>::zeros((ny, nx)))
        .unwrap();
    w.finish().unwrap();
    case_in(t.path(), &["fields-info", "clip"], "density");
    case_in(
        t.path(),
        &["fit", "clip", "--out", "q.json", "--epochs", "1"],
        "density",
    );
}

// ---- Full disk: a file-size limit in the child ----

#[test]
fn simulate_on_a_full_disk_leaves_nothing() {
    let t = workdir();
    harness::case_full_disk(
        t.path(),
        &[
            "simulate", "--agents", "200", "--steps", "200", "--out", "a.csv",
        ],
        "a.csv",
        50_000,
    );
}

#[test]
fn synth_video_on_a_full_disk_leaves_nothing() {
    let t = workdir();
    harness::case_full_disk(
        t.path(),
        &[
            "synth",
            "--agents",
            "10",
            "--frame-count",
            "30",
            "--grid-size",
            "8x8",
            "--cell-size",
            "2",
            "--video-file",
            "v.avi",
            "--out",
            "s",
        ],
        "v.avi",
        61_440,
    );
}

#[test]
fn synth_clip_on_a_full_disk_leaves_nothing() {
    let t = workdir();
    harness::case_full_disk(
        t.path(),
        &[
            "synth",
            "--agents",
            "10",
            "--frame-count",
            "300",
            "--grid-size",
            "8x8",
            "--cell-size",
            "2",
            "--out",
            "s",
        ],
        "s/",
        20_000,
    );
}

#[test]
fn fields_info_json_on_a_full_disk_leaves_nothing() {
    let t = workdir();
    harness::case_full_disk(
        t.path(),
        &["fields-info", "clip", "--json", "i.json"],
        "i.json",
        100,
    );
}

// ---- Signals and leftovers ----

fn temp_leftovers(dir: &std::path::Path) -> Vec<String> {
    std::fs::read_dir(dir)
        .unwrap()
        .filter_map(|e| e.ok()?.file_name().into_string().ok())
        .filter(|n| n.starts_with(".herdfit-"))
        .collect()
}

fn start_long_run(dir: &std::path::Path) -> std::process::Child {
    let mut c = harness::bin();
    c.args([
        "simulate", "--agents", "50", "--steps", "2000000", "--out", "long.csv",
    ])
    .current_dir(dir)
    .stderr(std::process::Stdio::piped());
    spawn_until_writing(c, dir, "")
}

/// Starts `cmd` and waits (25 ms polls, up to a minute) until a temporary sibling in `dir` whose
/// name ends with `suffix` holds data: the writability probe that comes first is an empty
/// temporary sibling too, removed at once, and on a slow machine the run can be caught between
/// the two.
fn spawn_until_writing(
    mut cmd: std::process::Command,
    dir: &std::path::Path,
    suffix: &str,
) -> std::process::Child {
    let c = cmd.spawn().unwrap();
    let writing = || {
        temp_leftovers(dir).iter().any(|n| {
            n.ends_with(suffix) && std::fs::metadata(dir.join(n)).is_ok_and(|m| m.len() > 0)
        })
    };
    for _ in 0..2400 {
        if writing() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(25));
    }
    assert!(writing(), "the run writes a temporary sibling ({suffix})");
    c
}

#[test]
fn sigint_and_sigterm_remove_temporary_siblings() {
    for sig in [libc::SIGINT, libc::SIGTERM] {
        let t = tempfile::tempdir().unwrap();
        let c = start_long_run(t.path());
        // SAFETY: signalling our own child.
        unsafe { libc::kill(c.id() as i32, sig) };
        let o = c.wait_with_output().unwrap();
        assert_eq!(
            o.status.code(),
            Some(128 + sig),
            "exit code after signal {sig}"
        );
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(err.lines().count(), 1, "{err}");
        assert!(
            temp_leftovers(t.path()).is_empty(),
            "{:?}",
            temp_leftovers(t.path())
        );
        assert!(!t.path().join("long.csv").exists());
    }
}

#[test]
fn sigkill_leftovers_are_removed_by_the_next_run_on_the_same_output() {
    let t = tempfile::tempdir().unwrap();
    let mut c = start_long_run(t.path());
    c.kill().unwrap();
    c.wait().unwrap();
    let left = temp_leftovers(t.path());
    assert_eq!(left.len(), 1, "{left:?}");
    // A run on another output leaves it alone; a run on the same output removes it.
    harness::bin()
        .args([
            "simulate",
            "--agents",
            "3",
            "--steps",
            "1",
            "--out",
            "other.csv",
        ])
        .current_dir(t.path())
        .status()
        .unwrap();
    assert_eq!(temp_leftovers(t.path()), left);
    let st = harness::bin()
        .args([
            "simulate", "--agents", "3", "--steps", "1", "--out", "long.csv",
        ])
        .current_dir(t.path())
        .status()
        .unwrap();
    assert!(st.success());
    assert!(temp_leftovers(t.path()).is_empty());
    assert!(t.path().join("long.csv").is_file());
}

/// Issue #14's list: a kill while a video was written left a hidden `.herdfit-*` AVI (44.7 MB in
/// one case). The next run that writes the same video removes it; nothing else is left.
#[cfg(feature = "video")]
#[test]
fn sigkill_while_a_video_is_written_is_cleaned_by_the_next_run() {
    let t = tempfile::tempdir().unwrap();
    let d = t.path();
    #[rustfmt::skip]
    let synth = |frames: &str, out: &str| {
        let mut c = harness::bin();
        c.args(["synth", "--agents", "50", "--frame-count", frames, "--grid-size", "16x16",
                "--cell-size", "2", "--video-file", "v.avi", "--out", out])
            .current_dir(d);
        c
    };
    let mut long = synth("20000", "long");
    long.stderr(std::process::Stdio::null());
    let mut c = spawn_until_writing(long, d, ".avi");
    c.kill().unwrap();
    c.wait().unwrap();
    assert!(!d.join("v.avi").exists() && !d.join("long").exists());
    assert_eq!(temp_leftovers(d).len(), 1, "{:?}", temp_leftovers(d));
    let o = synth("3", "short").output().unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(temp_leftovers(d).is_empty(), "{:?}", temp_leftovers(d));
    assert!(d.join("v.avi").is_file() && d.join("short/clip.json").is_file());
}

// ---- The "Lesser" list: truncated video, clamped ranges, nonsense flags, polygons, duplicate
// frames, resume without a checkpoint, OpenCV's own log line, `-` ----

/// A workdir with a 12-frame synthetic video `v.avi` (and its clip `vclip/`).
fn with_video() -> tempfile::TempDir {
    let t = workdir();
    #[rustfmt::skip]
    let o = harness::bin()
        .args(["synth", "--agents", "20", "--frame-count", "12", "--grid-size", "8x8",
               "--cell-size", "2", "--video-file", "v.avi", "--out", "vclip"])
        .current_dir(t.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    t
}

const EXTRACT: [&str; 4] = ["extract", "v.avi", "--body-length-px", "12"];

fn extract_case(dir: &std::path::Path, extra: &[&str], names: &str) {
    let mut args: Vec<&str> = EXTRACT.to_vec();
    args.extend_from_slice(extra);
    case_in(dir, &args, names);
}

#[test]
fn extract_of_a_truncated_video_is_refused() {
    let t = with_video();
    let p = t.path().join("v.avi");
    let bytes = std::fs::read(&p).unwrap();
    std::fs::write(&p, &bytes[..bytes.len() / 2]).unwrap();
    extract_case(t.path(), &["--out", "c"], "v.avi");
}

#[test]
fn extract_frames_beyond_the_video_are_refused_not_clamped() {
    let t = with_video();
    extract_case(
        t.path(),
        &["--frames", "0..100000", "--out", "c"],
        "--frames",
    );
}

#[test]
fn extract_one_preview_every_zero_frames_is_refused() {
    let t = with_video();
    #[rustfmt::skip]
    extract_case(t.path(), &["--preview", "pv", "--preview-every", "0", "--out", "c"], "--preview-every");
}

#[test]
fn extract_a_negative_colour_threshold_is_refused() {
    let t = with_video();
    #[rustfmt::skip]
    extract_case(t.path(), &["--colour-threshold=-1", "--out", "c"], "--colour-threshold");
}

#[test]
fn extract_a_grid_of_100000_cells_per_side_is_refused() {
    let t = with_video();
    extract_case(t.path(), &["--grid", "100000", "--out", "c"], "--grid");
}

#[test]
fn extract_a_missing_mask_gives_one_line_and_no_opencv_warning() {
    let t = with_video();
    #[rustfmt::skip]
    extract_case(t.path(), &["--obstacles", "nomask.png", "--out", "c"], "nomask.png");
}

#[test]
fn fit_a_window_longer_than_the_clip_is_refused() {
    #[rustfmt::skip]
    case(&["fit", "clip", "--out", "q.json", "--epochs", "1", "--window", "1000"], "--window");
}

#[test]
fn fit_a_nan_density_threshold_is_refused() {
    #[rustfmt::skip]
    case(&["fit", "clip", "--out", "q.json", "--density-threshold", "NaN"], "--density-threshold");
}

#[test]
fn fit_resume_without_a_checkpoint_is_refused() {
    #[rustfmt::skip]
    case(&["fit", "clip", "--out", "q.json", "--epochs", "1", "--checkpoint", "ck", "--resume"],
         "checkpoint.json");
}

#[test]
fn validate_a_warmup_longer_than_the_clip_is_refused() {
    #[rustfmt::skip]
    case(&["validate", "clip", "--params", "p.json", "--warmup", "1000000000", "--no-video",
           "--out", "rep"], "--warmup");
}

#[test]
fn bench_with_zero_repeats_is_refused() {
    #[rustfmt::skip]
    case(&["bench", "--agents", "10", "--steps", "2", "--repeats", "0", "--json", "b.json"],
         "--repeats");
}

#[test]
fn synth_with_every_cell_an_obstacle_is_refused() {
    let t = workdir();
    let cells: Vec<String> = (0..8)
        .flat_map(|x| (0..8).map(move |y| format!("[{x},{y}]")))
        .collect();
    let text = format!("{{\"cells\": [{}]}}", cells.join(","));
    std::fs::write(t.path().join("all.json"), text).unwrap();
    #[rustfmt::skip]
    case_in(t.path(), &["synth", "--agents", "10", "--frame-count", "3", "--grid-size", "8x8",
                        "--cell-size", "2", "--obstacles", "all.json", "--out", "s"], "all.json");
}

#[test]
fn simulate_a_replay_of_another_herd_names_the_recording() {
    let t = workdir();
    #[rustfmt::skip]
    let o = harness::bin()
        .args(["simulate", "--agents", "5", "--steps", "3", "--record", "r.json", "--out", "a.csv"])
        .current_dir(t.path())
        .output()
        .unwrap();
    assert!(o.status.success());
    #[rustfmt::skip]
    case_in(t.path(), &["simulate", "--agents", "6", "--steps", "3", "--replay", "r.json",
                        "--out", "b.csv"], "r.json");
    #[rustfmt::skip]
    case_in(t.path(), &["simulate", "--agents", "5", "--steps", "9", "--replay", "r.json",
                        "--out", "b.csv"], "r.json");
}

/// A workdir with the pasture scene (and its parameter files) as `scene.json`, edited by `f`.
fn with_scene(f: impl FnOnce(&mut serde_json::Value)) -> tempfile::TempDir {
    let t = workdir();
    let repo = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
    std::fs::create_dir_all(t.path().join("pasture")).unwrap();
    for n in ["narrow.json", "broad.json"] {
        std::fs::copy(
            repo.join("scenes/pasture").join(n),
            t.path().join("pasture").join(n),
        )
        .unwrap();
    }
    let mut v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(repo.join("scenes/pasture.json")).unwrap()).unwrap();
    f(&mut v);
    std::fs::write(t.path().join("scene.json"), v.to_string()).unwrap();
    t
}

#[test]
fn author_a_self_intersecting_polygon_is_refused() {
    let t = with_scene(|v| {
        v["obstacles"]["polygons"] = serde_json::json!([[[0, 0], [10, 10], [10, 0], [0, 10]]]);
    });
    case_in(
        t.path(),
        &["author", "scene.json", "--out", "a"],
        "obstacles.polygons[0]",
    );
}

#[test]
fn author_a_zero_area_region_is_refused() {
    let t = with_scene(|v| {
        v["regions"][0]["polygon"] = serde_json::json!([[0, 0], [10, 10], [20, 20]]);
    });
    case_in(
        t.path(),
        &["author", "scene.json", "--out", "a"],
        "regions[0].polygon",
    );
}

#[test]
fn author_a_missing_mask_gives_one_line_and_no_opencv_warning() {
    let t = with_scene(|v| v["obstacles"]["mask"] = serde_json::json!("nomask.png"));
    case_in(
        t.path(),
        &["author", "scene.json", "--out", "a"],
        "obstacles.mask",
    );
}

#[test]
fn import_reference_with_a_repeated_frame_number_is_refused() {
    let t = workdir();
    let src = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/reference");
    for e in std::fs::read_dir(&src).unwrap() {
        let e = e.unwrap();
        let mut text = std::fs::read_to_string(e.path()).unwrap();
        if e.file_name().to_string_lossy().ends_with("_frame.txt") {
            text = text.replace("Frame 12", "Frame 11");
        }
        std::fs::write(t.path().join(e.file_name()), text).unwrap();
    }
    case_in(
        t.path(),
        &["import-reference", "sample", "--out", "r"],
        "Frame 11 repeats",
    );
}

#[test]
fn validate_video_on_a_full_disk_leaves_nothing() {
    let t = workdir();
    harness::case_full_disk(
        t.path(),
        &[
            "validate", "clip", "--params", "p.json", "--seeds", "1", "--out", "rep",
        ],
        "rep",
        40_000,
    );
}

#[test]
fn author_video_on_a_full_disk_leaves_nothing() {
    let t = with_scene(|_| {});
    harness::case_full_disk(
        t.path(),
        &["author", "scene.json", "--video", "--out", "a"],
        "a",
        60_000,
    );
}

#[test]
fn folders_and_sidecar_outputs_refuse_stdout() {
    #[rustfmt::skip]
    case(&["synth", "--agents", "10", "--frame-count", "3", "--grid-size", "8x8", "--cell-size",
           "2", "--out", "-"], "standard output");
    case(
        &["validate", "clip", "--params", "p.json", "--out", "-"],
        "standard output",
    );
}

#[test]
fn simulate_to_stdout_writes_the_csv_there_and_nothing_on_disk() {
    let t = workdir();
    let before = harness::snapshot(t.path());
    #[rustfmt::skip]
    let o = harness::bin()
        .args(["simulate", "--agents", "5", "--steps", "3", "--out", "-"])
        .current_dir(t.path())
        .output()
        .unwrap();
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8(o.stdout).unwrap();
    let lines: Vec<&str> = out.lines().collect();
    // The header, then 5 agents × 4 frames, and nothing else.
    assert_eq!(lines.len(), 1 + 5 * 4, "{out}");
    assert!(lines[0].starts_with("frame,"), "{out}");
    assert!(
        lines[1..].iter().all(|l| l.split(',').count() == 8),
        "{out}"
    );
    assert_eq!(before, harness::snapshot(t.path()), "nothing on disk");
}

#[test]
fn fit_to_stdout_without_log_and_plot_paths_is_refused() {
    #[rustfmt::skip]
    case(&["fit", "clip", "--out", "-", "--epochs", "1"], "--out");
}
