//! The shape-parameter file (`herdfit.flock-shape/1`, written by `flock extract`, read by `flock
//! animate`): save, load, and the checks a file read back must pass — every value within the
//! range a formation can have (issue #47: a `mean_gap` of 1e300 reached a solver's bounds and
//! panicked).

use super::extract::{ShapeParams, SHAPE_SCHEMA};
use crate::error::{Error, Result};
use std::path::Path;

impl ShapeParams {
    /// Writes the JSON atomically.
    pub fn save(&self, path: &Path) -> Result<()> {
        let s = serde_json::to_string_pretty(self)
            .map_err(|e| Error::Internal(format!("shape parameters: {e}")))?;
        crate::data::atomic::write_atomic(path, format!("{s}\n").as_bytes())
    }

    /// Reads and checks a shape-parameter file.
    pub fn load(path: &Path) -> Result<Self> {
        let text = crate::data::atomic::read_input_text(path)?;
        let p: ShapeParams = serde_json::from_str(&text)
            .map_err(|e| Error::file(path, format!("not a flock shape file: {e}")))?;
        p.check().map_err(|e| e.in_file(path))?;
        Ok(p)
    }

    /// Checks the schema tag and the values the steady flight relies on.
    pub fn check(&self) -> Result<()> {
        if self.schema != SHAPE_SCHEMA {
            return Err(Error::invalid(format!(
                "schema is '{}', expected '{SHAPE_SCHEMA}'",
                self.schema
            )));
        }
        if self.frames.is_empty() {
            return Err(Error::invalid("frames is empty"));
        }
        use crate::limits::{within, MAX_COORD};
        if !(self.wingspan.is_finite() && self.wingspan > 0.0) {
            return Err(Error::invalid(format!(
                "wingspan = {} must be > 0",
                self.wingspan
            )));
        }
        within("wingspan", self.wingspan, 0.0, MAX_COORD)?;
        within("heading_deg", self.heading_deg, -360.0, 360.0)?;
        for f in &self.frames {
            let bad = |m: &str| Error::invalid(format!("frame {}: {m}", f.frame));
            if f.birds.len() < 3 {
                return Err(bad("fewer than 3 birds"));
            }
            // Wingspans: a formation's gaps and deviations are a few wingspans; beyond 100 the
            // shape cannot be flown (and the solver's ranges overflow, issue #47).
            let at = |e: Error| bad(&e.to_string());
            within("mean_gap", f.mean_gap, 0.0, 100.0).map_err(at)?;
            within("std_gap", f.std_gap, 0.0, 100.0).map_err(at)?;
            within("mean_dev", f.mean_dev, -100.0, 100.0).map_err(at)?;
            within("std_dev", f.std_dev, 0.0, 100.0).map_err(at)?;
            for b in &f.birds {
                for (k, v) in [("x", b.x), ("y", b.y), ("dy", b.dy)] {
                    within(&format!("bird {} {k}", b.id), v, -1e4, 1e4).map_err(at)?;
                }
                if let Some(xi) = b.xi {
                    within(&format!("bird {} xi", b.id), xi, -1e3, 1e3).map_err(at)?;
                }
            }
            for s in [&f.left, &f.right].into_iter().flatten() {
                within("side angle_deg", s.angle_deg, -180.0, 180.0).map_err(at)?;
                for c in &s.coef {
                    within("side coef", *c, -1e6, 1e6).map_err(at)?;
                }
            }
            if !(f.mean_gap.is_finite() && f.mean_gap > 0.0 && f.std_gap.is_finite()) {
                return Err(bad("mean_gap/std_gap not positive and finite"));
            }
            if !(f.mean_dev.is_finite() && f.std_dev.is_finite() && f.std_dev >= 0.0) {
                return Err(bad("mean_dev/std_dev not finite"));
            }
            if f.left.is_none() && f.right.is_none() {
                return Err(bad("no side fit"));
            }
            for s in [&f.left, &f.right].into_iter().flatten() {
                if s.coef.len() != s.model.params() || s.coef.iter().any(|c| !c.is_finite()) {
                    return Err(bad("side coefficients malformed"));
                }
            }
        }
        Ok(())
    }
}
