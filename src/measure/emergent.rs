//! Measures of emergent behaviour (paper §7.1.2): polarization (eq. 12), angular momentum
//! (eq. 13) and the aspect ratio of the motion-aligned bounding box. Each works on weighted
//! points, so the same code measures a simulated herd (weight 1 per agent) and a clip's fields
//! (one point per occupied cell, weight = agents in the cell).

use crate::data::ClipFields;

type P2 = [f64; 2];

fn unit(v: P2) -> Option<P2> {
    let l = (v[0] * v[0] + v[1] * v[1]).sqrt();
    (l > 1e-12).then(|| [v[0] / l, v[1] / l])
}

/// Polarization, eq. 12: P = ‖Σ w_i N(V_i)‖ / Σ w_i ∈ [0, 1]. Points with zero velocity count in
/// the weight sum but add no direction. 0 for an empty set.
pub fn polarization(vel: &[P2], w: &[f64]) -> f64 {
    let (mut s, mut total) = ([0.0; 2], 0.0);
    for (v, &wi) in vel.iter().zip(w) {
        total += wi;
        if let Some(d) = unit(*v) {
            s[0] += wi * d[0];
            s[1] += wi * d[1];
        }
    }
    if total > 0.0 {
        (s[0] * s[0] + s[1] * s[1]).sqrt() / total
    } else {
        0.0
    }
}

/// Angular momentum, eq. 13: M = |Σ w_i N(R_i) × N(V_i)| / Σ w_i with R_i = p_i − c; 1 for a
/// perfect mill around c. Points at c or standing still add nothing.
pub fn angular_momentum(pos: &[P2], vel: &[P2], w: &[f64], centre: P2) -> f64 {
    let (mut s, mut total) = (0.0, 0.0);
    for ((p, v), &wi) in pos.iter().zip(vel).zip(w) {
        total += wi;
        if let (Some(r), Some(d)) = (unit([p[0] - centre[0], p[1] - centre[1]]), unit(*v)) {
            s += wi * (r[0] * d[1] - r[1] * d[0]);
        }
    }
    if total > 0.0 {
        s.abs() / total
    } else {
        0.0
    }
}

/// Weighted centroid (the origin for an empty set).
pub fn centroid(pos: &[P2], w: &[f64]) -> P2 {
    let (mut c, mut total) = ([0.0; 2], 0.0);
    for (p, &wi) in pos.iter().zip(w) {
        c[0] += wi * p[0];
        c[1] += wi * p[1];
        total += wi;
    }
    if total > 0.0 {
        [c[0] / total, c[1] / total]
    } else {
        [0.0; 2]
    }
}

/// Aspect ratio of the motion-aligned bounding box: lateral extent / extent along the mean
/// direction of motion N(Σ w_i N(V_i)). Low for a single file, high for a row abreast; `None` when
/// the herd has no mean direction or no extent along it.
pub fn aspect_ratio(pos: &[P2], vel: &[P2], w: &[f64]) -> Option<f64> {
    let mut s = [0.0; 2];
    for (v, &wi) in vel.iter().zip(w) {
        if let Some(d) = unit(*v) {
            s[0] += wi * d[0];
            s[1] += wi * d[1];
        }
    }
    let d = unit(s)?;
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for (p, &wi) in pos.iter().zip(w) {
        if wi <= 0.0 {
            continue;
        }
        let along = p[0] * d[0] + p[1] * d[1];
        let lateral = -p[0] * d[1] + p[1] * d[0];
        lo = [lo[0].min(along), lo[1].min(lateral)];
        hi = [hi[0].max(along), hi[1].max(lateral)];
    }
    let (len, wid) = (hi[0] - lo[0], hi[1] - lo[1]);
    (len > 1e-12).then(|| wid / len)
}

/// Per-frame measures of a clip computed from its fields.
#[derive(Clone, Debug, PartialEq, serde::Serialize)]
pub struct FrameMeasures {
    pub frame: usize,
    pub agents: f64,
    pub polarization: f64,
    /// About the density-weighted centroid of the herd.
    pub angular_momentum_centroid: f64,
    /// About the centre of the grid (the paper's default, "the centre of the image").
    pub angular_momentum_frame_centre: f64,
}

/// Occupied cells of frame `f` as weighted points: (cell centres, mean velocities, agents).
pub fn field_points(c: &ClipFields, f: usize) -> (Vec<P2>, Vec<P2>, Vec<f64>) {
    let g = c.grid();
    let (mut pos, mut vel, mut w) = (Vec::new(), Vec::new(), Vec::new());
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            let d = c.density[[f, iy, ix]] as f64;
            if d > 0.0 {
                pos.push(g.centre(ix, iy));
                vel.push([
                    c.velocity[[f, iy, ix, 0]] as f64,
                    c.velocity[[f, iy, ix, 1]] as f64,
                ]);
                w.push(d * g.cell_area());
            }
        }
    }
    (pos, vel, w)
}

/// Polarization and angular momentum of every frame of a clip, from its fields.
pub fn clip_measures(c: &ClipFields) -> Vec<FrameMeasures> {
    let g = c.grid();
    let size = g.size();
    let frame_centre = [g.origin[0] + size[0] / 2.0, g.origin[1] + size[1] / 2.0];
    (0..c.frames())
        .map(|f| {
            let (pos, vel, w) = field_points(c, f);
            FrameMeasures {
                frame: f,
                agents: w.iter().sum(),
                polarization: polarization(&vel, &w),
                angular_momentum_centroid: angular_momentum(&pos, &vel, &w, centroid(&pos, &w)),
                angular_momentum_frame_centre: angular_momentum(&pos, &vel, &w, frame_centre),
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    #[test]
    fn polarization_aligned_and_star() {
        let ones = vec![1.0; 8];
        let aligned = vec![[1.0, 0.5]; 8];
        assert!((polarization(&aligned, &ones) - 1.0).abs() < 1e-12);
        let star: Vec<P2> = (0..8)
            .map(|k| {
                let a = k as f64 * PI / 4.0;
                [a.cos(), a.sin()]
            })
            .collect();
        assert!(polarization(&star, &ones) < 1e-12);
    }

    #[test]
    fn angular_momentum_of_a_mill() {
        let n = 12;
        let pos: Vec<P2> = (0..n)
            .map(|k| {
                let a = k as f64 * 2.0 * PI / n as f64;
                [5.0 + 3.0 * a.cos(), -1.0 + 3.0 * a.sin()]
            })
            .collect();
        // Counter-clockwise tangents.
        let vel: Vec<P2> = pos.iter().map(|p| [-(p[1] + 1.0), p[0] - 5.0]).collect();
        let w = vec![1.0; n];
        let c = centroid(&pos, &w);
        assert!((angular_momentum(&pos, &vel, &w, c) - 1.0).abs() < 1e-12);
        // A mill has no polarization; a translating herd has no angular momentum.
        assert!(polarization(&vel, &w) < 1e-12);
        let straight = vec![[1.0, 0.0]; n];
        assert!(angular_momentum(&pos, &straight, &w, c) < 1e-12);
    }

    #[test]
    fn aspect_ratio_single_file_vs_row_abreast() {
        let w = vec![1.0; 5];
        let east = vec![[1.0, 0.0]; 5];
        // Single file along the direction of motion, slightly staggered.
        let file: Vec<P2> = (0..5).map(|k| [k as f64, 0.1 * (k % 2) as f64]).collect();
        let row: Vec<P2> = (0..5).map(|k| [0.1 * (k % 2) as f64, k as f64]).collect();
        let a_file = aspect_ratio(&file, &east, &w).unwrap();
        let a_row = aspect_ratio(&row, &east, &w).unwrap();
        assert!((a_file - 0.1 / 4.0).abs() < 1e-12, "{a_file}");
        assert!((a_row - 4.0 / 0.1).abs() < 1e-9, "{a_row}");
        assert_eq!(aspect_ratio(&file, &[[0.0, 0.0]; 5], &w), None);
    }
}
