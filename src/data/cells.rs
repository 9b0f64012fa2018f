//! Obstacle-cell files: `{"cells": [[ix, iy], …]}`, grid cells (row 0 at the bottom) that are
//! obstacles, as `synth --obstacles` reads them.

use crate::error::{Error, Result};
use ndarray::Array2;
use serde::Deserialize;
use std::path::Path;

/// Obstacle cells file: `{"cells": [[ix, iy], …]}` (row 0 at the bottom).
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct CellsFile {
    cells: Vec<[i64; 2]>,
}

/// Reads an obstacle-cells file for an `nx × ny` grid.
pub fn read_cells(path: &Path, nx: usize, ny: usize) -> Result<Array2<u8>> {
    crate::data::atomic::note_input(path);
    let text = std::fs::read_to_string(path)
        .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
    let f: CellsFile = serde_json::from_str(&text)
        .map_err(|e| Error::file(path, format!("expected {{\"cells\": [[ix, iy], …]}}: {e}")))?;
    let mut m = Array2::<u8>::zeros((ny, nx));
    for (k, &[ix, iy]) in f.cells.iter().enumerate() {
        if ix < 0 || iy < 0 || ix as usize >= nx || iy as usize >= ny {
            return Err(Error::file(
                path,
                format!("cells[{k}] = [{ix}, {iy}] is outside the {nx}×{ny} grid"),
            ));
        }
        m[[iy as usize, ix as usize]] = 1;
    }
    Ok(m)
}
