//! Helpers shared by the integration tests: run the `herdfit` binary and check its outcome.
#![allow(dead_code)]

use std::path::Path;
use std::process::{Command, Output};

/// Runs the binary built for these tests.
pub fn herdfit(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_herdfit"))
        .args(args)
        .output()
        .expect("the herdfit binary runs")
}

/// Runs a command that must succeed; returns its stdout.
pub fn ok(args: &[&str]) -> String {
    let o = herdfit(args);
    assert!(
        o.status.success(),
        "herdfit {args:?} failed: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    String::from_utf8_lossy(&o.stdout).into_owned()
}

/// Runs a command that must fail with exit code `code`, a single `error: …` line on stderr and
/// no panic; returns that line.
pub fn fails_with(args: &[&str], code: i32) -> String {
    let o = herdfit(args);
    assert_eq!(
        o.status.code(),
        Some(code),
        "herdfit {args:?} should exit {code}"
    );
    let err = String::from_utf8_lossy(&o.stderr).into_owned();
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(lines.len(), 1, "one line expected, got: {err}");
    assert!(lines[0].starts_with("error: "), "{err}");
    assert!(
        !err.contains("panicked") && !err.contains("internal error"),
        "{err}"
    );
    lines[0].to_string()
}

/// [`fails_with`] exit code 1 (a library error).
pub fn fails(args: &[&str]) -> String {
    fails_with(args, 1)
}

/// A path as a command-line argument.
pub fn s(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

/// A small synthetic clip on 8×6 cells of 3 BL (24 × 18 BL) in `dir/clip`: `agents` agents,
/// `frames` frames, seed `seed`.
pub fn small_clip(dir: &Path, agents: u32, frames: u32, seed: u32) -> std::path::PathBuf {
    let clip = dir.join("clip");
    let (a, f, sd) = (agents.to_string(), frames.to_string(), seed.to_string());
    ok(&[
        "synth",
        "--agents",
        &a,
        "--frame-count",
        &f,
        "--grid-size",
        "8x6",
        "--cell-size",
        "3",
        "--seed",
        &sd,
        "--out",
        s(&clip),
    ]);
    clip
}
