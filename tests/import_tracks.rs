//! `herdfit import-tracks`: tracked trajectories → clip fields. Hand-made tracks with known
//! densities and velocities (units, y flip, gaps), the real 15-fish school shipped with
//! trajectorytools 0.4.2 (fetched into `.testdata/` by `scripts/fetch-testdata.sh`), the ETH/UCY
//! `students003` pedestrians from `../shared/data`, and bad input.

use herdfit::data::clip::ClipFields;
use herdfit::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
use std::path::{Path, PathBuf};
use std::process::Command;

fn herdfit(args: &[&str]) -> std::process::Output {
    Command::new(env!("CARGO_BIN_EXE_herdfit"))
        .args(args)
        .output()
        .expect("run herdfit")
}

fn ok(args: &[&str]) -> String {
    let o = herdfit(args);
    assert!(
        o.status.success(),
        "herdfit {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8(o.stdout).unwrap()
}

/// Fails with one stderr line that contains every `needle`; returns it.
fn fails(args: &[&str], needles: &[&str]) -> String {
    let o = herdfit(args);
    assert!(!o.status.success(), "herdfit {args:?} should fail");
    let err = String::from_utf8(o.stderr).unwrap();
    assert_eq!(err.trim_end().lines().count(), 1, "one line: {err}");
    assert!(!err.contains("panicked"), "{err}");
    for n in needles {
        assert!(err.contains(n), "'{n}' not in: {err}");
    }
    err
}

fn repo() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn shared_data() -> PathBuf {
    if let Some(p) = std::env::var_os("HERDFIT_SHARED_DATA") {
        return PathBuf::from(p);
    }
    let beside = repo().join("../shared/data");
    if beside.is_dir() {
        beside
    } else {
        PathBuf::from("/work/shared/data")
    }
}

fn testdata(rel: &str) -> PathBuf {
    let p = repo().join(".testdata").join(rel);
    assert!(
        p.is_file(),
        "{} is missing: run scripts/fetch-testdata.sh (scripts/setup-debian.sh does)",
        p.display()
    );
    p
}

fn row(frame: u64, id: u64, x: f64, y: f64, fps: f64) -> TrackRow {
    TrackRow {
        frame,
        time: frame as f64 / fps,
        id,
        pos: [x, y, 0.0],
        vel: None,
        role: None,
    }
}

fn write_tracks(path: &Path, units: Units, fps: f64, rows: Vec<TrackRow>) {
    Tracks::new(TracksMeta::new(units, fps, 2), rows)
        .unwrap()
        .save(path)
        .unwrap();
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

#[test]
fn hand_made_tracks_give_known_density_velocity_and_gaps() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("t.csv");
    // Animal 0 walks +x at 2 BL/s (10 fps: 0.2 BL per frame) at y = 0.5; animal 1 stands at
    // (3.5, 3.5) but is lost in frame 2.
    let fps = 10.0;
    let mut rows: Vec<TrackRow> = (0..5)
        .map(|f| row(f, 0, 0.5 + 0.2 * f as f64, 0.5, fps))
        .collect();
    rows.extend([0, 1, 3, 4].iter().map(|&f| row(f, 1, 3.5, 3.5, fps)));
    write_tracks(&csv, Units::BodyLengths, fps, rows);
    let out = dir.path().join("clip");
    let text = ok(&[
        "import-tracks",
        s(&csv),
        "--out",
        s(&out),
        "--cell-size",
        "1",
    ]);
    assert!(text.contains("2 animals, 5 frames at 10 fps"), "{text}");
    let clip = ClipFields::load(&out).unwrap();
    assert_eq!(clip.frames(), 5);
    assert_eq!(clip.meta.fps, 10.0);
    assert_eq!(clip.meta.cell_size, 1.0);
    assert_eq!(clip.meta.origin, [0.5, 0.5]);
    assert_eq!((clip.meta.nx, clip.meta.ny), (4, 4));
    assert_eq!(clip.meta.provenance["source"], "import-tracks");
    // One animal per 1 BL² cell: density 1 agent/BL²; the lost frame holds one animal.
    let counts: Vec<f64> = (0..5).map(|f| clip.count(f)).collect();
    assert_eq!(counts, vec![2.0, 2.0, 1.0, 2.0, 2.0]);
    assert_eq!(clip.density[[0, 0, 0]], 1.0);
    assert_eq!(clip.density[[0, 3, 3]], 1.0);
    assert_eq!(clip.density[[2, 3, 3]], 0.0);
    // Central differences inside, one-sided at the ends: 2 BL/s along +x everywhere.
    for f in 0..5 {
        let ix = ((0.2 * f as f64) / 1.0).floor() as usize;
        let v = [clip.velocity[[f, 0, ix, 0]], clip.velocity[[f, 0, ix, 1]]];
        assert!(
            (v[0] - 2.0).abs() < 1e-5 && v[1].abs() < 1e-6,
            "frame {f}: {v:?}"
        );
        assert_eq!(clip.velocity[[f, 3, 3, 0]], 0.0);
    }
    // The speed model: mean over every animal in every frame, 4 × 0 + 5 × 2 over 9.
    assert!(
        (clip.meta.speed.mean - 10.0 / 9.0).abs() < 1e-9,
        "{:?}",
        clip.meta.speed
    );
    // The animals in the clip's own frames and body lengths, for `fit --tracks`: every tracked
    // row, the walker at 2 BL/s along +x, the stander still.
    let t = Tracks::load(&out.join("tracks.csv")).unwrap();
    assert_eq!(t.meta.units, Units::BodyLengths);
    assert_eq!(t.meta.fps, 10.0);
    assert_eq!(t.rows.len(), 9);
    for r in &t.rows {
        let v = r.vel.unwrap();
        match r.id {
            0 => {
                assert!((r.pos[0] - (0.5 + 0.2 * r.frame as f64)).abs() < 1e-12);
                assert!((v[0] - 2.0).abs() < 1e-9 && v[1].abs() < 1e-12, "{r:?}");
            }
            _ => assert_eq!((r.pos[0], r.pos[1], v[0], v[1]), (3.5, 3.5, 0.0, 0.0)),
        }
    }
    assert!(!t.rows.iter().any(|r| r.id == 1 && r.frame == 2));
}

#[test]
fn pixels_become_body_lengths_with_y_up_and_smoothing_is_recorded() {
    let dir = tempfile::tempdir().unwrap();
    let csv = dir.path().join("px.csv");
    // 20 px per BL; moving down the image (+y in pixels) at 40 px/s = 2 BL/s, i.e. −y in BL.
    let fps = 4.0;
    let rows = (0..6)
        .map(|f| row(f, 7, 100.0, 200.0 + 10.0 * f as f64, fps))
        .collect();
    write_tracks(&csv, Units::Pixels, fps, rows);
    let out = dir.path().join("clip");
    fails(
        &["import-tracks", s(&csv), "--out", s(&out)],
        &["--body-length-px", "pixels"],
    );
    assert!(!out.exists(), "nothing written on error");
    ok(&[
        "import-tracks",
        s(&csv),
        "--out",
        s(&out),
        "--body-length-px",
        "20",
        "--grid",
        "4",
        "--smooth",
        "3",
    ]);
    let clip = ClipFields::load(&out).unwrap();
    assert_eq!(clip.meta.body_length_px, Some(20.0));
    assert_eq!(clip.meta.velocity_window(), 3);
    // Positions 5 BL right, 10 … 12.5 BL down: the origin is the lowest y, −12.5 BL.
    assert_eq!(clip.meta.origin, [5.0, -12.5]);
    let total: f32 = (0..clip.frames())
        .map(|f| clip.velocity.index_axis(ndarray::Axis(0), f).sum())
        .sum();
    assert!(total.is_finite());
    let vy: Vec<f32> = (0..clip.frames())
        .flat_map(|f| {
            let d = clip.density.index_axis(ndarray::Axis(0), f).to_owned();
            let v = clip.velocity.index_axis(ndarray::Axis(0), f).to_owned();
            d.indexed_iter()
                .filter(|(_, &x)| x > 0.0)
                .map(|((iy, ix), _)| v[[iy, ix, 1]])
                .collect::<Vec<_>>()
        })
        .collect();
    assert_eq!(vy.len(), 6);
    for v in vy {
        assert!((v + 2.0).abs() < 1e-5, "vy = {v} BL/s, expected −2");
    }
}

#[test]
fn the_trajectorytools_fish_school_imports_with_its_arena() {
    let npy = testdata("trajectorytools/trajectories_with_points.npy");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("fish");
    // trajectorytools records the body length as a numpy scalar, which the pickle reader cannot
    // rebuild: the user is told to give it.
    fails(
        &["import-tracks", s(&npy), "--out", s(&out)],
        &["--body-length-px"],
    );
    let text = ok(&[
        "import-tracks",
        s(&npy),
        "--out",
        s(&out),
        "--body-length-px",
        "57",
        "--arena",
        "border",
    ]);
    assert!(text.contains("15 animals, 1000 frames at 32 fps"), "{text}");
    let clip = ClipFields::load(&out).unwrap();
    assert_eq!(clip.frames(), 1000);
    assert_eq!(clip.meta.fps, 32.0);
    let counts: Vec<f64> = (0..1000).map(|f| clip.count(f)).collect();
    let mean = counts.iter().sum::<f64>() / 1000.0;
    assert!(counts.iter().all(|&c| (13.999..=15.001).contains(&c)));
    assert!(
        mean > 14.9,
        "mean {mean} fish per frame (a few NaN gaps only)"
    );
    // The arena border leaves the corners of the bounding box outside, and almost no fish there.
    let cells = clip.meta.nx * clip.meta.ny;
    let blocked = clip.obstacles.iter().filter(|&&o| o != 0).count();
    assert!(
        blocked > cells / 20 && blocked < cells / 2,
        "{blocked} of {cells}"
    );
    let mut outside = 0.0f64;
    let mut all = 0.0f64;
    for ((_, iy, ix), &d) in clip.density.indexed_iter() {
        all += d as f64;
        if clip.obstacles[[iy, ix]] != 0 {
            outside += d as f64;
        }
    }
    assert!(
        outside / all < 0.02,
        "{:.4} of the fish mass in obstacle cells",
        outside / all
    );
    // Fish speeds in BL/s: positive, below 20 BL/s (57 px bodies at 32 fps).
    assert!(clip.meta.speed.mean > 0.5 && clip.meta.speed.mean < 20.0);
}

#[test]
fn eth_ucy_pedestrians_import_in_metres() {
    let txt = shared_data().join("pedestrians/eth-ucy/students003.txt");
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("st3");
    fails(
        &["import-tracks", s(&txt), "--out", s(&out), "--fps", "2.5"],
        &["--body-length-m", "metres"],
    );
    fails(&["import-tracks", s(&txt), "--out", s(&out)], &["--fps"]);
    let text = ok(&[
        "import-tracks",
        s(&txt),
        "--out",
        s(&out),
        "--fps",
        "2.5",
        "--body-length-m",
        "0.3",
        "--frames",
        "0..100",
    ]);
    let clip = ClipFields::load(&out).unwrap();
    assert_eq!(clip.frames(), 100);
    assert_eq!(clip.meta.fps, 2.5);
    // Walking pedestrians: 1.3 m/s is ≈ 4.3 BL/s of 0.3 m.
    let v = clip.meta.speed.mean * 0.3;
    assert!(v > 0.3 && v < 2.0, "{v} m/s; {text}");
}

#[test]
fn bad_input_gets_one_line_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let junk = dir.path().join("junk.npy");
    std::fs::write(&junk, b"not numpy").unwrap();
    let out = dir.path().join("clip");
    fails(
        &["import-tracks", s(&junk), "--out", s(&out), "--fps", "10"],
        &["junk.npy", "npy"],
    );
    let csv = dir.path().join("t.csv");
    write_tracks(
        &csv,
        Units::BodyLengths,
        5.0,
        vec![row(0, 0, 0.0, 0.0, 5.0), row(1, 0, 1.0, 0.0, 5.0)],
    );
    fails(
        &["import-tracks", s(&csv), "--out", s(&out), "--smooth", "2"],
        &["--smooth", "odd"],
    );
    fails(
        &[
            "import-tracks",
            s(&csv),
            "--out",
            s(&out),
            "--frames",
            "0..9",
        ],
        &["--frames"],
    );
    fails(
        &[
            "import-tracks",
            s(&csv),
            "--out",
            s(&out),
            "--arena",
            "border",
        ],
        &["--arena", "border"],
    );
    assert!(!out.exists());
    let names: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 3, "only junk.npy, t.csv and t.json: {names:?}");
}
