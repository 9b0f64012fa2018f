//! The crowd verbs' settings: JSON settings files read and laid over a preset, reports written,
//! and how a bad value is named (issue #47): the library's errors name config keys
//! (`features.radius = -1 …`); the command line renames them to the flag that set the key, or
//! to the settings file (`--config`) when no flag did.

use crate::cli::paths::InFile;
use crate::crowd::features::IntentWindow;
use crate::crowd::model::LearnConfig;
use crate::error::{Error, Result};
use clap::Args;
use std::path::Path;

/// Config keys (as the library's messages start) and the flags that set them.
const FLAGS: [(&str, &str); 18] = [
    ("features.radius", "--radius"),
    ("action.k", "--k"),
    ("action.continuation", "--continuation"),
    ("pca_dims", "--pca-dims"),
    ("smoothing", "--smoothing"),
    ("max_samples", "--max-samples"),
    ("features.intent_window", "--intent-window"),
    ("eth_fps", "--eth-fps"),
    ("action.attraction", "--attraction"),
    ("min_distance", "--min-distance"),
    ("goal_cone", "--goal-cone"),
    ("steps", "--steps"),
    ("synth.duration", "--duration"),
    ("cell", "--cell"),
    ("seed", "--seed"),
    ("split", "--split"),
    ("together", "--together"),
    ("together_seconds", "--together-seconds"),
];

/// A library error about a config key renamed to the flag that set it (issue #47: crowd errors
/// named the key), or attributed to the settings file `file` when no flag set it.
pub(super) fn flagged(e: Error, given: &dyn Fn(&str) -> bool, file: Option<&Path>) -> Error {
    let rename = |key: &str, rest: &str| -> Option<String> {
        let (_, flag) = FLAGS.iter().find(|(k, _)| *k == key)?;
        Some(format!("{flag}: {rest}"))
    };
    match e {
        Error::Invalid(m) => {
            let key = FLAGS
                .iter()
                .map(|(k, _)| *k)
                .filter(|k| {
                    m.strip_prefix(k)
                        .is_some_and(|r| r.starts_with(' ') || r.starts_with(':'))
                })
                .max_by_key(|k| k.len());
            match key {
                Some(k) if given(k) => {
                    let rest = m[k.len()..].trim_start_matches([' ', ':']);
                    let rest = rest.strip_prefix("= ").unwrap_or(rest);
                    Error::Invalid(rename(k, rest).unwrap_or(m))
                }
                _ => match file {
                    Some(f) => Error::file(f, m),
                    None => Error::Invalid(m),
                },
            }
        }
        Error::Config { file: None, err } if given(&err.key) => {
            Error::Invalid(rename(&err.key, &err.msg).unwrap_or_else(|| err.to_string()))
        }
        other => other,
    }
}

impl LearnFlags {
    /// Whether a flag set config key `k`.
    pub(super) fn given(&self, k: &str) -> bool {
        match k {
            "features.radius" => self.radius.is_some(),
            "action.k" => self.k.is_some(),
            "action.continuation" => self.continuation.is_some(),
            "pca_dims" => self.pca_dims.is_some(),
            "smoothing" => self.smoothing.is_some(),
            "max_samples" => self.max_samples.is_some(),
            "features.intent_window" => self.intent_window.is_some(),
            "eth_fps" => self.eth_fps.is_some(),
            _ => self.config.is_none(),
        }
    }

    /// [`flagged`] for these flags.
    pub(super) fn name(&self, e: Error) -> Error {
        flagged(e, &|k| self.given(k), self.config.as_deref())
    }
}

/// `base` with the keys of the JSON file `p` put over it (objects key by key, anything else
/// replaced), so a `--config` file changes only what it names, whichever preset it starts from.
pub(super) fn over<T: serde::Serialize + serde::de::DeserializeOwned>(
    base: &T,
    p: &Path,
) -> Result<T> {
    fn put(b: &mut serde_json::Value, o: serde_json::Value) {
        match (b, o) {
            (serde_json::Value::Object(b), serde_json::Value::Object(o)) => {
                for (k, v) in o {
                    put(b.entry(k).or_insert(serde_json::Value::Null), v);
                }
            }
            (b, o) => *b = o,
        }
    }
    let mut v = serde_json::to_value(base).map_err(|e| Error::Internal(e.to_string()))?;
    put(&mut v, read_json(p)?);
    serde_json::from_value(v).map_err(|e| Error::file(p, format!("bad configuration: {e}")))
}

pub(super) fn read_json<T: serde::de::DeserializeOwned>(p: &Path) -> Result<T> {
    crate::data::atomic::note_input(p);
    let s = std::fs::read_to_string(p).map_err(|e| Error::file(p, format!("cannot read: {e}")))?;
    serde_json::from_str(&s).map_err(|e| Error::file(p, format!("bad configuration: {e}")))
}

pub(super) fn write_json<T: serde::Serialize>(p: &Path, v: &T) -> Result<()> {
    let s = serde_json::to_string_pretty(v).map_err(|e| Error::Internal(e.to_string()))?;
    crate::data::atomic::write_atomic(p, format!("{s}\n").as_bytes())
}

/// Flags that override a learn configuration.
#[derive(Args, Debug, Clone)]
pub struct LearnFlags {
    /// Configuration (LearnConfig JSON); the flags below override it.
    #[arg(long, value_name = "learn.json")]
    pub config: Option<InFile>,
    /// Neighbourhood radius r of eq. 1 (tracks' unit).
    #[arg(long, value_name = "R")]
    pub radius: Option<f64>,
    /// Nearest samples per query.
    #[arg(long, value_name = "K")]
    pub k: Option<usize>,
    /// Continuation: an agent takes the next step of its last sample's own track when that
    /// sample is among the query's N nearest (0: every step drawn afresh; the pedestrians
    /// preset: 1). Only with a sampled output.
    #[arg(long, value_name = "N")]
    pub continuation: Option<usize>,
    /// PCA dimensions.
    #[arg(long, value_name = "D")]
    pub pca_dims: Option<usize>,
    /// σ (frames) of the Gaussian smoothing of the training tracks.
    #[arg(long, value_name = "S")]
    pub smoothing: Option<f64>,
    /// At most this many samples per behaviour.
    #[arg(long, value_name = "N")]
    pub max_samples: Option<usize>,
    /// Frames in the intended-direction window.
    #[arg(long, value_name = "W")]
    pub intent_window: Option<usize>,
    /// Intended direction of training samples from past frames only (default: past and future).
    #[arg(long)]
    pub past_intent: bool,
    /// Frame rate of ETH/UCY .txt inputs.
    #[arg(long, value_name = "FPS")]
    pub eth_fps: Option<f64>,
}

impl LearnFlags {
    pub fn config(&self, base: LearnConfig) -> Result<LearnConfig> {
        let mut c = match &self.config {
            Some(p) => over(&base, p)?,
            None => base,
        };
        if let Some(v) = self.radius {
            c.features.radius = v;
        }
        if let Some(v) = self.k {
            c.action.k = v;
        }
        if let Some(v) = self.continuation {
            c.action.continuation = v;
        }
        if let Some(v) = self.pca_dims {
            c.pca_dims = v;
        }
        if let Some(v) = self.smoothing {
            c.smoothing = v;
        }
        if let Some(v) = self.max_samples {
            c.max_samples = v;
        }
        if let Some(v) = self.intent_window {
            c.features.intent_window = v;
        }
        if self.past_intent {
            c.features.intent = IntentWindow::Past;
        }
        if let Some(v) = self.eth_fps {
            c.eth_fps = v;
        }
        Ok(c)
    }
}
