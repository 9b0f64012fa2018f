//! The environment annotation of §3 and §6.1 (`herdfit.crowd-layout/1`, JSON): walls (polylines),
//! obstacles (polygons), pivot objects with position and orientation, behaviour regions, and the
//! spawns of a simulated scene (entry point, goal, count, timing).

use super::features::V2;
use super::model::Pivot;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema tag of layout files.
pub const LAYOUT_SCHEMA: &str = "herdfit.crowd-layout/1";

/// A named pivot object.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct NamedPivot {
    pub name: String,
    pub position: V2,
    /// Degrees counter-clockwise from +x (a line forms behind the pivot, against this direction).
    pub orientation_deg: f64,
}

impl NamedPivot {
    pub fn pivot(&self) -> Pivot {
        Pivot {
            position: self.position,
            orientation_deg: self.orientation_deg,
        }
    }
}

/// A region whose agents use one behaviour (§6.1: "annotate the environment what behavior models
/// are appropriate in which part").
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Region {
    /// `locomotion`, `interaction` or `line` (a line needs a pivot).
    pub behaviour: String,
    pub polygon: Vec<V2>,
    /// Name of the region's pivot object.
    #[serde(default)]
    pub pivot: Option<String>,
    /// For a `line` region: the probability that an agent entering it joins the line, drawn
    /// once per agent (1, the default: everyone who passes through queues).
    #[serde(default = "always", skip_serializing_if = "is_always")]
    pub join: f64,
}

fn always() -> f64 {
    1.0
}

fn is_always(v: &f64) -> bool {
    *v == 1.0
}

/// Agents entering the scene.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Spawn {
    /// Entry point.
    pub position: V2,
    /// Agents start uniformly within this radius of the entry point.
    #[serde(default)]
    pub spread: f64,
    /// Where they head for; they leave the scene within `arrive` of it.
    pub goal: V2,
    pub count: usize,
    /// Time of the first entry (s).
    #[serde(default)]
    pub start: f64,
    /// Seconds between entries.
    #[serde(default = "one")]
    pub interval: f64,
}

fn one() -> f64 {
    1.0
}

/// A layout file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Layout {
    pub schema: String,
    /// Extent for renders and density maps, [[x0, y0], [x1, y1]] (default: what the agents cover).
    #[serde(default)]
    pub bounds: Option<[V2; 2]>,
    #[serde(default)]
    pub walls: Vec<Vec<V2>>,
    #[serde(default)]
    pub obstacles: Vec<Vec<V2>>,
    #[serde(default)]
    pub pivots: Vec<NamedPivot>,
    #[serde(default)]
    pub regions: Vec<Region>,
    #[serde(default)]
    pub spawns: Vec<Spawn>,
    /// Simulated duration (s) when the layout drives a simulation.
    #[serde(default)]
    pub duration: Option<f64>,
}

impl Default for Layout {
    fn default() -> Self {
        Layout {
            schema: LAYOUT_SCHEMA.into(),
            bounds: None,
            walls: vec![],
            obstacles: vec![],
            pivots: vec![],
            regions: vec![],
            spawns: vec![],
            duration: None,
        }
    }
}

/// Finite points within ±[`MAX_COORD`](crate::limits::MAX_COORD).
fn finite(p: &[V2]) -> bool {
    p.iter()
        .flatten()
        .all(|v| v.is_finite() && v.abs() <= crate::limits::MAX_COORD)
}

impl Layout {
    /// Checks the layout; errors name the key (`obstacles[2]`, `regions[0].pivot`, …).
    pub fn check(&self) -> Result<()> {
        if self.schema != LAYOUT_SCHEMA {
            return Err(Error::invalid(format!(
                "schema is '{}', expected '{LAYOUT_SCHEMA}'",
                self.schema
            )));
        }
        for (i, w) in self.walls.iter().enumerate() {
            if w.len() < 2 || !finite(w) {
                return Err(Error::invalid(format!(
                    "walls[{i}]: a wall needs at least 2 finite points, found {}",
                    w.len()
                )));
            }
        }
        let polygon = |p: &[V2], key: String| match crate::data::polygon::polygon_problem(p) {
            Some(m) => Err(Error::invalid(format!("{key}: {m}"))),
            None => Ok(()),
        };
        for (i, o) in self.obstacles.iter().enumerate() {
            polygon(o, format!("obstacles[{i}]"))?;
        }
        for (i, r) in self.regions.iter().enumerate() {
            polygon(&r.polygon, format!("regions[{i}].polygon"))?;
            if !(0.0..=1.0).contains(&r.join) {
                return Err(Error::invalid(format!(
                    "regions[{i}].join = {} must be a probability in 0..=1",
                    r.join
                )));
            }
            if let Some(n) = &r.pivot {
                if !self.pivots.iter().any(|p| &p.name == n) {
                    return Err(Error::invalid(format!(
                        "regions[{i}].pivot: no pivot named '{n}'"
                    )));
                }
            } else if r.behaviour == super::behaviour::LINE {
                return Err(Error::invalid(format!(
                    "regions[{i}]: a 'line' region needs a pivot (the front of the line)"
                )));
            }
        }
        use crate::limits::{check_count, within, MAX_AGENTS, MAX_COORD, MAX_SECONDS};
        let mut agents = 0usize;
        for (i, s) in self.spawns.iter().enumerate() {
            // Counted before anything is drawn (issue #47: a spawn of 10^9 aborted).
            agents = agents.saturating_add(s.count);
            check_count(&format!("spawns[{i}].count"), s.count, MAX_AGENTS)
                .and_then(|_| check_count("spawns (all counts)", agents, MAX_AGENTS))
                .map_err(|e| Error::invalid(e.to_string()))?;
            within(&format!("spawns[{i}].spread"), s.spread, 0.0, MAX_COORD)?;
            within(&format!("spawns[{i}].start"), s.start, 0.0, MAX_SECONDS)?;
            within(
                &format!("spawns[{i}].interval"),
                s.interval,
                0.0,
                MAX_SECONDS,
            )?;
            let ok = finite(&[s.position, s.goal])
                && s.spread.is_finite()
                && s.spread >= 0.0
                && s.start.is_finite()
                && s.start >= 0.0
                && s.interval.is_finite()
                && s.interval > 0.0;
            if !ok {
                return Err(Error::invalid(format!(
                    "spawns[{i}]: position and goal must be finite, spread and start ≥ 0, interval > 0"
                )));
            }
        }
        if let Some(d) = self.duration {
            if !(d.is_finite() && d > 0.0) {
                return Err(Error::invalid(format!("duration = {d} must be > 0")));
            }
            within("duration", d, 0.0, MAX_SECONDS)?;
        }
        Ok(())
    }

    /// Reads and checks a layout file.
    pub fn load(path: &Path) -> Result<Layout> {
        crate::data::atomic::note_input(path);
        let s = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let l: Layout = serde_json::from_str(&s)
            .map_err(|e| Error::file(path, format!("not a crowd layout: {e}")))?;
        l.check().map_err(|e| e.in_file(path))?;
        Ok(l)
    }

    /// Writes the layout atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        self.check().map_err(|e| e.in_file(path))?;
        let s = serde_json::to_string_pretty(self)
            .map_err(|e| Error::Internal(format!("crowd layout: {e}")))?;
        crate::data::atomic::write_atomic(path, format!("{s}\n").as_bytes())
    }

    /// Every wall and obstacle edge as a segment.
    pub fn segments(&self) -> Vec<[V2; 2]> {
        let mut out = Vec::new();
        for w in &self.walls {
            out.extend(w.windows(2).map(|s| [s[0], s[1]]));
        }
        for o in &self.obstacles {
            for i in 0..o.len() {
                out.push([o[i], o[(i + 1) % o.len()]]);
            }
        }
        out
    }

    /// The first region containing `p`.
    pub fn region_at(&self, p: V2) -> Option<&Region> {
        self.regions.iter().find(|r| inside(&r.polygon, p))
    }

    /// The pivot named `name`.
    pub fn pivot(&self, name: &str) -> Option<&NamedPivot> {
        self.pivots.iter().find(|p| p.name == name)
    }

    /// The move `p → q` with walls and obstacles in the way: unchanged when clear; else slid along
    /// the first edge crossed; else no move at all.
    pub fn constrain(&self, segs: &[[V2; 2]], p: V2, q: V2) -> V2 {
        let blocked = |a: V2, b: V2| {
            segs.iter()
                .find(|s| crosses(a, b, s[0], s[1]))
                .copied()
                .or_else(|| {
                    self.obstacles
                        .iter()
                        .any(|o| inside(o, b))
                        .then_some([b, b])
                })
        };
        let Some(s) = blocked(p, q) else { return q };
        let t = [s[1][0] - s[0][0], s[1][1] - s[0][1]];
        let tl = t[0] * t[0] + t[1] * t[1];
        if tl > 0.0 {
            let d = [q[0] - p[0], q[1] - p[1]];
            let k = (d[0] * t[0] + d[1] * t[1]) / tl;
            let slid = [p[0] + k * t[0], p[1] + k * t[1]];
            if blocked(p, slid).is_none() {
                return slid;
            }
        }
        p
    }
}

/// Whether segments a–b and c–d properly intersect.
pub fn crosses(a: V2, b: V2, c: V2, d: V2) -> bool {
    let orient =
        |p: V2, q: V2, r: V2| (q[0] - p[0]) * (r[1] - p[1]) - (q[1] - p[1]) * (r[0] - p[0]);
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    o1 * o2 < 0.0 && o3 * o4 < 0.0
}

/// Even–odd point-in-polygon test.
pub fn inside(poly: &[V2], p: V2) -> bool {
    let mut c = false;
    let n = poly.len();
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + n - 1) % n]);
        if (a[1] > p[1]) != (b[1] > p[1])
            && p[0] < (b[0] - a[0]) * (p[1] - a[1]) / (b[1] - a[1]) + a[0]
        {
            c = !c;
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn moves_slide_along_walls() {
        let l = Layout {
            walls: vec![vec![[0.0, 1.0], [10.0, 1.0]]],
            obstacles: vec![vec![[5.0, -1.0], [6.0, -1.0], [6.0, 0.0], [5.0, 0.0]]],
            ..Layout::default()
        };
        l.check().unwrap();
        let segs = l.segments();
        assert_eq!(l.constrain(&segs, [1.0, 0.5], [1.5, 0.7]), [1.5, 0.7]);
        let q = l.constrain(&segs, [1.0, 0.5], [2.0, 1.5]);
        assert!(
            (q[0] - 2.0).abs() < 1e-12 && (q[1] - 0.5).abs() < 1e-12,
            "{q:?}"
        );
        assert!(inside(&l.obstacles[0], [5.5, -0.5]));
        let q = l.constrain(&segs, [4.5, -0.5], [5.5, -0.5]);
        assert!(!inside(&l.obstacles[0], q), "{q:?}");
        let bad = Layout {
            obstacles: vec![vec![[0.0, 0.0], [1.0, 0.0]]],
            ..Layout::default()
        };
        let e = bad.check().unwrap_err().to_string();
        assert!(
            e.contains("obstacles[0]") && e.contains("at least 3 points"),
            "{e}"
        );
    }
}
