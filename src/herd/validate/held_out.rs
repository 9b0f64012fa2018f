//! What every validation report states of its run ([`HeldOut`]), flattened into its JSON.

use crate::backend::Compute;
use serde::Serialize;

/// What every validation report states of its run (flattened into its JSON): the schema, the
/// clip, the held-out frames, the split, the coarse grid and the seeds.
#[derive(Clone, Debug, Serialize)]
pub struct HeldOut {
    /// [`super::VALIDATION_SCHEMA`], or the zone report's.
    pub schema: String,
    pub clip: String,
    pub frames: [usize; 2],
    pub split: f64,
    /// The coarse grid of the errors ([`super::ValidateConfig::coarse_grid`]).
    pub grid: usize,
    pub seeds: usize,
    /// [`super::ValidateConfig::horizon`], when the herd was drawn afresh every so many frames.
    #[serde(skip_serializing_if = "is_zero")]
    pub horizon: usize,
    /// [`super::ValidateConfig::tracks`], when every run started from the tracked animals.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tracks: Option<String>,
    /// [`super::ValidateConfig::device`], when the runs were not on the CPU.
    #[serde(skip_serializing_if = "Compute::is_cpu")]
    pub device: Compute,
}

fn is_zero(x: &usize) -> bool {
    *x == 0
}

impl HeldOut {
    /// "Clip `C`, held-out frames a..b (split s), k seed(s), errors on a g×g coarse grid".
    pub fn summary(&self) -> String {
        let horizon = match self.horizon {
            0 => String::new(),
            h => format!(", the herd drawn afresh from the clip every {h} frames"),
        };
        let tracks = match (&self.tracks, self.horizon) {
            (None, _) => String::new(),
            (Some(t), 0) => format!(", the herd started from the animals tracked in `{t}`"),
            (Some(t), _) => format!(" (each time from the animals tracked in `{t}`)"),
        };
        let device = match self.device {
            Compute::Cpu => "",
            Compute::Gpu => ", simulated on the GPU",
        };
        format!(
            "Clip `{}`, held-out frames {}..{} (split {}), {} seed(s), errors on a {}×{} coarse grid{horizon}{tracks}{device}",
            self.clip, self.frames[0], self.frames[1], self.split, self.seeds, self.grid, self.grid
        )
    }
}
