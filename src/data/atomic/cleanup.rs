//! Temporary siblings that never outlive their run (issue #14): each is named
//! `.herdfit-<pid>-<target name>-<random>` and recorded while it exists; SIGINT and SIGTERM remove
//! the recorded ones before the process dies, and a sibling left by a run that was killed outright
//! (SIGKILL, power loss) is recognised by its prefix and a process id that no longer runs, and
//! removed by the next run that writes the same output.
//!
//! Signals are handled without a crate: the CLI blocks SIGINT/SIGTERM in every thread
//! ([`install_signal_cleanup`], before rayon starts its pool, so the workers inherit the mask) and
//! one thread waits for them with `sigwait`. The cleanup then runs as ordinary code on that thread
//! (taking a lock and deleting files are not async-signal-safe, so a flag-setting handler would
//! need the main loop to poll; `sigwait` needs no polling and no `signal-hook` dependency).

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::Mutex;

static LIVE: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Every temporary sibling made by this process, with the output it stands for, so that an error
/// raised inside one (a plotting library writing `<temp folder>/metrics.png`, say) names the
/// user's output and not a hidden path ([`user_facing`]).
static NAMES: Mutex<Vec<(String, String)>> = Mutex::new(Vec::new());

/// `msg` with every temporary sibling's path replaced by the output it stands for.
pub fn user_facing(msg: &str) -> String {
    let names = NAMES.lock().unwrap_or_else(|e| e.into_inner());
    names.iter().fold(msg.to_string(), |m, (tmp, user)| {
        m.replace(tmp.as_str(), user)
    })
}

/// Prefix of every temporary sibling herdfit makes.
pub const TEMP_PREFIX: &str = ".herdfit-";

/// The name prefix of this process's temporary siblings of `target`:
/// `.herdfit-<pid>-<name>-` (the name cut to 80 bytes at a character boundary).
pub fn temp_prefix(target: &Path) -> String {
    let name = target
        .file_name()
        .map(|n| n.to_string_lossy().into_owned())
        .unwrap_or_default();
    let mut cut = name.len().min(80);
    while !name.is_char_boundary(cut) {
        cut -= 1;
    }
    format!("{TEMP_PREFIX}{}-{}-", std::process::id(), &name[..cut])
}

/// Records a temporary sibling of `target` so that a signal removes it and an error raised inside
/// it names `target` ([`user_facing`]).
pub fn register(path: &Path, target: &Path) {
    LIVE.lock()
        .unwrap_or_else(|e| e.into_inner())
        .push(path.to_path_buf());
    NAMES
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .push((path.display().to_string(), target.display().to_string()));
}

/// Forgets a temporary sibling (renamed into place or removed).
pub fn unregister(path: &Path) {
    LIVE.lock()
        .unwrap_or_else(|e| e.into_inner())
        .retain(|p| p != path);
}

/// Removes every recorded temporary sibling (files and folders).
pub fn remove_live() {
    let live = std::mem::take(&mut *LIVE.lock().unwrap_or_else(|e| e.into_inner()));
    for p in live {
        if p.is_dir() {
            let _ = std::fs::remove_dir_all(&p);
        } else {
            let _ = std::fs::remove_file(&p);
        }
        // A folder being replaced is first moved to `<temp>.old`.
        let _ = std::fs::remove_dir_all(p.with_extension("old"));
    }
}

/// Whether process `pid` still runs.
#[cfg(unix)]
fn alive(pid: u32) -> bool {
    let Ok(pid) = libc::pid_t::try_from(pid) else {
        return false;
    };
    // SAFETY: kill with signal 0 only checks that the process exists.
    let r = unsafe { libc::kill(pid, 0) };
    r == 0 || std::io::Error::last_os_error().raw_os_error() == Some(libc::EPERM)
}

#[cfg(not(unix))]
fn alive(_: u32) -> bool {
    true
}

/// Removes the temporary siblings of `target` left in `dir` by herdfit runs that no longer run.
pub fn remove_stale(dir: &Path, target: &Path) {
    let Some(name) = target.file_name() else {
        return;
    };
    let name = name.to_string_lossy().into_owned();
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let file: OsString = e.file_name();
        let file = file.to_string_lossy();
        let Some(rest) = file.strip_prefix(TEMP_PREFIX) else {
            continue;
        };
        let Some((pid, rest)) = rest.split_once('-') else {
            continue;
        };
        let Ok(pid) = pid.parse::<u32>() else {
            continue;
        };
        let mut cut = name.len().min(80);
        while !name.is_char_boundary(cut) {
            cut -= 1;
        }
        let ours = rest
            .strip_prefix(&name[..cut])
            .is_some_and(|r| r.starts_with('-'));
        if !ours || pid == std::process::id() || alive(pid) {
            continue;
        }
        let p = e.path();
        match std::fs::symlink_metadata(&p) {
            Ok(m) if m.is_dir() => {
                let _ = std::fs::remove_dir_all(&p);
            }
            Ok(m) if m.is_file() => {
                let _ = std::fs::remove_file(&p);
            }
            _ => {}
        }
    }
}

/// Blocks SIGINT and SIGTERM in this thread (and the threads it starts later) and starts the thread
/// that, on either, removes the recorded temporary siblings and exits with 128 + the signal
/// number, as a shell reports a death by that signal; `first` runs before the removal (the output
/// plan's discard, which lives above this module). Call first thing in `main`.
#[cfg(unix)]
pub fn install_signal_cleanup(first: fn()) {
    // SAFETY: plain libc calls on a locally owned, initialised signal set.
    unsafe {
        let mut set: libc::sigset_t = std::mem::zeroed();
        libc::sigemptyset(&mut set);
        libc::sigaddset(&mut set, libc::SIGINT);
        libc::sigaddset(&mut set, libc::SIGTERM);
        if libc::pthread_sigmask(libc::SIG_BLOCK, &set, std::ptr::null_mut()) != 0 {
            return;
        }
        let set = SigSet(set);
        let _ = std::thread::Builder::new()
            .name("herdfit-signals".into())
            .spawn(move || {
                let set = set;
                let mut sig: libc::c_int = 0;
                if libc::sigwait(&set.0, &mut sig) == 0 {
                    first();
                    remove_live();
                    eprintln!("error: interrupted by signal {sig}; temporary files removed");
                    std::process::exit(128 + sig);
                }
            });
    }
}

#[cfg(not(unix))]
pub fn install_signal_cleanup(_first: fn()) {}

#[cfg(unix)]
struct SigSet(libc::sigset_t);
// SAFETY: a sigset_t is plain data.
#[cfg(unix)]
unsafe impl Send for SigSet {}
