//! Measures that compare crowds (§8 asks for "statistical measures, such as the average
//! interpersonal space, the density"): distributions of speed, nearest-neighbour distance, turning
//! rate and polarization, their 1-Wasserstein distances, and occupancy density maps.

use super::features::{unit, Scene, V2};
use crate::error::{Error, Result};
pub use crate::measure::distribution::{mean, wasserstein};
use serde::{Deserialize, Serialize};

/// Schema tag of comparison reports.
pub const COMPARE_SCHEMA: &str = "herdfit.crowd-compare/1";

/// Samples of each measure over a scene.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Measures {
    /// Speed (units/s) of every step.
    pub speed: Vec<f64>,
    /// Distance (units) to the nearest other agent, every agent-frame with company.
    pub nn: Vec<f64>,
    /// |change of direction| / Δt (rad/s) between successive moving steps.
    pub turning: Vec<f64>,
    /// Polarization |Σ v̂|/N of every frame with at least two moving agents.
    pub polarization: Vec<f64>,
}

/// [`Measures`] of a scene; steps shorter than `still` units/s count as not moving for the
/// turning rate and polarization.
pub fn measures(scene: &Scene, still: f64) -> Measures {
    let mut m = Measures::default();
    let dt = scene.dt;
    let step = |p: &[V2], j: usize| [p[j][0] - p[j - 1][0], p[j][1] - p[j - 1][1]];
    for s in &scene.segments {
        for j in 1..s.pos.len() {
            let d = step(&s.pos, j);
            m.speed.push(d[0].hypot(d[1]) / dt);
            if j >= 2 {
                let e = step(&s.pos, j - 1);
                if d[0].hypot(d[1]) > still * dt && e[0].hypot(e[1]) > still * dt {
                    let a = (e[0] * d[1] - e[1] * d[0]).atan2(e[0] * d[0] + e[1] * d[1]);
                    m.turning.push(a.abs() / dt);
                }
            }
        }
    }
    for f in 0..scene.frames() {
        let here = &scene.at_frame[f];
        let pts: Vec<V2> = here
            .iter()
            .map(|&k| scene.segments[k].at(f).expect("present"))
            .collect();
        if pts.len() >= 2 {
            for (i, p) in pts.iter().enumerate() {
                let d = pts
                    .iter()
                    .enumerate()
                    .filter(|(j, _)| *j != i)
                    .map(|(_, q)| (p[0] - q[0]).hypot(p[1] - q[1]))
                    .fold(f64::INFINITY, f64::min);
                m.nn.push(d);
            }
        }
        let mut sum = [0.0, 0.0];
        let mut n = 0;
        for &k in here {
            let s = &scene.segments[k];
            if f > s.start {
                let d = step(&s.pos, f - s.start);
                if d[0].hypot(d[1]) > still * dt {
                    let u = unit(d).expect("moving");
                    sum[0] += u[0];
                    sum[1] += u[1];
                    n += 1;
                }
            }
        }
        if n >= 2 {
            m.polarization.push(sum[0].hypot(sum[1]) / n as f64);
        }
    }
    m
}

/// An occupancy map: agent-frames per cell divided by all agent-frames inside the bounds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct DensityMap {
    pub origin: V2,
    pub cell: f64,
    pub nx: usize,
    pub ny: usize,
    /// Row-major, row 0 at the bottom.
    pub values: Vec<f64>,
}

/// The occupancy map of `scene` over `bounds` in cells of `cell` units.
pub fn density_map(scene: &Scene, bounds: [V2; 2], cell: f64) -> Result<DensityMap> {
    let w = bounds[1][0] - bounds[0][0];
    let h = bounds[1][1] - bounds[0][1];
    if !(cell > 0.0 && w > 0.0 && h > 0.0 && w / cell <= 4096.0 && h / cell <= 4096.0) {
        return Err(Error::invalid(format!(
            "density map: bounds {bounds:?} and cell {cell} give no grid"
        )));
    }
    let (nx, ny) = ((w / cell).ceil() as usize, (h / cell).ceil() as usize);
    let mut values = vec![0.0; nx * ny];
    let mut n = 0.0;
    for s in &scene.segments {
        for p in &s.pos {
            let (fx, fy) = ((p[0] - bounds[0][0]) / cell, (p[1] - bounds[0][1]) / cell);
            if fx >= 0.0 && fy >= 0.0 && (fx as usize) < nx && (fy as usize) < ny {
                values[fy as usize * nx + fx as usize] += 1.0;
                n += 1.0;
            }
        }
    }
    if n > 0.0 {
        values.iter_mut().for_each(|v| *v /= n);
    }
    Ok(DensityMap {
        origin: bounds[0],
        cell,
        nx,
        ny,
        values,
    })
}

/// The bounds covering every position of the scenes.
pub fn bounds(scenes: &[&Scene]) -> [V2; 2] {
    let mut b = [[f64::INFINITY; 2], [f64::NEG_INFINITY; 2]];
    for s in scenes {
        for p in s.segments.iter().flat_map(|g| &g.pos) {
            for a in 0..2 {
                b[0][a] = b[0][a].min(p[a]);
                b[1][a] = b[1][a].max(p[a]);
            }
        }
    }
    b
}

/// One measure of a comparison.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MeasureRow {
    pub name: String,
    pub unit: String,
    pub mean_a: f64,
    pub mean_b: f64,
    /// 1-Wasserstein distance between the two distributions.
    pub wasserstein: f64,
}

/// A comparison of two crowds (`crowd compare`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Comparison {
    pub schema: String,
    pub a: String,
    pub b: String,
    pub measures: Vec<MeasureRow>,
    /// Total-variation distance ½ Σ|ρ_a − ρ_b| between the occupancy maps (0: same, 1: disjoint).
    pub density_tv: f64,
    /// Pearson correlation of the occupancy maps.
    pub density_correlation: f64,
    pub density_cell: f64,
}

/// Compares crowd `a` with crowd `b` (named `na`, `nb` in the report).
pub fn compare(
    a: &Scene,
    b: &Scene,
    na: &str,
    nb: &str,
    still: f64,
    unit_name: &str,
    cell: f64,
) -> Result<Comparison> {
    let (ma, mb) = (measures(a, still), measures(b, still));
    let row = |name: &str, u: String, x: &[f64], y: &[f64]| MeasureRow {
        name: name.into(),
        unit: u,
        mean_a: mean(x),
        mean_b: mean(y),
        wasserstein: wasserstein(x, y),
    };
    let bd = bounds(&[a, b]);
    let (da, db) = (density_map(a, bd, cell)?, density_map(b, bd, cell)?);
    let tv = 0.5
        * da.values
            .iter()
            .zip(&db.values)
            .map(|(x, y)| (x - y).abs())
            .sum::<f64>();
    Ok(Comparison {
        schema: COMPARE_SCHEMA.into(),
        a: na.into(),
        b: nb.into(),
        measures: vec![
            row("speed", format!("{unit_name}/s"), &ma.speed, &mb.speed),
            row("nearest_neighbour", unit_name.to_string(), &ma.nn, &mb.nn),
            row("turning_rate", "rad/s".into(), &ma.turning, &mb.turning),
            row(
                "polarization",
                "1".into(),
                &ma.polarization,
                &mb.polarization,
            ),
        ],
        density_tv: tv,
        density_correlation: correlation(&da.values, &db.values),
        density_cell: cell,
    })
}

/// Pearson correlation (NaN when either side is constant).
pub fn correlation(a: &[f64], b: &[f64]) -> f64 {
    let (ma, mb) = (mean(a), mean(b));
    let (mut sab, mut saa, mut sbb) = (0.0, 0.0, 0.0);
    for (x, y) in a.iter().zip(b) {
        sab += (x - ma) * (y - mb);
        saa += (x - ma).powi(2);
        sbb += (y - mb).powi(2);
    }
    sab / (saa * sbb).sqrt()
}
