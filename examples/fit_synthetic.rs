//! Fit a synthetic herd from Rust: simulate a clip with known parameters, fit it from a generic
//! start, and print true vs fitted values.
//!
//! `cargo run --release --example fit_synthetic`

use herdfit::backend::{cpu_device, Precision};
use herdfit::data::Grid;
use herdfit::herd::fit::{fit, FitConfig, LossKind};
use herdfit::herd::params::{param_names, Params};
use herdfit::herd::synth::{synthesise, SynthConfig};

fn main() -> herdfit::Result<()> {
    let device = cpu_device(Precision::F32)?;
    let truth = Params::default();
    let clip = synthesise(
        &SynthConfig {
            params: truth.clone(),
            agents: 200,
            frames: 60,
            fps: 25.0,
            grid: Grid {
                origin: [0.0, 0.0],
                cell_size: 3.0,
                nx: 14,
                ny: 8,
            },
            obstacles: ndarray::Array2::zeros((8, 14)),
            seed: 1,
            heading_deg: 0.0,
            precision: Precision::F32,
        },
        &device,
        || {},
    )?
    .clip;
    let cfg = FitConfig {
        window: 16,
        epochs: 4,
        frames: 0..60,
        loss: LossKind::Fields,
        ..FitConfig::default()
    };
    let result = fit(
        &clip,
        &Params::neutral(),
        &cfg,
        None,
        |epoch, frame, e, _| {
            if frame + cfg.window >= 60 {
                println!("epoch {epoch}: E_mean {e:.4}");
            }
        },
    )?;
    for ((name, t), f) in param_names()
        .iter()
        .zip(truth.to_vec())
        .zip(result.params.to_vec())
    {
        println!("{name:<20} true {t:.3}  fitted {f:.3}");
    }
    Ok(())
}
