//! The whole-CLI test's starting folder (small inputs of every kind, made by herdfit itself) and
//! its working invocations, one or more per verb (issue #47). Shared with `tests/kill_rerun.rs`.
#![allow(dead_code)]

use std::path::{Path, PathBuf};
use std::process::Command;
use std::sync::OnceLock;

pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_herdfit"))
}

pub fn run(dir: &Path, args: &[&str]) {
    let o = bin().args(args).current_dir(dir).output().unwrap();
    assert!(
        o.status.success(),
        "fixture: herdfit {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

fn write(dir: &Path, name: &str, text: &str) {
    std::fs::write(dir.join(name), text).unwrap();
}

/// The folder every case starts from: small inputs of every kind, made by herdfit itself.
pub fn fixture() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        // Fixtures of earlier test processes that no longer run are removed.
        let tmp = std::env::temp_dir();
        for e in std::fs::read_dir(&tmp).into_iter().flatten().flatten() {
            let name = e.file_name().to_string_lossy().into_owned();
            if let Some(pid) = name.strip_prefix("herdfit-fixture-") {
                let alive = pid
                    .parse::<i32>()
                    .is_ok_and(|p| unsafe { libc::kill(p, 0) } == 0);
                if !alive {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
        }
        let d = tmp.join(format!("herdfit-fixture-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let grid = ["--grid-size", "8x8", "--cell-size", "2"];
        let mut a = vec!["synth", "--agents", "20", "--frame-count", "12"];
        a.extend(grid);
        a.extend(["--out", "clip"]);
        run(&d, &a);
        std::fs::copy(d.join("clip/truth.json"), d.join("p.json")).unwrap();
        run(
            &d,
            &[
                "simulate", "--agents", "5", "--steps", "2", "--record", "rec.json", "--out",
                "s.csv",
            ],
        );
        let t = std::fs::read_to_string(d.join("s.csv")).unwrap();
        let mut init = String::from("id,x,y,vx,vy\n");
        for l in t.lines().skip(1) {
            let f: Vec<&str> = l.split(',').collect();
            if f[0] == "0" {
                init += &format!("{},{},{},{},{}\n", f[2], f[3], f[4], f[5], f[6]);
            }
        }
        write(&d, "init.csv", &init);
        std::fs::remove_file(d.join("s.csv")).unwrap();
        write(
            &d,
            "zones.json",
            r#"{"schema": "herdfit.zones/1", "zones": [
                {"name": "west", "polygon": [[0, 0], [8, 0], [8, 16], [0, 16]]},
                {"name": "east", "polygon": [[8, 0], [16, 0], [16, 16], [8, 16]]}]}"#,
        );
        run(
            &d,
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
                "sets.json",
                "--log",
                "sets.log.csv",
                "--plot",
                "sets.png",
            ],
        );
        for f in ["sets.log.csv", "sets.png"] {
            std::fs::remove_file(d.join(f)).unwrap();
        }
        run(
            &d,
            &[
                "synth",
                "--agents",
                "30",
                "--frame-count",
                "6",
                "--grid-size",
                "8x6",
                "--cell-size",
                "3",
                "--px-per-bl",
                "8",
                "--video-file",
                "v.avi",
                "--image",
                "vi.png",
                "--out",
                "vclip",
            ],
        );
        std::fs::remove_dir_all(d.join("vclip")).unwrap();
        write(
            &d,
            "polys.json",
            r#"{"schema": "herdfit.obstacle-polygons/1", "polygons": [[[1, 1], [6, 1], [6, 6]]]}"#,
        );
        write(&d, "cells.json", r#"{"cells": [[1, 1]]}"#);
        // An open boundary of the 8×8 clip (herdfit.boundary/1, issue #46).
        write(
            &d,
            "gates.json",
            r#"{"schema": "herdfit.boundary/1", "entries": [{"cell": [7, 3], "side": "right"}],
                "exits": [{"cell": [0, 4], "side": "left"}]}"#,
        );
        write(
            &d,
            "scene.json",
            r#"{"schema": "herdfit.scene/1", "world": {"width": 20, "height": 12, "cell_size": 2},
                "destination": {"point": [18, 6]},
                "spawn": {"count": 8, "centre": [4, 6], "size": [4, 4], "heading_deg": 0},
                "duration": 1, "fps": 10, "seed": 2}"#,
        );
        std::fs::create_dir_all(d.join("ref")).unwrap();
        let src = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/reference");
        for s in ["meta", "frame", "cell"] {
            let f = format!("sample_data_{s}.txt");
            std::fs::copy(src.join(&f), d.join("ref").join(&f)).unwrap();
        }
        // Crowds: tracks, a second crowd, a model, a layout, an ETH/UCY folder.
        run(
            &d,
            &["crowd", "synth", "--duration", "12", "--out", "t.csv"],
        );
        run(
            &d,
            &[
                "crowd",
                "synth",
                "--duration",
                "8",
                "--seed",
                "1",
                "--out",
                "u.csv",
            ],
        );
        run(&d, &["crowd", "learn", "t.csv", "--out", "model.json"]);
        write(
            &d,
            "layout.json",
            r#"{"schema": "herdfit.crowd-layout/1", "bounds": [[-1, -1], [21, 11]],
                "walls": [[[0, 0], [20, 0]], [[0, 10], [20, 10]]],
                "obstacles": [[[9, 4], [11, 4], [11, 6], [9, 6]]],
                "spawns": [{"position": [0.5, 3], "spread": 1, "goal": [19.5, 5], "count": 4,
                            "start": 0, "interval": 1}],
                "duration": 3}"#,
        );
        std::fs::create_dir_all(d.join("eth")).unwrap();
        let t = std::fs::read_to_string(d.join("t.csv")).unwrap();
        let mut eth = String::new();
        for l in t.lines().skip(1) {
            let f: Vec<&str> = l.split(',').collect();
            let frame: u64 = f[0].parse().unwrap();
            eth += &format!("{} {} {} {}\n", frame * 10, f[2], f[3], f[4]);
        }
        for f in [
            "biwi_eth.txt",
            "biwi_hotel.txt",
            "students001.txt",
            "students003.txt",
            "crowds_zara01.txt",
            "crowds_zara02.txt",
            "uni_examples.txt",
            "crowds_zara03.txt",
        ] {
            write(&d.join("eth"), f, &eth);
        }
        // Flocks and 3D lifts.
        run(
            &d,
            &[
                "flock", "synth", "--birds", "5", "--frames", "4", "--out", "f.csv",
            ],
        );
        run(&d, &["flock", "extract", "f.csv", "--out", "shape.json"]);
        run(
            &d,
            &[
                "lift", "synth", "--birds", "4", "--frames", "6", "--out", "ls",
            ],
        );
        for (from, to) in [
            ("tracks2d.csv", "t2.csv"),
            ("tracks2d.json", "t2.json"),
            ("truth3d.csv", "t3.csv"),
            ("truth3d.json", "t3.json"),
            ("camera.json", "cam.json"),
        ] {
            std::fs::rename(d.join("ls").join(from), d.join(to)).unwrap();
        }
        std::fs::remove_dir_all(d.join("ls")).unwrap();
        // Settings files that keep every default.
        for f in [
            "learn.json",
            "tuning.json",
            "lift.json",
            "boids.json",
            "fsyn.json",
            "fanim.json",
            "extract.json",
        ] {
            write(&d, f, "{}");
        }
        write(&d, "poly.json", "[[0, 0], [30, 0], [30, 12], [0, 12]]");
        d
    })
}

/// One or more working invocations per verb, with every output flag written somewhere.
pub const BASELINES: &[(&str, &str)] = &[
    (
        "simulate",
        "--params p.json --init init.csv --steps 2 --record r.json --out sim.csv",
    ),
    (
        "simulate",
        "--replay rec.json --agents 5 --steps 2 --guidance 1,0 --out sim.csv",
    ),
    (
        "gradcheck",
        "--params p.json --agents 6 --steps 2 --record r.json --json g.json",
    ),
    (
        "gradcheck",
        "--replay rec.json --agents 5 --steps 2 --json g.json",
    ),
    (
        "gradcheck",
        "--objective loss --clip clip --steps 2 --json g.json",
    ),
    ("bench", "--agents 20 --steps 2 --repeats 1 --json b.json"),
    (
        "fit",
        "clip --out fp.json --epochs 1 --window 2 --no-uncertainty --start p.json \
             --tracks clip/trajectories.csv --log fl.csv --plot fl.png --checkpoint ck \
             --frames 0..12 --boundary gates.json",
    ),
    (
        "fit",
        "clip --zones zones.json --out zb.json --epochs 1 --window 2 --no-uncertainty",
    ),
    (
        "extract",
        "v.avi --out ex --config extract.json --background vi-ground.png \
                 --obstacles polys.json --preview pv --preview-every 2 --frames 0..6 \
                 --body-colour 235,235,225",
    ),
    (
        "validate",
        "clip --params p.json --baseline p.json --seeds 1 \
                  --tracks clip/trajectories.csv --boundary gates.json --frames 2..12 \
                  --measures reference --out val",
    ),
    (
        "validate",
        "clip --params sets.json --seeds 1 --no-video --out val",
    ),
    (
        "validate-tracks",
        "clip --params p.json --baseline p.json --tracks clip/trajectories.csv --frames 6..12 \
                  --speed-frames 0..6 --horizons 0.1 --seeds 1 --free-run 0 --out vt",
    ),
    (
        "ablate",
        "clip --out ab --epochs 1 --window 2 --seeds 1 --start p.json",
    ),
    (
        "ablate",
        "clip --out ab --zones zones.json --epochs 1 --window 2 --seeds 1",
    ),
    ("author", "scene.json --out au --video"),
    (
        "synth",
        "--agents 10 --frame-count 4 --grid-size 6x6 --cell-size 2 --params p.json \
               --obstacles cells.json --zone-sets sets.json --video-file sv.avi --image si.png \
               --out sy",
    ),
    ("import-reference", "ref/sample --out ir"),
    (
        "import-tracks",
        "t.csv --body-length-m 0.5 --arena poly.json --frames 0..40 --out it",
    ),
    ("fields-info", "clip --json fi.json"),
    ("demo", "--out dm"),
    ("flock synth", "--birds 5 --frames 4 --out fs.csv"),
    ("flock synth", "--examples fx"),
    ("flock synth", "--config fsyn.json --out fs.csv"),
    ("flock extract", "f.csv --out fe.json"),
    (
        "flock animate",
        "shape.json --birds 5 --frames 10 --config fanim.json --out fa",
    ),
    ("crowd learn", "t.csv --config learn.json --out m.json"),
    (
        "crowd simulate",
        "model.json --layout layout.json --png cs.png --video cs.avi --out cs.csv",
    ),
    (
        "crowd simulate",
        "model.json --entries t.csv --steps 10 --compare cc.json --out ce.csv",
    ),
    (
        "crowd evaluate",
        "--data eth --scene HOTEL --config learn.json --tuning tuning.json \
                        --json ev.json",
    ),
    ("crowd compare", "t.csv u.csv --json cmp.json"),
    (
        "crowd holdout",
        "t.csv --split 0.7 --layout layout.json --config learn.json --out ho.csv --json hoj.json",
    ),
    ("crowd synth", "--duration 5 --out cy.csv"),
    (
        "lift run",
        "t2.csv --camera cam.json --config lift.json --v-target 0.1 --d-near 1 --d-far 100 \
                  --out lr.csv --report lrr.json --plots lp --video lv.avi",
    ),
    (
        "lift synth",
        "--config boids.json --birds 4 --frames 5 --out lsy",
    ),
    ("lift project", "t3.csv --camera cam.json --out lpj.csv"),
    (
        "lift evaluate",
        "t3.csv --camera cam.json --config lift.json --v-target 0.1 --d-near 1 --d-far 100 \
                  --out lev",
    ),
    (
        "lift camera",
        "--position 0,0,0 --look-at 10,0,0 --out lc.json",
    ),
    (
        "export-gltf",
        "t3.csv --out e.glb --preview ep.png --preview-camera cam.json",
    ),
];
