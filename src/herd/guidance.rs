//! Leader guidance from a clip (DESIGN §4.2): the clip's momentum, optionally smoothed, taken as
//! the direction leaders follow in every accessible cell, propagated into empty cells.

use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::sim::Guidance;

/// Default σ (cells) of [`guidance_field`]: each cell's own mean velocity (see there for why).
pub const GUIDANCE_SCALE: f64 = 0.0;

/// Gaussian smoothing of a `ny × nx` field (row-major) with σ = `sigma` cells, zero outside the
/// grid, truncated at 4σ; σ = ∞ gives the field's sum everywhere.
fn gauss_smooth(v: &[f64], nx: usize, ny: usize, sigma: f64) -> Vec<f64> {
    if sigma.is_infinite() {
        return vec![v.iter().sum(); v.len()];
    }
    let reach = (4.0 * sigma).ceil() as i64;
    let w: Vec<f64> = (-reach..=reach)
        .map(|d| (-0.5 * (d as f64 / sigma).powi(2)).exp())
        .collect();
    crate::measure::fields::separable_filter(v, nx, ny, &w)
}

/// Checks a `guidance_scale` value: ≥ 0, ∞ allowed.
pub fn check_guidance_scale(v: f64) -> Result<()> {
    // A finite σ beyond a million cells is no scale (its kernel would not fit in memory, issue
    // #47); inf says "the herd's mean direction everywhere".
    if v.is_nan() || v < 0.0 || (v.is_finite() && v > 1e6) {
        return Err(Error::config(
            "guidance_scale",
            format!(
                "{} is out of range: it must be in 0..=1e6 cells (or inf)",
                crate::limits::show(v)
            ),
        ));
    }
    Ok(())
}

/// [`guidance_field`] of every frame of the clip.
pub fn guidance_fields(clip: &ClipFields, scale: f64) -> Vec<Guidance> {
    (0..clip.frames())
        .map(|f| guidance_field(clip, f, scale))
        .collect()
}

/// Leader guidance of frame `f`: the clip's momentum ρV smoothed by a Gaussian of σ = `scale`
/// cells (0: each occupied cell's own mean velocity; ∞: the herd's mean direction everywhere),
/// taken as a direction in every accessible cell it reaches, then propagated into the remaining
/// accessible cells (each takes the mean of its already-filled 4-neighbours, breadth first).
///
/// A cell's mean velocity holds the followers' own motion too, such as the inward drift of a
/// herd's flanks under cohesion; leaders that follow it pull the flanks in further. On the
/// recovery clips (RESULTS.md §1, seeds 11–13), the true parameters started from the clip's own
/// agents end 200 frames with a radius of gyration 0.16–0.42 BL below the clip’s with σ = 0, and
/// within 0.1 BL of it with σ = ∞ (`cargo run --release --example init_bias`). But the raw field
/// also carries how this clip's herd went round its obstacles, which a smoothed one loses: fitted
/// from θ* on clips 11–14, σ = 0 ends 0.138 from θ*, σ = ∞ 0.213. Hence σ = 0 by default;
/// `--guidance-scale` sets it.
pub fn guidance_field(clip: &ClipFields, f: usize, scale: f64) -> Guidance {
    let g = clip.grid();
    let (nx, ny) = (g.nx, g.ny);
    let mut dirs = vec![[0.0f64; 2]; nx * ny];
    let mut filled = vec![false; nx * ny];
    let mut frontier = Vec::new();
    // Each cell's velocity (σ = 0) or momentum ρV (to be smoothed), component k.
    let cells = |k: usize| -> Vec<f64> {
        let mut m = vec![0.0; nx * ny];
        for iy in 0..ny {
            for ix in 0..nx {
                let v = clip.velocity[[f, iy, ix, k]] as f64;
                m[iy * nx + ix] = if scale > 0.0 {
                    clip.density[[f, iy, ix]] as f64 * v
                } else {
                    v
                };
            }
        }
        m
    };
    let (mx, my) = if scale > 0.0 {
        (
            gauss_smooth(&cells(0), nx, ny, scale),
            gauss_smooth(&cells(1), nx, ny, scale),
        )
    } else {
        (cells(0), cells(1))
    };
    for iy in 0..ny {
        for ix in 0..nx {
            let c = iy * nx + ix;
            let v = [mx[c], my[c]];
            let reached = if scale > 0.0 {
                clip.obstacles[[iy, ix]] == 0
            } else {
                clip.density[[f, iy, ix]] > 0.0
            };
            let moving = if scale > 0.0 {
                (v[0] * v[0] + v[1] * v[1]).sqrt() > 1e-9
            } else {
                v[0] != 0.0 || v[1] != 0.0
            };
            if reached && moving {
                dirs[c] = v;
                filled[c] = true;
                frontier.push(c);
            }
        }
    }
    while !frontier.is_empty() {
        let mut next = Vec::new();
        let mut acc: std::collections::BTreeMap<usize, ([f64; 2], u32)> = Default::default();
        for &c in &frontier {
            let (ix, iy) = ((c % nx) as i64, (c / nx) as i64);
            for (dx, dy) in [(1, 0), (-1, 0), (0, 1), (0, -1)] {
                let (jx, jy) = (ix + dx, iy + dy);
                if jx < 0 || jy < 0 || jx >= nx as i64 || jy >= ny as i64 {
                    continue;
                }
                let j = jy as usize * nx + jx as usize;
                if filled[j] || clip.obstacles[[jy as usize, jx as usize]] != 0 {
                    continue;
                }
                let e = acc.entry(j).or_insert(([0.0; 2], 0));
                e.0[0] += dirs[c][0];
                e.0[1] += dirs[c][1];
                e.1 += 1;
            }
        }
        for (j, (v, k)) in acc {
            dirs[j] = [v[0] / k as f64, v[1] / k as f64];
            filled[j] = true;
            next.push(j);
        }
        frontier = next;
    }
    Guidance::Field {
        origin: g.origin,
        cell_size: g.cell_size,
        nx,
        ny,
        dirs,
    }
}
