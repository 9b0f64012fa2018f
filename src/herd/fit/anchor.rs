//! Fits anchored on tracked animals (`fit --tracks`): every window starts from the animals a tracks
//! file holds at its first frame instead of the herd carried over from the previous window.
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

use super::FitConfig;
use crate::data::agents::AgentRow;
use crate::data::tracks::{Tracks, Units};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use std::collections::BTreeMap;
use std::ops::Range;
use std::path::Path;

/// The tracked animals of one clip, frame by frame (clip frame → rows ordered by id).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Anchors {
    frames: BTreeMap<usize, Vec<AgentRow>>,
}

impl Anchors {
    /// Reads `path` for `clip`, whose frames `frames` are fitted. Errors name the file: units
    /// other than body lengths, no velocity columns, a frame past the clip's last, or no tracked
    /// animal in the fitted frames.
    pub fn load(path: &Path, clip: &ClipFields, frames: Range<usize>) -> Result<Anchors> {
        let t = Tracks::load(path)?;
        let bad = |what: String| Error::file(path, what);
        if t.meta.units != Units::BodyLengths {
            return Err(bad(format!(
                "the tracks are in {}: a fit's tracks are in the clip's body lengths (as synth \
                 and import-tracks write them)",
                t.meta.units.as_str()
            )));
        }
        if t.meta.dimension != 2 {
            return Err(bad("the tracks are 3D: a fit's tracks are 2D".into()));
        }
        let n = clip.frames();
        let mut out = Anchors::default();
        for r in &t.rows {
            let f = r.frame as usize;
            if f >= n {
                return Err(bad(format!(
                    "frame {} is past the clip's {n} frames (the tracks' frames are the clip's)",
                    r.frame
                )));
            }
            let v = r.vel.ok_or_else(|| {
                bad("no vx, vy columns: the tracked velocities start each window".into())
            })?;
            out.frames.entry(f).or_default().push(AgentRow {
                id: r.id,
                x: r.pos[0],
                y: r.pos[1],
                vx: v[0],
                vy: v[1],
            });
        }
        if out.frames.range(frames.clone()).next().is_none() {
            return Err(bad(format!(
                "no tracked animal in the fitted frames {}..{}",
                frames.start, frames.end
            )));
        }
        Ok(out)
    }

    /// The animals tracked in clip frame `f`, if any.
    pub fn at(&self, f: usize) -> Option<&[AgentRow]> {
        self.frames
            .get(&f)
            .map(Vec::as_slice)
            .filter(|r| !r.is_empty())
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
