//! Tracked animals as starting herds (`fit --tracks`, `validate --tracks`): a fit's every window,
//! and a validation's every run, starts from the animals a tracks file holds at its first frame
//! instead of a herd drawn from the fields.
//!
//! A fit from fields alone draws its herd from the clip's density and velocity fields and carries
//! it from window to window through population control (§6.1). On a synthetic clip the fit's
//! objective then ranks the generating set *below* sets that organise such a drawn herd into the
//! clip's fields (RESULTS §8, session 42), so no optimiser recovers it. Started from the tracked
//! animals, each window asks what the paper's step (eq. 2–6) does with the herd that was really
//! there, and the generating set is the objective's minimum again. The loss is the fit's own
//! (fields, paper or ensemble), the perception, roles and speed noise are the model's.
//!
//! The tracks are a `herdfit.tracks/1` CSV in the clip's coordinates and frames: body lengths, y
//! up, `frame` the clip's frame index, velocities `vx, vy` in BL/s — what `synth` writes as
//! `trajectories.csv` and `import-tracks` as `tracks.csv`.

use crate::data::agents::AgentRow;
use crate::data::tracks::{Tracks, Units};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};
use std::time::SystemTime;

/// Tracked animals by clip frame (rows ordered by id).
type ByFrame = BTreeMap<usize, Vec<AgentRow>>;

/// The tracked animals of one clip, frame by frame.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Anchors {
    frames: Arc<ByFrame>,
}

impl Anchors {
    /// Reads `path` for `clip`, whose frames `frames` are fitted. Errors name the file: units
    /// other than body lengths, no velocity columns, a frame past the clip's last, or no tracked
    /// animal in the fitted frames.
    pub fn load(path: &Path, clip: &ClipFields, frames: Range<usize>) -> Result<Anchors> {
        let by_frame = parsed(path)?;
        let n = clip.frames();
        if let Some((&last, _)) = by_frame.last_key_value().filter(|(&f, _)| f >= n) {
            return Err(Error::file(
                path,
                format!(
                    "frame {last} is past the clip's {n} frames (the tracks' frames are the clip's)"
                ),
            ));
        }
        if by_frame.range(frames.clone()).next().is_none() {
            return Err(Error::file(
                path,
                format!(
                    "no tracked animal in the fitted frames {}..{}",
                    frames.start, frames.end
                ),
            ));
        }
        Ok(Anchors { frames: by_frame })
    }

    /// The animals tracked in clip frame `f`, if any.
    pub fn at(&self, f: usize) -> Option<&[AgentRow]> {
        self.frames
            .get(&f)
            .map(Vec::as_slice)
            .filter(|r| !r.is_empty())
    }
}

/// The rows of a tracks file by frame, parsed once per process for each version of the file (its
/// path, modification time and length): a fit makes many runs over the same clip — the start's
/// and the fitted set's losses, the identifiability probes, the global phase's candidates, the
/// evaluation — and each would otherwise read the whole file again.
fn parsed(path: &Path) -> Result<Arc<ByFrame>> {
    type Key = (PathBuf, Option<SystemTime>, u64);
    static PARSED: Mutex<Vec<(Key, Arc<ByFrame>)>> = Mutex::new(Vec::new());
    let meta = std::fs::metadata(path).ok();
    let key: Key = (
        path.to_path_buf(),
        meta.as_ref().and_then(|m| m.modified().ok()),
        meta.as_ref().map_or(0, |m| m.len()),
    );
    if let Some((_, m)) = PARSED
        .lock()
        .unwrap_or_else(|e| e.into_inner())
        .iter()
        .find(|(k, _)| *k == key)
    {
        return Ok(m.clone());
    }
    let t = Tracks::load(path)?;
    let bad = |what: String| Error::file(path, what);
    if t.meta.units != Units::BodyLengths {
        return Err(bad(format!(
            "the tracks are in {}: a fit's tracks are in the clip's body lengths (as synth and \
             import-tracks write them)",
            t.meta.units.as_str()
        )));
    }
    if t.meta.dimension != 2 {
        return Err(bad("the tracks are 3D: a fit's tracks are 2D".into()));
    }
    let mut by_frame = ByFrame::new();
    for r in &t.rows {
        let v = r.vel.ok_or_else(|| {
            bad("no vx, vy columns: the tracked velocities start each window".into())
        })?;
        by_frame
            .entry(r.frame as usize)
            .or_default()
            .push(AgentRow {
                id: r.id,
                x: r.pos[0],
                y: r.pos[1],
                vx: v[0],
                vy: v[1],
            });
    }
    let by_frame = Arc::new(by_frame);
    let mut cache = PARSED.lock().unwrap_or_else(|e| e.into_inner());
    cache.retain(|(k, _)| k.0 != key.0);
    cache.push((key, by_frame.clone()));
    Ok(by_frame)
}
