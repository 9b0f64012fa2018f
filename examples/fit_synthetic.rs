//! Fit a synthetic herd from Rust: simulate a clip with known parameters, fit it from a generic
//! start with the same library call as `herdfit fit` (so `params.json` carries the same
//! provenance: settings, losses and the evaluation of start and fitted set), and print true vs
//! fitted values.
//!
//! `cargo run --release --example fit_synthetic` (writes `out/fit_synthetic/`)

use herdfit::backend::Precision;
use herdfit::herd::fit::job::{run, FitJob};
use herdfit::herd::fit::{FitConfig, LossKind};
use herdfit::herd::params::{param_names, Params};
use herdfit::herd::synth::{write_clip, SynthJob};
use herdfit::progress::NoProgress;
use std::path::Path;

fn main() -> herdfit::Result<()> {
    let out = Path::new("out/fit_synthetic");
    std::fs::create_dir_all(out).map_err(|e| herdfit::Error::file(out, e.to_string()))?;
    // 200 agents for 60 frames on a 14 × 8 grid of 3-BL cells, the built-in parameters as truth.
    let synth = SynthJob {
        params: None,
        agents: 200,
        frame_count: 60,
        fps: 25.0,
        grid_size: (14, 8),
        cell_size: 3.0,
        obstacles: None,
        heading_deg: 0.0,
        seed: 1,
        precision: Precision::F32,
        out: out.join("clip"),
        video: None,
        zone_sets: None,
        ..SynthJob::default()
    };
    write_clip(&synth, &mut NoProgress)?;
    let job = FitJob {
        clips: vec![synth.out.clone()],
        config: FitConfig {
            window: 16,
            epochs: 4,
            loss: LossKind::Fields,
            ..FitConfig::default()
        },
        out: out.join("params.json"),
        ..FitJob::default()
    };
    let summary = run(&job, &mut NoProgress)?;
    print!("{summary}");
    for ((name, t), f) in param_names()
        .iter()
        .zip(Params::default().to_vec())
        .zip(summary.result.params.to_vec())
    {
        println!("{name:<20} true {t:.3}  fitted {f:.3}");
    }
    Ok(())
}
