//! Obstacle cells on a regular grid: line-of-sight traversal and obstacle points in range.

use crate::geometry::P2;

/// Square cells of side `cell_size`, `nx × ny`, lower-left corner at `origin`, row-major with
/// row 0 at the bottom (y up, DESIGN §3). `blocked[iy * nx + ix]` marks an obstacle cell.
#[derive(Clone, Debug, PartialEq)]
pub struct ObstacleMap {
    pub origin: P2,
    pub cell_size: f64,
    pub nx: usize,
    pub ny: usize,
    pub blocked: Vec<bool>,
}

impl ObstacleMap {
    /// A map with no obstacle cells.
    pub fn empty(origin: P2, cell_size: f64, nx: usize, ny: usize) -> Self {
        ObstacleMap {
            origin,
            cell_size,
            nx,
            ny,
            blocked: vec![false; nx * ny],
        }
    }

    /// Does the map hold any obstacle cell?
    pub fn any(&self) -> bool {
        self.blocked.iter().any(|&b| b)
    }

    /// The cell holding `p`, if inside the grid.
    #[inline]
    pub fn cell_of(&self, p: P2) -> Option<(usize, usize)> {
        let fx = (p[0] - self.origin[0]) / self.cell_size;
        let fy = (p[1] - self.origin[1]) / self.cell_size;
        if fx < 0.0 || fy < 0.0 || fx >= self.nx as f64 || fy >= self.ny as f64 {
            return None;
        }
        Some((fx as usize, fy as usize))
    }

    /// Is cell `(ix, iy)` an obstacle? Cells outside the grid are free.
    #[inline]
    pub fn is_blocked(&self, ix: i64, iy: i64) -> bool {
        ix >= 0
            && iy >= 0
            && (ix as usize) < self.nx
            && (iy as usize) < self.ny
            && self.blocked[iy as usize * self.nx + ix as usize]
    }

    /// Centre of cell `(ix, iy)`.
    #[inline]
    pub fn centre(&self, ix: usize, iy: usize) -> P2 {
        [
            self.origin[0] + (ix as f64 + 0.5) * self.cell_size,
            self.origin[1] + (iy as f64 + 0.5) * self.cell_size,
        ]
    }

    /// Does the segment `a`→`b` pass through an obstacle cell other than the cells holding `a`
    /// and `b`? Exact grid traversal (Amanatides & Woo), so every crossed cell is visited once.
    pub fn segment_blocked(&self, a: P2, b: P2) -> bool {
        let s = self.cell_size;
        let fa = [(a[0] - self.origin[0]) / s, (a[1] - self.origin[1]) / s];
        let fb = [(b[0] - self.origin[0]) / s, (b[1] - self.origin[1]) / s];
        let mut c = [fa[0].floor() as i64, fa[1].floor() as i64];
        let end = [fb[0].floor() as i64, fb[1].floor() as i64];
        let d = [fb[0] - fa[0], fb[1] - fa[1]];
        let mut step = [0i64; 2];
        let mut t_max = [f64::INFINITY; 2];
        let mut t_delta = [f64::INFINITY; 2];
        for k in 0..2 {
            if d[k] > 0.0 {
                step[k] = 1;
                t_max[k] = ((c[k] + 1) as f64 - fa[k]) / d[k];
                t_delta[k] = 1.0 / d[k];
            } else if d[k] < 0.0 {
                step[k] = -1;
                t_max[k] = (fa[k] - c[k] as f64) / -d[k];
                t_delta[k] = -1.0 / d[k];
            }
        }
        let start = c;
        // At most |Δix| + |Δiy| cell crossings.
        let max_steps = (end[0] - c[0]).unsigned_abs() + (end[1] - c[1]).unsigned_abs();
        for _ in 0..max_steps {
            if t_max[0] < t_max[1] {
                c[0] += step[0];
                t_max[0] += t_delta[0];
            } else {
                c[1] += step[1];
                t_max[1] += t_delta[1];
            }
            if c == end {
                break;
            }
            if c != start && self.is_blocked(c[0], c[1]) {
                return true;
            }
        }
        false
    }

    /// Cells within `radius` of `p` (by centre), with their centres and squared distances.
    pub fn blocked_in_range(&self, p: P2, radius: f64, out: &mut Vec<(f64, P2)>) {
        let s = self.cell_size;
        let r2 = radius * radius;
        let lo = |v: f64, o: f64| (((v - radius - o) / s).floor() as i64).max(0);
        let hi =
            |v: f64, o: f64, n: usize| (((v + radius - o) / s).floor() as i64).min(n as i64 - 1);
        for iy in lo(p[1], self.origin[1])..=hi(p[1], self.origin[1], self.ny) {
            for ix in lo(p[0], self.origin[0])..=hi(p[0], self.origin[0], self.nx) {
                if !self.is_blocked(ix, iy) {
                    continue;
                }
                let q = self.centre(ix as usize, iy as usize);
                let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                if d2 < r2 && d2 > 0.0 {
                    out.push((d2, q));
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map_with(cells: &[(usize, usize)]) -> ObstacleMap {
        let mut m = ObstacleMap::empty([0.0, 0.0], 1.0, 10, 10);
        for &(x, y) in cells {
            m.blocked[y * 10 + x] = true;
        }
        m
    }

    /// Dense sampling along the segment: the reference for the traversal.
    fn sampled(m: &ObstacleMap, a: P2, b: P2) -> bool {
        let ca = m.cell_of(a);
        let cb = m.cell_of(b);
        (0..=20000).any(|s| {
            let t = s as f64 / 20000.0;
            let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
            match m.cell_of(p) {
                Some(c) if Some(c) != ca && Some(c) != cb => m.blocked[c.1 * 10 + c.0],
                _ => false,
            }
        })
    }

    #[test]
    fn traversal_matches_dense_sampling() {
        use rand::{Rng, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let m = map_with(&[(4, 4), (5, 4), (2, 7), (7, 2), (6, 6)]);
        for _ in 0..2000 {
            let a = [rng.gen_range(-1.0..11.0), rng.gen_range(-1.0..11.0)];
            let b = [rng.gen_range(-1.0..11.0), rng.gen_range(-1.0..11.0)];
            assert_eq!(m.segment_blocked(a, b), sampled(&m, a, b), "{a:?} -> {b:?}");
        }
    }

    #[test]
    fn end_cells_do_not_block() {
        let m = map_with(&[(4, 4)]);
        assert!(!m.segment_blocked([4.5, 4.5], [6.5, 4.5]));
        assert!(!m.segment_blocked([2.5, 4.5], [4.5, 4.5]));
        assert!(m.segment_blocked([2.5, 4.5], [6.5, 4.5]));
    }

    #[test]
    fn blocked_cells_in_range() {
        let m = map_with(&[(4, 4), (9, 9)]);
        let mut out = vec![];
        m.blocked_in_range([2.5, 4.5], 3.0, &mut out);
        assert_eq!(out, vec![(4.0, [4.5, 4.5])]);
    }
}
