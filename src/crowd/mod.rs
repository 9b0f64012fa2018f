//! Crowds from tracked trajectories (Lee, Choi, Hong, Lee 2007, "Group Behavior from Video"):
//! learn how each individual acts given what it perceives, then simulate a virtual crowd that
//! behaves like the real one, in new layouts and at any size.
//!
//! Stages, one file each:
//! - [`features`]: tracks as segments, Gaussian smoothing (§3), the state of §4 (speed, eq. 1
//!   formation now and before, pivot, intended direction; Table 1 weights);
//! - [`pca`]: the state's principal components (§4);
//! - [`knn`]: kd-tree (own, widest-dimension splits; kiddo's as the peer) and brute-force k
//!   nearest samples (§5.1);
//! - [`action`]: the query: k-means output possibilities ([`kmeans`]), eq. 2 choice, eq. 3
//!   regression ([`lwr`]), §5.3 attraction;
//! - [`behaviour`]: rule-based labels and the behaviour machine's statistics (§6.1);
//! - [`model`]: learning and the `herdfit.crowd-model/1` file;
//! - [`layout`]: walls, obstacles, pivots, regions, spawns (`herdfit.crowd-layout/1`);
//! - [`step`], [`sim`]: perception → decision → move, groups and lines (§6); [`entries`]: who
//!   enters, where and when, and when they leave;
//! - [`eval`]: ETH/UCY leave-one-scene-out forecasting against constant velocity;
//! - [`holdout`]: real tracks split in time, the second part's entries simulated by a model
//!   learnt from the first, compared with both;
//! - [`measure`]: distributions, Wasserstein distances, density maps; [`render`]: PNG/AVI;
//! - [`synth`]: a social-force corridor crowd as a stand-in for video-tracked data.

pub mod action;
pub mod attract;
pub mod behaviour;
pub mod entries;
pub mod eval;
pub mod features;
pub mod forecast;
pub mod holdout;
pub mod kmeans;
pub mod knn;
pub mod layout;
pub mod lwr;
pub mod measure;
pub mod model;
pub mod pca;
pub mod render;
pub mod samples;
pub mod sim;
pub mod steer;
pub mod step;
pub mod synth;
pub mod tune;

use crate::error::{Error, Result};
use crate::progress::Progress;
use std::path::{Path, PathBuf};

/// What the crowd section of `herdfit demo` did.
pub struct DemoSummary {
    pub source_agents: usize,
    pub samples: usize,
    pub behaviours: Vec<String>,
    pub simulated_agents: usize,
    pub agent_steps: u64,
    pub seconds_simulating: f64,
    pub line_joins: usize,
    /// Agents that reached their exits before the hall's duration ran out.
    pub arrived: usize,
    pub comparison: measure::Comparison,
    pub picture: PathBuf,
    pub out: PathBuf,
}

impl std::fmt::Display for DemoSummary {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(
            f,
            "crowd: learnt {} state–action samples ({}) from {} walkers of a social-force corridor",
            self.samples,
            self.behaviours.join(", "),
            self.source_agents
        )?;
        writeln!(
            f,
            "crowd: simulated {} agents in a new hall with a pillar and a ticket line ({} joined it, \
             {} reached their exits): {} agent-steps in {:.2} s",
            self.simulated_agents,
            self.line_joins,
            self.arrived,
            self.agent_steps,
            self.seconds_simulating
        )?;
        for m in &self.comparison.measures {
            writeln!(
                f,
                "crowd: {:<17} corridor mean {:>6.3}, hall mean {:>6.3} {} (W1 {:.3})",
                m.name, m.mean_a, m.mean_b, m.unit, m.wasserstein
            )?;
        }
        write!(
            f,
            "crowd: picture {}; tracks, model and comparison in {}",
            self.picture.display(),
            self.out.display()
        )
    }
}

/// The hall of the demo: 30 × 10 m between two walls, a pillar, a ticket booth with its line.
pub fn demo_layout() -> layout::Layout {
    use layout::{Layout, NamedPivot, Region, Spawn};
    Layout {
        bounds: Some([[-1.0, -1.0], [31.0, 11.0]]),
        walls: vec![
            vec![[0.0, 0.0], [30.0, 0.0]],
            vec![[0.0, 10.0], [30.0, 10.0]],
        ],
        obstacles: vec![vec![[14.0, 4.0], [16.0, 4.0], [16.0, 6.0], [14.0, 6.0]]],
        pivots: vec![NamedPivot {
            name: "booth".into(),
            position: [22.0, 9.0],
            orientation_deg: 90.0,
        }],
        regions: vec![Region {
            behaviour: behaviour::LINE.into(),
            polygon: vec![[21.0, 4.5], [23.0, 4.5], [23.0, 9.5], [21.0, 9.5]],
            pivot: Some("booth".into()),
            join: 0.3,
        }],
        spawns: vec![
            Spawn {
                position: [0.5, 3.0],
                spread: 2.0,
                goal: [29.5, 5.0],
                count: 40,
                start: 0.0,
                interval: 1.0,
            },
            Spawn {
                position: [29.5, 7.0],
                spread: 2.0,
                goal: [0.5, 5.0],
                count: 40,
                start: 0.5,
                interval: 1.0,
            },
        ],
        duration: Some(70.0),
        ..Layout::default()
    }
}

/// The crowd section of `herdfit demo`: a synthetic corridor crowd is tracked (its tracks written),
/// learnt, and the model drives a larger crowd in a new hall; writes tracks, the model, a PNG
/// (and an AVI with the `video` feature) and a comparison into `out`.
pub fn demo(out: &Path, progress: &mut dyn Progress) -> Result<DemoSummary> {
    crate::data::atomic::make_dir(out)?;
    let source = synth::corridor(&synth::SynthConfig::default())?;
    source.save(&out.join("corridor.csv"))?;
    let cfg = model::LearnConfig {
        max_samples: 6000,
        ..model::LearnConfig::default()
    };
    let m = model::learn(std::slice::from_ref(&source), &cfg, progress)?;
    m.save(&out.join("model.json"))?;
    let hall = demo_layout();
    // Not `hall.json`: that is the sidecar of `hall.csv`.
    hall.save(&out.join("hall-layout.json"))?;
    let entries = sim::entries_from_layout(&hall, m.dt, sim::typical_speed(&m), 1);
    let t0 = std::time::Instant::now();
    let run = sim::simulate(
        &m,
        Some(&hall),
        &entries,
        // The seed of the entries too: `herdfit crowd simulate model.json --layout
        // hall-layout.json --seed 1` repeats this run.
        &sim::SimConfig {
            seed: 1,
            ..sim::SimConfig::default()
        },
        progress,
    )?;
    let seconds = t0.elapsed().as_secs_f64();
    run.tracks.save(&out.join("hall.csv"))?;
    let picture = out.join("hall.png");
    let mid = run.tracks.rows.last().map_or(0, |r| r.frame) / 2;
    render::top_view_png(
        &picture,
        "crowd learnt from a corridor, replayed in a hall (blue: walking, green: in line)",
        &run.tracks,
        None,
        Some(&hall),
        mid,
        15,
    )?;
    #[cfg(feature = "video")]
    render::top_view_avi(&out.join("hall.avi"), &run.tracks, Some(&hall), 24.0)?;
    let a = features::Scene::from_tracks(&source, 0.0)?;
    let b = features::Scene::from_tracks(&run.tracks, 0.0)?;
    let comparison = measure::compare(&a, &b, "corridor", "hall", 0.05, "m", 1.0)?;
    let json = serde_json::to_string_pretty(&comparison)
        .map_err(|e| Error::Internal(format!("comparison: {e}")))?;
    crate::data::atomic::write_atomic(&out.join("compare.json"), format!("{json}\n").as_bytes())?;
    Ok(DemoSummary {
        source_agents: source.ids().len(),
        samples: m.samples(),
        behaviours: m.behaviours.iter().map(|b| b.name.clone()).collect(),
        simulated_agents: entries.len(),
        agent_steps: run.agent_steps,
        seconds_simulating: seconds,
        line_joins: run.line_joins,
        arrived: run.arrived,
        comparison,
        picture,
        out: out.to_path_buf(),
    })
}
