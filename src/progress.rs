//! Progress of long library work, reported through a trait so the library knows no terminal: the
//! CLI implements it with indicatif bars (`cli::progress`), tests and Rust callers pass
//! [`NoProgress`].

/// Receives the progress of a long-running library call.
pub trait Progress {
    /// A new stage named `what` with `len` units of work (0 when unknown).
    fn start(&mut self, what: &str, len: u64);
    /// `n` more units of the current stage are done.
    fn inc(&mut self, n: u64);
    /// A short status for the current stage (e.g. the latest loss).
    fn message(&mut self, _msg: &str) {}
    /// The current stage is finished.
    fn finish(&mut self);
}

/// Reports nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn start(&mut self, _what: &str, _len: u64) {}
    fn inc(&mut self, _n: u64) {}
    fn finish(&mut self) {}
}
