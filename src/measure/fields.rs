//! Field comparisons and the emergent measures of fields (paper §7.1.2): per-frame polarization,
//! angular momentum and aspect ratio of a clip's fields; density and velocity errors of a herd or
//! of other fields against a clip, on its own grid or a coarse one; the like-for-like smoothing
//! of velocities.

use crate::data::{AgentRow, ClipFields};
use crate::measure::emergent::{
    angular_momentum, aspect_ratio, centroid, field_points, polarization,
};
use serde::Serialize;

/// Per-frame emergent measures of a set of fields.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Emergent {
    pub polarization: f64,
    pub angular_momentum_centroid: f64,
    pub angular_momentum_frame_centre: f64,
    /// NaN when the herd has no mean direction.
    pub aspect_ratio: f64,
}

impl Emergent {
    /// [polarization, angular momentum about the centroid, about the frame centre, aspect ratio]
    /// (the order of validation's measures after the two errors).
    pub fn values(&self) -> [f64; 4] {
        [
            self.polarization,
            self.angular_momentum_centroid,
            self.angular_momentum_frame_centre,
            self.aspect_ratio,
        ]
    }
}

/// The emergent measures of frame `f` of `c`, from its fields.
pub fn emergent(c: &ClipFields, f: usize) -> Emergent {
    let (pos, vel, w) = field_points(c, f);
    let g = c.grid();
    let size = g.size();
    let centre = [g.origin[0] + size[0] / 2.0, g.origin[1] + size[1] / 2.0];
    Emergent {
        polarization: polarization(&vel, &w),
        angular_momentum_centroid: angular_momentum(&pos, &vel, &w, centroid(&pos, &w)),
        angular_momentum_frame_centre: angular_momentum(&pos, &vel, &w, centre),
        aspect_ratio: aspect_ratio(&pos, &vel, &w).unwrap_or(f64::NAN),
    }
}

/// Agents and momentum of frame `f` of `c` summed into the cells of a coarse `k × k` grid (fewer
/// along an axis with fewer cells): `[n, n·Vx, n·Vy]` per coarse cell, row-major.
pub fn coarse_cells(c: &ClipFields, f: usize, k: usize) -> Vec<[f64; 3]> {
    let g = c.grid();
    let a = g.cell_area();
    let kx = k.min(g.nx).max(1);
    let ky = k.min(g.ny).max(1);
    let mut n = vec![[0.0f64; 3]; kx * ky];
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            let cell = (iy * ky / g.ny) * kx + ix * kx / g.nx;
            let d = c.density[[f, iy, ix]] as f64 * a;
            n[cell][0] += d;
            n[cell][1] += d * c.velocity[[f, iy, ix, 0]] as f64;
            n[cell][2] += d * c.velocity[[f, iy, ix, 1]] as f64;
        }
    }
    n
}

/// One cell of a comparison with a clip: the clip's agents `n` and mean velocity `v` there, and
/// the other side's (`n_sim`, `v_sim`; zero velocity where it has nobody).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CellPair {
    pub n: f64,
    pub v: [f64; 2],
    pub n_sim: f64,
    pub v_sim: [f64; 2],
}

/// The density and velocity errors of a comparison, cell by cell: density Σ|n' − n| / Σ n,
/// velocity Σ n ‖V' − V‖ / Σ n ‖V‖ over the clip's occupied cells (0 when the clip has nobody).
/// `norm(x, y)` is the length of a vector: the coarse errors of validation have always used
/// `hypot`, the fit's errors on the clip's grid √(x² + y²); each keeps its own so that the
/// numbers it has recorded keep their bytes.
pub fn relative_errors(
    cells: impl IntoIterator<Item = CellPair>,
    norm: fn(f64, f64) -> f64,
) -> (f64, f64) {
    let (mut dn, mut tn, mut dv, mut tv) = (0.0, 0.0, 0.0, 0.0);
    for p in cells {
        dn += (p.n_sim - p.n).abs();
        tn += p.n;
        if p.n > 0.0 {
            dv += p.n * norm(p.v_sim[0] - p.v[0], p.v_sim[1] - p.v[1]);
            tv += p.n * norm(p.v[0], p.v[1]);
        }
    }
    (
        if tn > 0.0 { dn / tn } else { 0.0 },
        if tv > 0.0 { dv / tv } else { 0.0 },
    )
}

/// √(x² + y²).
fn sqrt_norm(x: f64, y: f64) -> f64 {
    (x * x + y * y).sqrt()
}

/// Density and velocity errors of simulated coarse cells `sim` against the clip's `clip` (from
/// [`coarse_cells`]; [`relative_errors`] with `hypot`).
pub fn cell_errors(clip: &[[f64; 3]], sim: &[[f64; 3]]) -> (f64, f64) {
    // Mean velocity of a coarse cell from its momentum (zero where it is empty).
    let mean = |c: &[f64; 3]| {
        if c[0] > 0.0 {
            [c[1] / c[0], c[2] / c[0]]
        } else {
            [0.0, 0.0]
        }
    };
    let pairs = clip.iter().zip(sim).map(|(c, s)| CellPair {
        n: c[0],
        v: mean(c),
        n_sim: s[0],
        v_sim: mean(s),
    });
    relative_errors(pairs, f64::hypot)
}

/// Density and velocity errors of frame `fs` of `sim` against frame `f` of `clip` (same grid), on
/// a coarse `k × k` grid ([`coarse_cells`], [`cell_errors`]).
pub fn coarse_errors(
    clip: &ClipFields,
    f: usize,
    sim: &ClipFields,
    fs: usize,
    k: usize,
) -> (f64, f64) {
    cell_errors(&coarse_cells(clip, f, k), &coarse_cells(sim, fs, k))
}

/// Averages each cell's velocity over a centred window of `window` frames, weighted by density —
/// what extraction does to the flow — so a simulation is compared with a clip like with like.
pub fn smooth_velocity(c: &mut ClipFields, window: usize) {
    if window <= 1 {
        return;
    }
    let (nf, ny, nx) = c.density.dim();
    let half = window / 2;
    let src_v = c.velocity.clone();
    for f in 0..nf {
        let (lo, hi) = (f.saturating_sub(half), (f + half + 1).min(nf));
        for iy in 0..ny {
            for ix in 0..nx {
                if c.density[[f, iy, ix]] <= 0.0 {
                    continue;
                }
                let (mut sx, mut sy, mut w) = (0.0f64, 0.0f64, 0.0f64);
                for g in lo..hi {
                    let d = c.density[[g, iy, ix]] as f64;
                    sx += d * src_v[[g, iy, ix, 0]] as f64;
                    sy += d * src_v[[g, iy, ix, 1]] as f64;
                    w += d;
                }
                if w > 0.0 {
                    c.velocity[[f, iy, ix, 0]] = (sx / w) as f32;
                    c.velocity[[f, iy, ix, 1]] = (sy / w) as f32;
                }
            }
        }
    }
}

/// Agents and summed velocities of `rows` per cell of the clip's grid (row-major).
pub fn cell_counts(clip: &ClipFields, rows: &[AgentRow]) -> (Vec<f64>, Vec<[f64; 2]>) {
    let g = clip.grid();
    let mut n = vec![0.0; g.nx * g.ny];
    let mut v = vec![[0.0; 2]; g.nx * g.ny];
    for r in rows {
        if let Some((ix, iy)) = g.cell_of([r.x, r.y]) {
            let c = iy * g.nx + ix;
            n[c] += 1.0;
            v[c][0] += r.vx;
            v[c][1] += r.vy;
        }
    }
    (n, v)
}

/// Density and velocity errors of a herd against frame `f` of the clip on the clip's grid
/// ([`relative_errors`] with √(x² + y²)), by cell counts n = ρ·area.
pub fn field_errors(clip: &ClipFields, f: usize, rows: &[AgentRow]) -> (f64, f64) {
    let g = clip.grid();
    let a = g.cell_area();
    let (n_sim, v_sum) = cell_counts(clip, rows);
    let pairs = (0..g.ny * g.nx).map(|c| {
        let (iy, ix) = (c / g.nx, c % g.nx);
        CellPair {
            n: clip.density[[f, iy, ix]] as f64 * a,
            v: [
                clip.velocity[[f, iy, ix, 0]] as f64,
                clip.velocity[[f, iy, ix, 1]] as f64,
            ],
            n_sim: n_sim[c],
            v_sim: if n_sim[c] > 0.0 {
                [v_sum[c][0] / n_sim[c], v_sum[c][1] / n_sim[c]]
            } else {
                [0.0, 0.0]
            },
        }
    });
    relative_errors(pairs, sqrt_norm)
}

/// A cell field (row-major `[ny·nx]`) filtered by a symmetric kernel of odd length, centred on
/// each cell, along x then along y; weights falling outside the grid are dropped.
pub fn separable_filter(field: &[f64], nx: usize, ny: usize, kernel: &[f64]) -> Vec<f64> {
    let half = (kernel.len() / 2) as i64;
    // One pass along x (stride 1, length nx), one along y (stride nx, length ny).
    let pass = |v: &[f64], stride: usize, len: usize| -> Vec<f64> {
        let mut out = vec![0.0; v.len()];
        for (c, &x) in v.iter().enumerate() {
            let i = (c / stride) % len;
            for (d, k) in kernel.iter().enumerate() {
                let j = i as i64 + d as i64 - half;
                if j >= 0 && (j as usize) < len {
                    out[c + j as usize * stride - i * stride] += k * x;
                }
            }
        }
        out
    };
    pass(&pass(field, 1, nx), nx, ny)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::measure::rasterise;

    #[test]
    fn velocity_smoothing_is_density_weighted_and_centred() {
        let mut frames = Vec::new();
        for (f, v) in [[1.0, 0.0], [0.0, 1.0], [0.0, 1.0]].iter().enumerate() {
            // Frame 2 has two agents in the cell: twice the weight.
            let n = if f == 2 { 2 } else { 1 };
            frames.push(
                (0..n)
                    .map(|i| AgentRow {
                        id: i,
                        x: 0.5,
                        y: 0.5,
                        vx: v[0],
                        vy: v[1],
                    })
                    .collect::<Vec<_>>(),
            );
        }
        let g = crate::data::Grid {
            origin: [0.0, 0.0],
            cell_size: 1.0,
            nx: 1,
            ny: 1,
        };
        let mut c = rasterise(
            &frames,
            g,
            10.0,
            ndarray::Array2::zeros((1, 1)),
            serde_json::Value::Null,
        )
        .unwrap();
        smooth_velocity(&mut c, 3);
        // Frame 0 averages frames 0–1 (weights 1, 1); frame 1 frames 0–2 (1, 1, 2).
        assert_eq!(c.velocity[[0, 0, 0, 0]], 0.5);
        assert_eq!(c.velocity[[0, 0, 0, 1]], 0.5);
        assert_eq!(c.velocity[[1, 0, 0, 0]], 0.25);
        assert_eq!(c.velocity[[1, 0, 0, 1]], 0.75);
        assert_eq!(c.meta.velocity_window(), 1);
    }
}
