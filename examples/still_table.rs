//! Fits from a single image (paper §7.2.4, issue #17): one synthetic frame of randomly aligned
//! agents at three densities, each fitted as a still from the generic start with direction
//! variance matching (E_var, eq. 8) and without it (λ_var = 0, every parameter from the density
//! term), and measured after settling (RESULTS.md §8); then the same frame as a rendered image
//! through `extract --dir-variance 3.29` and fitted with E_var (measured against the extracted
//! clip).
//!
//! `cargo run --release --example still_table [-- OUT_DIR]` (default `out/still_table/`)

use herdfit::herd::fit::job::{run, FitJob};
use herdfit::herd::fit::FitConfig;
use herdfit::herd::synth::{write_clip, SynthJob};
use herdfit::progress::NoProgress;
use herdfit::video::extract;
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
                image: Some(out.join(format!("still-{density}.png"))),
                ..SynthJob::default()
            },
            &mut NoProgress,
        )?;
        let image = out.join(format!("still-{density}.png"));
        let extracted = out.join(format!("extracted-{density}"));
        let ex = extract::run(
            &extract::ExtractJob {
                video: image,
                out: extracted.clone(),
                config: extract::ExtractConfig {
                    dir_variance: Some(3.29),
                    ..Default::default()
                },
                ..Default::default()
            },
            &mut NoProgress,
        )?;
        eprintln!("{density}: {}", ex.summary(&extracted));
        let mut rows = Vec::new();
        let arms = [
            ("fit with E_var", 1.0, true, &clip),
            ("fit without E_var", 0.0, false, &clip),
            (
                "fit without E_var, alignment by the split",
                0.0,
                true,
                &clip,
            ),
            ("extracted image: fit with E_var", 1.0, true, &extracted),
        ];
        for (name, var_weight, split, clip) in arms {
            let job = FitJob {
                clips: vec![clip.clone()],
                config: FitConfig {
                    epochs: 16,
                    var_weight,
                    split_gradients: split,
                    ..FitConfig::default()
                },
                out: out.join(format!("fit-{density}-{}.json", rows.len())),
                uncertainty: herdfit::herd::fit::identify::UncertaintyConfig {
                    enabled: false,
                    ..Default::default()
                },
                ..FitJob::default()
            };
            let s = run(&job, &mut NoProgress)?;
            let (_, [drawn, start, fitted]) =
                s.still.expect("a one-frame clip is fitted as a still");
            if rows.is_empty() || name.starts_with("extracted") {
                let pre = if rows.is_empty() {
                    ""
                } else {
                    "extracted image: "
                };
                rows.push((format!("{pre}as drawn from the image (no step)"), drawn));
                rows.push((format!("{pre}generic start (unfitted)"), start));
            }
            rows.push((name.to_string(), fitted));
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
