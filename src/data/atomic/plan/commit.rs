//! The end of a run's plan: every staged output renamed into place together ([`finish`]), each
//! replaced output kept aside until all renames succeed and put back if one fails; or every staged
//! output removed ([`abort`]).

use super::{check_target, cleanup, lock, remove, remove_made, Active, Staged, ACTIVE};
use crate::error::{Error, Result};
use std::path::PathBuf;

/// Renames every staged output into place and closes the plan; on any failure nothing is left
/// changed (replaced outputs are put back) and the error names the output.
pub fn finish() -> Result<()> {
    let Some(a) = lock().take() else {
        return Ok(());
    };
    // Every check first: a refusal here must leave nothing renamed.
    for s in &a.staged {
        let r = check_target(&s.target).and_then(|_| {
            if s.dir {
                super::super::replaceable(&s.target).map(|_| ())
            } else if s.target.is_dir() {
                Err(Error::file(&s.target, "cannot write: is a directory"))
            } else {
                Ok(())
            }
        });
        if let Err(e) = r {
            discard(a);
            return Err(e);
        }
    }
    let mut done: Vec<(PathBuf, Option<PathBuf>, bool)> = Vec::new();
    let mut failed = None;
    for s in &a.staged {
        match swap_in(s) {
            Ok(backup) => done.push((s.target.clone(), backup, s.dir)),
            Err(e) => {
                failed = Some(Error::file(&s.target, format!("cannot write: {e}")));
                break;
            }
        }
    }
    if let Some(e) = failed {
        for (target, backup, dir) in done.into_iter().rev() {
            remove(&target, dir);
            if let Some(b) = backup {
                let _ = std::fs::rename(&b, &target);
            }
        }
        discard(a);
        return Err(e);
    }
    for (_, backup, dir) in done {
        if let Some(b) = backup {
            remove(&b, dir);
        }
    }
    for s in &a.staged {
        cleanup::unregister(&s.tmp);
    }
    Ok(())
}

/// Renames one staged output into place; an existing target is first moved to a hidden backup
/// sibling (returned), so that a later failure can put it back.
fn swap_in(s: &Staged) -> std::io::Result<Option<PathBuf>> {
    #[cfg(unix)]
    if s.dir {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(&s.tmp, std::fs::Permissions::from_mode(0o755))?;
    }
    let backup = match std::fs::symlink_metadata(&s.target) {
        Ok(_) => {
            let b = s.tmp.with_extension("old");
            cleanup::register(&b, &s.target);
            std::fs::rename(&s.target, &b)?;
            Some(b)
        }
        Err(_) => None,
    };
    if let Err(e) = std::fs::rename(&s.tmp, &s.target) {
        if let Some(b) = &backup {
            let _ = std::fs::rename(b, &s.target);
        }
        return Err(e);
    }
    Ok(backup)
}

/// Removes every staged output and the parents made for them.
fn discard(a: Active) {
    for s in &a.staged {
        remove(&s.tmp, s.dir);
        cleanup::unregister(&s.tmp);
    }
    for p in &a.private {
        let _ = std::fs::remove_dir_all(p);
    }
    remove_made(&a.made);
}

/// Closes the plan after a failure: every staged output is removed, nothing is renamed.
pub fn abort() {
    if let Some(a) = lock().take() {
        discard(a);
    }
}

/// The paths of the staged outputs and made folders (for the signal handler's cleanup).
pub fn abort_on_signal() {
    // The lock may be held by the interrupted thread; try once and leave the rest to the next run.
    if let Ok(mut g) = ACTIVE.try_lock() {
        if let Some(a) = g.take() {
            discard(a);
        }
    }
}
