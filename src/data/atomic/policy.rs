//! The output-path policy every writer applies (issue #14): an existing target is replaced only
//! when it is a regular file (or, for folders, a herdfit output folder, see `AtomicDir`); devices,
//! FIFOs, sockets and symbolic links are refused, never renamed over; and an output that is, is
//! inside, or contains an input of the same command is refused (canonical paths compared, so
//! symlinks and `..` do not hide it).
//!
//! Inputs are recorded by the readers in `data` (and the subsystems' own readers) through
//! [`note_input`]. The record is kept only once [`guard_inputs`] has been called, which the
//! command line does at start: one process runs one command, so "the inputs of the same command"
//! are the files this process has read. Library users who read and rewrite a file on purpose (a
//! test round trip, a resumed checkpoint) are not affected unless they opt in.

use crate::error::{Error, Result};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;

static GUARD: AtomicBool = AtomicBool::new(false);
static INPUTS: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Turns on the input record for this process (the CLI calls it once, before the command).
pub fn guard_inputs() {
    GUARD.store(true, Ordering::SeqCst);
}

/// Records `path` (a file or a folder) as an input of this process's command.
pub fn note_input(path: &Path) {
    if !GUARD.load(Ordering::SeqCst) {
        return;
    }
    if let Ok(c) = std::fs::canonicalize(path) {
        let mut v = INPUTS.lock().unwrap_or_else(|e| e.into_inner());
        if !v.contains(&c) {
            v.push(c);
        }
    }
}

/// Reads a text input, recording it with [`note_input`]; errors name the file.
pub fn read_input_text(path: &Path) -> crate::error::Result<String> {
    note_input(path);
    std::fs::read_to_string(path)
        .map_err(|e| crate::error::Error::file(path, format!("cannot read: {e}")))
}

/// The canonical form of an output path that may not exist yet: its folder resolved, its name
/// kept.
pub(super) fn canonical_target(path: &Path) -> Option<PathBuf> {
    if let Ok(c) = std::fs::canonicalize(path) {
        return Some(c);
    }
    let name = path.file_name()?;
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    std::fs::canonicalize(dir).ok().map(|d| d.join(name))
}

/// What an existing non-regular path is, in words.
#[cfg(unix)]
fn kind(ft: std::fs::FileType) -> &'static str {
    use std::os::unix::fs::FileTypeExt;
    if ft.is_char_device() {
        "a character device"
    } else if ft.is_block_device() {
        "a block device"
    } else if ft.is_fifo() {
        "a FIFO"
    } else if ft.is_socket() {
        "a socket"
    } else {
        "not a regular file"
    }
}

#[cfg(not(unix))]
fn kind(_: std::fs::FileType) -> &'static str {
    "not a regular file"
}

/// Checks `path` as an output target: `Ok` when it does not exist, or is a regular file or a
/// folder (folders are judged further by `AtomicDir`), and is neither an input of this command
/// nor inside nor above one. The error names `path` and says why.
pub fn check_target(path: &Path) -> Result<()> {
    match std::fs::symlink_metadata(path) {
        Ok(m) => {
            let ft = m.file_type();
            if ft.is_symlink() {
                return Err(Error::file(
                    path,
                    "is a symbolic link; refusing to replace it (give the path it points to)",
                ));
            }
            if !ft.is_file() && !ft.is_dir() {
                return Err(Error::file(
                    path,
                    format!("is {}; refusing to replace it with a file", kind(ft)),
                ));
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(Error::file(path, format!("cannot write: {e}"))),
    }
    let Some(out) = canonical_target(path) else {
        return Ok(());
    };
    let inputs = INPUTS.lock().unwrap_or_else(|e| e.into_inner());
    for inp in inputs.iter() {
        if *inp == out {
            return Err(Error::file(
                path,
                "is an input of this command; refusing to overwrite it",
            ));
        }
        if inp.starts_with(&out) {
            return Err(Error::file(
                path,
                format!(
                    "contains an input of this command ({}); refusing to replace it",
                    inp.display()
                ),
            ));
        }
        if out.starts_with(inp) {
            return Err(Error::file(
                path,
                format!(
                    "is inside an input of this command ({}); refusing to write there",
                    inp.display()
                ),
            ));
        }
    }
    Ok(())
}
