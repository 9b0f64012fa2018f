//! herdfit's errors as the package's exceptions (`herdfit.errors`): a bad config key →
//! `ConfigError` (a `ValueError`, `.key` the key), a bad file → `FileError` (an `OSError`,
//! `.filename` the file), anything else → `HerdfitError`; each carries herdfit's one-line
//! message. An interrupted call raises the exception that stopped it (KeyboardInterrupt).

use crate::progress::PyProgress;
use herdfit::error::Error;
use pyo3::prelude::*;

/// The package's exception `class` built with `args`.
fn raise<'py, A>(py: Python<'py>, class: &str, args: A) -> PyErr
where
    A: pyo3::call::PyCallArgs<'py>,
{
    let made = py
        .import("herdfit.errors")
        .and_then(|m| m.getattr(class))
        .and_then(|c| c.call1(args));
    match made {
        Ok(e) => PyErr::from_value(e),
        Err(e) => e,
    }
}

/// `e` as a Python exception; `progress`'s stored exception when `e` is the interruption.
pub fn to_py(py: Python<'_>, e: Error, progress: Option<&mut PyProgress>) -> PyErr {
    let msg = e.to_string();
    match e {
        Error::Interrupted => match progress.and_then(|p| p.error.take()) {
            Some(err) => err,
            None => pyo3::exceptions::PyKeyboardInterrupt::new_err(msg),
        },
        Error::Config { err, .. } => raise(py, "ConfigError", (msg, err.key)),
        Error::File { path, .. } => raise(py, "FileError", (msg, path)),
        Error::Invalid(_) | Error::Internal(_) => raise(py, "HerdfitError", (msg,)),
    }
}

/// A dict that does not fit a config (pythonize's serde error): `ConfigError` naming the key
/// serde names (an unknown or missing field), under `what` (e.g. "fit").
pub fn from_serde(py: Python<'_>, what: &str, e: pythonize::PythonizeError) -> PyErr {
    let text = e.to_string();
    let key = ["unknown field `", "missing field `", "unknown variant `"]
        .iter()
        .find_map(|p| {
            let rest = &text[text.find(p)? + p.len()..];
            Some(rest[..rest.find('`')?].to_string())
        })
        .unwrap_or_default();
    raise(py, "ConfigError", (format!("{what}: {text}"), key))
}
