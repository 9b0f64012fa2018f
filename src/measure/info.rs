//! A clip's summary (`herdfit fields-info`): grid, frames, agents, speed model, and the emergent
//! measures of every frame from its fields.

use crate::data::atomic::write_atomic;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::measure::emergent::{clip_measures, FrameMeasures};
use std::path::Path;

/// Schema tag of `fields-info --json` files.
pub const FIELDS_INFO_SCHEMA: &str = "herdfit.fields-info/1";

/// The summary of a clip.
#[derive(Clone, Debug)]
pub struct FieldsInfo<'a> {
    /// The clip's name (its folder).
    pub name: String,
    pub clip: &'a ClipFields,
    pub obstacle_cells: usize,
    /// Agents, polarization and angular momentum of every frame.
    pub frames: Vec<FrameMeasures>,
}

impl<'a> FieldsInfo<'a> {
    /// Measures `clip`, named `name`.
    pub fn new(name: &str, clip: &'a ClipFields) -> Self {
        FieldsInfo {
            name: name.to_string(),
            clip,
            obstacle_cells: clip.obstacles.iter().filter(|&&v| v != 0).count(),
            frames: clip_measures(clip),
        }
    }

    /// The summary and the per-frame measures as JSON.
    pub fn to_json(&self) -> serde_json::Value {
        serde_json::json!({
            "schema": FIELDS_INFO_SCHEMA,
            "clip": self.name,
            "meta": self.clip.meta,
            "obstacle_cells": self.obstacle_cells,
            "frames": self.frames,
        })
    }

    /// Writes [`FieldsInfo::to_json`] to `path`.
    pub fn save(&self, path: &Path) -> Result<()> {
        let text = serde_json::to_string_pretty(&self.to_json())
            .map_err(|e| Error::Internal(format!("serialising: {e}")))?;
        write_atomic(path, format!("{text}\n").as_bytes())
    }
}

impl std::fmt::Display for FieldsInfo<'_> {
    /// The table `herdfit fields-info` prints.
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        let m = &self.clip.meta;
        let counts: Vec<f64> = self.frames.iter().map(|x| x.agents).collect();
        let mean = counts.iter().sum::<f64>() / counts.len() as f64;
        writeln!(f, "clip        {}", self.name)?;
        writeln!(
            f,
            "grid        {}×{} cells of {} BL (origin {:?}), {} obstacle cells",
            m.nx, m.ny, m.cell_size, m.origin, self.obstacle_cells
        )?;
        writeln!(
            f,
            "frames      {} at {} fps ({:.2} s)",
            m.frames,
            m.fps,
            m.frames as f64 / m.fps
        )?;
        writeln!(
            f,
            "agents      min {:.1}, mean {:.1}, max {:.1} per frame (Σ density × cell area)",
            counts.iter().cloned().fold(f64::INFINITY, f64::min),
            mean,
            counts.iter().cloned().fold(0.0, f64::max)
        )?;
        writeln!(
            f,
            "speed       mean {:.4} BL/s, std {:.4} BL/s, {} speed–density rows",
            m.speed.mean,
            m.speed.std,
            m.speed.density_table.len()
        )?;
        for r in &m.speed.density_table {
            writeln!(
                f,
                "              density {:.4} agents/BL² → {:.4} BL/s",
                r[0], r[1]
            )?;
        }
        writeln!(
            f,
            "{:>6} {:>10} {:>13} {:>18} {:>18}",
            "frame", "agents", "polarization", "ang.mom centroid", "ang.mom centre"
        )?;
        for x in &self.frames {
            writeln!(
                f,
                "{:>6} {:>10.2} {:>13.4} {:>18.4} {:>18.4}",
                x.frame,
                x.agents,
                x.polarization,
                x.angular_momentum_centroid,
                x.angular_momentum_frame_centre
            )?;
        }
        Ok(())
    }
}
