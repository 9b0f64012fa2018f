//! herdfit's [`Progress`] reported to a Python object (the package's tqdm adapter or the user's
//! callback) and Ctrl-C: every report takes the GIL for a moment, runs Python's signal handlers
//! (`Python::check_signals`) and, when one raised (KeyboardInterrupt) or the callback raised,
//! tells the library to stop ([`Progress::interrupted`]); the exception is raised on return.

use herdfit::progress::Progress;
use pyo3::prelude::*;

/// Progress for a Python object with `start(what, total)`, `inc(n)`, `message(text)` and
/// `finish()` (any may be missing), or none.
pub struct PyProgress {
    target: Option<Py<PyAny>>,
    /// The first Python exception seen (a signal handler's or the callback's).
    pub error: Option<PyErr>,
}

impl PyProgress {
    pub fn new(target: Option<Py<PyAny>>) -> Self {
        PyProgress {
            target: target.filter(|t| Python::attach(|py| !t.is_none(py))),
            error: None,
        }
    }

    fn call<A>(&mut self, method: &str, args: A)
    where
        A: for<'py> pyo3::call::PyCallArgs<'py>,
    {
        if self.error.is_some() {
            return;
        }
        Python::attach(|py| {
            let result = match &self.target {
                Some(t) => {
                    let t = t.bind(py);
                    match t.hasattr(method) {
                        Ok(true) => t.call_method1(method, args).map(|_| ()),
                        Ok(false) => Ok(()),
                        Err(e) => Err(e),
                    }
                }
                None => Ok(()),
            };
            if let Err(e) = result.and_then(|_| py.check_signals()) {
                self.error = Some(e);
            }
        });
    }
}

impl Progress for PyProgress {
    fn start(&mut self, what: &str, len: u64) {
        self.call("start", (what.to_string(), len));
    }
    fn inc(&mut self, n: u64) {
        self.call("inc", (n,));
    }
    fn message(&mut self, msg: &str) {
        self.call("message", (msg.to_string(),));
    }
    fn finish(&mut self) {
        self.call("finish", ());
    }
    fn interrupted(&mut self) -> bool {
        if self.error.is_none() {
            Python::attach(|py| {
                if let Err(e) = py.check_signals() {
                    self.error = Some(e);
                }
            });
        }
        self.error.is_some()
    }
}
