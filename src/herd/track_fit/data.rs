//! The tracked animals a track fit learns from, frame by frame, in the clip's coordinates (body
//! lengths, y up, the clip's frame numbers): what `synth` writes as `trajectories.csv` and
//! `import-tracks` as `tracks.csv`.
//!
//! Trackers lose animals: a row whose position is `NaN` (or empty) is an untracked frame of that
//! animal, a frame with no row likewise; the animal keeps every other frame. Velocities are read
//! from positions where a window needs them without looking ahead ([`TrackSet::back_vel`]), and
//! from the file (or the step into the frame) where they only orient a replayed neighbour.

use crate::data::tracks::{Tracks, Units};
use crate::error::{Error, Result};
use herdfit_kernels::P2;
use std::ops::Range;
use std::path::{Path, PathBuf};

/// Frames a tracks file may number (a track set holds one list per frame).
pub const MAX_FRAMES: usize = 10_000_000;

/// One animal in one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fix {
    pub id: u64,
    pub pos: P2,
    /// The file's velocity (BL/s), when it has one.
    pub vel: Option<P2>,
}

/// The tracked animals of one clip, frame by frame.
#[derive(Clone, Debug, PartialEq)]
pub struct TrackSet {
    /// Frames per second of the clip.
    pub fps: f64,
    /// `frames[f]`: the animals tracked in clip frame `f`, ordered by id.
    pub frames: Vec<Vec<Fix>>,
    /// Rows left out for a missing position or velocity.
    pub missing_rows: usize,
    /// Where the tracks came from (empty for tracks built in memory).
    pub path: PathBuf,
}

impl TrackSet {
    /// Tracks built in memory: `frames[f]` are the animals of frame `f` (any order).
    pub fn new(fps: f64, mut frames: Vec<Vec<Fix>>) -> Self {
        for f in &mut frames {
            f.sort_by_key(|a| a.id);
        }
        TrackSet {
            fps,
            frames,
            missing_rows: 0,
            path: PathBuf::new(),
        }
    }

    /// Reads a `herdfit.tracks/1` CSV in body lengths, at the clip's `fps` (else the file's own).
    /// `clip_frames` (a clip's frame count) bounds the frame numbers. Errors name the file: other
    /// units, 3D tracks, frames out of order, a frame past the clip, a file whose every position
    /// is missing.
    pub fn load(path: &Path, fps: Option<f64>, clip_frames: Option<usize>) -> Result<TrackSet> {
        let (t, missing) = Tracks::load_with_gaps(path)?;
        let bad = |what: String| Error::file(path, what);
        if t.meta.units != Units::BodyLengths {
            return Err(bad(format!(
                "the tracks are in {}: a track fit reads the clip's body lengths (import the file \
                 with import-tracks, which writes the clip's tracks.csv)",
                t.meta.units.as_str()
            )));
        }
        if t.meta.dimension != 2 {
            return Err(bad("the tracks are 3D: the herd model is 2D".into()));
        }
        let last = t.rows.last().map_or(0, |r| r.frame) as usize;
        if let Some(n) = clip_frames.filter(|&n| last >= n) {
            return Err(bad(format!(
                "frame {last} is past the clip's {n} frames (the tracks' frames are the clip's)"
            )));
        }
        if last >= MAX_FRAMES {
            return Err(bad(format!(
                "frame {last} is beyond the {MAX_FRAMES} frames a track fit reads"
            )));
        }
        let mut frames = vec![Vec::new(); clip_frames.unwrap_or(last + 1)];
        for r in &t.rows {
            frames[r.frame as usize].push(Fix {
                id: r.id,
                pos: [r.pos[0], r.pos[1]],
                vel: r.vel.map(|v| [v[0], v[1]]),
            });
        }
        let mut set = TrackSet::new(fps.unwrap_or(t.meta.fps), frames);
        set.missing_rows = missing;
        set.path = path.to_path_buf();
        Ok(set)
    }

    /// Number of frames.
    pub fn len(&self) -> usize {
        self.frames.len()
    }

    /// Whether no frame is held.
    pub fn is_empty(&self) -> bool {
        self.frames.is_empty()
    }

    /// The animals of frame `f` (none outside the tracks).
    pub fn at(&self, f: usize) -> &[Fix] {
        self.frames.get(f).map_or(&[], Vec::as_slice)
    }

    /// Animal `id` in frame `f`.
    pub fn fix(&self, f: usize, id: u64) -> Option<&Fix> {
        let row = self.at(f);
        row.binary_search_by_key(&id, |a| a.id)
            .ok()
            .map(|i| &row[i])
    }

    /// Position of animal `id` in frame `f`.
    pub fn pos(&self, f: usize, id: u64) -> Option<P2> {
        self.fix(f, id).map(|a| a.pos)
    }

    /// The velocity of `id` arriving at frame `f`, (p(f) − p(f − 1)) · fps: what the model's step
    /// into frame `f` produced (eq. 2 and 6: p' = p + Δt v' d'), read without looking past `f`.
    pub fn back_vel(&self, f: usize, id: u64) -> Option<P2> {
        let (a, b) = (self.pos(f.checked_sub(1)?, id)?, self.pos(f, id)?);
        Some([(b[0] - a[0]) * self.fps, (b[1] - a[1]) * self.fps])
    }

    /// The unit heading of `id` in frame `f` for a replayed neighbour: the file's velocity, else
    /// the step into `f` (the model's own heading after that step, eq. 2), else the step out of
    /// it where `f − 1` is untracked; +x for an animal that does not move.
    pub fn heading(&self, f: usize, id: u64) -> P2 {
        let v = self
            .fix(f, id)
            .and_then(|a| a.vel)
            .or_else(|| self.back_vel(f, id))
            .or_else(|| self.back_vel(f + 1, id))
            .unwrap_or([0.0; 2]);
        unit(v).unwrap_or([1.0, 0.0])
    }

    /// The distinct ids tracked in `frames`.
    pub fn ids_in(&self, frames: Range<usize>) -> Vec<u64> {
        let mut ids: Vec<u64> = frames
            .flat_map(|f| self.at(f).iter().map(|a| a.id))
            .collect();
        ids.sort_unstable();
        ids.dedup();
        ids
    }

    /// Checks that `frames` can be learnt from: two or more animals, and some frame with an
    /// animal tracked in it and the frame before (a window's start). Errors name the file.
    pub fn check_frames(&self, frames: Range<usize>) -> Result<()> {
        let here = |msg: String| match self.path.as_os_str().is_empty() {
            true => Error::invalid(msg),
            false => Error::file(&self.path, msg),
        };
        let ids = self.ids_in(frames.clone());
        match ids.as_slice() {
            [] => {
                return Err(here(format!(
                    "no tracked animal in frames {}..{}",
                    frames.start, frames.end
                )))
            }
            [one] => {
                return Err(here(format!(
                    "one animal (id {one}) in frames {}..{}: the track objective learns how \
                     animals respond to each other and needs two or more",
                    frames.start, frames.end
                )))
            }
            _ => {}
        }
        let startable = (frames.start + 1..frames.end.saturating_sub(1))
            .any(|f| self.at(f).iter().any(|a| self.back_vel(f, a.id).is_some()));
        if !startable {
            return Err(here(format!(
                "no animal is tracked in two consecutive frames of {}..{}: no window can start",
                frames.start, frames.end
            )));
        }
        Ok(())
    }
}

/// `v / |v|`, or `None` for a (near) zero vector.
pub fn unit(v: P2) -> Option<P2> {
    let l = (v[0] * v[0] + v[1] * v[1]).sqrt();
    (l > 1e-12 && l.is_finite()).then(|| [v[0] / l, v[1] / l])
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fix(id: u64, x: f64, y: f64) -> Fix {
        Fix {
            id,
            pos: [x, y],
            vel: None,
        }
    }

    #[test]
    fn velocities_look_back_and_headings_fill_gaps() {
        // Animal 1 in frames 0, 1, 3 (lost in frame 2); animal 2 in every frame.
        let t = TrackSet::new(
            10.0,
            vec![
                vec![fix(2, 0.0, 0.0), fix(1, 0.0, 1.0)],
                vec![fix(1, 0.1, 1.0), fix(2, 0.0, 0.2)],
                vec![fix(2, 0.0, 0.4)],
                vec![fix(1, 0.3, 1.0), fix(2, 0.0, 0.6)],
                vec![fix(1, 0.3, 1.1)],
            ],
        );
        let v = t.back_vel(1, 1).unwrap();
        assert!((v[0] - 1.0).abs() < 1e-12 && v[1].abs() < 1e-12);
        assert_eq!(t.back_vel(3, 1), None, "no look across the gap");
        assert_eq!(t.back_vel(0, 2), None);
        let h = t.heading(2, 2);
        assert!((h[1] - 1.0).abs() < 1e-12, "the step into the frame");
        let h = t.heading(3, 1);
        assert!(
            (h[1] - 1.0).abs() < 1e-12,
            "one-sided where the other side is lost"
        );
        assert_eq!(t.ids_in(2..3), vec![2]);
        assert!(t.check_frames(0..5).is_ok());
        let one = t.check_frames(2..3).unwrap_err().to_string();
        assert!(one.contains("one animal (id 2)"), "{one}");
    }
}
