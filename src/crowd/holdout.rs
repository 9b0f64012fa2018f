//! The split-in-time check of a learnt crowd on real tracks (`crowd holdout`): the tracks are cut
//! at the frame before which lie half their agent-frames; a model learnt from the first part
//! simulates the second part's entries (each individual enters where and when it appeared, heads
//! for where it was last seen and leaves when it was), and the second part is compared with the
//! simulation and with the first part. A measure holds when the simulation is no farther from the
//! second part than `limit` × the first part is (1-Wasserstein distances of [`measures`]).
//!
//! [`measures`]: super::measure::measures

use super::features::Scene;
use super::layout::Layout;
use super::measure::compare;
use super::model::{learn, LearnConfig};
use super::sim::{entries_from_tracks, simulate, SimConfig};
use crate::data::tracks::Tracks;
use crate::error::{Error, Result};
use crate::progress::Progress;
use serde::{Deserialize, Serialize};

/// Schema tag of holdout reports.
pub const HOLDOUT_SCHEMA: &str = "herdfit.crowd-holdout/1";

/// Settings of `crowd holdout`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HoldoutConfig {
    /// How the model is learnt from the first part (default [`LearnConfig::pedestrians`]).
    pub learn: LearnConfig,
    /// How the second part's entries are simulated.
    pub sim: SimConfig,
    /// Fraction of the agent-frames in the first (learning) part.
    pub split: f64,
    /// A measure holds when its simulated distance is at most this many times the halves'.
    pub limit: f64,
    /// Agents leave on reaching their goals (or when their time is up) instead of when the real
    /// ones left (`crowd simulate --leave-at-goal`).
    pub leave_at_goal: bool,
}

impl Default for HoldoutConfig {
    fn default() -> Self {
        HoldoutConfig {
            learn: LearnConfig::pedestrians(),
            sim: SimConfig {
                seed: 1,
                ..SimConfig::default()
            },
            split: 0.5,
            limit: 2.0,
            leave_at_goal: false,
        }
    }
}

impl HoldoutConfig {
    /// Checks every value; errors name the key.
    pub fn check(&self) -> Result<()> {
        self.learn.check()?;
        self.sim.check()?;
        if !(self.split > 0.0 && self.split < 1.0) {
            return Err(Error::invalid(format!(
                "split = {} must be in (0, 1)",
                self.split
            )));
        }
        if !(self.limit.is_finite() && self.limit > 0.0) {
            return Err(Error::invalid(format!(
                "limit = {} must be > 0",
                self.limit
            )));
        }
        Ok(())
    }
}

/// One measure of the check.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HoldoutRow {
    pub name: String,
    pub unit: String,
    /// Means over the first part, the second part and the simulation.
    pub learn_mean: f64,
    pub test_mean: f64,
    pub simulated_mean: f64,
    /// W1 between the two real parts.
    pub halves: f64,
    /// W1 between the simulation and the second part.
    pub simulated: f64,
    /// `simulated / halves`.
    pub ratio: f64,
    /// `ratio ≤ limit`.
    pub holds: bool,
}

/// The report of `crowd holdout` (`herdfit.crowd-holdout/1`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct HoldoutReport {
    pub schema: String,
    pub source: String,
    /// The first frame of the second part (the tracks' own frame numbers).
    pub split_frame: u64,
    pub learn_agent_frames: usize,
    pub test_agent_frames: usize,
    /// Individuals of the second part simulated (its entries).
    pub agents: usize,
    /// State–action samples of the model.
    pub samples: usize,
    pub measures: Vec<HoldoutRow>,
    pub config: HoldoutConfig,
}

/// The report and the simulated tracks.
pub struct Holdout {
    pub report: HoldoutReport,
    pub simulated: Tracks,
}

/// Cuts tracks in time: the rows before the first frame at or past the `fraction` quantile of
/// the agent-frames, and the rest. Errors: a part with fewer than two individuals.
pub fn split_in_time(t: &Tracks, fraction: f64) -> Result<(Tracks, Tracks, u64)> {
    if t.rows.is_empty() {
        return Err(Error::invalid("no rows to split"));
    }
    let i = ((t.rows.len() as f64 * fraction) as usize).min(t.rows.len() - 1);
    let at = t.rows[i].frame;
    let (a, b): (Vec<_>, Vec<_>) = t.rows.iter().cloned().partition(|r| r.frame < at);
    let part = |rows, which: &str| {
        let p = Tracks::new(t.meta.clone(), rows)?;
        if p.ids().len() < 2 {
            return Err(Error::invalid(format!(
                "the {which} part of the split (frame {at}) holds fewer than 2 individuals"
            )));
        }
        Ok(p)
    };
    Ok((part(a, "first")?, part(b, "second")?, at))
}

/// Runs the check on `tracks` (`source` names them in the report), the simulation inside
/// `layout`'s walls and obstacles when given.
pub fn holdout(
    tracks: &Tracks,
    layout: Option<&Layout>,
    cfg: &HoldoutConfig,
    source: &str,
    progress: &mut dyn Progress,
) -> Result<Holdout> {
    cfg.check()?;
    let (first, second, split_frame) = split_in_time(tracks, cfg.split)?;
    let model = learn(std::slice::from_ref(&first), &cfg.learn, progress)?;
    let test = Scene::from_tracks(&second, 0.0)?;
    let mut entries = entries_from_tracks(&test);
    if cfg.leave_at_goal {
        entries.iter_mut().for_each(|e| e.leave = None);
    }
    let run = simulate(&model, layout, &entries, &cfg.sim, progress)?;
    let sim = Scene::from_tracks(&run.tracks, 0.0)?;
    let learnt = Scene::from_tracks(&first, 0.0)?;
    let still = cfg.learn.features.still_speed;
    let units = tracks.meta.units.as_str();
    let halves = compare(&test, &learnt, "second", "first", still, units, 1.0)?;
    let simulated = compare(&test, &sim, "second", "simulated", still, units, 1.0)?;
    let measures = halves
        .measures
        .iter()
        .zip(&simulated.measures)
        .map(|(h, s)| {
            let ratio = s.wasserstein / h.wasserstein;
            HoldoutRow {
                name: h.name.clone(),
                unit: h.unit.clone(),
                learn_mean: h.mean_b,
                test_mean: h.mean_a,
                simulated_mean: s.mean_b,
                halves: h.wasserstein,
                simulated: s.wasserstein,
                ratio,
                holds: ratio <= cfg.limit,
            }
        })
        .collect();
    Ok(Holdout {
        report: HoldoutReport {
            schema: HOLDOUT_SCHEMA.into(),
            source: source.into(),
            split_frame,
            learn_agent_frames: first.rows.len(),
            test_agent_frames: second.rows.len(),
            agents: entries.len(),
            samples: model.samples(),
            measures,
            config: cfg.clone(),
        },
        simulated: run.tracks,
    })
}

impl std::fmt::Display for HoldoutReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "{}: learnt from {} agent-frames before frame {} ({} samples), simulated the {} \
             individuals of the {} after it",
            self.source,
            self.learn_agent_frames,
            self.split_frame,
            self.samples,
            self.agents,
            self.test_agent_frames
        )?;
        writeln!(
            f,
            "{:<18} {:>9} {:>9} {:>9} {:>11} {:>11} {:>7}",
            "measure", "mean 1st", "mean 2nd", "mean sim", "W1 halves", "W1 sim", "ratio"
        )?;
        for m in &self.measures {
            writeln!(
                f,
                "{:<18} {:>9.3} {:>9.3} {:>9.3} {:>11.4} {:>11.4} {:>6.2}{} {}",
                m.name,
                m.learn_mean,
                m.test_mean,
                m.simulated_mean,
                m.halves,
                m.simulated,
                m.ratio,
                if m.holds { " " } else { "!" },
                m.unit
            )?;
        }
        let held = self.measures.iter().filter(|m| m.holds).count();
        write!(
            f,
            "{held} of {} measures within {}× the distance between the real halves",
            self.measures.len(),
            self.config.limit
        )
    }
}
