//! One file per verb (cargo's `commands/` style): its flags, and `exec`, which turns them into
//! the library's job, makes one library call and prints the result.

pub mod ablate;
pub mod author;
pub mod bench;
pub mod crowd;
mod crowd_flags;
pub mod demo;
pub mod export_gltf;
pub mod extract;
pub mod fields_info;
pub mod fit;
pub mod fit_objective;
pub mod flock;
pub mod gradcheck;
pub mod import_reference;
pub mod import_tracks;
pub mod lift;
mod lift_print;
pub mod simulate;
pub mod synth;
pub mod track_fit;
pub mod validate;
pub mod validate_tracks;
