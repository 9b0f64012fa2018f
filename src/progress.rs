//! Progress of long library work, reported through a trait so the library knows no terminal: the
//! CLI implements it with indicatif bars (`cli::progress`), tests and Rust callers pass
//! [`NoProgress`]. A caller can also stop long work: loops consult [`Progress::check`] between
//! units of work and return [`Error::Interrupted`] when it says so (the Python package's Ctrl-C).

use crate::error::{Error, Result};

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
    /// Whether the caller asks the work to stop (consulted between units of work).
    fn interrupted(&mut self) -> bool {
        false
    }
    /// [`Error::Interrupted`] when [`Progress::interrupted`] says so.
    fn check(&mut self) -> Result<()> {
        match self.interrupted() {
            true => Err(Error::Interrupted),
            false => Ok(()),
        }
    }
}

/// What a long loop's per-unit callback returns: `()` (go on) or a `Result` whose error (e.g.
/// [`Error::Interrupted`] from [`Progress::check`]) stops the loop with that error.
pub trait Proceed {
    /// `Ok` to go on.
    fn proceed(self) -> Result<()>;
}

impl Proceed for () {
    fn proceed(self) -> Result<()> {
        Ok(())
    }
}

impl Proceed for Result<()> {
    fn proceed(self) -> Result<()> {
        self
    }
}

/// Reports nothing.
#[derive(Clone, Copy, Debug, Default)]
pub struct NoProgress;

impl Progress for NoProgress {
    fn start(&mut self, _what: &str, _len: u64) {}
    fn inc(&mut self, _n: u64) {}
    fn finish(&mut self) {}
}

#[cfg(test)]
mod tests {
    use super::*;

    struct StopAfter(u64);

    impl Progress for StopAfter {
        fn start(&mut self, _what: &str, _len: u64) {}
        fn inc(&mut self, n: u64) {
            self.0 = self.0.saturating_sub(n);
        }
        fn finish(&mut self) {}
        fn interrupted(&mut self) -> bool {
            self.0 == 0
        }
    }

    #[test]
    fn check_turns_an_interrupt_into_the_interrupted_error() {
        let mut p = StopAfter(2);
        assert!(p.check().is_ok());
        p.inc(2);
        assert!(matches!(p.check(), Err(Error::Interrupted)));
        assert!(NoProgress.check().is_ok());
        assert!(().proceed().is_ok());
        assert!(matches!(
            Err(Error::Interrupted).proceed(),
            Err(Error::Interrupted)
        ));
    }
}
