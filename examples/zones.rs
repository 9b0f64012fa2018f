//! Zone fit vs single-set fit on a synthetic two-zone clip (issue #17, paper §7.2.4).
//!
//! A herd crosses a field whose left zone ("herding") plays one parameter set and right zone
//! ("loose") another (`synth --zone-sets`). The first half of the clip is fitted twice from the
//! generic start — one set per zone (`fit --zones`) and one set for the whole clip — and both,
//! the generating sets, and the generating sets moved by ±0.06 per parameter are validated on the
//! second half with the same seeds (common random numbers): the whole grid's coarse density
//! error and each zone's density, polarization, angular momentum and aspect-ratio errors.
//!
//! Then a zone fit started at the generating sets, and the fit's own objective on the fitted
//! frames for every choice against the generating sets' (paired over fit seeds).
//!
//! `cargo run --release --example zones -- [EPOCHS] [OUT] [SPEEDS] [SEEDS] [STARTS] [LOSS]
//! [WINDOWS] [CLIP_SEED] [GUIDANCE]`, by default 6, `out/zones/`, `-`, 4, 1, `fields`, `fields`,
//! 5, 0:
//! - `SPEEDS` = `A,B` gives the zones fixed speeds A and B BL/s (paper §7.2.4, the seals' water
//!   and land): the clip is generated with them, the zone fit is told them, and a second zone fit
//!   without them is validated beside it; `-` for none;
//! - `SEEDS`: validation seeds; `STARTS` = K runs both fits with the global phase of K starts;
//! - `LOSS` = `paper` or `ensemble` (4 replicas) fits by that objective instead;
//! - `WINDOWS` = `tracks` starts every window from the clip's `trajectories.csv` (`fit
//!   --tracks`), as do the objective table and the validation (`validate --tracks`);
//! - `CLIP_SEED`: the seed the scene's clip is synthesised with;
//! - `GUIDANCE`: σ (cells) of the leaders' guidance in the fits and the validation
//!   (`--guidance-scale`; `inf`, the herd's mean direction everywhere, is what the scene's
//!   leaders followed: `synth`'s uniform guidance).

use herdfit::herd::fit::global::objective;
use herdfit::herd::fit::job::{run, FitJob};
use herdfit::herd::fit::run::zone_loss_of;
use herdfit::herd::fit::zone_job::run_zones;
use herdfit::herd::fit::{fit_zones, FitConfig, LossKind, UncertaintyConfig};
use herdfit::herd::params::Params;
use herdfit::herd::sets::{NamedSet, ParamSets, PARAM_SETS_SCHEMA};
use herdfit::herd::synth::{write_clip, SynthJob};
use herdfit::herd::validate::zones::{validate_zones, ZoneSetReport};
use herdfit::herd::validate::ValidateConfig;
use herdfit::herd::zoned::ZoneSets;
use herdfit::herd::zones::{ZoneSpec, Zones, ZonesFile};
use herdfit::progress::NoProgress;
use rand::{Rng, SeedableRng};
use std::path::Path;

fn write(path: &Path, v: &impl serde::Serialize) -> herdfit::Result<()> {
    let s = serde_json::to_string_pretty(v).map_err(|e| herdfit::Error::Internal(e.to_string()))?;
    std::fs::write(path, s).map_err(|e| herdfit::Error::file(path, e.to_string()))
}

fn main() -> herdfit::Result<()> {
    let args: Vec<String> = std::env::args().collect();
    let epochs: usize = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(6);
    let out = Path::new(args.get(2).map_or("out/zones", String::as_str)).to_path_buf();
    let speeds: Option<[f64; 2]> = args.get(3).filter(|s| s.as_str() != "-").map(|s| {
        let v: Vec<f64> = s.split(',').filter_map(|x| x.parse().ok()).collect();
        assert_eq!(v.len(), 2, "SPEEDS is A,B (BL/s), or - for none");
        [v[0], v[1]]
    });
    let seeds: usize = args.get(4).and_then(|s| s.parse().ok()).unwrap_or(4);
    let starts: usize = args.get(5).and_then(|s| s.parse().ok()).unwrap_or(1);
    let loss = match args.get(6).map(String::as_str) {
        None | Some("fields") => LossKind::Fields,
        Some("paper") => LossKind::Paper,
        Some("ensemble") => LossKind::Ensemble,
        Some(x) => panic!("LOSS is fields, paper or ensemble, not {x}"),
    };
    let anchored = match args.get(7).map(String::as_str) {
        None | Some("fields") => false,
        Some("tracks") => true,
        Some(x) => panic!("START is fields or tracks, not {x}"),
    };
    let clip_seed: u64 = args.get(8).and_then(|s| s.parse().ok()).unwrap_or(5);
    let guidance_scale: f64 = args
        .get(9)
        .and_then(|s| s.parse().ok())
        .unwrap_or(herdfit::herd::guidance::GUIDANCE_SCALE);
    std::fs::create_dir_all(&out).map_err(|e| herdfit::Error::file(&out, e.to_string()))?;
    // 16 × 8 cells of 3 BL; the zones meet at x = 21 BL (between cell columns 6 and 7).
    let zones = vec![
        ZoneSpec {
            name: "herding".into(),
            polygon: vec![[0.0, 0.0], [21.0, 0.0], [21.0, 24.0], [0.0, 24.0]],
            speed: speeds.map(|s| s[0]),
            ..ZoneSpec::default()
        },
        ZoneSpec {
            name: "loose".into(),
            polygon: vec![[21.0, 0.0], [48.0, 0.0], [48.0, 24.0], [21.0, 24.0]],
            speed: speeds.map(|s| s[1]),
            ..ZoneSpec::default()
        },
    ];
    let mut base = Params::default();
    base.speed.mean = 1.5;
    base.speed.std = 0.3;
    let set = |v: [f64; 12]| base.with_vec(&v);
    // Herding: strong cohesion and alignment over wide ranges; loose: weak cohesion, no
    // alignment to speak of, strong short-range avoidance.
    let truth = vec![
        set([0.6, 0.7, 0.7, 0.4, 0.2, 0.6, 0.8, 0.6, 0.6, 0.7, 0.3, 0.5]),
        set([0.15, 0.3, 0.4, 0.8, 0.3, 0.8, 0.1, 0.3, 0.4, 0.7, 0.3, 0.5]),
    ];
    let bundle = ParamSets {
        schema: PARAM_SETS_SCHEMA.into(),
        sets: zones
            .iter()
            .zip(&truth)
            .map(|(z, p)| NamedSet {
                name: z.name.clone(),
                polygon: z.polygon.clone(),
                colour: None,
                speed: z.speed,
                params: p.clone(),
            })
            .collect(),
        mask: None,
        provenance: None,
    };
    let (truth_path, zones_path) = (out.join("truth-sets.json"), out.join("zones.json"));
    write(&truth_path, &bundle)?;
    let zfile = ZonesFile {
        schema: herdfit::herd::zones::ZONES_SCHEMA.into(),
        mask: None,
        zones: zones.clone(),
    };
    write(&zones_path, &zfile)?;
    // The same zones without their speeds (the fit that is not told them).
    let plain_path = out.join("zones-no-speed.json");
    let plain = ZonesFile {
        zones: zones
            .iter()
            .map(|z| ZoneSpec {
                speed: None,
                ..z.clone()
            })
            .collect(),
        ..zfile.clone()
    };
    write(&plain_path, &plain)?;
    base.save(&out.join("base.json"))?;
    let clip_dir = out.join("clip");
    let clip = scene_clip(&out, &truth_path, clip_seed, &clip_dir)?;
    let config = FitConfig {
        epochs,
        window: 4,
        loss,
        // The ensemble objective compares the mean of 4 replicas' fields.
        replicas: if loss == LossKind::Ensemble { 4 } else { 1 },
        guidance_scale,
        // `fit --tracks`: every window starts from the generating run's animals.
        tracks: match anchored {
            true => vec![clip_dir.join("trajectories.csv")],
            false => Vec::new(),
        },
        global: herdfit::herd::fit::GlobalPhase {
            starts,
            ..Default::default()
        },
        ..FitConfig::default()
    };
    let t0 = std::time::Instant::now();
    let job = FitJob {
        clips: vec![clip_dir.clone()],
        frames: Some(0..80),
        config: config.clone(),
        eval_seeds: 2,
        out: out.join("zone-fit.json"),
        uncertainty: UncertaintyConfig {
            enabled: false,
            ..UncertaintyConfig::default()
        },
        zones: Some(zones_path.clone()),
        ..FitJob::default()
    };
    let zs = run_zones(&job, &mut NoProgress)?;
    let zone_secs = t0.elapsed().as_secs_f64();
    print!("{zs}");
    let t0 = std::time::Instant::now();
    let single_job = FitJob {
        out: out.join("single-fit.json"),
        zones: None,
        ..job
    };
    run(&single_job, &mut NoProgress)?;
    let single_secs = t0.elapsed().as_secs_f64();
    let grid = clip.grid();
    let of = |b: &ParamSets, p: &Path| ZoneSets::of_bundle(b, p, &grid, &clip.obstacles);
    let zone_fit = ParamSets::load(&out.join("zone-fit.json"))?;
    let single = Params::load(&out.join("single-fit.json"))?;
    let repeat = |p: &Params| ParamSets {
        sets: bundle
            .sets
            .iter()
            .map(|s| NamedSet {
                params: p.clone(),
                // One set for the whole clip: no zone speeds either.
                speed: None,
                ..s.clone()
            })
            .collect(),
        ..bundle.clone()
    };
    // θ* moved by ±0.06 per parameter (random signs, seed 17).
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(17);
    let mut moved = bundle.clone();
    for s in &mut moved.sets {
        let mut v = s.params.to_vec();
        for x in v.iter_mut() {
            *x = (*x + if rng.gen::<bool>() { 0.06 } else { -0.06 }).clamp(0.001, 1.0);
        }
        s.params = s.params.with_vec(&v);
    }
    let mut unspeeded = None;
    if speeds.is_some() {
        let t0 = std::time::Instant::now();
        let job = FitJob {
            out: out.join("zone-fit-no-speed.json"),
            zones: Some(plain_path.clone()),
            ..single_job.clone()
        };
        run_zones(&job, &mut NoProgress)?;
        println!(
            "zone fit without the speeds: {:.1} s",
            t0.elapsed().as_secs_f64()
        );
        unspeeded = Some(ParamSets::load(&job.out)?);
    }
    let mut sets = vec![
        ("zone fit".to_string(), of(&zone_fit, &out)?),
        ("single fit".to_string(), of(&repeat(&single), &out)?),
        ("truth".to_string(), of(&bundle, &out)?),
        ("truth ±0.06".to_string(), of(&moved, &out)?),
    ];
    if let Some(b) = &unspeeded {
        sets.insert(1, ("zone fit, speeds not given".to_string(), of(b, &out)?));
    }
    let vcfg = ValidateConfig {
        seeds,
        // `validate --tracks`: the held-out run starts from the generating run's animals.
        tracks: anchored.then(|| clip_dir.join("trajectories.csv")),
        guidance_scale,
        ..ValidateConfig::default()
    };
    let reports = validate_zones(&clip, &sets, &vcfg, || {})?;
    write(&out.join("zones-validation.json"), &reports)?;
    println!("fit wall: zone {zone_secs:.1} s, single {single_secs:.1} s ({epochs} epochs)");
    table(&reports);
    // The emergent measures of the seeds' mean prediction (`validate --ensemble-mean`): per-seed
    // errors also charge each set for its own run-to-run spread.
    let mean_cfg = ValidateConfig {
        ensemble_mean: true,
        ..vcfg.clone()
    };
    println!("With the seeds' mean prediction of the emergent measures (--ensemble-mean):");
    table(&validate_zones(&clip, &sets, &mean_cfg, || {})?);
    let dist = |a: &ParamSets| -> Vec<f64> {
        a.sets
            .iter()
            .zip(&bundle.sets)
            .map(|(x, t)| {
                let (p, q) = (x.params.to_vec(), t.params.to_vec());
                p.iter().zip(&q).map(|(a, b)| (a - b).abs()).sum::<f64>() / 12.0
            })
            .collect()
    };
    println!(
        "mean |θ − θ*| per parameter, per zone: zone fit {:?}, single fit {:?}",
        dist(&zone_fit),
        dist(&repeat(&single))
    );
    // In behaviour, with common random numbers: each choice's clip from the same initial herd and
    // seed as the truth's, and its fields' distance from the truth's. The forces are compared:
    // every choice plays with the truth's speed model (as `scripts/identifiability.py --sets`).
    let forces_of = |b: &ParamSets| -> ParamSets {
        let mut b = b.clone();
        for (s, t) in b.sets.iter_mut().zip(&bundle.sets) {
            s.params.speed = t.params.speed.clone();
            s.speed = t.speed;
        }
        b
    };
    // The zone fit started at the generating sets themselves: where the objective leads from θ*.
    let zcfg = FitConfig {
        frames: 0..80,
        ..config.clone()
    };
    let zones_of_clip = Zones::load(&zones_path, &clip)?;
    let from_truth = fit_zones(&clip, &truth, &zcfg, &zones_of_clip, None, |_, _, _, _| {})?;
    let mut truth_start = bundle.clone();
    for (s, p) in truth_start.sets.iter_mut().zip(&from_truth.sets) {
        s.params = p.clone();
    }
    write(&out.join("zone-fit-from-truth.json"), &truth_start)?;
    let choices = [
        ("zone fit", forces_of(&zone_fit)),
        ("single fit", forces_of(&repeat(&single))),
        ("zone fit started at the truth", forces_of(&truth_start)),
        ("truth ±0.06", moved.clone()),
    ];
    println!(
        "| set | field distance from the truth's clip, seeds 5..{} (mean ± std) |",
        5 + seeds
    );
    println!("|---|---:|");
    for (name, b) in &choices {
        let d: Vec<f64> = (0..seeds as u64)
            .map(|k| field_distance(&out, &bundle, b, 5 + k))
            .collect::<herdfit::Result<_>>()?;
        let m = d.iter().sum::<f64>() / d.len() as f64;
        let sd = (d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / d.len() as f64).sqrt();
        println!("| {name} | {m:.4} ± {sd:.4} |");
    }
    println!(
        "mean |θ − θ*| per parameter, per zone: zone fit started at the truth {:?}",
        dist(&truth_start)
    );
    objective_table(&clip, &zcfg, &zones_of_clip, &bundle, &choices, seeds)
}

/// The fit's own objective (E_fields + λ_var E_var, one epoch of the zone fit's schedule on the
/// fitted frames without updates, `zone_loss_of`) of each choice and of the generating sets, for
/// fit seeds 0..`seeds` (common random numbers: the same herds and noise for every choice), and
/// each choice's paired difference from the generating sets' (mean ± standard error): a choice
/// whose objective is below the truth's beyond the noise is what the fit prefers to θ*.
fn objective_table(
    clip: &herdfit::data::ClipFields,
    cfg: &FitConfig,
    zones: &Zones,
    truth: &ParamSets,
    choices: &[(&str, ParamSets)],
    seeds: usize,
) -> herdfit::Result<()> {
    let objective = |b: &ParamSets| -> herdfit::Result<Vec<f64>> {
        let sets: Vec<Params> = b.sets.iter().map(|s| s.params.clone()).collect();
        (0..seeds as u64)
            .map(|seed| {
                let c = FitConfig {
                    seed,
                    ..cfg.clone()
                };
                zone_loss_of(clip, &sets, &c, zones).map(|l| objective(&c, l))
            })
            .collect()
    };
    let t = objective(truth)?;
    println!();
    println!("| set | fit objective on frames 0..80, seeds 0..{seeds} (mean) | minus the truth's, paired (mean ± s.e.) |");
    println!("|---|---:|---:|");
    println!(
        "| truth | {:.5} | – |",
        t.iter().sum::<f64>() / t.len() as f64
    );
    for (name, b) in choices {
        let v = objective(b)?;
        let d: Vec<f64> = v.iter().zip(&t).map(|(a, b)| a - b).collect();
        let n = d.len() as f64;
        let m = d.iter().sum::<f64>() / n;
        let se = (d.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0).max(1.0) / n).sqrt();
        println!(
            "| {name} | {:.5} | {m:+.5} ± {se:.5} |",
            v.iter().sum::<f64>() / n
        );
    }
    Ok(())
}

/// The scene's clip (300 agents, 160 frames, 16 × 8 cells of 3 BL, `out/base.json`'s constants)
/// with the zone sets of the bundle `sets`, synthesised with `seed` into `dir`.
fn scene_clip(
    out: &Path,
    sets: &Path,
    seed: u64,
    dir: &Path,
) -> herdfit::Result<herdfit::data::ClipFields> {
    write_clip(
        &SynthJob {
            params: Some(out.join("base.json")),
            agents: 300,
            frame_count: 160,
            grid_size: (16, 8),
            cell_size: 3.0,
            seed,
            out: dir.to_path_buf(),
            zone_sets: Some(sets.to_path_buf()),
            ..SynthJob::default()
        },
        &mut NoProgress,
    )?;
    herdfit::data::ClipFields::load(dir)
}

/// Σ(ρ' − ρ)²/Σρ² + Σ‖m' − m‖²/Σ‖m‖² (m = ρ v, over every cell and frame) between the clips of
/// `sets` and of `truth` synthesised with the same seed (the same initial herd and noise).
fn field_distance(
    out: &Path,
    truth: &ParamSets,
    sets: &ParamSets,
    seed: u64,
) -> herdfit::Result<f64> {
    let clip_of = |b: &ParamSets, name: &str| -> herdfit::Result<herdfit::data::ClipFields> {
        let (bp, dir) = (
            out.join(format!("crn-{name}.json")),
            out.join(format!("crn-{name}")),
        );
        write(&bp, b)?;
        scene_clip(out, &bp, seed, &dir)
    };
    let (a, b) = (clip_of(truth, "truth")?, clip_of(sets, "set")?);
    let (mut dr, mut nr, mut dm, mut nm) = (0.0, 0.0, 0.0, 0.0);
    for ((f, iy, ix), &r) in a.density.indexed_iter() {
        let r2 = b.density[[f, iy, ix]] as f64;
        let r = r as f64;
        dr += (r2 - r).powi(2);
        nr += r * r;
        for c in 0..2 {
            let m = r * a.velocity[[f, iy, ix, c]] as f64;
            let m2 = r2 * b.velocity[[f, iy, ix, c]] as f64;
            dm += (m2 - m).powi(2);
            nm += m * m;
        }
    }
    Ok(dr / nr.max(1e-12) + dm / nm.max(1e-12))
}

fn table(reports: &[ZoneSetReport]) {
    println!("| set | density err (coarse) | velocity err | zone | zone density err | polarization err | ang. momentum err | aspect err |");
    println!("|---|---:|---:|---|---:|---:|---:|---:|");
    for r in reports {
        for z in &r.zones {
            println!(
                "| {} | {:.4} | {:.4} | {} | {:.4} | {:.4} | {:.4} | {:.4} |",
                r.name,
                r.density_error.mean,
                r.velocity_error.mean,
                z.zone,
                z.density_error.mean,
                z.polarization_error.mean,
                z.angular_momentum_error.mean,
                z.aspect_ratio_error.mean
            );
        }
    }
}
