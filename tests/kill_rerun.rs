//! Issue #47: kill -9 in any long verb, then the same command again: the rerun writes the same
//! bytes as an uninterrupted run, and no hidden temporary file (`.herdfit-…`) is left anywhere —
//! the killed run's are recognised (a process id that no longer runs) and removed by the rerun.
//!
//! Each verb runs in folders holding the same inputs: once uninterrupted (its time T), once
//! killed with SIGKILL at T/2 and at 0.9·T (while it computes, while it writes), and once more in
//! the killed run's folder. The uninterrupted and the rerun outputs are compared byte for byte
//! (wall-clock figures aside: `*_seconds` in JSON, `wall s` rows in Markdown).

#[path = "whole_cli/fixture.rs"]
mod fixture;

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::{Duration, Instant};

/// The long verbs, at sizes that take a second or more.
const LONG: &[&str] = &[
    "fit clip --out fp.json --epochs 30 --window 2 --no-uncertainty --checkpoint ck",
    "validate clip --params p.json --seeds 6 --out val",
    "ablate clip --out ab --epochs 2 --window 2 --seeds 1",
    "extract v.avi --out ex --preview pv --preview-every 1",
    "synth --agents 300 --frame-count 60 --grid-size 16x16 --cell-size 2 --video-file sv.avi \
     --image si.png --out sy",
    "author scene.json --out au --video",
    "flock animate shape.json --birds 9 --frames 200 --out fa",
    "crowd simulate model.json --layout layout.json --steps 400 --png cs.png --video cs.avi \
     --out cs.csv",
    "crowd evaluate --data eth --scene HOTEL --json ev.json",
    "lift run t2.csv --camera cam.json --v-target 0.1 --d-near 1 --d-far 100 --out lr.csv --plots lp --video lv.avi",
    "lift evaluate t3.csv --camera cam.json --v-target 0.1 --d-near 1 --d-far 100 --out lev",
    "import-tracks t.csv --body-length-m 0.5 --out it",
];

/// When each verb is killed, as a fraction of its uninterrupted time: while it computes, and
/// (for most verbs) while it writes.
const KILL_AT: [f64; 2] = [0.5, 0.9];

fn copy_tree(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap().flatten() {
        let (p, t) = (e.path(), to.join(e.file_name()));
        if p.is_dir() {
            copy_tree(&p, &t);
        } else {
            std::fs::copy(&p, &t).unwrap();
        }
    }
}

/// Every file under `dir` with its bytes.
fn files(dir: &Path) -> BTreeMap<PathBuf, Vec<u8>> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                stack.push(p.clone());
            }
            let bytes = std::fs::read(&p).unwrap_or_default();
            out.insert(
                p.strip_prefix(dir).unwrap().to_path_buf(),
                untimed(&p, bytes),
            );
        }
    }
    out
}

/// A file's bytes without its wall-clock figures — `fit_seconds` in `ablation.json`, the `fit wall
/// s` row of `ablation.md`: how long a fit took is reported, and differs between any two runs by
/// design — other files as they are.
fn untimed(p: &Path, bytes: Vec<u8>) -> Vec<u8> {
    fn strip(v: &mut serde_json::Value) {
        match v {
            serde_json::Value::Object(m) => {
                m.retain(|k, _| !k.ends_with("_seconds"));
                m.values_mut().for_each(strip);
            }
            serde_json::Value::Array(a) => a.iter_mut().for_each(strip),
            _ => {}
        }
    }
    if p.extension().is_some_and(|e| e == "md") {
        let text = String::from_utf8_lossy(&bytes);
        let kept: Vec<&str> = text.lines().filter(|l| !l.contains(" wall s ")).collect();
        return kept.join("\n").into_bytes();
    }
    if p.extension().is_none_or(|e| e != "json") {
        return bytes;
    }
    match serde_json::from_slice::<serde_json::Value>(&bytes) {
        Ok(mut v) => {
            strip(&mut v);
            serde_json::to_vec(&v).unwrap()
        }
        Err(_) => bytes,
    }
}

fn command(dir: &Path, line: &str) -> Command {
    let mut c = Command::new(env!("CARGO_BIN_EXE_herdfit"));
    c.args(line.split_whitespace())
        .current_dir(dir)
        .env("RAYON_NUM_THREADS", "1")
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped());
    c
}

fn run_ok(dir: &Path, line: &str) -> f64 {
    let t0 = Instant::now();
    let o = command(dir, line).output().unwrap();
    assert!(
        o.status.success(),
        "herdfit {line}: {}",
        String::from_utf8_lossy(&o.stderr)
    );
    t0.elapsed().as_secs_f64()
}

#[test]
fn kill_9_then_rerun_gives_the_same_bytes_and_leaves_no_hidden_file() {
    let fx = fixture::fixture();
    let mut problems = Vec::new();
    for (line, at) in LONG
        .iter()
        .flat_map(|l| KILL_AT.iter().map(move |f| (*l, *f)))
    {
        let clean = tempfile::tempdir().unwrap();
        let killed = tempfile::tempdir().unwrap();
        copy_tree(fx, clean.path());
        copy_tree(fx, killed.path());
        let t = run_ok(clean.path(), line);
        let mut child = command(killed.path(), line).spawn().unwrap();
        std::thread::sleep(Duration::from_secs_f64(t * at));
        let was_running = child.try_wait().unwrap().is_none();
        let _ = child.kill();
        let _ = child.wait();
        let left: Vec<PathBuf> = files(killed.path())
            .into_keys()
            .filter(|p| p.to_string_lossy().contains(".herdfit-"))
            .collect();
        run_ok(killed.path(), line);
        let (a, b) = (files(clean.path()), files(killed.path()));
        let hidden: Vec<&PathBuf> = b
            .keys()
            .filter(|p| p.to_string_lossy().contains(".herdfit-"))
            .collect();
        println!(
            "{line}: {t:.2} s, killed at {:.2} s{}, {} hidden file(s) left by the kill",
            t * at,
            if was_running { "" } else { " (had finished)" },
            left.len()
        );
        if !hidden.is_empty() {
            problems.push(format!("{line}: hidden files after the rerun: {hidden:?}"));
        }
        if a.keys().collect::<Vec<_>>() != b.keys().collect::<Vec<_>>() {
            problems.push(format!(
                "{line}: files differ: {:?} vs {:?}",
                a.keys().collect::<Vec<_>>(),
                b.keys().collect::<Vec<_>>()
            ));
            continue;
        }
        for (p, bytes) in &a {
            if b[p] != *bytes {
                problems.push(format!(
                    "{line}: {} differs after kill + rerun",
                    p.display()
                ));
            }
        }
    }
    assert!(problems.is_empty(), "{problems:#?}");
}
