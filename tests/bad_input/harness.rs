//! The harness of the bad-input suite (issue #14): a case runs the binary in a folder of its own
//! and asserts every promise at once — non-zero exit, exactly one stderr line `error: …` that
//! names the file or key, no panic text, nothing new or removed on disk (the folder listing,
//! hidden files included) and every input unchanged (a hash of each file's bytes, before/after).

use std::collections::BTreeMap;
use std::hash::{Hash, Hasher};
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

/// Every file and folder under `dir` (hidden ones included) with a hash of each file's bytes.
pub fn snapshot(dir: &Path) -> BTreeMap<PathBuf, u64> {
    let mut out = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for e in std::fs::read_dir(&d).expect("listable folder") {
            let p = e.expect("entry").path();
            let m = std::fs::symlink_metadata(&p).expect("metadata");
            let h = if m.is_dir() {
                stack.push(p.clone());
                0
            } else if m.is_file() {
                let mut s = std::collections::hash_map::DefaultHasher::new();
                std::fs::read(&p).expect("readable").hash(&mut s);
                s.finish()
            } else {
                1 + m.len()
            };
            out.insert(p.strip_prefix(dir).unwrap().to_path_buf(), h);
        }
    }
    out
}

/// A fresh folder for one case with a copy of the small fixture clip as `clip/`, its parameter set
/// as `p.json` and an initial herd as `init.csv`.
pub fn workdir() -> tempfile::TempDir {
    let t = tempfile::tempdir().expect("temp dir");
    let fx = fixture();
    copy_dir(&fx.join("clip"), &t.path().join("clip"));
    for f in ["p.json", "init.csv"] {
        std::fs::copy(fx.join(f), t.path().join(f)).expect("copy fixture");
    }
    t
}

fn copy_dir(from: &Path, to: &Path) {
    std::fs::create_dir_all(to).unwrap();
    for e in std::fs::read_dir(from).unwrap() {
        let e = e.unwrap();
        std::fs::copy(e.path(), to.join(e.file_name())).unwrap();
    }
}

fn fixture() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let d = std::env::temp_dir().join(format!("herdfit-bad-input-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let run = |args: &[&str]| {
            let o = bin().args(args).current_dir(&d).output().unwrap();
            assert!(
                o.status.success(),
                "{args:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
        };
        run(&[
            "synth",
            "--agents",
            "20",
            "--frame-count",
            "12",
            "--grid-size",
            "8x8",
            "--cell-size",
            "2",
            "--out",
            "clip",
        ]);
        std::fs::copy(d.join("clip/truth.json"), d.join("p.json")).unwrap();
        run(&[
            "simulate", "--agents", "5", "--steps", "1", "--out", "t.csv",
        ]);
        let t = std::fs::read_to_string(d.join("t.csv")).unwrap();
        let mut init = String::from("id,x,y,vx,vy\n");
        for l in t.lines().skip(1) {
            let f: Vec<&str> = l.split(',').collect();
            if f[0] != "0" {
                continue;
            }
            init += &format!("{},{},{},{},{}\n", f[2], f[3], f[4], f[5], f[6]);
        }
        std::fs::write(d.join("init.csv"), init).unwrap();
        d
    })
}

/// The binary under test.
pub fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_herdfit"))
}

/// Checks one finished run against the promises; `dir` was snapshotted as `before`.
pub fn check(args: &[&str], o: &Output, names: &str, dir: &Path, before: &BTreeMap<PathBuf, u64>) {
    assert!(!o.status.success(), "herdfit {args:?} should fail");
    let err = String::from_utf8_lossy(&o.stderr);
    let lines: Vec<&str> = err.lines().filter(|l| !l.trim().is_empty()).collect();
    assert_eq!(
        lines.len(),
        1,
        "herdfit {args:?}: one stderr line expected, got: {err}"
    );
    assert!(lines[0].starts_with("error: "), "herdfit {args:?}: {err}");
    assert!(
        lines[0].contains(names),
        "herdfit {args:?}: the error should name '{names}': {err}"
    );
    for bad in [
        "panicked",
        "internal error",
        "RUST_BACKTRACE",
        "capacity overflow",
        "WARN",
        // The error names the user's output, never its hidden temporary sibling (issue #14: on
        // a full disk validate's error named `.herdfit-…`).
        ".herdfit-",
    ] {
        assert!(!err.contains(bad), "herdfit {args:?}: {err}");
    }
    let after = snapshot(dir);
    assert_eq!(before, &after, "herdfit {args:?}: the folder changed");
}

/// Runs `herdfit args` in `dir` and checks every promise; the error must contain `names`.
pub fn case_in(dir: &Path, args: &[&str], names: &str) {
    case_in_env(dir, args, names, &[]);
}

/// [`case_in`] with extra environment variables for the child (e.g. `HERDFIT_MEMORY_LIMIT`).
pub fn case_in_env(dir: &Path, args: &[&str], names: &str, env: &[(&str, &str)]) {
    let before = snapshot(dir);
    let o = bin()
        .args(args)
        .envs(env.iter().copied())
        .current_dir(dir)
        .output()
        .expect("runs");
    check(args, &o, names, dir, &before);
}

/// [`case_in`] in a fresh [`workdir`].
pub fn case(args: &[&str], names: &str) {
    let t = workdir();
    case_in(t.path(), args, names);
}

/// [`case_in`] with the child's file-size limit set to `bytes` (`RLIMIT_FSIZE`, as `ulimit -f`)
/// and SIGXFSZ ignored, so that a write past it fails with EFBIG: a full disk, reproducibly.
pub fn case_full_disk(dir: &Path, args: &[&str], names: &str, bytes: u64) {
    use std::os::unix::process::CommandExt;
    let before = snapshot(dir);
    let mut cmd = bin();
    cmd.args(args).current_dir(dir);
    // SAFETY: only async-signal-safe calls (setrlimit, signal) between fork and exec.
    unsafe {
        cmd.pre_exec(move || {
            let r = libc::rlimit {
                rlim_cur: bytes,
                rlim_max: bytes,
            };
            libc::signal(libc::SIGXFSZ, libc::SIG_IGN);
            if libc::setrlimit(libc::RLIMIT_FSIZE, &r) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
    let o = cmd.output().expect("runs");
    check(args, &o, names, dir, &before);
}
