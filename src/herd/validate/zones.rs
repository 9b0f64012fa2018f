//! Held-out validation per zone (paper §7.2.4): parameter sets per zone (a zone fit's bundle, or
//! one set used in every zone) simulated from the first held-out frame's fields, compared with
//! the clip on the whole grid (coarse density and velocity errors) and inside each zone (the
//! zone's relative density error on the clip's cells, and the polarization, angular momentum
//! and aspect ratio of the fields inside the zone, eq. 12–13).

use super::{stat, Stat, ValidateConfig};
use crate::backend::{device, Precision};
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::eval::run_from;
use crate::herd::guidance::guidance_fields;
use crate::herd::zoned::ZoneSets;
use crate::measure::fields::{cell_errors, coarse_cells, emergent, smooth_velocity};
use crate::measure::rasterise;
use crate::progress::Proceed;
use ndarray::s;
use serde::Serialize;

/// Errors of one parameter-set choice inside one zone, mean ± STD over the held-out frames.
#[derive(Clone, Debug, Serialize)]
pub struct ZoneRow {
    pub zone: String,
    /// Σ_zone |ρ' − ρ| / Σ_zone ρ on the clip's cells.
    pub density_error: Stat,
    pub polarization_error: Stat,
    pub angular_momentum_error: Stat,
    pub aspect_ratio_error: Stat,
}

/// One parameter-set choice: the whole grid's coarse errors and each zone's.
#[derive(Clone, Debug, Serialize)]
pub struct ZoneSetReport {
    pub name: String,
    pub density_error: Stat,
    pub velocity_error: Stat,
    pub zones: Vec<ZoneRow>,
}

/// One frame of `c` with the density outside `cells` set to 0 (the fields inside a zone).
fn inside(c: &ClipFields, f: usize, cells: &[bool]) -> ClipFields {
    let mut density = c.density.slice(s![f..f + 1, .., ..]).to_owned();
    let nx = c.meta.nx;
    for ((_, iy, ix), v) in density.indexed_iter_mut() {
        if !cells[iy * nx + ix] {
            *v = 0.0;
        }
    }
    ClipFields {
        meta: c.meta.clone(),
        density,
        velocity: c.velocity.slice(s![f..f + 1, .., .., ..]).to_owned(),
        dir_variance: c.dir_variance.slice(s![f..f + 1, .., ..]).to_owned(),
        obstacles: c.obstacles.clone(),
    }
}

/// Σ_cells |ρ'_f' − ρ_f| / Σ_cells ρ_f over the `cells` of the grid.
fn zone_density_error(
    clip: &ClipFields,
    f: usize,
    sim: &ClipFields,
    k: usize,
    cells: &[bool],
) -> f64 {
    let nx = clip.meta.nx;
    let (mut d, mut n) = (0.0f64, 0.0f64);
    for (c, _) in cells.iter().enumerate().filter(|(_, &x)| x) {
        let (iy, ix) = (c / nx, c % nx);
        let a = clip.density[[f, iy, ix]] as f64;
        d += (sim.density[[k, iy, ix]] as f64 - a).abs();
        n += a;
    }
    if n > 0.0 {
        d / n
    } else {
        f64::NAN
    }
}

/// Validates each named choice of per-zone sets on the held-out part `[split·F, F)` of `clip`
/// (`cfg.seeds` runs each, errors averaged over the runs' frames; with `cfg.ensemble_mean` the
/// zones' emergent measures are averaged over the runs frame by frame before they are compared,
/// the density errors stay per run).
pub fn validate_zones<R: Proceed>(
    clip: &ClipFields,
    sets: &[(String, ZoneSets)],
    cfg: &ValidateConfig,
    mut progress: impl FnMut() -> R,
) -> Result<Vec<ZoneSetReport>> {
    cfg.check()?;
    let anchors = cfg.anchors(clip)?;
    if cfg.horizon != 0 {
        return Err(Error::config(
            "horizon",
            format!(
                "{}: a zone bundle is validated in one run through the held-out part; leave it 0",
                cfg.horizon
            ),
        ));
    }
    let nf = clip.frames();
    let start = cfg.held_out_start(nf);
    if nf - start < 2 || cfg.warmup > start {
        return Err(Error::invalid(format!(
            "the held-out part {start}..{nf} (warm-up {}) does not fit the clip",
            cfg.warmup
        )));
    }
    let device = device(cfg.device, Precision::F32)?;
    let guidance = guidance_fields(clip, cfg.guidance_scale);
    let first = start - cfg.warmup;
    let gates = cfg.boundary.gates(clip)?;
    let mut out = Vec::new();
    for (name, zs) in sets {
        let nz = zs.zones.len();
        let cells: Vec<Vec<bool>> = (0..nz)
            .map(|z| zs.zones.cell_zone.iter().map(|c| *c == Some(z)).collect())
            .collect();
        let (mut de, mut ve) = (Vec::new(), Vec::new());
        let mut per_zone: Vec<[Vec<f64>; 4]> = vec![Default::default(); nz];
        // With `ensemble_mean`, each zone's emergent measures averaged over the seeds frame by
        // frame (the ensemble's prediction), compared with the clip after the last seed.
        let mut means = vec![vec![[0.0f64; 3]; nz]; nf - start];
        for seed in 0..cfg.seeds {
            let mut frames = Vec::new();
            let (rows, _) = run_from(
                clip,
                &zs.sets[0],
                Some(zs),
                anchors.as_ref().and_then(|a| a.at(first)),
                &gates,
                (first, nf - 1),
                seed as u64,
                &cfg.settle,
                &guidance,
                &device,
                |f, state, ids| {
                    if f >= start {
                        frames.push(state.rows(ids)?);
                    }
                    Ok(())
                },
            )?;
            if first == start {
                frames.insert(0, rows);
            }
            let prov = serde_json::json!({"source": "zone validation", "seed": seed});
            let mut sim = rasterise(
                &frames,
                clip.grid(),
                clip.meta.fps,
                clip.obstacles.clone(),
                prov,
            )?;
            smooth_velocity(&mut sim, clip.meta.velocity_window());
            for (k, mean_k) in means.iter_mut().enumerate() {
                let f = start + k;
                let c = coarse_cells(clip, f, cfg.coarse_grid);
                let (d, v) = cell_errors(&c, &coarse_cells(&sim, k, cfg.coarse_grid));
                de.push(d);
                ve.push(v);
                for (z, acc) in per_zone.iter_mut().enumerate() {
                    let own = emergent(&inside(&sim, k, &cells[z]), 0).values();
                    let own = [own[0], own[1], own[3]];
                    acc[0].push(zone_density_error(clip, f, &sim, k, &cells[z]));
                    if cfg.ensemble_mean {
                        for (m, o) in mean_k[z].iter_mut().zip(own) {
                            *m += o / cfg.seeds as f64;
                        }
                    } else {
                        push_errors(acc, own, &video_values(clip, f, &cells[z]));
                    }
                }
            }
            progress().proceed()?;
        }
        if cfg.ensemble_mean {
            for (k, mean_k) in means.iter().enumerate() {
                for (z, acc) in per_zone.iter_mut().enumerate() {
                    push_errors(acc, mean_k[z], &video_values(clip, start + k, &cells[z]));
                }
            }
        }
        out.push(ZoneSetReport {
            name: name.clone(),
            density_error: stat(&de),
            velocity_error: stat(&ve),
            zones: per_zone
                .iter()
                .zip(&zs.zones.specs)
                .map(|(a, spec)| ZoneRow {
                    zone: spec.name.clone(),
                    density_error: stat(&a[0]),
                    polarization_error: stat(&a[1]),
                    angular_momentum_error: stat(&a[2]),
                    aspect_ratio_error: stat(&a[3]),
                })
                .collect(),
        });
    }
    Ok(out)
}

/// The clip's polarization, angular momentum (about the centroid) and aspect ratio inside the
/// cells `cells` of frame `f`.
fn video_values(clip: &ClipFields, f: usize, cells: &[bool]) -> [f64; 3] {
    let v = emergent(&inside(clip, f, cells), 0).values();
    [v[0], v[1], v[3]]
}

/// Appends the absolute errors of the simulated measures `own` against the clip's `video` to the
/// polarization, angular-momentum and aspect-ratio lists of `acc`.
fn push_errors(acc: &mut [Vec<f64>; 4], own: [f64; 3], video: &[f64; 3]) {
    for (i, (o, v)) in own.iter().zip(video).enumerate() {
        acc[i + 1].push((o - v).abs());
    }
}
