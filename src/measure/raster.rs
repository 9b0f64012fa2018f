//! Rasterising a herd (positions and velocities over frames) into clip fields. Synthetic clips,
//! validation and the reference import all produce fields with these definitions.

use crate::data::agents::AgentRow;
use crate::data::clip::{ClipFields, ClipMeta, ClipSpeed, Grid};
use crate::error::{Error, Result};
use ndarray::{Array2, Array3, Array4};

/// Bins of the speed–density table.
pub const DENSITY_BINS: usize = 8;

/// Builds the speed–density table (§6.2) from `(density, speed, weight)` samples: the density
/// range is split into [`DENSITY_BINS`] equal bins, and each non-empty bin gives one row
/// `[weighted mean density, weighted mean speed]`, densities increasing.
pub fn speed_density_table(samples: &[(f64, f64, f64)]) -> Vec<[f64; 2]> {
    let (lo, hi) = samples
        .iter()
        .filter(|s| s.2 > 0.0)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), s| {
            (lo.min(s.0), hi.max(s.0))
        });
    if !lo.is_finite() {
        return Vec::new();
    }
    let width = ((hi - lo) / DENSITY_BINS as f64).max(1e-12);
    let mut acc = [[0.0f64; 3]; DENSITY_BINS];
    for &(d, v, w) in samples.iter().filter(|s| s.2 > 0.0) {
        let b = (((d - lo) / width) as usize).min(DENSITY_BINS - 1);
        acc[b][0] += w * d;
        acc[b][1] += w * v;
        acc[b][2] += w;
    }
    acc.iter()
        .filter(|a| a[2] > 0.0)
        .map(|a| [a[0] / a[2], a[1] / a[2]])
        .collect()
}

/// Rasterises `frames` (one list of agents per frame; positions in BL, velocities in BL/s) on
/// `grid`:
/// - density = agents in the cell / cell area (agents/BL²);
/// - velocity = mean velocity of the cell's agents (BL/s);
/// - dir_variance = mean over the cell's moving agents of the squared angle between the agent's
///   direction and the cell's mean direction N(Σ d_i) (rad²; 0 for a single agent);
/// - speed mean/std over every agent inside the grid in every frame, and the speed–density table
///   from the occupied cells.
///
/// Agents outside the grid are ignored.
pub fn rasterise(
    frames: &[Vec<AgentRow>],
    grid: Grid,
    fps: f64,
    obstacles: Array2<u8>,
    provenance: serde_json::Value,
) -> Result<ClipFields> {
    if frames.is_empty() {
        return Err(Error::invalid("no frames to rasterise"));
    }
    let (nx, ny, nf) = (grid.nx, grid.ny, frames.len());
    if obstacles.shape() != [ny, nx] {
        return Err(Error::invalid(format!(
            "obstacles have shape {:?}, the grid is {ny}×{nx}",
            obstacles.shape()
        )));
    }
    let area = grid.cell_area();
    let mut density = Array3::<f32>::zeros((nf, ny, nx));
    let mut velocity = Array4::<f32>::zeros((nf, ny, nx, 2));
    let mut dir_variance = Array3::<f32>::zeros((nf, ny, nx));
    let mut speeds = Vec::new();
    let mut samples = Vec::new();
    let cells = nx * ny;
    for (f, agents) in frames.iter().enumerate() {
        let mut count = vec![0usize; cells];
        let mut vsum = vec![[0.0f64; 2]; cells];
        let mut ssum = vec![0.0f64; cells];
        let mut dsum = vec![[0.0f64; 2]; cells];
        let mut placed = Vec::with_capacity(agents.len());
        for a in agents {
            let Some((ix, iy)) = grid.cell_of([a.x, a.y]) else {
                continue;
            };
            let c = iy * nx + ix;
            let s = (a.vx * a.vx + a.vy * a.vy).sqrt();
            count[c] += 1;
            vsum[c][0] += a.vx;
            vsum[c][1] += a.vy;
            ssum[c] += s;
            speeds.push(s);
            if s > 1e-12 {
                let d = [a.vx / s, a.vy / s];
                dsum[c][0] += d[0];
                dsum[c][1] += d[1];
                placed.push((c, d));
            }
        }
        let mut sq = vec![0.0f64; cells];
        let mut moving = vec![0usize; cells];
        for &(c, d) in &placed {
            let m = dsum[c];
            let cross = m[0] * d[1] - m[1] * d[0];
            let dot = m[0] * d[0] + m[1] * d[1];
            let ang = cross.abs().atan2(dot);
            sq[c] += ang * ang;
            moving[c] += 1;
        }
        for iy in 0..ny {
            for ix in 0..nx {
                let c = iy * nx + ix;
                let n = count[c];
                if n == 0 {
                    continue;
                }
                let rho = n as f64 / area;
                density[[f, iy, ix]] = rho as f32;
                velocity[[f, iy, ix, 0]] = (vsum[c][0] / n as f64) as f32;
                velocity[[f, iy, ix, 1]] = (vsum[c][1] / n as f64) as f32;
                if moving[c] > 0 {
                    dir_variance[[f, iy, ix]] = (sq[c] / moving[c] as f64) as f32;
                }
                samples.push((rho, ssum[c] / n as f64, n as f64));
            }
        }
    }
    let (mean, std) = if speeds.is_empty() {
        (0.0, 0.0)
    } else {
        let m = speeds.iter().sum::<f64>() / speeds.len() as f64;
        let v = speeds.iter().map(|s| (s - m) * (s - m)).sum::<f64>() / speeds.len() as f64;
        (m, v.sqrt())
    };
    let clip = ClipFields {
        meta: ClipMeta {
            provenance,
            ..ClipMeta::of_grid(
                &grid,
                fps,
                nf,
                ClipSpeed {
                    mean,
                    std,
                    density_table: speed_density_table(&samples),
                },
            )
        },
        density,
        velocity,
        dir_variance,
        obstacles,
    };
    clip.validate()?;
    Ok(clip)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn a(x: f64, y: f64, vx: f64, vy: f64) -> AgentRow {
        AgentRow {
            id: 0,
            x,
            y,
            vx,
            vy,
        }
    }

    fn grid() -> Grid {
        Grid {
            origin: [0.0, 0.0],
            cell_size: 2.0,
            nx: 3,
            ny: 2,
        }
    }

    /// One frame rasterised on [`grid`] at 10 fps without obstacles.
    fn one_frame(frame: Vec<AgentRow>) -> ClipFields {
        rasterise(
            &[frame],
            grid(),
            10.0,
            Array2::zeros((2, 3)),
            serde_json::Value::Null,
        )
        .unwrap()
    }

    #[test]
    fn hand_made_herd() {
        // Cell (0,0): two agents, velocities (1,0) and (0,1). Cell (2,1): one agent (−2, 0).
        // One agent outside the grid.
        let frame = vec![
            a(0.5, 0.5, 1.0, 0.0),
            a(1.5, 1.0, 0.0, 1.0),
            a(5.0, 3.0, -2.0, 0.0),
            a(7.0, 1.0, 1.0, 0.0),
        ];
        let c = one_frame(frame);
        assert_eq!(c.density[[0, 0, 0]], 0.5);
        assert_eq!(c.density[[0, 1, 2]], 0.25);
        assert_eq!(c.density.iter().filter(|&&d| d > 0.0).count(), 2);
        assert_eq!(c.velocity[[0, 0, 0, 0]], 0.5);
        assert_eq!(c.velocity[[0, 0, 0, 1]], 0.5);
        assert_eq!(c.velocity[[0, 1, 2, 0]], -2.0);
        // Both directions are 45° from the mean direction: variance (π/4)².
        let want = (std::f64::consts::FRAC_PI_4).powi(2) as f32;
        assert!((c.dir_variance[[0, 0, 0]] - want).abs() < 1e-6);
        assert_eq!(c.dir_variance[[0, 1, 2]], 0.0);
        assert!((c.count(0) - 3.0).abs() < 1e-9);
        // Speeds 1, 1, 2 inside the grid.
        assert!((c.meta.speed.mean - 4.0 / 3.0).abs() < 1e-12);
        let var: f64 = [1.0, 1.0, 2.0]
            .iter()
            .map(|s: &f64| (s - 4.0 / 3.0).powi(2))
            .sum::<f64>()
            / 3.0;
        assert!((c.meta.speed.std - var.sqrt()).abs() < 1e-12);
        // Two occupied cells → two table rows, densities increasing.
        assert_eq!(c.meta.speed.density_table, vec![[0.25, 2.0], [0.5, 1.0]]);
    }

    #[test]
    fn opposite_directions_have_variance_pi_squared_over_four() {
        // Three agents: two heading +x, one heading −x; mean direction +x.
        let frame = [(0.5, 1.0), (1.0, 1.0), (1.5, -1.0)].map(|(x, vx)| a(x, 0.5, vx, 0.0));
        let c = one_frame(frame.to_vec());
        let want = (std::f64::consts::PI.powi(2) / 3.0) as f32;
        assert!((c.dir_variance[[0, 0, 0]] - want).abs() < 1e-5);
    }

    #[test]
    fn standing_agents_count_in_density_only() {
        let frame = vec![a(0.5, 0.5, 0.0, 0.0), a(1.0, 0.5, 0.0, 2.0)];
        let c = one_frame(frame);
        assert_eq!(c.density[[0, 0, 0]], 0.5);
        assert_eq!(c.velocity[[0, 0, 0, 1]], 1.0);
        assert_eq!(c.dir_variance[[0, 0, 0]], 0.0);
    }

    #[test]
    fn speed_table_bins() {
        let t = speed_density_table(&[(0.0, 2.0, 1.0), (1.0, 1.0, 1.0), (1.0, 3.0, 1.0)]);
        assert_eq!(t, vec![[0.0, 2.0], [1.0, 2.0]]);
        assert!(speed_density_table(&[]).is_empty());
    }
}
