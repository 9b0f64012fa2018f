//! Zones of a clip (paper §7.2.4, the seals' ocean, shoreline and in-shore): named polygons in
//! the clip's coordinates (BL, y up), assigned to the clip's
//! cells by their centres. Every accessible cell belongs to exactly one zone; the fit learns one
//! parameter set per zone, each agent using its cell's zone's set.

use crate::data::polygon::in_polygon;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

mod mask;

/// Schema tag of a zones file.
pub const ZONES_SCHEMA: &str = "herdfit.zones/1";

/// One zone: its name, its polygon (or its colour in the file's mask image) and optionally a
/// fixed speed.
#[derive(Clone, Debug, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZoneSpec {
    pub name: String,
    /// Corners in the clip's coordinates (BL, y up), a closed ring (zones without a mask).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub polygon: Vec<[f64; 2]>,
    /// The zone's colour in the mask image, `#rrggbb` (zones with a mask).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub colour: Option<String>,
    /// A fixed mean speed v_μ (BL/s) of eq. 6 inside the zone (the paper's seals: 3.0 in water,
    /// 0.5 on land); without it the clip's speed model applies.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub speed: Option<f64>,
}

/// A zones file (`herdfit.zones/1`): polygons, or a mask image whose colours name the zones.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ZonesFile {
    pub schema: String,
    /// A mask image stretched over the clip's grid (row 0 of the image at the top), path
    /// relative to the zones file; each zone names its `colour` in it.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub mask: Option<PathBuf>,
    pub zones: Vec<ZoneSpec>,
}

/// Zones assigned to a clip's cells.
#[derive(Clone, Debug)]
pub struct Zones {
    pub specs: Vec<ZoneSpec>,
    /// Per cell (row-major, row 0 at the bottom): its zone, or `None` for an obstacle cell.
    pub cell_zone: Vec<Option<usize>>,
    pub nx: usize,
    /// The file the zones came from (for messages).
    pub file: PathBuf,
    /// The mask image the cells were assigned from (resolved), if any.
    pub mask: Option<PathBuf>,
}

/// The largest fixed zone speed accepted (BL/s).
pub const MAX_ZONE_SPEED: f64 = 100.0;

impl Zones {
    /// Reads a zones file and assigns the clip's cells; errors name the file and the key.
    pub fn load(path: &Path, clip: &ClipFields) -> Result<Zones> {
        let text = crate::data::atomic::read_input_text(path)?;
        let file: ZonesFile = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a zones file: {e}")))?;
        Zones::of_file(file, path, &clip.grid(), &clip.obstacles)
    }

    /// Checks the zones and assigns every accessible cell of grid `g` to the zone whose polygon
    /// holds its centre: overlapping zones, unassigned cells, bad polygons and speeds are
    /// errors naming the file, the zone and the cell.
    pub fn of_file(
        file: ZonesFile,
        path: &Path,
        g: &crate::data::Grid,
        obstacles: &ndarray::Array2<u8>,
    ) -> Result<Zones> {
        let bad = |msg: String| Error::file(path, msg);
        if file.schema != ZONES_SCHEMA {
            return Err(bad(format!(
                "schema: '{}' is not {ZONES_SCHEMA}",
                file.schema
            )));
        }
        if file.zones.is_empty() {
            return Err(bad("zones: give at least one zone".into()));
        }
        for (k, z) in file.zones.iter().enumerate() {
            if file.zones[..k].iter().any(|o| o.name == z.name) {
                return Err(bad(format!("zones[{k}].name: '{}' is used twice", z.name)));
            }
            if let Some(v) = z.speed {
                if !(v.is_finite() && v > 0.0 && v <= MAX_ZONE_SPEED) {
                    return Err(bad(format!(
                        "zones[{k}].speed ('{}'): {v} is not a speed in (0, {MAX_ZONE_SPEED}] BL/s",
                        z.name
                    )));
                }
            }
        }
        if let Some(mask) = &file.mask {
            let mask = match path.parent() {
                Some(d) if mask.is_relative() => d.join(mask),
                _ => mask.clone(),
            };
            let cell_zone = mask::assign(&file.zones, &mask, path, g, obstacles)?;
            return Ok(Zones {
                specs: file.zones,
                cell_zone,
                nx: g.nx,
                file: path.to_path_buf(),
                mask: Some(mask),
            });
        }
        for (k, z) in file.zones.iter().enumerate() {
            if z.colour.is_some() {
                return Err(bad(format!(
                    "zones[{k}].colour ('{}'): a colour needs a mask image (\"mask\")",
                    z.name
                )));
            }
            if let Some(m) = crate::data::polygon::polygon_problem(&z.polygon) {
                return Err(bad(format!("zones[{k}].polygon ('{}'): {m}", z.name)));
            }
        }
        let mut cell_zone = vec![None; g.nx * g.ny];
        for iy in 0..g.ny {
            for ix in 0..g.nx {
                if obstacles[[iy, ix]] != 0 {
                    continue;
                }
                let c = g.centre(ix, iy);
                let mut hit = file
                    .zones
                    .iter()
                    .enumerate()
                    .filter(|(_, z)| in_polygon(c, &z.polygon))
                    .map(|(k, _)| k);
                let first = hit.next();
                if let (Some(a), Some(b)) = (first, hit.next()) {
                    return Err(bad(format!(
                        "zones '{}' and '{}' overlap at cell ({ix}, {iy}), centre ({:.3}, {:.3})",
                        file.zones[a].name, file.zones[b].name, c[0], c[1]
                    )));
                }
                match first {
                    Some(k) => cell_zone[iy * g.nx + ix] = Some(k),
                    None => {
                        return Err(bad(format!(
                            "cell ({ix}, {iy}), centre ({:.3}, {:.3}), is in no zone",
                            c[0], c[1]
                        )))
                    }
                }
            }
        }
        Ok(Zones {
            specs: file.zones,
            cell_zone,
            nx: g.nx,
            file: path.to_path_buf(),
            mask: None,
        })
    }

    /// The fixed zone speeds as a per-cell map of grid `g` (the grid the zones were assigned
    /// on), or `None` when no zone fixes its speed.
    pub fn speed_map(&self, g: &crate::data::Grid) -> Option<crate::herd::sim::SpeedMap> {
        self.specs
            .iter()
            .any(|z| z.speed.is_some())
            .then(|| crate::herd::sim::SpeedMap {
                grid: *g,
                speed: self
                    .cell_zone
                    .iter()
                    .map(|z| z.and_then(|k| self.specs[k].speed))
                    .collect(),
            })
    }

    /// The number of zones.
    pub fn len(&self) -> usize {
        self.specs.len()
    }

    /// Whether there are no zones (never, once loaded).
    pub fn is_empty(&self) -> bool {
        self.specs.is_empty()
    }

    /// The zone of a cell index (`iy·nx + ix`); agents outside the grid or on an obstacle cell
    /// use zone 0.
    pub fn zone_of_cell(&self, cell: i64) -> usize {
        usize::try_from(cell)
            .ok()
            .and_then(|c| self.cell_zone.get(c).copied().flatten())
            .unwrap_or(0)
    }

    /// Every zone must hold agents in the frames fitted: a zone that never does has nothing to
    /// learn from (error naming the file and the zone).
    pub fn check_agents(&self, clip: &ClipFields, frames: Range<usize>) -> Result<()> {
        let area = clip.meta.cell_size * clip.meta.cell_size;
        let mut count = vec![0.0f64; self.len()];
        for f in frames.clone() {
            for (c, z) in self.cell_zone.iter().enumerate() {
                if let Some(z) = z {
                    let (iy, ix) = (c / self.nx, c % self.nx);
                    count[*z] += clip.density[[f, iy, ix]] as f64 * area;
                }
            }
        }
        for (k, n) in count.iter().enumerate() {
            if *n < 0.5 {
                return Err(Error::file(
                    &self.file,
                    format!(
                        "zone '{}' holds no agents in frames {}..{}: nothing to fit there",
                        self.specs[k].name, frames.start, frames.end
                    ),
                ));
            }
        }
        Ok(())
    }
}
