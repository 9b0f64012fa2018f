//! Uniform bucket grid over agent positions for fixed-radius neighbour queries.

use crate::geometry::P2;

/// Agents bucketed into square cells of side `cell` (≥ the query radius), built by counting sort,
/// so the order of agents inside a cell is their index order and every query is deterministic.
#[derive(Clone, Debug)]
pub struct UniformGrid {
    origin: P2,
    cell: f64,
    nx: usize,
    ny: usize,
    /// `starts[c]..starts[c + 1]` indexes `items` for cell `c`.
    starts: Vec<u32>,
    items: Vec<u32>,
}

impl UniformGrid {
    /// Bucket `positions` into cells of side at least `radius`. The cell count is kept below
    /// `4 N + 16` (cells grow when the herd is sparse) so memory stays linear in N.
    pub fn build(positions: &[P2], radius: f64) -> Self {
        let n = positions.len();
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in positions {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        if n == 0 {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let mut cell = radius.max(1e-9);
        let max_cells = (4 * n + 16) as f64;
        let extent = [(hi[0] - lo[0]).max(0.0), (hi[1] - lo[1]).max(0.0)];
        while ((extent[0] / cell).floor() + 1.0) * ((extent[1] / cell).floor() + 1.0) > max_cells {
            cell *= 1.5;
        }
        let nx = (extent[0] / cell).floor() as usize + 1;
        let ny = (extent[1] / cell).floor() as usize + 1;
        let mut counts = vec![0u32; nx * ny + 1];
        let cell_of = |p: &P2| -> usize {
            let ix = (((p[0] - lo[0]) / cell) as usize).min(nx - 1);
            let iy = (((p[1] - lo[1]) / cell) as usize).min(ny - 1);
            iy * nx + ix
        };
        let cells: Vec<usize> = positions.iter().map(cell_of).collect();
        for &c in &cells {
            counts[c + 1] += 1;
        }
        for c in 0..nx * ny {
            counts[c + 1] += counts[c];
        }
        let starts = counts.clone();
        let mut fill = counts;
        let mut items = vec![0u32; n];
        for (i, &c) in cells.iter().enumerate() {
            items[fill[c] as usize] = i as u32;
            fill[c] += 1;
        }
        UniformGrid {
            origin: lo,
            cell,
            nx,
            ny,
            starts,
            items,
        }
    }

    /// Calls `f(j)` for every agent `j` in the cells that can hold points within `radius` of `p`
    /// (a superset of the true neighbours; callers test the distance).
    #[inline]
    pub fn for_each_candidate(&self, p: P2, radius: f64, mut f: impl FnMut(usize)) {
        let cx0 = ((p[0] - radius - self.origin[0]) / self.cell).floor();
        let cx1 = ((p[0] + radius - self.origin[0]) / self.cell).floor();
        let cy0 = ((p[1] - radius - self.origin[1]) / self.cell).floor();
        let cy1 = ((p[1] + radius - self.origin[1]) / self.cell).floor();
        let clamp = |v: f64, n: usize| -> Option<usize> {
            if v < 0.0 {
                Some(0)
            } else if v >= n as f64 {
                None
            } else {
                Some(v as usize)
            }
        };
        if cx1 < 0.0 || cy1 < 0.0 {
            return;
        }
        let (Some(x0), Some(y0)) = (clamp(cx0, self.nx), clamp(cy0, self.ny)) else {
            return;
        };
        let x1 = (cx1 as usize).min(self.nx - 1);
        let y1 = (cy1 as usize).min(self.ny - 1);
        for iy in y0..=y1 {
            let row = iy * self.nx;
            let (s, e) = (
                self.starts[row + x0] as usize,
                self.starts[row + x1 + 1] as usize,
            );
            for &j in &self.items[s..e] {
                f(j as usize);
            }
        }
    }

    /// Side of one bucket.
    pub fn cell_size(&self) -> f64 {
        self.cell
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    #[test]
    fn candidates_cover_all_true_neighbours() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let pts: Vec<P2> = (0..500)
            .map(|_| [rng.gen_range(-20.0..20.0), rng.gen_range(-5.0..30.0)])
            .collect();
        let g = UniformGrid::build(&pts, 4.0);
        for (i, p) in pts.iter().enumerate() {
            let mut got = vec![];
            g.for_each_candidate(*p, 4.0, |j| got.push(j));
            for (j, q) in pts.iter().enumerate() {
                let d2 = (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2);
                if d2 < 16.0 {
                    assert!(got.contains(&j), "agent {i} misses {j}");
                }
            }
        }
    }

    #[test]
    fn sparse_herd_keeps_cell_count_linear() {
        let pts: Vec<P2> = vec![[0.0, 0.0], [1e6, 1e6]];
        let g = UniformGrid::build(&pts, 1.0);
        assert!(g.nx * g.ny <= 4 * 2 + 16);
        let mut got = vec![];
        g.for_each_candidate([1e6, 1e6], 1.0, |j| got.push(j));
        assert!(got.contains(&1));
    }

    #[test]
    fn empty_grid_is_fine() {
        let g = UniformGrid::build(&[], 4.0);
        let mut n = 0;
        g.for_each_candidate([0.0, 0.0], 4.0, |_| n += 1);
        assert_eq!(n, 0);
    }
}
