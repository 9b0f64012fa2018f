//! herdfit: learn how animal groups move from video and replay that behaviour anywhere.
//!
//! The pipeline (see `ARCHITECTURE.md`): clip fields → fit → parameter set → simulate/author.
//! This crate holds the differentiable herd model ([`sim`]), its parameters ([`params`]), the
//! gradient checks ([`train::gradcheck`]) and the command-line interface ([`cli`]).

pub mod author;
pub mod backend;
pub mod bench;
pub mod cli;
pub mod data;
pub mod error;
pub mod fields;
pub mod io;
pub mod lift;
pub mod metrics;
pub mod params;
pub mod plot;
pub mod progress;
pub mod sim;
pub mod synth;
pub mod train;
pub mod validate;
#[cfg(feature = "video")]
pub mod video;

pub use error::{Error, Result};
