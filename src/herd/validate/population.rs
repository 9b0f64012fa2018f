//! A validation's account of the open boundary ([`crate::herd::boundary`]): what entered and
//! left in each set's runs and the count in view frame by frame, beside the video's.

use super::SimRun;
use crate::data::boundary::Gates;
use serde::Serialize;

/// The open boundary a validation ran through.
#[derive(Clone, Debug, Serialize)]
pub struct BoundaryReport {
    pub gates: Gates,
    /// Animals in the video's view at each held-out frame.
    pub video_count: Vec<f64>,
}

/// A set's herd through an open boundary, averaged over the seeds.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Population {
    /// Agents that entered at the entry gates, per run.
    pub entered: f64,
    /// Agents removed after leaving the grid, per run, per side (left, right, bottom, top).
    pub left: [f64; 4],
    /// Of those, agents removed in an exit cell before crossing its edge (the run holding more
    /// than the video's count), per run.
    pub early: f64,
    /// Agents inside the grid at each held-out frame.
    pub count: Vec<f64>,
}

impl Population {
    pub(super) fn new(frames: usize) -> Self {
        Population {
            count: vec![0.0; frames],
            ..Default::default()
        }
    }

    /// Adds one run with weight `w` (1/seeds).
    pub(super) fn add(&mut self, run: &SimRun, w: f64) {
        self.entered += w * run.crossings.entered as f64;
        self.early += w * run.crossings.early as f64;
        for (a, b) in self.left.iter_mut().zip(run.crossings.left) {
            *a += w * b as f64;
        }
        for (k, c) in self.count.iter_mut().enumerate() {
            *c += w * run.fields.count(k);
        }
    }

    /// The largest relative difference between this count and the video's, over the frames.
    pub fn worst_deviation(&self, video: &[f64]) -> f64 {
        self.count
            .iter()
            .zip(video)
            .map(|(s, v)| (s - v).abs() / v.max(1.0))
            .fold(0.0, f64::max)
    }
}
