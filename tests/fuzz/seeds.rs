//! Valid seed files for the fuzz, written once per test process: the small synthetic clip, a run
//! with its recording, flock shape parameters, a crowd model (through the binary), and what the
//! library writes in-process (tracks + sidecar, camera, glTF, checkpoint, default configs); real
//! data excerpts (ETH/UCY, jackdaws) from the shared data folder.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The repository root.
pub fn repo() -> &'static Path {
    Path::new(env!("CARGO_MANIFEST_DIR"))
}

/// The shared data folder: `HERDFIT_SHARED_DATA`, else `<repo>/../shared/data`, else
/// `/work/shared/data`.
pub fn shared_data() -> PathBuf {
    if let Ok(p) = std::env::var("HERDFIT_SHARED_DATA") {
        return PathBuf::from(p);
    }
    let sib = repo().join("../shared/data");
    if sib.is_dir() {
        return sib;
    }
    PathBuf::from("/work/shared/data")
}

/// The first `n` lines of a file.
pub fn head(path: &Path, n: usize) -> Vec<u8> {
    let t = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut s: String = t.lines().take(n).collect::<Vec<_>>().join("\n");
    s.push('\n');
    s.into_bytes()
}

/// A folder of seeds written by the binary (once per process).
pub fn fixture() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let tmp = std::env::temp_dir();
        // Folders of earlier runs whose process is gone.
        for e in std::fs::read_dir(&tmp).into_iter().flatten().flatten() {
            let n = e.file_name().to_string_lossy().into_owned();
            if let Some(pid) = n.strip_prefix("herdfit-fuzz-") {
                if !Path::new("/proc").join(pid).exists() {
                    let _ = std::fs::remove_dir_all(e.path());
                }
            }
        }
        let d = tmp.join(format!("herdfit-fuzz-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        let run = |args: &[&str]| {
            let o = std::process::Command::new(env!("CARGO_BIN_EXE_herdfit"))
                .args(args)
                .current_dir(&d)
                .output()
                .unwrap();
            assert!(
                o.status.success(),
                "{args:?}: {}",
                String::from_utf8_lossy(&o.stderr)
            );
        };
        #[rustfmt::skip]
        run(&["synth", "--agents", "12", "--frame-count", "3", "--grid-size", "5x4",
              "--cell-size", "2", "--out", "clip"]);
        #[rustfmt::skip]
        run(&["simulate", "--agents", "4", "--steps", "2", "--out", "t.csv", "--record", "rec.json"]);
        let v = repo().join("examples/flocks/v.csv");
        run(&["flock", "extract", v.to_str().unwrap(), "--out", "shape.json"]);
        #[rustfmt::skip]
        run(&["crowd", "synth", "--seed", "1", "--duration", "6", "--out", "crowd.csv"]);
        // A small model (≈ 9 kB): few samples, two PCA dimensions.
        std::fs::write(d.join("learn.json"), r#"{"min_samples": 20}"#).unwrap();
        #[rustfmt::skip]
        run(&["crowd", "learn", "crowd.csv", "--config", "learn.json", "--pca-dims", "2",
              "--out", "model.json"]);
        d
    })
}

/// A fixture file's bytes.
pub fn read(name: &str) -> Vec<u8> {
    let p = fixture().join(name);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A repository file's bytes.
pub fn repo_file(rel: &str) -> Vec<u8> {
    let p = repo().join(rel);
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// A value as pretty JSON bytes.
pub fn json<T: serde::Serialize>(v: &T) -> Vec<u8> {
    let mut b = serde_json::to_vec_pretty(v).unwrap();
    b.push(b'\n');
    b
}
