//! `synth --video`: the rendered overhead video (OpenCV reads it back; bodies where the
//! trajectories put them; the camera starts at the identity and then moves).
#![cfg(feature = "video")]

mod common;
use common::ok;
use opencv::core::{Mat, Vec3b};
use opencv::prelude::*;
use opencv::videoio::{self, VideoCapture};
use std::path::Path;
use std::process::Command;

fn frames(path: &Path) -> Vec<Mat> {
    let mut cap = VideoCapture::from_file(path.to_str().unwrap(), videoio::CAP_ANY).unwrap();
    assert!(cap.is_opened().unwrap());
    let mut out = Vec::new();
    loop {
        let mut m = Mat::default();
        if !cap.read(&mut m).unwrap() || m.empty() {
            break;
        }
        out.push(m);
    }
    out
}

fn mean_abs_diff(a: &Mat, b: &Mat) -> f64 {
    let (x, y) = (a.data_bytes().unwrap(), b.data_bytes().unwrap());
    x.iter()
        .zip(y)
        .map(|(p, q)| (*p as f64 - *q as f64).abs())
        .sum::<f64>()
        / x.len() as f64
}

fn synth(dir: &Path, name: &str, extra: &[&str]) -> (std::path::PathBuf, std::path::PathBuf) {
    let clip = dir.join(name);
    let video = dir.join(format!("{name}.avi"));
    let mut args = vec![
        "synth",
        "--agents",
        "40",
        "--frames",
        "10",
        "--grid",
        "16x8",
        "--cell-size",
        "2",
        "--px-per-bl",
        "8",
        "--seed",
        "4",
        "--out",
        clip.to_str().unwrap(),
        "--video",
        video.to_str().unwrap(),
    ];
    args.extend_from_slice(extra);
    ok(&args);
    (clip, video)
}

#[test]
fn rendered_video_shows_the_herd_where_the_trajectories_are() {
    let dir = tempfile::tempdir().unwrap();
    let (clip, video) = synth(dir.path(), "still", &[]);
    let fr = frames(&video);
    assert_eq!(fr.len(), 10);
    assert_eq!((fr[0].cols(), fr[0].rows()), (256, 128));
    let meta: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(clip.join("clip.json")).unwrap()).unwrap();
    assert_eq!(meta["body_length_px"], 8.0);
    assert!(meta["provenance"]["video"]["file"]
        .as_str()
        .unwrap()
        .ends_with("still.avi"));
    // Every agent of frame 0 lies on a body-coloured pixel; agents of frame 0 are ≥ 1 BL from
    // the sampled ground pixels.
    let traj = std::fs::read_to_string(clip.join("trajectories.csv")).unwrap();
    let agents: Vec<[f64; 2]> = traj
        .lines()
        .skip(1)
        .map(|l| l.split(',').collect::<Vec<_>>())
        .filter(|c| c[0] == "0")
        .map(|c| [c[3].parse().unwrap(), c[4].parse().unwrap()])
        .collect();
    assert_eq!(agents.len(), 40);
    let px = |p: [f64; 2]| -> Vec3b {
        let (x, y) = ((p[0] * 8.0) as i32, (128.0 - p[1] * 8.0) as i32);
        *fr[0].at_2d::<Vec3b>(y, x).unwrap()
    };
    let mut on_body = 0;
    for &a in &agents {
        if (0.0..32.0).contains(&a[0]) && (0.0..16.0).contains(&a[1]) {
            let c = px(a);
            if c[0] > 170 && c[1] > 170 && c[2] > 170 {
                on_body += 1;
            }
        }
    }
    assert!(
        on_body >= 36,
        "{on_body} of 40 agents on body-coloured pixels"
    );
    let mut ground = 0;
    for gx in 0..32 {
        for gy in 0..16 {
            let p = [gx as f64 + 0.5, gy as f64 + 0.5];
            if agents
                .iter()
                .all(|a| (a[0] - p[0]).hypot(a[1] - p[1]) > 1.0)
            {
                let c = px(p);
                assert!(c[1] > c[0] && c[2] < 170, "ground pixel {p:?} = {c:?}");
                ground += 1;
            }
        }
    }
    assert!(ground > 100);
}

#[test]
fn camera_motion_starts_at_identity_then_moves() {
    let dir = tempfile::tempdir().unwrap();
    let (_, still) = synth(dir.path(), "still", &[]);
    let (clip, moving) = synth(dir.path(), "moving", &["--camera-motion"]);
    let (a, b) = (frames(&still), frames(&moving));
    assert_eq!(a.len(), b.len());
    assert!(
        mean_abs_diff(&a[0], &b[0]) < 0.5,
        "frame 0 is the identity view"
    );
    assert!(
        mean_abs_diff(&a[9], &b[9]) > 5.0,
        "the last frame is panned, zoomed, rotated"
    );
    let cams: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(clip.join("camera.json")).unwrap()).unwrap();
    let cams = cams.as_array().unwrap();
    assert_eq!(cams.len(), 10);
    assert_eq!(cams[0]["zoom"], 1.0);
    assert!((cams[9]["rotation_deg"].as_f64().unwrap() - 8.0).abs() < 1e-9);
}

#[test]
fn unwritable_video_leaves_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let clip = dir.path().join("c");
    let o = Command::new(env!("CARGO_BIN_EXE_herdfit"))
        .args([
            "synth",
            "--agents",
            "10",
            "--frames",
            "3",
            "--grid",
            "8x8",
            "--cell-size",
            "2",
            "--out",
            clip.to_str().unwrap(),
            "--video",
            dir.path().join("no-dir").join("v.avi").to_str().unwrap(),
        ])
        .output()
        .unwrap();
    assert_eq!(o.status.code(), Some(1));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("no-dir") && err.trim().lines().count() == 1,
        "{err}"
    );
    assert!(!clip.exists());
}
