//! The static surroundings of a herd: obstacle cells and the guidance field leaders follow.

use crate::data::Grid;
use herdfit_kernels::{ObstacleMap, P2};
use ndarray::Array2;

/// Direction field that leaders follow (DESIGN §4.2): during fitting the clip's velocity field
/// propagated into empty cells, during authoring the navigation field.
#[derive(Clone, Debug, PartialEq, Default)]
pub enum Guidance {
    /// No field: leaders act as followers.
    #[default]
    None,
    /// The same direction everywhere.
    Uniform(P2),
    /// One vector per cell of a grid (row-major, row 0 at the bottom); zero vectors mean "no
    /// guidance here".
    Field {
        origin: P2,
        cell_size: f64,
        nx: usize,
        ny: usize,
        dirs: Vec<P2>,
    },
}

/// Obstacles, guidance and fixed zone speeds of a run.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct World {
    pub obstacles: Option<ObstacleMap>,
    pub guidance: Guidance,
    /// Zones whose speed is fixed (paper §7.2.4: the seals' 3.0 BL/s in water, 0.5 on land):
    /// there v_μ of eq. 6 is the zone's speed instead of the clip's mean or speed–density table.
    pub fixed_speed: Option<SpeedMap>,
}

/// A fixed mean speed v_μ (BL/s) per cell of a grid (row-major, row 0 at the bottom); `None`
/// where the speed model of the parameter set applies.
#[derive(Clone, Debug, PartialEq)]
pub struct SpeedMap {
    pub grid: Grid,
    pub speed: Vec<Option<f64>>,
}

impl SpeedMap {
    /// The fixed speed at `p`, or `None` outside the grid or where none is fixed.
    pub fn at(&self, p: P2) -> Option<f64> {
        let (ix, iy) = self.grid.cell_of(p)?;
        self.speed.get(iy * self.grid.nx + ix).copied().flatten()
    }
}

impl World {
    /// An open plane: no obstacles, no guidance.
    pub fn open() -> Self {
        World::default()
    }

    /// The unit guidance direction at `p`, or `None` where the field is absent or zero.
    pub fn guidance_at(&self, p: P2) -> Option<P2> {
        let v = match &self.guidance {
            Guidance::None => return None,
            Guidance::Uniform(d) => *d,
            Guidance::Field {
                origin,
                cell_size,
                nx,
                ny,
                dirs,
            } => {
                let fx = (p[0] - origin[0]) / cell_size;
                let fy = (p[1] - origin[1]) / cell_size;
                if fx < 0.0 || fy < 0.0 || fx >= *nx as f64 || fy >= *ny as f64 {
                    return None;
                }
                dirs[fy as usize * nx + fx as usize]
            }
        };
        let len = (v[0] * v[0] + v[1] * v[1]).sqrt();
        (len > 1e-12 && len.is_finite()).then(|| [v[0] / len, v[1] / len])
    }

    /// Is `p` inside an obstacle cell?
    pub fn in_obstacle(&self, p: P2) -> bool {
        self.obstacles.as_ref().is_some_and(|m| {
            m.cell_of(p)
                .is_some_and(|(ix, iy)| m.blocked[iy * m.nx + ix])
        })
    }
}

/// The obstacle map of a simulation from a grid's obstacle cells (non-zero = obstacle).
pub fn obstacle_map(grid: &Grid, obstacles: &Array2<u8>) -> ObstacleMap {
    let mut m = ObstacleMap::empty(grid.origin, grid.cell_size, grid.nx, grid.ny);
    for ((iy, ix), &v) in obstacles.indexed_iter() {
        m.blocked[iy * grid.nx + ix] = v != 0;
    }
    m
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn guidance_lookup() {
        assert_eq!(World::open().guidance_at([0.0, 0.0]), None);
        let w = World {
            obstacles: None,
            guidance: Guidance::Uniform([3.0, 4.0]),
            fixed_speed: None,
        };
        assert_eq!(w.guidance_at([9.0, 9.0]), Some([0.6, 0.8]));
        let w = World {
            obstacles: None,
            guidance: Guidance::Field {
                origin: [0.0, 0.0],
                cell_size: 2.0,
                nx: 2,
                ny: 1,
                dirs: vec![[0.0, 0.0], [0.0, -2.0]],
            },
            fixed_speed: None,
        };
        assert_eq!(w.guidance_at([1.0, 1.0]), None);
        assert_eq!(w.guidance_at([3.0, 1.0]), Some([0.0, -1.0]));
        assert_eq!(w.guidance_at([5.0, 1.0]), None);
    }
}
