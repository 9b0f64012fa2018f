//! A scene's sources and sinks (`boundary` in the scene file): the open boundary of
//! [`crate::herd::boundary`] on an authored world's edge.

use super::scene::Scene;
use crate::data::boundary::{Gates, Side};
use crate::data::Grid;
use crate::error::{Error, Result};
use ndarray::Array2;
use serde::Deserialize;
use std::path::Path;

/// A scene's sources and sinks: agents enter at the `entries` cells of the world's edge (just
/// outside it, heading along the navigation field there) to keep `count` agents in the world, or
/// at `rate` agents per second; agents crossing the world's edge at the `exits` cells leave it
/// and are removed. Elsewhere the edge stays a wall.
#[derive(Clone, Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SceneBoundary {
    #[serde(default)]
    pub entries: Vec<crate::data::boundary::Gate>,
    #[serde(default)]
    pub exits: Vec<crate::data::boundary::Gate>,
    #[serde(default)]
    pub count: Option<usize>,
    #[serde(default)]
    pub rate: Option<f64>,
}

impl SceneBoundary {
    /// The gates as a boundary.
    pub fn gates(&self) -> Gates {
        Gates::new(self.entries.clone(), self.exits.clone())
    }
}

impl Scene {
    /// Whether a step from `old` to `p` leaves the world through an exit cell of its
    /// boundary: the world's edge is crossed on a side where the cell last stood in is an exit.
    pub fn exits_at(&self, old: [f64; 2], p: [f64; 2]) -> bool {
        let Some(b) = &self.file.boundary else {
            return false;
        };
        let Some((ix, iy)) = self.grid.cell_of(old) else {
            return false;
        };
        let [w, h] = self.grid.size();
        b.exits.iter().any(|g| {
            g.cell == [ix, iy]
                && match g.side {
                    Side::Left => p[0] < 0.0,
                    Side::Right => p[0] > w,
                    Side::Bottom => p[1] < 0.0,
                    Side::Top => p[1] > h,
                }
        })
    }
}

/// The scene's sources and sinks: gates on the world's edge, free cells; a count or a rate (one
/// of them) when anything enters.
pub(super) fn check(
    b: &SceneBoundary,
    grid: &Grid,
    obstacles: &Array2<u8>,
    path: &Path,
) -> Result<()> {
    let bad = |at: &str, msg: &str| Error::file(path, format!("{at}: {msg}"));
    b.gates()
        .check(grid.nx, grid.ny, obstacles)
        .map_err(|e| bad("boundary", &e.to_string()))?;
    match (b.count, b.rate, b.entries.is_empty()) {
        (Some(_), Some(_), _) => Err(bad("boundary", "give count or rate, not both")),
        (None, None, false) => Err(bad(
            "boundary",
            "entries need a count (agents kept in the world) or a rate (agents/s)",
        )),
        (Some(c), None, _) if c > crate::limits::MAX_AGENTS => Err(bad(
            "boundary.count",
            &format!("{c} is above the limit of {}", crate::limits::MAX_AGENTS),
        )),
        (None, Some(r), _) if !(r.is_finite() && (0.0..=1e4).contains(&r)) => Err(bad(
            "boundary.rate",
            &format!("{r} must be in [0, 10000] agents/s"),
        )),
        _ => Ok(()),
    }
}
