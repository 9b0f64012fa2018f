//! Stage 1: 2D tracks + camera → the table every lifting method works on (thesis §3.1): one
//! observation p_n^f per bird and frame, its viewing ray, and the links to the same bird in the
//! previous and next frames. Tracks may start and end anywhere; a gap in a bird's frames starts a
//! new segment (no velocity is read across it).

use crate::data::camera::Camera;
use crate::data::tracks::{TrackRow, Tracks, TracksMeta, Units};
use crate::error::{Error, Result};
use std::ops::Range;

/// The observations of a lifting problem, in the tracks' row order (by frame, then id).
#[derive(Clone, Debug)]
pub struct Observations {
    pub camera: Camera,
    /// Frames per second of the tracks.
    pub fps: f64,
    pub frame: Vec<u64>,
    pub time: Vec<f64>,
    pub id: Vec<u64>,
    /// Pixel positions (top-left origin, y down).
    pub pixel: Vec<[f64; 2]>,
    /// World direction of each pixel, scaled to unit depth: the bird is at `C + d · ray`.
    pub ray: Vec<[f64; 3]>,
    /// The same bird in frame − 1 (same segment), if tracked there.
    pub prev: Vec<Option<usize>>,
    /// The same bird in frame + 1, if tracked there.
    pub next: Vec<Option<usize>>,
    /// Frames in order: frame number and the range of its observations.
    pub frames: Vec<(u64, Range<usize>)>,
    /// The distinct bird ids.
    pub birds: usize,
}

impl Observations {
    /// Builds the table from 2D pixel tracks seen by `camera`. Errors (naming the row) when the
    /// tracks are not 2D pixels, a point lies outside the image, or fewer than two birds are
    /// tracked (a flock term needs a flock).
    pub fn new(tracks: &Tracks, camera: &Camera) -> Result<Self> {
        camera.check()?;
        let m = &tracks.meta;
        if m.dimension != 2 || m.units != Units::Pixels {
            return Err(Error::invalid(format!(
                "tracks are {}D in '{}': lifting needs 2D tracks in pixels (dimension 2, units px)",
                m.dimension,
                m.units.as_str()
            )));
        }
        let ids = tracks.ids();
        if ids.len() < 2 {
            return Err(Error::invalid(format!(
                "only one bird (id {}) is tracked: lifting needs a flock of at least 2",
                ids.first().copied().unwrap_or(0)
            )));
        }
        let n = tracks.rows.len();
        let mut pixel = Vec::with_capacity(n);
        let mut ray = Vec::with_capacity(n);
        for (i, r) in tracks.rows.iter().enumerate() {
            let p = [r.pos[0], r.pos[1]];
            if !camera.in_image(p) {
                return Err(Error::invalid(format!(
                    "row {} (frame {}, id {}): ({}, {}) px lies outside the {} × {} image of the camera",
                    i + 1,
                    r.frame,
                    r.id,
                    p[0],
                    p[1],
                    camera.width,
                    camera.height
                )));
            }
            pixel.push(p);
            ray.push(camera.ray(p));
        }
        let mut prev = vec![None; n];
        let mut next = vec![None; n];
        for rows in tracks.by_id().values() {
            for w in rows.windows(2) {
                if tracks.rows[w[1]].frame == tracks.rows[w[0]].frame + 1 {
                    prev[w[1]] = Some(w[0]);
                    next[w[0]] = Some(w[1]);
                }
            }
        }
        Ok(Observations {
            camera: camera.clone(),
            fps: m.fps,
            frame: tracks.rows.iter().map(|r| r.frame).collect(),
            time: tracks.rows.iter().map(|r| r.time).collect(),
            id: tracks.rows.iter().map(|r| r.id).collect(),
            pixel,
            ray,
            prev,
            next,
            frames: tracks.frames(),
            birds: ids.len(),
        })
    }

    /// Number of observations.
    pub fn len(&self) -> usize {
        self.pixel.len()
    }

    /// Whether there are none (never, for a checked table).
    pub fn is_empty(&self) -> bool {
        self.pixel.is_empty()
    }

    /// World position of observation `i` at depth `d` (thesis eq. 1.1).
    pub fn position(&self, i: usize, d: f64) -> [f64; 3] {
        let c = self.camera.position;
        let r = self.ray[i];
        [c[0] + d * r[0], c[1] + d * r[1], c[2] + d * r[2]]
    }

    /// All positions for depths `d`.
    pub fn positions(&self, d: &[f64]) -> Vec<[f64; 3]> {
        (0..self.len()).map(|i| self.position(i, d[i])).collect()
    }

    /// 3D tracks (world units of the camera, z up) for depths `d`, with velocities by central
    /// differences inside a segment and one-sided ones at its ends (zero for a single frame).
    pub fn tracks_3d(&self, d: &[f64], provenance: serde_json::Value) -> Result<Tracks> {
        let b = self.positions(d);
        let rows = (0..self.len())
            .map(|i| {
                let (a, z, steps) = match (self.prev[i], self.next[i]) {
                    (Some(p), Some(q)) => (p, q, 2.0),
                    (Some(p), None) => (p, i, 1.0),
                    (None, Some(q)) => (i, q, 1.0),
                    (None, None) => (i, i, 1.0),
                };
                let k = self.fps / steps;
                TrackRow {
                    frame: self.frame[i],
                    time: self.time[i],
                    id: self.id[i],
                    pos: b[i],
                    vel: Some([
                        (b[z][0] - b[a][0]) * k,
                        (b[z][1] - b[a][1]) * k,
                        (b[z][2] - b[a][2]) * k,
                    ]),
                    role: None,
                }
            })
            .collect();
        let mut meta = TracksMeta::new(self.camera.units, self.fps, 3);
        meta.provenance = provenance;
        Tracks::new(meta, rows)
    }

    /// The largest distance (px) between the projection of the 3D points for depths `d` and the
    /// tracked pixels.
    pub fn reprojection_error(&self, points: &[[f64; 3]]) -> f64 {
        points
            .iter()
            .zip(&self.pixel)
            .map(|(x, p)| match self.camera.project(*x) {
                Some((q, _)) => (q[0] - p[0]).hypot(q[1] - p[1]),
                None => f64::INFINITY,
            })
            .fold(0.0, f64::max)
    }
}

/// 2D pixel tracks of 3D tracks seen through `camera` (the virtual camera of the evaluation and of
/// the synthetic flock): every row is kept when `crop` is false (a point outside the image or
/// behind the camera is then an error naming the row); with `crop`, such points are dropped, so
/// birds leave and enter the view. Returns the tracks and, per kept row, its true depth.
pub fn project_tracks(tracks: &Tracks, camera: &Camera, crop: bool) -> Result<(Tracks, Vec<f64>)> {
    camera.check()?;
    if tracks.meta.dimension != 3 {
        return Err(Error::invalid(format!(
            "tracks are {}D: projecting needs 3D tracks",
            tracks.meta.dimension
        )));
    }
    if tracks.meta.units != camera.units {
        return Err(Error::invalid(format!(
            "tracks are in '{}' but the camera in '{}'",
            tracks.meta.units.as_str(),
            camera.units.as_str()
        )));
    }
    let mut rows = Vec::with_capacity(tracks.rows.len());
    let mut depth = Vec::with_capacity(tracks.rows.len());
    for (i, r) in tracks.rows.iter().enumerate() {
        let seen = camera.project(r.pos).filter(|(p, _)| camera.in_image(*p));
        match seen {
            Some((p, d)) => {
                rows.push(TrackRow {
                    frame: r.frame,
                    time: r.time,
                    id: r.id,
                    pos: [p[0], p[1], 0.0],
                    vel: None,
                    role: None,
                });
                depth.push(d);
            }
            None if crop => {}
            None => {
                return Err(Error::invalid(format!(
                    "row {} (frame {}, id {}): the point is outside the camera's view",
                    i + 1,
                    r.frame,
                    r.id
                )))
            }
        }
    }
    if rows.is_empty() {
        return Err(Error::invalid(
            "no point of the tracks is in the camera's view",
        ));
    }
    let mut meta = TracksMeta::new(Units::Pixels, tracks.meta.fps, 2);
    meta.provenance = serde_json::json!({
        "projected_from": tracks.meta.provenance,
        "camera": camera,
        "crop": crop,
    });
    // Rows keep their (frame, id) order.
    Ok((Tracks::new(meta, rows)?, depth))
}
