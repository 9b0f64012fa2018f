//! Navigation fields for authoring (paper §7.3): the field of guidance arrows propagated with
//! decay, the cancelling field around obstacles (eq. 14), a destination field by Dijkstra on the
//! grid around obstacles (after Patil et al.), and their blend.

use crate::data::Grid;
use ndarray::Array2;
use std::cmp::Ordering;
use std::collections::{BinaryHeap, VecDeque};

type P2 = [f64; 2];

fn free(obst: &Array2<u8>, ix: i64, iy: i64) -> bool {
    let (ny, nx) = obst.dim();
    ix >= 0
        && iy >= 0
        && (ix as usize) < nx
        && (iy as usize) < ny
        && obst[[iy as usize, ix as usize]] == 0
}

fn unit(v: P2) -> P2 {
    let l = v[0].hypot(v[1]);
    if l > 1e-12 {
        [v[0] / l, v[1] / l]
    } else {
        [0.0, 0.0]
    }
}

/// The arrows' field: every arrow is cut into pieces no longer than half a cell; each accessible
/// cell crossed gets the mean direction of its pieces. Directions then spread breadth-first to
/// neighbouring accessible cells (each new cell the mean of its filled neighbours) at full
/// strength out to `radius` (BL) from the arrows, decaying as exp(−(d − radius)/decay) beyond.
pub fn arrow_field(
    grid: &Grid,
    obst: &Array2<u8>,
    arrows: &[Vec<P2>],
    radius: f64,
    decay: f64,
) -> Vec<P2> {
    let (nx, ny) = (grid.nx, grid.ny);
    let mut sum = vec![[0.0f64; 2]; nx * ny];
    for arrow in arrows {
        for w in arrow.windows(2) {
            let (a, b) = (w[0], w[1]);
            let len = (b[0] - a[0]).hypot(b[1] - a[1]);
            if len <= 0.0 {
                continue;
            }
            let d = [(b[0] - a[0]) / len, (b[1] - a[1]) / len];
            let pieces = (len / (grid.cell_size * 0.5)).ceil().max(1.0) as usize;
            for k in 0..pieces {
                let t = (k as f64 + 0.5) / pieces as f64;
                let p = [a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1])];
                if let Some((ix, iy)) = grid.cell_of(p) {
                    if obst[[iy, ix]] == 0 {
                        sum[iy * nx + ix][0] += d[0];
                        sum[iy * nx + ix][1] += d[1];
                    }
                }
            }
        }
    }
    let mut field = vec![[0.0f64; 2]; nx * ny];
    let mut ring = vec![usize::MAX; nx * ny];
    let mut frontier = Vec::new();
    for c in 0..nx * ny {
        let u = unit(sum[c]);
        if u != [0.0, 0.0] {
            field[c] = u;
            ring[c] = 0;
            frontier.push(c);
        }
    }
    let mut r = 0usize;
    while !frontier.is_empty() {
        r += 1;
        let mut acc: std::collections::BTreeMap<usize, P2> = Default::default();
        for &c in &frontier {
            let (ix, iy) = ((c % nx) as i64, (c / nx) as i64);
            for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                let (jx, jy) = (ix + dx, iy + dy);
                if !free(obst, jx, jy) {
                    continue;
                }
                let j = jy as usize * nx + jx as usize;
                if ring[j] != usize::MAX && ring[j] < r {
                    continue;
                }
                let e = acc.entry(j).or_insert([0.0, 0.0]);
                let u = unit(field[c]);
                e[0] += u[0];
                e[1] += u[1];
            }
        }
        let d = r as f64 * grid.cell_size;
        let strength = if d <= radius {
            1.0
        } else if decay > 0.0 {
            (-(d - radius) / decay).exp()
        } else {
            0.0
        };
        frontier = Vec::new();
        for (j, v) in acc {
            let u = unit(v);
            if u == [0.0, 0.0] || strength < 1e-3 {
                continue;
            }
            field[j] = [u[0] * strength, u[1] * strength];
            ring[j] = r;
            frontier.push(j);
        }
    }
    field
}

/// The cancelling field of eq. 14 summed onto `field`: for each accessible cell within
/// `radius` (BL) of an obstacle cell, with V the unit vector to the nearest obstacle cell,
/// CF = −(GF·V) V where GF·V > 0 (zero otherwise), weighted 1 next to the obstacle and falling
/// linearly to 0 at `radius`. The result keeps no component toward the nearest obstacle next to it.
pub fn cancel_obstacles(grid: &Grid, obst: &Array2<u8>, field: &mut [P2], radius: f64) {
    let (nx, ny) = (grid.nx, grid.ny);
    // Multi-source BFS from obstacle cells: nearest obstacle cell of every accessible cell.
    let mut nearest = vec![usize::MAX; nx * ny];
    let mut q = VecDeque::new();
    for iy in 0..ny {
        for ix in 0..nx {
            if obst[[iy, ix]] != 0 {
                nearest[iy * nx + ix] = iy * nx + ix;
                q.push_back(iy * nx + ix);
            }
        }
    }
    while let Some(c) = q.pop_front() {
        let (ix, iy) = ((c % nx) as i64, (c / nx) as i64);
        for dy in -1..=1i64 {
            for dx in -1..=1i64 {
                let (jx, jy) = (ix + dx, iy + dy);
                if (dx, dy) == (0, 0) || !free(obst, jx, jy) {
                    continue;
                }
                let j = jy as usize * nx + jx as usize;
                if nearest[j] == usize::MAX {
                    let o = nearest[c];
                    let cj = grid.centre(jx as usize, jy as usize);
                    let co = grid.centre(o % nx, o / nx);
                    if (co[0] - cj[0]).hypot(co[1] - cj[1]) <= radius + grid.cell_size {
                        nearest[j] = o;
                        q.push_back(j);
                    }
                }
            }
        }
    }
    for iy in 0..ny {
        for ix in 0..nx {
            let c = iy * nx + ix;
            if obst[[iy, ix]] != 0 || nearest[c] == usize::MAX {
                continue;
            }
            let o = nearest[c];
            let (pc, po) = (grid.centre(ix, iy), grid.centre(o % nx, o / nx));
            let dist = (po[0] - pc[0]).hypot(po[1] - pc[1]);
            let v = unit([po[0] - pc[0], po[1] - pc[1]]);
            let w = if dist <= grid.cell_size * 1.5 {
                1.0
            } else if radius > grid.cell_size {
                (1.0 - (dist - grid.cell_size * 1.5) / (radius - grid.cell_size)).clamp(0.0, 1.0)
            } else {
                0.0
            };
            let g = field[c];
            let dot = g[0] * v[0] + g[1] * v[1];
            if dot > 0.0 {
                field[c] = [g[0] - w * dot * v[0], g[1] - w * dot * v[1]];
            }
        }
    }
}

#[derive(PartialEq)]
struct Node(f64, usize);
impl Eq for Node {}
impl PartialOrd for Node {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}
impl Ord for Node {
    fn cmp(&self, o: &Self) -> Ordering {
        o.0.total_cmp(&self.0).then(o.1.cmp(&self.1))
    }
}

/// Shortest-path distances (BL) from the goal cell over accessible cells, 8-connected (diagonal
/// moves only between two free side cells); unreachable cells get +∞.
pub fn distance_to(grid: &Grid, obst: &Array2<u8>, goal: P2) -> Vec<f64> {
    let (nx, ny) = (grid.nx, grid.ny);
    let mut dist = vec![f64::INFINITY; nx * ny];
    let Some((gx, gy)) = grid.cell_of(goal) else {
        return dist;
    };
    let mut heap = BinaryHeap::new();
    dist[gy * nx + gx] = 0.0;
    heap.push(Node(0.0, gy * nx + gx));
    while let Some(Node(d, c)) = heap.pop() {
        if d > dist[c] {
            continue;
        }
        let (ix, iy) = ((c % nx) as i64, (c / nx) as i64);
        for dy in -1..=1i64 {
            for dx in -1..=1i64 {
                if (dx, dy) == (0, 0) || !free(obst, ix + dx, iy + dy) {
                    continue;
                }
                if dx != 0 && dy != 0 && (!free(obst, ix + dx, iy) || !free(obst, ix, iy + dy)) {
                    continue;
                }
                let j = (iy + dy) as usize * nx + (ix + dx) as usize;
                let nd = d + grid.cell_size * ((dx * dx + dy * dy) as f64).sqrt();
                if nd < dist[j] {
                    dist[j] = nd;
                    heap.push(Node(nd, j));
                }
            }
        }
    }
    dist
}

/// The destination field: each accessible cell points to its neighbour of least distance to the
/// goal (unit vectors; zero at the goal and where the goal is unreachable).
pub fn destination_field(grid: &Grid, obst: &Array2<u8>, goal: P2) -> (Vec<P2>, Vec<f64>) {
    let (nx, ny) = (grid.nx, grid.ny);
    let dist = distance_to(grid, obst, goal);
    let mut field = vec![[0.0f64; 2]; nx * ny];
    for iy in 0..ny as i64 {
        for ix in 0..nx as i64 {
            let c = iy as usize * nx + ix as usize;
            if !dist[c].is_finite() || dist[c] == 0.0 {
                continue;
            }
            let mut best = (dist[c], [0.0, 0.0]);
            for dy in -1..=1i64 {
                for dx in -1..=1i64 {
                    if (dx, dy) == (0, 0) || !free(obst, ix + dx, iy + dy) {
                        continue;
                    }
                    if dx != 0 && dy != 0 && (!free(obst, ix + dx, iy) || !free(obst, ix, iy + dy))
                    {
                        continue;
                    }
                    let j = (iy + dy) as usize * nx + (ix + dx) as usize;
                    if dist[j] < best.0 {
                        best = (dist[j], unit([dx as f64, dy as f64]));
                    }
                }
            }
            field[c] = best.1;
        }
    }
    (field, dist)
}

/// The final navigation field: arrows (with the cancelling field) and destination blended as
/// N(a + w·d) where both exist, either alone otherwise.
pub fn blend(arrows: Option<&[P2]>, dest: Option<(&[P2], f64)>) -> Vec<P2> {
    match (arrows, dest) {
        (Some(a), None) => a.to_vec(),
        (None, Some((d, _))) => d.to_vec(),
        (Some(a), Some((d, w))) => a
            .iter()
            .zip(d)
            .map(|(a, d)| {
                let v = [a[0] + w * d[0], a[1] + w * d[1]];
                let l = v[0].hypot(v[1]);
                let m = a[0].hypot(a[1]).max(d[0].hypot(d[1]));
                if l > 1e-12 {
                    [v[0] / l * m, v[1] / l * m]
                } else {
                    [0.0, 0.0]
                }
            })
            .collect(),
        (None, None) => Vec::new(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(nx: usize, ny: usize) -> Grid {
        Grid {
            origin: [0.0, 0.0],
            cell_size: 1.0,
            nx,
            ny,
        }
    }

    #[test]
    fn arrow_cells_take_the_arrow_direction_and_strength_decays() {
        let g = grid(30, 11);
        let obst = Array2::zeros((11, 30));
        let f = arrow_field(&g, &obst, &[vec![[2.0, 5.5], [28.0, 5.5]]], 2.0, 2.0);
        // On the arrow: +x, unit.
        let on = f[5 * 30 + 10];
        assert!((on[0] - 1.0).abs() < 1e-12 && on[1].abs() < 1e-12);
        // Within the radius (2 rows away): full strength; beyond: exp decay, monotone.
        let at = |row: usize| f[row * 30 + 10][0].hypot(f[row * 30 + 10][1]);
        assert!((at(3) - 1.0).abs() < 1e-12);
        assert!((at(2) - (-0.5f64).exp()).abs() < 1e-12);
        assert!((at(1) - (-1.0f64).exp()).abs() < 1e-12);
        assert!(at(0) < at(1));
        // Still pointing along the arrow.
        assert!(f[10][0] > 0.0 && f[10][1].abs() < 1e-12);
    }

    #[test]
    fn cancelling_field_removes_the_component_toward_an_obstacle() {
        let g = grid(10, 10);
        let mut obst = Array2::zeros((10, 10));
        obst[[5, 6]] = 1; // obstacle at cell (6, 5)
        let mut f = vec![[1.0, 0.0]; 100]; // everything heads +x, into the obstacle
        cancel_obstacles(&g, &obst, &mut f, 3.0);
        // The cell just left of the obstacle keeps no +x component.
        let left = f[5 * 10 + 5];
        assert!(left[0].abs() < 1e-12, "{left:?}");
        // A cell above-left keeps some motion but less than 1 toward it.
        let diag = f[6 * 10 + 5];
        let v = unit([1.0, -1.0]);
        assert!(diag[0] * v[0] + diag[1] * v[1] < 1e-12);
        // Far cells are untouched; cells moving away are untouched.
        assert_eq!(f[50], [1.0, 0.0]);
        assert_eq!(f[5 * 10 + 7], [1.0, 0.0]);
    }

    #[test]
    fn destination_field_descends_shortest_paths_around_obstacles() {
        let g = grid(20, 20);
        let mut obst = Array2::zeros((20, 20));
        // A U open to the left around (10, 10); goal on the right.
        for y in 5..15 {
            obst[[y, 12]] = 1;
        }
        for x in 6..13 {
            obst[[5, x]] = 1;
            obst[[14, x]] = 1;
        }
        let goal = [18.5, 10.5];
        let (f, dist) = destination_field(&g, &obst, goal);
        // From inside the U, following the field reaches the goal with distance strictly falling.
        let (mut x, mut y) = (9usize, 10usize);
        let mut steps = 0;
        while dist[y * 20 + x] > 0.0 {
            let d = f[y * 20 + x];
            let (nx, ny) = (
                (x as f64 + d[0].round()) as usize,
                (y as f64 + d[1].round()) as usize,
            );
            assert!(
                dist[ny * 20 + nx] < dist[y * 20 + x],
                "not monotone at ({x}, {y})"
            );
            assert_eq!(obst[[ny, nx]], 0);
            (x, y) = (nx, ny);
            steps += 1;
            assert!(steps < 100);
        }
        assert_eq!((x, y), (18, 10));
        // The path had to leave the U by its open (left) side first.
        assert!(dist[10 * 20 + 9] > 18.5 - 9.5);
    }
}
