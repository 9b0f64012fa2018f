//! `-` as an output path means standard output, for the outputs that are one stream (a
//! trajectory CSV, a JSON report). The command line calls [`take_stdout`] when an argument is
//! `-`: the data keep the original standard output, and the process's own messages (progress,
//! the closing summary) go to standard error from then on, so that `herdfit simulate … --out - |
//! next` receives nothing but data. Outputs that are folders or pictures refuse `-`.

use crate::error::{Error, Result};
use std::io::Write;
use std::path::Path;
use std::sync::atomic::{AtomicI32, Ordering};

/// The descriptor data written to `-` go to (-1: standard output as it is).
static DATA_FD: AtomicI32 = AtomicI32::new(-1);

/// Is `path` the stdout marker `-`?
pub fn is_stdout(path: &Path) -> bool {
    path.as_os_str() == "-"
}

/// Keeps the current standard output for data written to `-` and points descriptor 1 at standard
/// error (Unix; elsewhere data and messages share standard output).
pub fn take_stdout() {
    #[cfg(unix)]
    // SAFETY: dup/dup2 on the process's own standard descriptors.
    unsafe {
        if DATA_FD.load(Ordering::SeqCst) >= 0 {
            return;
        }
        let saved = libc::dup(1);
        if saved >= 0 && libc::dup2(2, 1) >= 0 {
            DATA_FD.store(saved, Ordering::SeqCst);
        }
    }
}

/// The error of an output that cannot be a stream.
pub fn not_a_stream(path: &Path, what: &str) -> Error {
    Error::file(
        path,
        format!("{what} cannot go to standard output ('-'); give a file name"),
    )
}

/// The data stream behind `-`.
pub struct Stdout;

impl Write for Stdout {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        #[cfg(unix)]
        {
            let fd = DATA_FD.load(Ordering::SeqCst);
            if fd >= 0 {
                // SAFETY: writing a caller's buffer to a descriptor this process owns.
                let n = unsafe { libc::write(fd, buf.as_ptr().cast(), buf.len()) };
                return if n < 0 {
                    Err(std::io::Error::last_os_error())
                } else {
                    Ok(n as usize)
                };
            }
        }
        std::io::stdout().write(buf)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        std::io::stdout().flush()
    }
}

/// Writes `bytes` to the data stream (errors name `-`).
pub fn write_all(path: &Path, bytes: &[u8]) -> Result<()> {
    let mut s = Stdout;
    s.write_all(bytes)
        .and_then(|_| s.flush())
        .map_err(|e| Error::file(path, format!("cannot write to standard output: {e}")))
}
