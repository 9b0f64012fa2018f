//! On-disk formats shared by herdfit's systems: each has a schema tag, load/save and validation,
//! and every file is written atomically ([`atomic`]). No model types live here.

pub mod agents;
pub mod atomic;
pub mod cells;
pub mod clip;
pub mod reference;
pub mod tracks;

pub use agents::AgentRow;
pub use clip::{ClipFields, ClipMeta, ClipSpeed, Grid, CLIP_SCHEMA};
