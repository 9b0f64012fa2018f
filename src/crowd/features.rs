//! Tracks as per-agent segments, Gaussian smoothing (§3) and the state features of §4: self speed,
//! the neighbourhood formation of eq. 1 at the current and previous frame, the pivot in the
//! agent's frame and the intended moving direction, each weighted as in Table 1.

use crate::data::tracks::Tracks;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};

/// A 2-D vector (position, velocity, direction).
pub type V2 = [f64; 2];

/// Number of radial sectors of the neighbourhood formation (§4, Figure 2).
pub const SECTORS: usize = 8;

/// How the intended moving direction of a training sample is averaged (§4: "a window of past and
/// future frames"). At prediction and simulation time only past frames (or a goal) exist.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum IntentWindow {
    /// Past and future frames, centred on the sample (the paper's choice when learning).
    Centred,
    /// The `intent_window` frames up to the sample, as at prediction time.
    Past,
    /// Not the paper's: the velocity that takes the individual from where it is to where it leaves
    /// the scene when it leaves it, (exit − p)/(time left), in its own frame (units/s). In
    /// simulation the agent's goal and its time to leave (`crowd simulate --entries`: where and
    /// when the real one left) give the same vector, so the feature means the same when learnt
    /// and when used, where the paper's one-second window of past and future frames is replaced
    /// by the direction to the goal; and an agent that stands until it leaves (goal at hand,
    /// much time left) sees a small vector, as the standing people it learnt from did.
    Exit,
}

/// Feature weights of Table 1. A weight scales the squared distance between two states in that
/// feature (each feature value is multiplied by √w before PCA), so "formation 100" makes a unit
/// change in a sector count 100 times a unit change in speed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeatureWeights {
    pub speed: f64,
    pub formation: f64,
    pub pivot: f64,
    pub direction: f64,
    /// Not in Table 1: the weight of the neighbours' headings ([`alignment`]). The paper's
    /// pedestrians need no such feature, but agents that align (the Reynolds imitation of §7) turn
    /// toward their neighbours' headings, which eq. 1's positions alone do not show. 0 (the
    /// default) leaves the feature out of the state altogether.
    #[serde(skip_serializing_if = "is_zero")]
    pub alignment: f64,
}

pub(crate) fn is_zero(v: &f64) -> bool {
    *v == 0.0
}

impl FeatureWeights {
    /// Whether the state holds the alignment feature (its weight is > 0).
    pub fn aligns(&self) -> bool {
        self.alignment > 0.0
    }
}

impl Default for FeatureWeights {
    /// Table 1's "Locomotion" row (speed 1, formation 100, pivot 0, direction 1).
    fn default() -> Self {
        FeatureWeights {
            speed: 1.0,
            formation: 100.0,
            pivot: 0.0,
            direction: 1.0,
            alignment: 0.0,
        }
    }
}

/// Settings of the state features (§4).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct FeatureConfig {
    /// Neighbourhood radius r of eq. 1, in the tracks' length unit (Table 1: 1–2 m).
    pub radius: f64,
    /// Table 1's weights.
    pub weights: FeatureWeights,
    /// Frames averaged into the intended moving direction (§4: one second).
    pub intent_window: usize,
    /// Which frames the training samples average (prediction always uses past frames).
    pub intent: IntentWindow,
    /// Below this speed (units/s) an agent keeps its previous heading.
    pub still_speed: f64,
}

impl Default for FeatureConfig {
    fn default() -> Self {
        FeatureConfig {
            radius: 2.0,
            weights: FeatureWeights::default(),
            intent_window: 4,
            intent: IntentWindow::Centred,
            still_speed: 0.05,
        }
    }
}

impl FeatureConfig {
    /// Checks the values; errors name the key.
    pub fn check(&self) -> Result<()> {
        let pos = |v: f64, key: &str| {
            if v.is_finite() && v > 0.0 {
                Ok(())
            } else {
                Err(Error::invalid(format!("{key} = {v} must be > 0")))
            }
        };
        pos(self.radius, "features.radius")?;
        let w = &self.weights;
        for (v, k) in [
            (w.speed, "speed"),
            (w.formation, "formation"),
            (w.pivot, "pivot"),
            (w.direction, "direction"),
            (w.alignment, "alignment"),
        ] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::invalid(format!(
                    "features.weights.{k} = {v} must be ≥ 0"
                )));
            }
        }
        if self.intent_window == 0 {
            return Err(Error::invalid("features.intent_window must be ≥ 1"));
        }
        if !(self.still_speed.is_finite() && self.still_speed >= 0.0) {
            return Err(Error::invalid(format!(
                "features.still_speed = {} must be ≥ 0",
                self.still_speed
            )));
        }
        Ok(())
    }

    /// Length of the state vector under weights `w`: speed, 2 × 8 sectors, 4 pivot values when
    /// `pivot`, 2 direction, and 2 alignment values when `w.alignment` > 0.
    pub fn dims(pivot: bool, w: &FeatureWeights) -> usize {
        1 + 2 * SECTORS + if pivot { 4 } else { 0 } + 2 + if w.aligns() { 2 } else { 0 }
    }
}

/// One agent's features at one instant, before weighting.
#[derive(Clone, Debug, PartialEq)]
pub struct StateParts {
    /// Self speed (units/s).
    pub speed: f64,
    /// Eq. 1 at the current frame.
    pub now: [f64; SECTORS],
    /// Eq. 1 at the previous frame.
    pub prev: [f64; SECTORS],
    /// Pivot position (x, y) and orientation (cos, sin) in the agent's frame.
    pub pivot: Option<[f64; 4]>,
    /// Intended direction in the agent's frame (cos, sin of its angle to the heading).
    pub intent: V2,
    /// The neighbours' headings ([`alignment`]), computed only when its weight is > 0.
    pub align: Option<V2>,
}

impl StateParts {
    /// The weighted state vector (√w per feature, see [`FeatureWeights`]) appended to `out`.
    pub fn write(&self, w: &FeatureWeights, out: &mut Vec<f64>) {
        let (ws, wf, wp, wd) = (
            w.speed.sqrt(),
            w.formation.sqrt(),
            w.pivot.sqrt(),
            w.direction.sqrt(),
        );
        out.push(ws * self.speed);
        out.extend(self.now.iter().map(|v| wf * v));
        out.extend(self.prev.iter().map(|v| wf * v));
        if let Some(p) = self.pivot {
            out.extend(p.iter().map(|v| wp * v));
        }
        out.push(wd * self.intent[0]);
        out.push(wd * self.intent[1]);
        if w.aligns() {
            let wa = w.alignment.sqrt();
            let a = self.align.unwrap_or([0.0, 0.0]);
            out.push(wa * a[0]);
            out.push(wa * a[1]);
        }
    }
}

/// `v` in the frame whose x axis is the unit vector `h` (y axis: `h` turned left).
pub fn to_local(v: V2, h: V2) -> V2 {
    [v[0] * h[0] + v[1] * h[1], -v[0] * h[1] + v[1] * h[0]]
}

/// The world vector of local `v` in the frame of unit `h` (inverse of [`to_local`]).
pub fn to_world(v: V2, h: V2) -> V2 {
    [v[0] * h[0] - v[1] * h[1], v[0] * h[1] + v[1] * h[0]]
}

/// The unit vector of `v`, or `None` when it is (nearly) zero.
pub fn unit(v: V2) -> Option<V2> {
    let l = v[0].hypot(v[1]);
    (l > 1e-12).then(|| [v[0] / l, v[1] / l])
}

/// Sector of a neighbour at local offset `d` (sector 0 straight ahead, counter-clockwise, each
/// 45° wide and centred on its direction).
pub fn sector(d: V2) -> usize {
    let a = d[1].atan2(d[0]) + std::f64::consts::PI / SECTORS as f64;
    let s =
        (a.rem_euclid(std::f64::consts::TAU) / (std::f64::consts::TAU / SECTORS as f64)) as usize;
    s.min(SECTORS - 1)
}

/// Eq. 1: in each sector, f = (r − d)²/r² for the nearest neighbour at distance d < r, else 0.
/// `frame` is the unit x axis of the sectors (the heading, or the pivot's orientation).
pub fn formation(p: V2, frame: V2, neighbours: impl Iterator<Item = V2>, r: f64) -> [f64; SECTORS] {
    let mut nearest = [f64::INFINITY; SECTORS];
    for q in neighbours {
        let d = [q[0] - p[0], q[1] - p[1]];
        let dist = d[0].hypot(d[1]);
        if dist >= r || dist <= 0.0 {
            continue;
        }
        let s = sector(to_local(d, frame));
        nearest[s] = nearest[s].min(dist);
    }
    nearest.map(|d| if d < r { eq1(d, r) } else { 0.0 })
}

/// Eq. 1's weight of a neighbour at distance `d` < `r`: (r − d)²/r².
#[inline]
fn eq1(d: f64, r: f64) -> f64 {
    (r - d) * (r - d) / (r * r)
}

/// The neighbours' headings in the frame of an agent at `p` heading `h`: Σ f_j ĥ_j over the
/// neighbours j within `r`, with eq. 1's weight f_j = (r − d_j)²/r², so a neighbour enters the
/// sum continuously at the radius. `neighbours` yields (position, unit heading). An extension of
/// §4 (see [`FeatureWeights::alignment`]).
pub fn alignment(p: V2, h: V2, neighbours: impl Iterator<Item = (V2, V2)>, r: f64) -> V2 {
    let mut s = [0.0, 0.0];
    for (q, hq) in neighbours {
        let dist = (q[0] - p[0]).hypot(q[1] - p[1]);
        if dist >= r || dist <= 0.0 {
            continue;
        }
        let f = eq1(dist, r);
        s[0] += f * hq[0];
        s[1] += f * hq[1];
    }
    to_local(s, h)
}

/// One tracked individual over consecutive frames (a track with a gap becomes two segments).
#[derive(Clone, Debug, PartialEq)]
pub struct Segment {
    pub id: u64,
    /// Index of its first frame in the scene.
    pub start: usize,
    pub pos: Vec<V2>,
}

impl Segment {
    /// Position at scene frame `f`, if the segment covers it.
    pub fn at(&self, f: usize) -> Option<V2> {
        f.checked_sub(self.start)
            .and_then(|j| self.pos.get(j).copied())
    }
    /// One past the last frame covered.
    pub fn end(&self) -> usize {
        self.start + self.pos.len()
    }
}

/// Tracks laid out for feature extraction: segments of consecutive frames and, per frame, the
/// segments present.
#[derive(Clone, Debug, PartialEq)]
pub struct Scene {
    /// Seconds per frame.
    pub dt: f64,
    /// The tracks' first frame number.
    pub first_frame: u64,
    pub segments: Vec<Segment>,
    /// Segment indices present at each frame.
    pub at_frame: Vec<Vec<usize>>,
}

impl Scene {
    /// Lays out 2-D tracks, smoothing each segment with a Gaussian of `sigma` frames (§3; 0: raw).
    /// Errors: 3-D tracks, fewer than two individuals.
    pub fn from_tracks(t: &Tracks, sigma: f64) -> Result<Scene> {
        t.check()?;
        if t.meta.dimension != 2 {
            return Err(Error::invalid("crowd tracks must be 2-D (dimension = 2)"));
        }
        let ids = t.ids();
        if ids.len() < 2 {
            return Err(Error::invalid(format!(
                "the tracks hold {} individual{}; a crowd needs at least 2",
                ids.len(),
                if ids.len() == 1 { "" } else { "s" }
            )));
        }
        let first = t.rows.first().map_or(0, |r| r.frame);
        let last = t.rows.last().map_or(0, |r| r.frame);
        let n_frames = (last - first) as usize + 1;
        let mut segments = Vec::new();
        for (id, rows) in t.by_id() {
            let mut cur: Option<Segment> = None;
            for &i in &rows {
                let r = &t.rows[i];
                let f = (r.frame - first) as usize;
                match &mut cur {
                    Some(s) if s.end() == f => s.pos.push([r.pos[0], r.pos[1]]),
                    _ => {
                        segments.extend(cur.take());
                        cur = Some(Segment {
                            id,
                            start: f,
                            pos: vec![[r.pos[0], r.pos[1]]],
                        });
                    }
                }
            }
            segments.extend(cur);
        }
        if sigma > 0.0 {
            for s in &mut segments {
                s.pos = smooth(&s.pos, sigma);
            }
        }
        let mut at_frame = vec![Vec::new(); n_frames];
        for (k, s) in segments.iter().enumerate() {
            for at in &mut at_frame[s.start..s.end()] {
                at.push(k);
            }
        }
        Ok(Scene {
            dt: 1.0 / t.meta.fps,
            first_frame: first,
            segments,
            at_frame,
        })
    }

    /// Number of frames.
    pub fn frames(&self) -> usize {
        self.at_frame.len()
    }

    /// Positions of the other segments present at frame `f`.
    pub fn others(&self, f: usize, me: usize) -> impl Iterator<Item = V2> + '_ {
        self.at_frame[f]
            .iter()
            .filter(move |&&k| k != me)
            .filter_map(move |&k| self.segments[k].at(f))
    }

    /// Positions and headings (`heads[k]`: segment k's, from [`headings`]) of the other segments
    /// present at frame `f`.
    pub fn others_headed<'a>(
        &'a self,
        f: usize,
        me: usize,
        heads: &'a [Vec<V2>],
    ) -> impl Iterator<Item = (V2, V2)> + 'a {
        self.at_frame[f]
            .iter()
            .filter(move |&&k| k != me)
            .filter_map(move |&k| {
                let s = &self.segments[k];
                s.at(f).map(|p| (p, heads[k][f - s.start]))
            })
    }
}

/// Gaussian smoothing of a path with σ = `sigma` samples, the kernel truncated at 3σ and
/// renormalised at the ends.
pub fn smooth(p: &[V2], sigma: f64) -> Vec<V2> {
    let h = (3.0 * sigma).ceil() as isize;
    let w: Vec<f64> = (-h..=h)
        .map(|k| (-0.5 * (k as f64 / sigma).powi(2)).exp())
        .collect();
    (0..p.len() as isize)
        .map(|i| {
            let (mut s, mut sw) = ([0.0, 0.0], 0.0);
            for k in -h..=h {
                let j = i + k;
                if j >= 0 && (j as usize) < p.len() {
                    let wk = w[(k + h) as usize];
                    s[0] += wk * p[j as usize][0];
                    s[1] += wk * p[j as usize][1];
                    sw += wk;
                }
            }
            [s[0] / sw, s[1] / sw]
        })
        .collect()
}

/// Headings along a path: the direction of the last displacement faster than `still` (units per
/// frame), else the previous heading; before the first such displacement, the first one's
/// direction (+x for a path that never moves).
pub fn headings(p: &[V2], still: f64) -> Vec<V2> {
    let dir = |j: usize| {
        let d = [p[j][0] - p[j - 1][0], p[j][1] - p[j - 1][1]];
        (d[0].hypot(d[1]) > still).then(|| unit(d)).flatten()
    };
    let first = (1..p.len()).find_map(dir).unwrap_or([1.0, 0.0]);
    let mut out = Vec::with_capacity(p.len());
    let mut h = first;
    for j in 0..p.len() {
        if j > 0 {
            if let Some(d) = dir(j) {
                h = d;
            }
        }
        out.push(h);
    }
    out
}

/// Mean of the unit displacement directions of `p` between indices `a..=b` (displacements
/// j−1 → j for j in a+1..=b), or `None` when none moves.
pub fn mean_direction(p: &[V2], a: usize, b: usize) -> Option<V2> {
    let mut s = [0.0, 0.0];
    for j in a + 1..=b.min(p.len().saturating_sub(1)) {
        if let Some(u) = unit([p[j][0] - p[j - 1][0], p[j][1] - p[j - 1][1]]) {
            s[0] += u[0];
            s[1] += u[1];
        }
    }
    unit(s)
}

/// The intended direction at index `j` of a path: the mean direction over the past `w` frames, or
/// (`centred`) over `w` frames centred on `j`; falls back to `heading`.
pub fn intent_at(p: &[V2], j: usize, w: usize, centred: bool, heading: V2) -> V2 {
    let (a, b) = if centred {
        (j.saturating_sub(w / 2), j + w.div_ceil(2))
    } else {
        (j.saturating_sub(w), j)
    };
    mean_direction(p, a, b).unwrap_or(heading)
}

/// The exit intent ([`IntentWindow::Exit`]) of a path at index `j` (< its last index): the
/// velocity from `p[j]` to the last position over the time left, `dt` per index.
pub fn exit_intent(p: &[V2], j: usize, dt: f64) -> V2 {
    let last = p.len() - 1;
    let t = (last - j) as f64 * dt;
    [(p[last][0] - p[j][0]) / t, (p[last][1] - p[j][1]) / t]
}

/// The pivot's position and orientation in the frame of an agent at `p` heading `h` (§4).
pub fn pivot_parts(p: V2, h: V2, pivot_pos: V2, pivot_dir: V2) -> [f64; 4] {
    let d = to_local([pivot_pos[0] - p[0], pivot_pos[1] - p[1]], h);
    let o = to_local(pivot_dir, h);
    [d[0], d[1], o[0], o[1]]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sectors_are_centred_on_their_direction() {
        assert_eq!(sector([1.0, 0.0]), 0);
        assert_eq!(sector([1.0, 0.3]), 0);
        assert_eq!(sector([1.0, -0.3]), 0);
        assert_eq!(sector([1.0, 1.0]), 1);
        assert_eq!(sector([0.0, 1.0]), 2);
        assert_eq!(sector([-1.0, 0.0]), 4);
        assert_eq!(sector([0.0, -1.0]), 6);
        assert_eq!(sector([1.0, -1.0]), 7);
    }

    #[test]
    fn smoothing_keeps_a_straight_line_and_damps_noise() {
        let p: Vec<V2> = (0..20).map(|i| [i as f64, 2.0 * i as f64]).collect();
        let s = smooth(&p, 1.5);
        for (a, b) in p.iter().zip(&s).skip(5).take(10) {
            assert!((a[0] - b[0]).abs() < 1e-9 && (a[1] - b[1]).abs() < 1e-9);
        }
        let z: Vec<V2> = (0..20)
            .map(|i| [i as f64, if i % 2 == 0 { 0.5 } else { -0.5 }])
            .collect();
        let s = smooth(&z, 2.0);
        assert!(s[10][1].abs() < 0.01, "{}", s[10][1]);
    }

    #[test]
    fn headings_hold_through_stops() {
        let p = vec![[0.0, 0.0], [0.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 1.0]];
        let h = headings(&p, 1e-6);
        assert_eq!(
            h,
            vec![[1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [1.0, 0.0], [0.0, 1.0]]
        );
        assert_eq!(to_world(to_local([0.3, -2.0], h[4]), h[4]), [0.3, -2.0]);
    }
}
