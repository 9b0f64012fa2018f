//! `herdfit.boundary/1`: the open boundary of a clip (paper §7.1.3, DESIGN §5) — the cells on
//! the grid's edge where animals enter the view (entries) and leave it (exits), each with the
//! side of the grid it lies on. `fit`, `validate` and `ablate` derive it from the clip's flux
//! ([`crate::herd::boundary::gates_of_clip`]) and write it into their outputs; a user overrides it
//! with a file of this format (`--boundary FILE`).
//!
//! ```json
//! {"schema": "herdfit.boundary/1",
//!  "entries": [{"cell": [19, 8], "side": "right"}],
//!  "exits": [{"cell": [0, 9], "side": "left"}]}
//! ```
//! Cells are `[ix, iy]` on the clip's grid (row 0 at the bottom, y up, as everywhere in herdfit).

use crate::data::atomic::write_atomic;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::path::Path;

/// Schema tag of boundary files.
pub const BOUNDARY_SCHEMA: &str = "herdfit.boundary/1";

/// A side of the grid, named by its outward normal.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Side {
    Left,
    Right,
    Bottom,
    Top,
}

impl Side {
    /// Every side, in file order.
    pub const ALL: [Side; 4] = [Side::Left, Side::Right, Side::Bottom, Side::Top];

    /// The outward unit normal.
    pub fn normal(self) -> [f64; 2] {
        match self {
            Side::Left => [-1.0, 0.0],
            Side::Right => [1.0, 0.0],
            Side::Bottom => [0.0, -1.0],
            Side::Top => [0.0, 1.0],
        }
    }

    /// Whether cell `(ix, iy)` of an `nx × ny` grid lies on this side.
    pub fn holds(self, ix: usize, iy: usize, nx: usize, ny: usize) -> bool {
        match self {
            Side::Left => ix == 0,
            Side::Right => ix + 1 == nx,
            Side::Bottom => iy == 0,
            Side::Top => iy + 1 == ny,
        }
    }
}

/// One boundary cell's outer edge: where animals cross the edge of the grid.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gate {
    /// `[ix, iy]`.
    pub cell: [usize; 2],
    pub side: Side,
}

/// The entry and exit gates of a clip. No gate at all is a closed clip: nothing enters or leaves,
/// and runs are what they were before open boundaries existed.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Gates {
    pub schema: String,
    pub entries: Vec<Gate>,
    pub exits: Vec<Gate>,
}

impl Gates {
    /// Gates of the given entries and exits.
    pub fn new(entries: Vec<Gate>, exits: Vec<Gate>) -> Self {
        Gates {
            schema: BOUNDARY_SCHEMA.into(),
            entries,
            exits,
        }
    }

    /// A closed boundary: no entries, no exits.
    pub fn closed() -> Self {
        Gates::new(Vec::new(), Vec::new())
    }

    /// Whether anything enters or leaves.
    pub fn is_open(&self) -> bool {
        !self.entries.is_empty() || !self.exits.is_empty()
    }

    /// Checks every gate against an `nx × ny` grid with `obstacles` (`[ny, nx]`, 1 = obstacle):
    /// inside the grid, on the side it names, accessible, and not listed twice. Errors name the
    /// list and the gate.
    pub fn check(&self, nx: usize, ny: usize, obstacles: &ndarray::Array2<u8>) -> Result<()> {
        if self.schema != BOUNDARY_SCHEMA {
            return Err(Error::config(
                "schema",
                format!("is '{}', expected '{BOUNDARY_SCHEMA}'", self.schema),
            ));
        }
        for (list, gates) in [("entries", &self.entries), ("exits", &self.exits)] {
            let mut seen = std::collections::BTreeSet::new();
            for (k, g) in gates.iter().enumerate() {
                let [ix, iy] = g.cell;
                let key = format!("{list}[{k}]");
                if ix >= nx || iy >= ny {
                    return Err(Error::config(
                        &key,
                        format!("cell [{ix}, {iy}] is outside the {nx}×{ny} grid"),
                    ));
                }
                if !g.side.holds(ix, iy, nx, ny) {
                    return Err(Error::config(
                        &key,
                        format!(
                            "cell [{ix}, {iy}] is not on the {:?} side of the {nx}×{ny} grid",
                            g.side
                        ),
                    ));
                }
                if obstacles[[iy, ix]] != 0 {
                    return Err(Error::config(
                        &key,
                        format!("cell [{ix}, {iy}] is an obstacle cell"),
                    ));
                }
                if !seen.insert(*g) {
                    return Err(Error::config(&key, "is listed twice"));
                }
            }
        }
        Ok(())
    }

    /// Reads a boundary file (checked against the grid by the caller with [`Gates::check`]).
    pub fn load(path: &Path) -> Result<Gates> {
        crate::data::atomic::note_input(path);
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a {BOUNDARY_SCHEMA} file: {e}")))
    }

    /// Writes the gates as JSON (atomically).
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(self)
            .map_err(|e| Error::Internal(format!("serialising boundary: {e}")))?;
        write_atomic(path, text.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gates_are_checked_against_the_grid() {
        let obstacles = ndarray::Array2::<u8>::zeros((4, 5));
        let gate = |ix, iy, side| Gate {
            cell: [ix, iy],
            side,
        };
        let ok = Gates::new(vec![gate(4, 1, Side::Right)], vec![gate(0, 2, Side::Left)]);
        ok.check(5, 4, &obstacles).unwrap();
        let off_side = Gates::new(vec![gate(3, 1, Side::Right)], vec![]);
        let e = off_side.check(5, 4, &obstacles).unwrap_err().to_string();
        assert!(
            e.contains("entries[0]") && e.contains("not on the Right side"),
            "{e}"
        );
        let outside = Gates::new(vec![], vec![gate(0, 9, Side::Left)]);
        let e = outside.check(5, 4, &obstacles).unwrap_err().to_string();
        assert!(e.contains("exits[0]") && e.contains("outside"), "{e}");
        let twice = Gates::new(
            vec![gate(4, 1, Side::Right), gate(4, 1, Side::Right)],
            vec![],
        );
        assert!(twice
            .check(5, 4, &obstacles)
            .unwrap_err()
            .to_string()
            .contains("twice"));
        let mut blocked = obstacles.clone();
        blocked[[1, 4]] = 1;
        assert!(ok
            .check(5, 4, &blocked)
            .unwrap_err()
            .to_string()
            .contains("obstacle"));
        // A corner cell lies on two sides.
        Gates::new(
            vec![gate(0, 0, Side::Bottom), gate(0, 0, Side::Left)],
            vec![],
        )
        .check(5, 4, &obstacles)
        .unwrap();
    }
}
