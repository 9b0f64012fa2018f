//! Zones from a mask image (issue #17: "polygons or a mask image"): the image is stretched over
//! the clip's grid (row 0 of the image at the top, the grid's row 0 at the bottom) and each cell
//! goes to the zone whose colour covers most of the pixels of its footprint. A pixel counts for a
//! zone when every channel is within [`COLOUR_TOLERANCE`] of the zone's colour, so anti-aliased
//! edges and JPEG noise do not leave cells without a zone.

use super::ZoneSpec;
use crate::data::Grid;
use crate::error::{Error, Result};
use ndarray::Array2;
use std::path::Path;

/// Largest per-channel difference (of 255) at which a pixel still has a zone's colour.
pub const COLOUR_TOLERANCE: u8 = 40;

/// Parses `#rrggbb` (or `rrggbb`) into RGB.
pub fn parse_colour(s: &str) -> Option<[u8; 3]> {
    let h = s.strip_prefix('#').unwrap_or(s);
    if h.len() != 6 || !h.is_ascii() {
        return None;
    }
    let c = |i: usize| u8::from_str_radix(&h[i..i + 2], 16).ok();
    Some([c(0)?, c(2)?, c(4)?])
}

/// The zones' colours, checked: each zone has one, it parses, no polygon, no two alike.
fn colours(zones: &[ZoneSpec], file: &Path) -> Result<Vec<[u8; 3]>> {
    let bad = |msg: String| Error::file(file, msg);
    let mut out: Vec<[u8; 3]> = Vec::with_capacity(zones.len());
    for (k, z) in zones.iter().enumerate() {
        if !z.polygon.is_empty() {
            return Err(bad(format!(
                "zones[{k}] ('{}'): give a polygon or a mask colour, not both",
                z.name
            )));
        }
        let Some(text) = &z.colour else {
            return Err(bad(format!(
                "zones[{k}].colour ('{}'): with a mask image every zone needs its colour",
                z.name
            )));
        };
        let Some(c) = parse_colour(text) else {
            return Err(bad(format!(
                "zones[{k}].colour ('{}'): '{text}' is not #rrggbb",
                z.name
            )));
        };
        if let Some(j) = out.iter().position(|o| *o == c) {
            return Err(bad(format!(
                "zones '{}' and '{}' have the same colour {text}",
                zones[j].name, z.name
            )));
        }
        out.push(c);
    }
    Ok(out)
}

/// The zone of each accessible cell of `g` from the mask image `mask` (errors name the zones
/// `file`, or the mask for an unreadable image): a cell no zone's colour covers is an error
/// naming the cell and the colour found there.
pub fn assign(
    zones: &[ZoneSpec],
    mask: &Path,
    file: &Path,
    g: &Grid,
    obstacles: &Array2<u8>,
) -> Result<Vec<Option<usize>>> {
    let cols = colours(zones, file)?;
    let img = read_rgb(mask)?;
    let mut cell_zone = vec![None; g.nx * g.ny];
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            if obstacles[[iy, ix]] != 0 {
                continue;
            }
            let (votes, centre) = img.votes(&cols, (ix, iy), (g.nx, g.ny));
            let best = (0..cols.len())
                .filter(|&k| votes[k] > 0)
                .max_by(|&a, &b| votes[a].cmp(&votes[b]).then(b.cmp(&a)));
            match best {
                Some(k) => cell_zone[iy * g.nx + ix] = Some(k),
                None => {
                    let c = g.centre(ix, iy);
                    return Err(Error::file(
                        file,
                        format!(
                            "cell ({ix}, {iy}), centre ({:.3}, {:.3}), is in no zone: the mask \
                             shows #{:02x}{:02x}{:02x} there, no zone's colour",
                            c[0], c[1], centre[0], centre[1], centre[2]
                        ),
                    ));
                }
            }
        }
    }
    Ok(cell_zone)
}

/// An RGB image, rows top to bottom.
pub struct Rgb {
    pub width: usize,
    pub height: usize,
    pub data: Vec<u8>,
}

impl Rgb {
    /// Votes per colour among the pixels of cell `(ix, iy)` of an `nx × ny` grid stretched over
    /// the image (grid row 0 at the image's bottom), and the colour at the cell's centre.
    fn votes(
        &self,
        cols: &[[u8; 3]],
        (ix, iy): (usize, usize),
        (nx, ny): (usize, usize),
    ) -> (Vec<usize>, [u8; 3]) {
        let (w, h) = (self.width, self.height);
        let x0 = ix * w / nx;
        let x1 = ((ix + 1) * w / nx).max(x0 + 1).min(w);
        let top = ny - 1 - iy;
        let y0 = top * h / ny;
        let y1 = ((top + 1) * h / ny).max(y0 + 1).min(h);
        let px = |x: usize, y: usize| {
            let i = 3 * (y.min(h - 1) * w + x.min(w - 1));
            [self.data[i], self.data[i + 1], self.data[i + 2]]
        };
        let mut votes = vec![0usize; cols.len()];
        for y in y0..y1 {
            for x in x0..x1 {
                let p = px(x, y);
                let near = cols
                    .iter()
                    .map(|c| (0..3).map(|k| p[k].abs_diff(c[k])).max().unwrap_or(0))
                    .enumerate()
                    .filter(|(_, d)| *d <= COLOUR_TOLERANCE)
                    .min_by_key(|(_, d)| *d);
                if let Some((k, _)) = near {
                    votes[k] += 1;
                }
            }
        }
        (votes, px((x0 + x1) / 2, (y0 + y1) / 2))
    }
}

/// Reads a colour image (any format OpenCV reads) as RGB.
#[cfg(feature = "video")]
pub fn read_rgb(path: &Path) -> Result<Rgb> {
    use opencv::prelude::*;
    let _ = opencv::core::set_log_level(opencv::core::LogLevel::LOG_LEVEL_SILENT);
    if !path.is_file() {
        return Err(Error::file(path, "cannot read: no such file"));
    }
    let cv = |e: opencv::Error| Error::file(path, format!("OpenCV: {}", e.message));
    let img =
        opencv::imgcodecs::imread(path.as_os_str(), opencv::imgcodecs::IMREAD_COLOR).map_err(cv)?;
    if img.empty() {
        return Err(Error::file(path, "cannot read as an image"));
    }
    let (width, height) = (img.cols() as usize, img.rows() as usize);
    let bgr = img.data_bytes().map_err(cv)?;
    let data = bgr
        .chunks_exact(3)
        .flat_map(|p| [p[2], p[1], p[0]])
        .collect();
    Ok(Rgb {
        width,
        height,
        data,
    })
}

/// Without OpenCV no image can be read.
#[cfg(not(feature = "video"))]
pub fn read_rgb(path: &Path) -> Result<Rgb> {
    Err(Error::file(
        path,
        "mask images need the `video` feature (OpenCV)",
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn colours_parse() {
        assert_eq!(parse_colour("#ff8000"), Some([255, 128, 0]));
        assert_eq!(parse_colour("00ff00"), Some([0, 255, 0]));
        assert_eq!(parse_colour("#ff80"), None);
        assert_eq!(parse_colour("#gg0000"), None);
        assert_eq!(parse_colour("#ffé000"), None);
    }

    #[test]
    fn votes_follow_the_image_orientation() {
        // 4 × 2 image: top row red, bottom row blue; a 1 × 2 grid's row 0 is the bottom.
        let red = [255u8, 0, 0];
        let blue = [0u8, 0, 255];
        let mut data = Vec::new();
        for _ in 0..4 {
            data.extend(red);
        }
        for _ in 0..4 {
            data.extend(blue);
        }
        let img = Rgb {
            width: 4,
            height: 2,
            data,
        };
        let cols = [red, blue];
        assert_eq!(img.votes(&cols, (0, 0), (1, 2)).0, vec![0, 4]);
        assert_eq!(img.votes(&cols, (0, 1), (1, 2)).0, vec![4, 0]);
        // A near colour (JPEG noise) still votes; a far one does not.
        let img2 = Rgb {
            width: 1,
            height: 1,
            data: vec![230, 20, 10],
        };
        assert_eq!(img2.votes(&cols, (0, 0), (1, 1)).0, vec![1, 0]);
        let img3 = Rgb {
            width: 1,
            height: 1,
            data: vec![128, 128, 128],
        };
        assert_eq!(img3.votes(&cols, (0, 0), (1, 1)).0, vec![0, 0]);
    }
}
