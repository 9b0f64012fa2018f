//! The synthetic-video table of RESULTS.md §2 (issue #16): herds of 200 and 800 at two body sizes
//! through a static and a moving camera (`herdfit synth --video`, 250 frames), extracted with no
//! flag but `--out`, and again with three `--anchor` rectangles on ground the herd never covers
//! (found from the trajectories), scored against the trajectories.
//!
//! `cargo build --release && cargo run --release --example extract_table [-- FILTER [FLAG…]]`
//! (the `herdfit` binary of `target/release` runs every command; HERDFIT_BIN overrides). FILTER
//! keeps the videos whose name (`still-800-10`, `moving-200-16`, …) contains it; the flags that
//! follow are added to every extraction (e.g. `--static-camera`).

#[path = "../tests/common/score.rs"]
mod score;
use herdfit::data::ClipFields;
use score::{read_traj, score};
use std::path::{Path, PathBuf};
use std::process::Command;

fn run(bin: &Path, args: &[String]) {
    let o = Command::new(bin).args(args).output().expect("herdfit runs");
    assert!(
        o.status.success(),
        "herdfit {args:?}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
}

/// Three 48-px anchor squares in the first frame (x, y, w, h) on ground no agent comes within
/// 2 BL of, right side first; none when there is no such room.
fn anchors(traj: &[Vec<herdfit::data::agents::AgentRow>], px: f64, w: f64, h: f64) -> Vec<String> {
    let size = 48.0;
    let clear = |x0: f64, y0: f64| {
        // Pixel (u, v) ↔ world (u / px, (h − v) / px); the camera moves the frame by ≤ 10 %.
        traj.iter().flatten().all(|a| {
            let (u, v) = (a.x * px, h - a.y * px);
            let m = 2.0 * px;
            u < x0 - m || u > x0 + size + m || v < y0 - m || v > y0 + size + m
        })
    };
    let mut out = Vec::new();
    let xs: Vec<f64> = (0..8)
        .map(|k| w * 0.9 - size - k as f64 * w * 0.05)
        .collect();
    for &y0 in &[h * 0.12, h * 0.5 - size / 2.0, h * 0.88 - size] {
        if let Some(&x0) = xs.iter().find(|&&x| clear(x, y0)) {
            out.push(format!(
                "{},{},{},{}",
                x0 as i64, y0 as i64, size as i64, size as i64
            ));
        }
    }
    if out.len() == 3 {
        out
    } else {
        Vec::new()
    }
}

fn main() {
    let bin = std::env::var_os("HERDFIT_BIN")
        .map(PathBuf::from)
        .unwrap_or_else(|| Path::new(env!("CARGO_MANIFEST_DIR")).join("target/release/herdfit"));
    let args: Vec<String> = std::env::args().skip(1).collect();
    let filter = args.first().cloned().unwrap_or_default();
    let extra = args.get(1..).unwrap_or_default().to_vec();
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    println!("| camera | agents | px/BL | frame | extraction | count error | density r | heading error | mean speed error | body length (px) |");
    println!("|---|---:|---:|---|---|---:|---:|---:|---:|---:|");
    for moving in [false, true] {
        for (agents, grid) in [(200, "20x12"), (800, "40x24")] {
            for px in [16.0, 10.0] {
                let name = format!("{}-{agents}-{px}", if moving { "moving" } else { "still" });
                if !name.contains(&filter) {
                    continue;
                }
                let clip = d.join(&name);
                let video = d.join(format!("{name}.avi"));
                let mut args: Vec<String> = [
                    "synth",
                    "--agents",
                    &agents.to_string(),
                    "--frames",
                    "250",
                    "--grid",
                    grid,
                    "--cell-size",
                    "2",
                    "--px-per-bl",
                    &px.to_string(),
                    "--seed",
                    "5",
                ]
                .iter()
                .map(|s| s.to_string())
                .collect();
                args.extend(["--out".into(), clip.display().to_string()]);
                args.extend(["--video".into(), video.display().to_string()]);
                if moving {
                    args.push("--camera-motion".into());
                }
                run(&bin, &args);
                let truth = read_traj(&clip.join("trajectories.csv"));
                let synth = ClipFields::load(&clip).unwrap();
                let g = synth.grid();
                let size = herdfit::video::render::frame_size(&g, px);
                let anchor_set = anchors(&truth, px, size.0 as f64, size.1 as f64);
                for with_anchors in [false, true] {
                    if with_anchors && anchor_set.is_empty() {
                        println!("| {} | {agents} | {px} | {}×{} | anchors | no clear ground for anchors | | | | |",
                            if moving { "moving" } else { "static" }, size.0, size.1);
                        continue;
                    }
                    let out = d.join(format!("{name}-ex{}", u8::from(with_anchors)));
                    let mut a = vec![
                        "extract".to_string(),
                        video.display().to_string(),
                        "--out".into(),
                        out.display().to_string(),
                    ];
                    a.extend(extra.iter().cloned());
                    if with_anchors {
                        for r in &anchor_set {
                            a.extend(["--anchor".into(), r.clone()]);
                        }
                    }
                    run(&bin, &a);
                    let ex = ClipFields::load(&out).unwrap();
                    let sc = score(&ex, &truth, synth.meta.speed.mean, px);
                    println!(
                        "| {} | {agents} | {px} | {}×{} | {} | {:.1} % | {:.3} | {:.2}° | {:.1} % | {:.2} |",
                        if moving { "moving" } else { "static" },
                        size.0,
                        size.1,
                        if with_anchors { format!("anchors {}", anchor_set.join(" ")) } else { "no flags".into() },
                        sc.count_err * 100.0,
                        sc.r,
                        sc.heading_err,
                        sc.speed_err * 100.0,
                        ex.meta.body_length_px.unwrap_or(f64::NAN),
                    );
                }
            }
        }
    }
}
