//! Fits from a single image (paper §7.2.4, issue #17): one synthetic frame of randomly aligned
//! agents at three densities, each fitted as a still from the generic start with direction
//! variance matching (E_var, eq. 8) and without it (λ_var = 0, every parameter from the density
//! term), and measured after settling (RESULTS.md §8).
//!
//! `cargo run --release --example still_table [-- OUT_DIR]` (default `out/still_table/`)

use herdfit::herd::fit::job::{run, FitJob};
use herdfit::herd::fit::FitConfig;
use herdfit::herd::synth::{write_clip, SynthJob};
use herdfit::progress::NoProgress;
use std::path::PathBuf;

fn main() -> herdfit::Result<()> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "out/still_table".into()),
    );
    std::fs::create_dir_all(&out).map_err(|e| herdfit::Error::file(&out, e.to_string()))?;
    println!("| density (agents/BL²) | set | density error | smoothed density error | crowding | polarization |");
    println!("|---|---|---:|---:|---:|---:|");
    for density in [0.2, 0.5, 1.0] {
        let clip = out.join(format!("still-{density}"));
        write_clip(
            &SynthJob {
                agents: 200,
                frame_count: 1,
                grid_size: (16, 16),
                cell_size: 3.0,
                density,
                random_headings: true,
                seed: 1,
                out: clip.clone(),
                ..SynthJob::default()
            },
            &mut NoProgress,
        )?;
        let mut rows = Vec::new();
        for (name, var_weight, split) in [
            ("fit with E_var", 1.0, true),
            ("fit without E_var", 0.0, false),
        ] {
            let job = FitJob {
                clips: vec![clip.clone()],
                config: FitConfig {
                    epochs: 16,
                    var_weight,
                    split_gradients: split,
                    ..FitConfig::default()
                },
                out: out.join(format!("fit-{density}-{var_weight}.json")),
                uncertainty: herdfit::herd::fit::identify::UncertaintyConfig {
                    enabled: false,
                    ..Default::default()
                },
                ..FitJob::default()
            };
            let s = run(&job, &mut NoProgress)?;
            let (_, [drawn, start, fitted]) =
                s.still.expect("a one-frame clip is fitted as a still");
            if rows.is_empty() {
                rows.push(("as drawn from the image (no step)", drawn));
                rows.push(("generic start (unfitted)", start));
            }
            rows.push((name, fitted));
        }
        for (name, m) in rows {
            println!(
                "| {density} | {name} | {:.3} | {:.3} | {:.3} | {:.3} |",
                m.density_error, m.smooth_density_error, m.crowding, m.polarization
            );
        }
    }
    Ok(())
}
