//! Fits from a single image (paper §7.2.4, issue #17): one synthetic frame of randomly aligned
//! agents at three densities, each fitted as a still from the generic start with direction
//! variance matching (E_var, eq. 8) and without it (λ_var = 0, every parameter from the density
//! term), and measured after settling (RESULTS.md §8); then the same frame as a rendered image
//! through `extract --dir-variance 3.29` and fitted with E_var (measured against the extracted
//! clip). "Without E_var, alignment by the split" is the paper's ablation: λ_var = 0 with the
//! split kept, so alignment (learnt from E_var only) stays at the start's. A second table fits
//! the 1.0 and 0.5 stills from random starts (the paper's Figure 15 "random parameters") with
//! and without E_var (split kept), the contrast of Figure 14. A third table runs every fitted
//! set of the 0.5 and 1.0 stills far longer than the fit looked (`HORIZON`), since Figure 14's
//! contrast is what the herd does given time. A fourth table starts from the random sets whose
//! own herd aligns on the image, and fits them by either objective (the density term, or the
//! paper's E_mean towards the density gradient) with and without E_var: whether a fit without
//! E_var keeps the herd aligned, as Figure 14 [right] shows.
//!
//! `cargo run --release --example still_table [-- OUT_DIR [aligning]]` (default
//! `out/still_table/`; `aligning`: the fourth table only)

use herdfit::backend::Precision;
use herdfit::data::ClipFields;
use herdfit::herd::fit::job::{run, FitJob};
use herdfit::herd::fit::still::{stationary_clip, still_measures, StillConfig, StillMeasures};
use herdfit::herd::fit::{FitConfig, LossKind};
use herdfit::herd::params::{Params, N_PARAMS};
use herdfit::herd::synth::{write_clip, SynthJob};
use herdfit::progress::NoProgress;
use herdfit::video::extract;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::path::{Path, PathBuf};

fn main() -> herdfit::Result<()> {
    let out = PathBuf::from(
        std::env::args()
            .nth(1)
            .unwrap_or_else(|| "out/still_table".into()),
    );
    std::fs::create_dir_all(&out).map_err(|e| herdfit::Error::file(&out, e.to_string()))?;
    let only_aligning = std::env::args().nth(2).as_deref() == Some("aligning");
    println!("| density (agents/BL²) | set | density error | smoothed density error | crowding | polarization |");
    println!("|---|---|---:|---:|---:|---:|");
    for density in [0.2, 0.5, 1.0] {
        let clip = out.join(format!("still-{density}"));
        if only_aligning {
            write_still(&clip, density, None)?;
            continue;
        }
        write_still(
            &clip,
            density,
            Some(out.join(format!("still-{density}.png"))),
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
            let fit = out.join(format!("fit-{density}-{}.json", rows.len()));
            let [drawn, start, fitted] = fit_still(clip, var_weight, split, None, fit)?;
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
    if !only_aligning {
        random_starts(&out)?;
        horizon(&out)?;
    }
    aligning_starts(&out)
}

/// The still of 200 randomly aligned agents at `density` agents/BL² (16 × 16 cells of 3 BL,
/// seed 1), and its rendered image when `image` is given.
fn write_still(clip: &Path, density: f64, image: Option<PathBuf>) -> herdfit::Result<()> {
    write_clip(
        &SynthJob {
            agents: 200,
            frame_count: 1,
            grid_size: (16, 16),
            cell_size: 3.0,
            density,
            random_headings: true,
            seed: 1,
            out: clip.to_path_buf(),
            image,
            ..SynthJob::default()
        },
        &mut NoProgress,
    )
    .map(|_| ())
}

/// Steps run from the image before, and then while, the third table measures.
const HORIZON: StillConfig = StillConfig {
    settle: 500,
    average: 250,
};

/// Figure 14 given time: each fitted set of the two tables above (the generic start's fits with
/// E_var and without it by the split, and the random starts' fits) run from the image for
/// `HORIZON.settle` steps and measured over the next `HORIZON.average` (2 seeds), beside the
/// set's alignment weight and its measures over the fit's own 25 + 50 steps.
fn horizon(out: &Path) -> herdfit::Result<()> {
    println!();
    println!(
        "Over a longer run ({} steps settled, {} measured, 2 seeds):",
        HORIZON.settle, HORIZON.average
    );
    println!();
    println!("| density (agents/BL²) | fitted set | alignment weight | polarization, fit's horizon | polarization, long run | smoothed density error, long run | crowding, long run |");
    println!("|---|---|---:|---:|---:|---:|---:|");
    for density in [0.5, 1.0] {
        let still = ClipFields::load(&out.join(format!("still-{density}")))?;
        let mut sets = vec![
            // The first table's file names number its rows: 0 is the fit with E_var, 4 the split
            // without it.
            ("generic start, with E_var".to_string(), 0),
            ("generic start, without E_var (split)".to_string(), 4),
        ]
        .into_iter()
        .map(|(n, arm)| (n, out.join(format!("fit-{density}-{arm}.json"))))
        .collect::<Vec<_>>();
        for k in 0..4 {
            for (arm, name) in [(1, "with E_var"), (2, "without E_var (split)")] {
                sets.push((
                    format!("random start {k}, {name}"),
                    out.join(format!("random-fit-{density}-{k}-{arm}.json")),
                ));
            }
        }
        let short = StillConfig::default();
        for (name, path) in sets {
            let p = Params::load(&path)?;
            let m = |cfg: &StillConfig| {
                let clip = stationary_clip(&still, cfg, &p.speed);
                still_measures(&clip, &p, cfg, 0, 2, Precision::F32).map(|[_, m]| m)
            };
            let (a, b) = (m(&short)?, m(&HORIZON)?);
            println!(
                "| {density} | {name} | {:.3} | {:.3} | {:.3} | {:.3} | {:.3} |",
                p.forces.alignment.weight,
                a.polarization,
                b.polarization,
                b.smooth_density_error,
                b.crowding
            );
        }
    }
    Ok(())
}

/// Fits the still `clip` (16 epochs, from `start` or the generic start) into `fit`; returns the
/// measures of the herd as drawn, of the start and of the fitted set.
fn fit_still(
    clip: &Path,
    var_weight: f64,
    split: bool,
    start: Option<PathBuf>,
    fit: PathBuf,
) -> herdfit::Result<[StillMeasures; 3]> {
    fit_still_by(clip, LossKind::Fields, var_weight, split, start, fit)
}

/// [`fit_still`] by the objective `loss` (fields: the density term; paper: E_mean towards the
/// density gradient).
fn fit_still_by(
    clip: &Path,
    loss: LossKind,
    var_weight: f64,
    split: bool,
    start: Option<PathBuf>,
    fit: PathBuf,
) -> herdfit::Result<[StillMeasures; 3]> {
    let job = FitJob {
        clips: vec![clip.to_path_buf()],
        start,
        config: FitConfig {
            epochs: 16,
            loss,
            var_weight,
            split_gradients: split,
            ..FitConfig::default()
        },
        out: fit,
        uncertainty: herdfit::herd::fit::identify::UncertaintyConfig {
            enabled: false,
            ..Default::default()
        },
        ..FitJob::default()
    };
    let s = run(&job, &mut NoProgress)?;
    Ok(s.still.expect("a one-frame clip is fitted as a still").1)
}

/// Figure 14's contrast from random starts: each of `STARTS` parameter sets drawn uniformly in
/// the normalised box (seeded) is fitted to the 0.5 and 1.0 stills with E_var and without it
/// (λ_var = 0, the split kept: alignment stays at the random start's); the table gives the mean
/// and range over the starts.
fn random_starts(out: &Path) -> herdfit::Result<()> {
    const STARTS: usize = 4;
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    let starts: Vec<PathBuf> = (0..STARTS)
        .map(|k| {
            let mut v = [0.0; N_PARAMS];
            v.iter_mut().for_each(|x| *x = rng.gen_range(0.0..1.0));
            Params::clamp_vec(&mut v);
            let p = out.join(format!("random-start-{k}.json"));
            Params::neutral().with_vec(&v).save(&p).map(|_| p)
        })
        .collect::<herdfit::Result<_>>()?;
    println!();
    println!("From {STARTS} random starts (mean, min–max over the starts):");
    println!();
    println!("| density (agents/BL²) | set | smoothed density error | crowding | polarization |");
    println!("|---|---|---|---|---|");
    for density in [0.5, 1.0] {
        let clip = out.join(format!("still-{density}"));
        let mut sets: [Vec<StillMeasures>; 3] = Default::default();
        for (k, start) in starts.iter().enumerate() {
            for (arm, var_weight) in [(1, 1.0), (2, 0.0)] {
                let fit = out.join(format!("random-fit-{density}-{k}-{arm}.json"));
                let [_, before, after] =
                    fit_still(&clip, var_weight, true, Some(start.clone()), fit)?;
                if arm == 1 {
                    sets[0].push(before);
                }
                sets[arm].push(after);
            }
        }
        let names = [
            "random start (unfitted)",
            "fit with E_var",
            "fit without E_var (split)",
        ];
        for (name, ms) in names.iter().zip(&sets) {
            let cell = |f: fn(&StillMeasures) -> f64| {
                let v: Vec<f64> = ms.iter().map(f).collect();
                let mean = v.iter().sum::<f64>() / v.len() as f64;
                let (lo, hi) = v
                    .iter()
                    .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
                        (a.min(x), b.max(x))
                    });
                format!("{mean:.3} ({lo:.3}–{hi:.3})")
            };
            println!(
                "| {density} | {name} | {} | {} | {} |",
                cell(|m| m.smooth_density_error),
                cell(|m| m.crowding),
                cell(|m| m.polarization)
            );
        }
    }
    Ok(())
}

/// Polarization at or above which a herd counts as aligned in the fourth table.
const ALIGNED: f64 = 0.5;

/// Figure 14 from starts that align: of `DRAWS` parameter sets drawn uniformly in the normalised
/// box (seed 14), those whose own herd, run from the image for `HORIZON`, aligns (polarization
/// ≥ [`ALIGNED`]) are fitted to the still by each objective (fields: the density term; paper:
/// E_mean towards the density gradient) with E_var and without it (λ_var = 0, the paper's split:
/// alignment keeps the start's values), and each fitted set is run for `HORIZON` again. The table
/// counts the fitted herds that stay aligned and those that end disordered (< 0.2).
fn aligning_starts(out: &Path) -> herdfit::Result<()> {
    const DRAWS: usize = 40;
    let mut rng = ChaCha8Rng::seed_from_u64(14);
    let draws: Vec<[f64; N_PARAMS]> = (0..DRAWS)
        .map(|_| {
            let mut v = [0.0; N_PARAMS];
            v.iter_mut().for_each(|x| *x = rng.gen_range(0.0..1.0));
            Params::clamp_vec(&mut v);
            v
        })
        .collect();
    println!();
    println!(
        "From the starts that align the image's herd ({DRAWS} draws; {} + {} steps, 2 seeds; \
         polarization mean (min–max), aligned ≥ {ALIGNED}, disordered < 0.2):",
        HORIZON.settle, HORIZON.average
    );
    println!();
    println!("| density (agents/BL²) | set | starts | polarization, long run | aligned | disordered | smoothed density error, fit's horizon |");
    println!("|---|---|---:|---|---:|---:|---|");
    for density in [0.2, 0.5, 1.0] {
        let clip_dir = out.join(format!("still-{density}"));
        let still = ClipFields::load(&clip_dir)?;
        let run = |p: &Params| -> herdfit::Result<[StillMeasures; 2]> {
            let m = |cfg: &StillConfig| {
                let clip = stationary_clip(&still, cfg, &p.speed);
                still_measures(&clip, p, cfg, 0, 2, Precision::F32).map(|[_, m]| m)
            };
            Ok([m(&StillConfig::default())?, m(&HORIZON)?])
        };
        let mut starts = Vec::new();
        for (k, v) in draws.iter().enumerate() {
            let p = Params::neutral().with_vec(v);
            let m = run(&p)?;
            if m[1].polarization >= ALIGNED {
                let path = out.join(format!("aligning-start-{density}-{k}.json"));
                p.save(&path)?;
                starts.push((path, m));
            }
        }
        let arms = [
            ("fields, with E_var", LossKind::Fields, 1.0),
            ("fields, without E_var (split)", LossKind::Fields, 0.0),
            ("paper, with E_var", LossKind::Paper, 1.0),
            ("paper, without E_var (split)", LossKind::Paper, 0.0),
        ];
        let jobs: Vec<(usize, usize)> = (0..arms.len())
            .flat_map(|a| (0..starts.len()).map(move |k| (a, k)))
            .collect();
        let fitted = jobs
            .par_iter()
            .map(|&(a, k)| {
                let (_, loss, var_weight) = arms[a];
                let fit = out.join(format!("aligning-fit-{density}-{k}-{a}.json"));
                let start = Some(starts[k].0.clone());
                fit_still_by(&clip_dir, loss, var_weight, true, start, fit.clone())?;
                run(&Params::load(&fit)?)
            })
            .collect::<herdfit::Result<Vec<_>>>()?;
        let mut rows = vec![(
            "aligning start (unfitted)",
            starts.iter().map(|s| s.1).collect::<Vec<_>>(),
        )];
        for (a, arm) in arms.iter().enumerate() {
            rows.push((
                arm.0,
                fitted[a * starts.len()..(a + 1) * starts.len()].to_vec(),
            ));
        }
        for (name, ms) in rows {
            let spread = |v: Vec<f64>| {
                let mean = v.iter().sum::<f64>() / v.len().max(1) as f64;
                let lo = v.iter().cloned().fold(f64::INFINITY, f64::min);
                let hi = v.iter().cloned().fold(f64::NEG_INFINITY, f64::max);
                format!("{mean:.3} ({lo:.3}–{hi:.3})")
            };
            let pol: Vec<f64> = ms.iter().map(|m| m[1].polarization).collect();
            println!(
                "| {density} | {name} | {} | {} | {} | {} | {} |",
                ms.len(),
                spread(pol.clone()),
                pol.iter().filter(|&&x| x >= ALIGNED).count(),
                pol.iter().filter(|&&x| x < 0.2).count(),
                spread(ms.iter().map(|m| m[0].smooth_density_error).collect())
            );
        }
    }
    Ok(())
}
