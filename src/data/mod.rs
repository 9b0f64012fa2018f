//! On-disk formats shared by herdfit's systems: each has a schema tag, load/save and validation.
//! No model types live here.

pub mod camera;
pub mod gltf;
pub mod jackdaw;
pub mod tracks;
