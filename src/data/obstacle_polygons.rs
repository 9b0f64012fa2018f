//! Painted obstacle polygons for `extract --obstacles` (issue #16, step 5):
//! `{"schema": "herdfit.obstacle-polygons/1", "polygons": [[[x, y], …], …]}` in the video's
//! pixels (x to the right, y down, the first frame of the extracted range — the reference frame
//! the camera path maps every frame to), as a user reads them off a still of the video in any
//! image editor. The alternative to a mask image; each polygon is checked like every other polygon
//! herdfit reads (`data::polygon`: three finite points or more, no crossing, non-zero area).

use crate::data::polygon::polygon_problem;
use crate::error::{Error, Result};
use serde::Deserialize;
use std::path::Path;

/// Schema tag of an obstacle-polygons file.
pub const OBSTACLE_POLYGONS_SCHEMA: &str = "herdfit.obstacle-polygons/1";

/// Largest file read (bytes): a hand-painted set of polygons is a few KiB.
const MAX_BYTES: u64 = 16 << 20;

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
struct PolygonsFile {
    schema: String,
    polygons: Vec<Vec<[f64; 2]>>,
}

/// Obstacle polygons in video pixels (x right, y down).
#[derive(Clone, Debug, PartialEq)]
pub struct ObstaclePolygons {
    pub polygons: Vec<Vec<[f64; 2]>>,
}

impl ObstaclePolygons {
    /// Reads and checks a polygons file (errors name the file and the polygon).
    pub fn load(path: &Path) -> Result<ObstaclePolygons> {
        crate::data::atomic::note_input(path);
        let len = std::fs::metadata(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?
            .len();
        if len > MAX_BYTES {
            return Err(Error::file(
                path,
                format!("is {len} bytes: an obstacle-polygons file is at most {MAX_BYTES}"),
            ));
        }
        let text = std::fs::read_to_string(path)
            .map_err(|e| Error::file(path, format!("cannot read: {e}")))?;
        let f: PolygonsFile = serde_json::from_str(&text).map_err(|e| {
            Error::file(
                path,
                format!("expected {{\"schema\": \"{OBSTACLE_POLYGONS_SCHEMA}\", \"polygons\": [[[x, y], …], …]}}: {e}"),
            )
        })?;
        crate::data::check_schema(&f.schema, OBSTACLE_POLYGONS_SCHEMA)
            .map_err(|m| Error::file(path, m))?;
        if f.polygons.is_empty() {
            return Err(Error::file(path, "polygons: empty (no obstacle to paint)"));
        }
        for (k, p) in f.polygons.iter().enumerate() {
            if let Some(m) = polygon_problem(p) {
                return Err(Error::file(path, format!("polygons[{k}]: {m}")));
            }
        }
        Ok(ObstaclePolygons {
            polygons: f.polygons,
        })
    }

    /// A `w × h` mask (row-major, row 0 at the top, 255 = obstacle): the pixels whose centre lies
    /// inside any polygon (even–odd rule per polygon, polygons united). Scanline fill: for each
    /// row the edges' crossings of the row's centre line, sorted, fill between pairs.
    pub fn mask(&self, w: usize, h: usize) -> Vec<u8> {
        let mut m = vec![0u8; w * h];
        let mut xs: Vec<f64> = Vec::new();
        for poly in &self.polygons {
            let (lo, hi) = poly
                .iter()
                .fold((f64::INFINITY, f64::NEG_INFINITY), |a, p| {
                    (a.0.min(p[1]), a.1.max(p[1]))
                });
            let first = (lo - 0.5).ceil().max(0.0) as usize;
            let last = ((hi - 0.5).floor().min(h as f64 - 1.0)).max(-1.0);
            if last < 0.0 {
                continue;
            }
            for row in first..=last as usize {
                let yc = row as f64 + 0.5;
                xs.clear();
                for (i, a) in poly.iter().enumerate() {
                    let b = poly[(i + 1) % poly.len()];
                    // Half-open in y, so a vertex on the line counts once.
                    if (a[1] <= yc) != (b[1] <= yc) {
                        xs.push(a[0] + (yc - a[1]) / (b[1] - a[1]) * (b[0] - a[0]));
                    }
                }
                xs.sort_by(f64::total_cmp);
                for pair in xs.chunks_exact(2) {
                    // Pixel centres x + 0.5 in [pair[0], pair[1]).
                    let x0 = (pair[0] - 0.5).ceil().max(0.0);
                    let x1 = (pair[1] - 0.5).ceil().min(w as f64);
                    if x1 > x0 {
                        m[row * w + x0 as usize..row * w + x1 as usize].fill(255);
                    }
                }
            }
        }
        m
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn polys(p: Vec<Vec<[f64; 2]>>) -> ObstaclePolygons {
        ObstaclePolygons { polygons: p }
    }

    #[test]
    fn a_rectangle_paints_exactly_the_pixels_whose_centres_it_holds() {
        // x in [2, 5), y in [1, 3): pixels 2..5 of rows 1 and 2.
        let m = polys(vec![vec![[2.0, 1.0], [5.0, 1.0], [5.0, 3.0], [2.0, 3.0]]]).mask(8, 5);
        let on: Vec<(usize, usize)> = (0..40)
            .filter(|&i| m[i] == 255)
            .map(|i| (i % 8, i / 8))
            .collect();
        assert_eq!(
            on,
            vec![(2, 1), (3, 1), (4, 1), (2, 2), (3, 2), (4, 2)],
            "{m:?}"
        );
    }

    #[test]
    fn a_triangle_covers_half_a_square_and_polygons_outside_the_frame_are_clipped() {
        // The lower-left half of a 100 × 100 square: 100·99/2 pixel centres strictly below the
        // diagonal plus the 100 on it counted by the half-open rule → 5050 of 10,000.
        let tri = polys(vec![vec![[0.0, 0.0], [100.0, 100.0], [0.0, 100.0]]]).mask(100, 100);
        let n = tri.iter().filter(|&&v| v == 255).count();
        assert!((4950..=5050).contains(&n), "{n}");
        let out = polys(vec![vec![
            [-50.0, -50.0],
            [20.0, -50.0],
            [20.0, 10.0],
            [-50.0, 10.0],
        ]])
        .mask(30, 30);
        assert_eq!(out.iter().filter(|&&v| v == 255).count(), 20 * 10);
    }

    #[test]
    fn bad_files_are_one_line_errors_naming_the_file_and_polygon() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("rocks.json");
        let cases = [
            ("{}", "rocks.json"),
            (
                r#"{"schema": "herdfit.obstacle-polygons/1", "polygons": []}"#,
                "empty",
            ),
            (
                r#"{"schema": "herdfit.obstacle-polygons/1", "polygons": [[[0,0],[1,1]]]}"#,
                "polygons[0]",
            ),
            (
                r#"{"schema": "herdfit.obstacle-polygons/1", "polygons": [[[0,0],[4,0],[4,4],[0,4]], [[0,0],[4,4],[4,0],[0,4]]]}"#,
                "polygons[1]",
            ),
            (
                r#"{"schema": "herdfit.cells/1", "polygons": [[[0,0],[4,0],[4,4]]]}"#,
                "schema",
            ),
        ];
        for (text, needle) in cases {
            std::fs::write(&p, text).unwrap();
            let e = ObstaclePolygons::load(&p).unwrap_err().to_string();
            assert!(
                e.contains("rocks.json") && e.contains(needle),
                "{text}: {e}"
            );
            assert!(!e.contains('\n'), "{e}");
        }
        std::fs::write(
            &p,
            r#"{"schema": "herdfit.obstacle-polygons/1", "polygons": [[[0,0],[4,0],[4,4]]]}"#,
        )
        .unwrap();
        assert_eq!(ObstaclePolygons::load(&p).unwrap().polygons.len(), 1);
    }
}
