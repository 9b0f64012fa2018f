//! Fits anchored on tracked animals (`fit --tracks`, [`crate::herd::anchors`]): the anchors of a
//! fit's clips, and how its provenance says where its runs start.

use super::FitConfig;
use crate::data::ClipFields;
use crate::error::{Error, Result};
pub use crate::herd::anchors::Anchors;

/// Where the evaluation's runs of a fit with `cfg` start, as its provenance says it.
pub fn runs_start_from(cfg: &FitConfig) -> &'static str {
    match cfg.tracks.is_empty() {
        true => "the first frame's fields",
        false => "the animals tracked in the first frame",
    }
}

/// The anchors of every clip of a fit from `cfg.tracks` (none when it is empty; otherwise one
/// file per clip, in clip order, or an error naming `tracks`).
pub fn load_all(cfg: &FitConfig, clips: &[&ClipFields]) -> Result<Vec<Option<Anchors>>> {
    if cfg.tracks.is_empty() {
        return Ok(vec![None; clips.len()]);
    }
    if cfg.tracks.len() != clips.len() {
        return Err(Error::config(
            "tracks",
            format!(
                "{} tracks files for {} clips: give one per clip, in clip order",
                cfg.tracks.len(),
                clips.len()
            ),
        ));
    }
    clips
        .iter()
        .zip(&cfg.tracks)
        .map(|(c, p)| Anchors::load(p, c, cfg.frames.clone()).map(Some))
        .collect()
}
