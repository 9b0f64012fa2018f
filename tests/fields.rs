//! Clip fields: the folder format (round trip, numpy), synthetic clips (mass conservation,
//! determinism), the reference import (hand-computed values), fields-info, and bad input.

mod common;
use common::{fails, ok, s};
use herdfit::backend::{cpu_device, Precision};
use herdfit::data::reference::import_reference;
use herdfit::data::{ClipFields, Grid};
use herdfit::herd::params::Params;
use herdfit::herd::synth::{synthesise, SynthConfig};
use ndarray::Array2;
use std::path::{Path, PathBuf};
use std::process::Command;

fn small_synth(seed: u64) -> (SynthConfig, herdfit::herd::synth::Synth) {
    let mut obstacles = Array2::zeros((8, 12));
    obstacles[[4, 7]] = 1;
    let cfg = SynthConfig {
        params: Params::default(),
        agents: 80,
        frame_count: 12,
        fps: 25.0,
        grid: Grid {
            origin: [0.0, 0.0],
            cell_size: 2.0,
            nx: 12,
            ny: 8,
        },
        obstacles,
        seed,
        heading_deg: 10.0,
        precision: Precision::F32,
        density: 0.5,
        random_headings: false,
    };
    let dev = cpu_device(Precision::F32).unwrap();
    let syn = synthesise(&cfg, &dev, || {}).unwrap();
    (cfg, syn)
}

#[test]
fn synthetic_clip_conserves_agents_per_frame() {
    let (cfg, syn) = small_synth(5);
    assert_eq!(syn.clip.frames(), 12);
    assert_eq!(syn.frames.len(), 12);
    for (f, rows) in syn.frames.iter().enumerate() {
        let inside = rows
            .iter()
            .filter(|r| cfg.grid.cell_of([r.x, r.y]).is_some())
            .count();
        assert!(inside > 40, "frame {f}: the herd is on the grid");
        assert!(
            (syn.clip.count(f) - inside as f64).abs() < 1e-3,
            "frame {f}"
        );
    }
    // The obstacle cell is in the fields, and the herd moves along +x (heading 10°).
    assert_eq!(syn.clip.obstacles[[4, 7]], 1);
    let vx: f32 = syn.clip.velocity.index_axis(ndarray::Axis(3), 0).sum();
    assert!(vx > 0.0);
    assert!(syn.clip.meta.speed.mean > 0.5 && syn.clip.meta.speed.mean < 1.5);
}

#[test]
fn round_trip_is_exact_and_numpy_reads_it() {
    let (_, syn) = small_synth(6);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("clip");
    syn.clip
        .save(&out, &[("truth.json", b"{}".to_vec())])
        .unwrap();
    let back = ClipFields::load(&out).unwrap();
    assert_eq!(back, syn.clip);
    let script = format!(
        "import numpy as np\n\
         z = np.load('{}')\n\
         for k in ['density', 'velocity', 'dir_variance', 'obstacles']:\n\
         \x20   print(k, z[k].shape, z[k].dtype)\n\
         print('total', round(float(z['density'][0].sum() * 4.0), 3))\n",
        out.join("fields.npz").display()
    );
    let py = Command::new("python3")
        .args(["-c", &script])
        .output()
        .expect("python3 runs (installed by .ci/run)");
    let text = String::from_utf8_lossy(&py.stdout);
    assert!(
        py.status.success(),
        "numpy failed: {}",
        String::from_utf8_lossy(&py.stderr)
    );
    let lines: Vec<&str> = text.lines().collect();
    assert_eq!(lines[0], "density (12, 8, 12) float32");
    assert_eq!(lines[1], "velocity (12, 8, 12, 2) float32");
    assert_eq!(lines[2], "dir_variance (12, 8, 12) float32");
    assert_eq!(lines[3], "obstacles (8, 12) uint8");
    let total: f64 = lines[4].trim_start_matches("total ").parse().unwrap();
    assert!((total - syn.clip.count(0)).abs() < 1e-3, "{total}");
}

fn sample_prefix() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/reference/sample")
}

#[test]
fn reference_sample_matches_hand_computed_values() {
    let c = import_reference(&sample_prefix()).unwrap();
    let m = &c.meta;
    // 4 cells on an 8 BL ground: 2 BL cells (area 4 BL²); FrameTime 0.04 s → 25 fps.
    assert_eq!((m.nx, m.ny, m.frames), (4, 4, 2));
    assert_eq!(m.cell_size, 2.0);
    assert!((m.fps - 25.0).abs() < 1e-9);
    assert_eq!((m.speed.mean, m.speed.std), (1.5, 0.25));
    // Labels 1 and 3 → 0.75 and 2.5 animals per 4 BL² cell.
    assert_eq!(m.speed.density_table, vec![[0.1875, 1.8], [0.625, 1.2]]);
    let deg2 = (std::f64::consts::PI / 180.0).powi(2);
    // Frame 0, image cell (1, 0) = top row → bottom-up row 3; 2 animals; vy flips sign.
    assert_eq!(c.density[[0, 3, 1]], 0.5);
    assert_eq!(c.velocity[[0, 3, 1, 0]], 1.5);
    assert_eq!(c.velocity[[0, 3, 1, 1]], 0.5);
    assert!((c.dir_variance[[0, 3, 1]] as f64 - 25.0 * deg2).abs() < 1e-7);
    // Frame 0, image cell (3, 2) → row 1.
    assert_eq!(c.density[[0, 1, 3]], 0.25);
    assert_eq!(c.velocity[[0, 1, 3, 0]], -1.0);
    // Frame 1, image cell (0, 3) → row 0: 4 animals, vy = +2 (down) → −2 (y up).
    assert_eq!(c.density[[1, 0, 0]], 1.0);
    assert_eq!(c.velocity[[1, 0, 0, 1]], -2.0);
    assert!((c.dir_variance[[1, 0, 0]] as f64 - 100.0 * deg2).abs() < 1e-6);
    // Nothing else is occupied.
    assert_eq!(c.density.iter().filter(|&&d| d > 0.0).count(), 3);
    // NAG 2 1 → obstacle at column 2, row 4 − 1 − 1 = 2.
    assert_eq!(c.obstacles[[2, 2]], 1);
    assert_eq!(c.obstacles.iter().filter(|&&v| v == 1).count(), 1);
    assert!((c.count(0) - 3.0).abs() < 1e-9 && (c.count(1) - 4.0).abs() < 1e-9);
}

#[test]
fn cli_synth_import_and_fields_info() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let cells = d.join("cells.json");
    std::fs::write(&cells, r#"{"cells": [[6, 3], [6, 4]]}"#).unwrap();
    let run = |name: &str| -> PathBuf {
        let out = d.join(name);
        ok(&[
            "synth",
            "--agents",
            "60",
            "--frames",
            "10",
            "--grid",
            "16x8",
            "--cell-size",
            "2",
            "--obstacles",
            s(&cells),
            "--seed",
            "2",
            "--out",
            s(&out),
        ]);
        out
    };
    let (a, b) = (run("a"), run("b"));
    for f in ["fields.npz", "clip.json", "truth.json", "trajectories.csv"] {
        assert_eq!(
            std::fs::read(a.join(f)).unwrap(),
            std::fs::read(b.join(f)).unwrap(),
            "{f}"
        );
    }
    // Running again over a previous clip replaces it.
    run("a");
    let truth = Params::load(&a.join("truth.json")).unwrap();
    assert_eq!(truth.to_vec(), Params::default().to_vec());
    let info_json = d.join("info.json");
    let text = ok(&["fields-info", s(&a), "--json", s(&info_json)]);
    assert!(
        text.contains("16×8 cells of 2 BL") && text.contains("2 obstacle cells"),
        "{text}"
    );
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&info_json).unwrap()).unwrap();
    let frames = info["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 10);
    let p0 = frames[0]["polarization"].as_f64().unwrap();
    assert!(
        p0 > 0.8 && p0 <= 1.0,
        "a herd behind one guidance direction is polarised: {p0}"
    );
    let imported = d.join("imported");
    ok(&[
        "import-reference",
        s(&sample_prefix()),
        "--out",
        s(&imported),
    ]);
    assert_eq!(
        ClipFields::load(&imported).unwrap(),
        import_reference(&sample_prefix()).unwrap()
    );
}

/// `import-reference --dir-variance V` records the directions' spread a still's files do not
/// measure (the seals: no per-cell angles), which E_var then targets instead of the files'
/// zeros; a value that is not a variance is refused naming the flag, writing nothing.
#[test]
fn import_reference_records_a_given_direction_spread() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let out = d.join("spread");
    let prefix = sample_prefix();
    ok(&[
        "import-reference",
        s(&prefix),
        "--out",
        s(&out),
        "--dir-variance",
        "0.9139",
    ]);
    let clip = ClipFields::load(&out).unwrap();
    assert_eq!(clip.meta.dir_spread, Some(0.9139));
    let mut plain = import_reference(&prefix).unwrap();
    assert_eq!(plain.meta.dir_spread, None, "not given: not recorded");
    plain.meta.dir_spread = Some(0.9139);
    assert_eq!(clip, plain, "the spread is the only difference");
    for bad in ["-1", "nan", "inf"] {
        let o = d.join(format!("bad{bad}"));
        let flag = format!("--dir-variance={bad}");
        let e = fails(&["import-reference", s(&prefix), "--out", s(&o), &flag]);
        assert!(e.contains("--dir-variance"), "{e}");
        assert!(!o.exists(), "nothing written for {bad}");
    }
}

#[test]
fn bad_clips_and_arguments_fail_cleanly() {
    let (_, syn) = small_synth(7);
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    let good = d.join("good");
    syn.clip.save(&good, &[]).unwrap();
    let copy = |name: &str| -> PathBuf {
        let p = d.join(name);
        std::fs::create_dir(&p).unwrap();
        for f in ["fields.npz", "clip.json"] {
            std::fs::copy(good.join(f), p.join(f)).unwrap();
        }
        p
    };
    // Truncated npz.
    let t = copy("truncated");
    let bytes = std::fs::read(t.join("fields.npz")).unwrap();
    std::fs::write(t.join("fields.npz"), &bytes[..bytes.len() / 2]).unwrap();
    assert!(fails(&["fields-info", s(&t)]).contains("fields.npz"));
    // Shapes that disagree with clip.json.
    let w = copy("wrong-shape");
    let j = std::fs::read_to_string(w.join("clip.json"))
        .unwrap()
        .replace("\"nx\": 12", "\"nx\": 13");
    std::fs::write(w.join("clip.json"), j).unwrap();
    let e = fails(&["fields-info", s(&w)]);
    assert!(
        e.contains("wrong-shape") && e.contains("density has shape"),
        "{e}"
    );
    // A missing key.
    let m = copy("missing-key");
    let j = std::fs::read_to_string(m.join("clip.json"))
        .unwrap()
        .replace("\"fps\"", "\"fpz\"");
    std::fs::write(m.join("clip.json"), j).unwrap();
    let e = fails(&["fields-info", s(&m)]);
    assert!(e.contains("clip.json") && e.contains("fpz"), "{e}");
    // fps ≤ 0.
    let z = copy("zero-fps");
    let j = std::fs::read_to_string(z.join("clip.json"))
        .unwrap()
        .replace("\"fps\": 25.0", "\"fps\": 0.0");
    std::fs::write(z.join("clip.json"), j).unwrap();
    assert!(fails(&["fields-info", s(&z)]).contains("fps"));
    // NaN and negative density, through the library (then the CLI message).
    for (name, v) in [("nan", f32::NAN), ("negative", -1.0)] {
        let mut c = syn.clip.clone();
        c.density[[3, 2, 1]] = v;
        let e = c.save(&d.join(name), &[]).unwrap_err().to_string();
        assert!(e.contains("density[3, 2, 1]"), "{e}");
        assert!(!d.join(name).exists(), "nothing written");
    }
    // Missing folder.
    assert!(fails(&["fields-info", s(&d.join("nope"))]).contains("nope"));
    // synth: an obstacle cell outside the grid, a bad grid, an unusable --out.
    let cells = d.join("cells.json");
    std::fs::write(&cells, r#"{"cells": [[40, 1]]}"#).unwrap();
    let out = d.join("clip-out");
    let e = fails(&[
        "synth",
        "--agents",
        "10",
        "--frames",
        "3",
        "--grid",
        "8x8",
        "--cell-size",
        "2",
        "--obstacles",
        s(&cells),
        "--out",
        s(&out),
    ]);
    assert!(e.contains("cells.json") && e.contains("cells[0]"), "{e}");
    let e = fails(&[
        "synth",
        "--agents",
        "0",
        "--frames",
        "3",
        "--grid",
        "8x8",
        "--cell-size",
        "2",
        "--out",
        s(&out),
    ]);
    assert!(e.contains("empty"), "{e}");
    let e = fails(&[
        "synth",
        "--agents",
        "5",
        "--frames",
        "3",
        "--grid",
        "8x8",
        "--cell-size",
        "0",
        "--out",
        s(&out),
    ]);
    assert!(e.contains("--cell-size"), "{e}");
    let busy = d.join("busy");
    std::fs::create_dir(&busy).unwrap();
    std::fs::write(busy.join("notes.txt"), "mine").unwrap();
    let e = fails(&[
        "synth",
        "--agents",
        "5",
        "--frames",
        "3",
        "--grid",
        "8x8",
        "--cell-size",
        "2",
        "--out",
        s(&busy),
    ]);
    assert!(e.contains("refusing"), "{e}");
    assert_eq!(
        std::fs::read_to_string(busy.join("notes.txt")).unwrap(),
        "mine"
    );
    assert!(!out.exists());
    // import-reference with a malformed row names the file and line.
    let bad = d.join("bad");
    for suffix in ["_data_meta.txt", "_data_cell.txt"] {
        std::fs::copy(
            format!("{}{suffix}", sample_prefix().display()),
            format!("{}{suffix}", bad.display()),
        )
        .unwrap();
    }
    std::fs::write(
        format!("{}_data_frame.txt", bad.display()),
        "Frame 1\nData 0 0 1.0 2.0\n",
    )
    .unwrap();
    let e = fails(&["import-reference", s(&bad), "--out", s(&d.join("imp"))]);
    assert!(e.contains("bad_data_frame.txt: line 2"), "{e}");
    assert!(!d.join("imp").exists());
}
