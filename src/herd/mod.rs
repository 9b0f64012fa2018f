//! Herds From Video (the paper, `papers/herds-from-video.md`): the 12-parameter herd model and
//! everything built on it — parameters ([`params`]), the differentiable step ([`sim`]), the fit
//! (paper §6, [`fit`]), held-out validation (§7.1, [`validate`]), gradient checks
//! ([`gradcheck`]), synthetic clips with known truth ([`synth`]), timing ([`bench`](mod@bench)) and
//! authoring new scenes (§7.3–7.5, [`author`]).
//!
//! This folder imports no other subsystem; it builds on the shared layers `data`, `measure`,
//! `optim`, `video` and the `herdfit-kernels` crate.

pub mod ablate;
pub mod anchors;
pub mod author;
pub mod bench;
pub mod boundary;
pub mod demo;
pub mod eval;
pub mod fit;
pub mod gradcheck;
pub mod guidance;
pub mod import_tracks;
pub mod params;
pub mod scenario;
pub mod sets;
pub mod sim;
pub mod simulate;
pub mod start;
pub mod synth;
pub mod track_fit;
pub mod uncertainty;
pub mod validate;
pub mod zoned;
pub mod zones;
