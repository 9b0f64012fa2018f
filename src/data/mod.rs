//! On-disk formats shared by herdfit's systems: each has a schema tag, load/save and validation,
//! and every file is written atomically ([`atomic`]). No model types live here.

pub mod agents;
pub mod atomic;
pub mod boundary;
pub mod camera;
pub mod cells;
pub mod clip;
pub mod csv;
pub mod gltf;
pub mod jackdaw;
pub mod npy_tracks;
pub mod obstacle_polygons;
pub mod polygon;
pub mod reference;
pub mod tracks;

pub use agents::AgentRow;

/// `Err("schema is 'found', expected 'expected'")` unless the schema tag is the expected one.
pub fn check_schema(found: &str, expected: &str) -> Result<(), String> {
    if found == expected {
        Ok(())
    } else {
        Err(format!("schema is '{found}', expected '{expected}'"))
    }
}
pub use clip::{ClipFields, ClipMeta, ClipSpeed, FrameMeasures, Grid, CLIP_SCHEMA};
