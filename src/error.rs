//! Typed errors of the library. Every message is one line that names the file or the config key
//! and the problem. Library errors name config keys (the fields of a `*Config` or `*Job` as serde
//! names them), never command-line flags: the CLI renames keys to its flags (ripgrep's rule), so
//! a Rust caller, or a value read from a settings file, is told about the key it set.

use std::path::{Path, PathBuf};

/// Errors returned by herdfit's library functions.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// A problem with a named file: unreadable, unwritable, malformed or holding bad values.
    #[error("{}: {msg}", path.display())]
    File { path: PathBuf, msg: String },
    /// A setting out of range or inconsistent with another, named by its config key; `file` is
    /// the file the setting was judged against (e.g. a clip too short for `frames`).
    #[error("{}{err}", file.as_ref().map(|p| format!("{}: ", p.display())).unwrap_or_default())]
    Config {
        file: Option<PathBuf>,
        err: ConfigError,
    },
    /// An impossible request that no single setting or file explains.
    #[error("{0}")]
    Invalid(String),
    /// The caller stopped the work ([`crate::progress::Progress::check`], e.g. Ctrl-C in Python).
    #[error("interrupted")]
    Interrupted,
    /// An internal numerical failure (e.g. a tensor read-back that failed).
    #[error("internal error: {0}")]
    Internal(String),
}

/// A bad value of the config key `key`. The message may name other keys as `{key}` (e.g.
/// "must be ≥ 2 with {loss} ensemble"); [`ConfigError::render`] writes every key by a naming rule.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ConfigError {
    pub key: String,
    pub msg: String,
}

impl ConfigError {
    /// `key`'s value is bad: `msg`.
    pub fn new(key: impl Into<String>, msg: impl Into<String>) -> Self {
        ConfigError {
            key: key.into(),
            msg: msg.into(),
        }
    }

    /// `key: message`, with the key and every `{key}` in the message written by `name`.
    pub fn render(&self, name: &dyn Fn(&str) -> String) -> String {
        let mut out = format!("{}: ", name(&self.key));
        let mut rest = self.msg.as_str();
        while let Some(open) = rest.find('{') {
            let close = rest[open..].find('}').map(|c| open + c);
            let key = close.map(|c| &rest[open + 1..c]);
            match (close, key) {
                (Some(c), Some(k))
                    if !k.is_empty()
                        && k.chars().all(|ch| ch.is_ascii_lowercase() || ch == '_') =>
                {
                    out.push_str(&rest[..open]);
                    out.push_str(&name(k));
                    rest = &rest[c + 1..];
                }
                _ => {
                    out.push_str(&rest[..=open]);
                    rest = &rest[open + 1..];
                }
            }
        }
        out.push_str(rest);
        out
    }
}

impl std::fmt::Display for ConfigError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(&self.render(&|k| k.to_string()))
    }
}

impl From<ConfigError> for Error {
    fn from(err: ConfigError) -> Self {
        Error::Config { file: None, err }
    }
}

impl Error {
    /// A problem with `path`.
    pub fn file(path: impl AsRef<Path>, msg: impl Into<String>) -> Self {
        Error::File {
            path: path.as_ref().to_path_buf(),
            msg: msg.into(),
        }
    }

    /// A bad value of the config key `key` ([`ConfigError`]).
    pub fn config(key: impl Into<String>, msg: impl Into<String>) -> Self {
        ConfigError::new(key, msg).into()
    }

    /// An impossible request (no single setting or file to blame).
    pub fn invalid(msg: impl Into<String>) -> Self {
        Error::Invalid(msg.into())
    }

    /// Attributes a file-less error to `path` (used when a value read from a file, or a setting
    /// judged against it, is rejected).
    pub fn in_file(self, path: impl AsRef<Path>) -> Self {
        match self {
            Error::Invalid(msg) => Error::file(path, msg),
            Error::Config { file: None, err } => Error::Config {
                file: Some(path.as_ref().to_path_buf()),
                err,
            },
            other => other,
        }
    }
}

/// A [`ConfigError`] "must be ≥ 1" for the first of `counts` (key, value) that is 0.
pub fn check_counts(counts: &[(&str, usize)]) -> Result<()> {
    match counts.iter().find(|(_, v)| *v == 0) {
        Some((key, _)) => Err(Error::config(*key, "must be ≥ 1")),
        None => Ok(()),
    }
}

/// A [`ConfigError`] "v must be > 0" for the first of `values` (key, value) that is not a finite
/// positive number.
pub fn check_positive(values: &[(&str, f64)]) -> Result<()> {
    match values.iter().find(|(_, v)| !(v.is_finite() && *v > 0.0)) {
        Some((key, v)) => Err(Error::config(*key, format!("{v} must be > 0"))),
        None => Ok(()),
    }
}

/// Result alias of the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn config_errors_name_keys_and_render_them_as_flags() {
        let e = ConfigError::new("replicas", "must be ≥ 2 with {loss} ensemble; {x} {Y} {}");
        assert_eq!(
            e.to_string(),
            "replicas: must be ≥ 2 with loss ensemble; x {Y} {}"
        );
        let flag = |k: &str| format!("--{}", k.replace('_', "-"));
        assert_eq!(
            e.render(&flag),
            "--replicas: must be ≥ 2 with --loss ensemble; --x {Y} {}"
        );
        let f = Error::from(ConfigError::new("frames", "0..9 is out of range")).in_file("clip");
        assert_eq!(f.to_string(), "clip: frames: 0..9 is out of range");
    }
}
