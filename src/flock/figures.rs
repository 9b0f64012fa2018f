//! PNG figures of an animation: the key shapes with each bird's saving, and the savings over time.

use super::animate::AnimationReport;
use crate::error::Result;
use crate::plot::{axes, legend, line_chart, png, Series, PALETTE};
use plotters::prelude::*;
use std::path::Path;

fn bounds(pts: impl Iterator<Item = [f64; 2]>) -> ([f64; 2], [f64; 2]) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in pts {
        for k in 0..2 {
            lo[k] = lo[k].min(p[k]);
            hi[k] = hi[k].max(p[k]);
        }
    }
    if !lo[0].is_finite() {
        return ([0.0, 0.0], [1.0, 1.0]);
    }
    (lo, hi)
}

/// Left: the first key shape (the initiation's target, black) and up to five later key shapes,
/// wingspans, flight direction up. Right: each bird's ξ over the key shapes (dots) against its
/// feasible range [(1 − ε) p_i, (1 + ε) P_i] (bars), birds ordered left to right.
pub fn shapes_png(path: &Path, r: &AnimationReport) -> Result<()> {
    let n = r.birds;
    // Lateral order of the birds in the first key shape.
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&a, &b| r.keys[0].pos[a][0].total_cmp(&r.keys[0].pos[b][0]));
    let shown: Vec<usize> = {
        let k = r.keys.len();
        let step = (k.saturating_sub(1)).div_ceil(5).max(1);
        (0..k).step_by(step).collect()
    };
    png(path, (1400, 620), |root| {
        root.fill(&WHITE)?;
        let (l, rt) = root.split_horizontally(700);
        let (lo, hi) = bounds(shown.iter().flat_map(|&k| r.keys[k].pos.iter().copied()));
        let pad = 1.0;
        let mut chart = ChartBuilder::on(&l)
            .caption(
                format!("{} key shapes of {} birds (wingspans)", r.keys.len(), n),
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(48)
            .build_cartesian_2d(lo[0] - pad..hi[0] + pad, lo[1] - pad..hi[1] + pad)?;
        axes(
            &mut chart,
            "lateral x (b)",
            "longitudinal y (b), flight ↑",
            13,
        )?;
        for (c, &k) in shown.iter().enumerate() {
            let colour = if k == 0 {
                BLACK
            } else {
                PALETTE[c % PALETTE.len()]
            };
            let t = r.key_times.get(k).copied().unwrap_or(0.0);
            chart
                .draw_series(
                    r.keys[k]
                        .pos
                        .iter()
                        .map(|p| Circle::new((p[0], p[1]), 4, colour.filled())),
                )?
                .label(format!("key {k} (t = {t:.1} s)"))
                .legend(move |(x, y)| Circle::new((x + 8, y), 4, colour.filled()));
        }
        legend(&mut chart, 0.8, 13)?;
        let eps = r.config.steady.epsilon;
        let ymax = r
            .xi_range
            .iter()
            .map(|v| v[1] * (1.0 + eps))
            .chain(r.keys.iter().flat_map(|k| k.xi.iter().copied()))
            .fold(0.0, f64::max)
            * 1.1;
        let mut chart = ChartBuilder::on(&rt)
            .caption(
                "relative saving ξ per bird: range and key shapes",
                ("sans-serif", 20),
            )
            .margin(12)
            .x_label_area_size(36)
            .y_label_area_size(60)
            .build_cartesian_2d(-0.5..n as f64 - 0.5, 0.0..ymax.max(1e-6))?;
        axes(&mut chart, "bird, left to right", "ξ = e_i / Σ e", 13)?;
        chart
            .draw_series(order.iter().enumerate().map(|(c, &i)| {
                let v = r.xi_range[i];
                Rectangle::new(
                    [
                        (c as f64 - 0.3, v[0] * (1.0 - eps)),
                        (c as f64 + 0.3, v[1] * (1.0 + eps)),
                    ],
                    RGBColor(200, 200, 200).filled(),
                )
            }))?
            .label("feasible range")
            .legend(|(x, y)| {
                Rectangle::new(
                    [(x, y - 5), (x + 16, y + 5)],
                    RGBColor(200, 200, 200).filled(),
                )
            });
        for k in &r.keys {
            chart.draw_series(order.iter().enumerate().map(|(c, &i)| {
                Circle::new((c as f64, k.xi[i]), 2, RGBColor(31, 119, 180).filled())
            }))?;
        }
        legend(&mut chart, 0.8, 13)?;
        Ok(())
    })
}

/// The flock's mean power reduction over the steady frames, with the least and the most saving
/// bird, in percent of induced power.
pub fn savings_png(path: &Path, rows: &[(u64, f64, u64, f64, f64)], birds: usize) -> Result<()> {
    let mut mean = Vec::new();
    let mut lo = Vec::new();
    let mut hi = Vec::new();
    for chunk in rows.chunks(birds.max(1)) {
        let t = chunk[0].1;
        let e: Vec<f64> = chunk.iter().map(|r| 100.0 * r.3).collect();
        mean.push((t, e.iter().sum::<f64>() / e.len() as f64));
        lo.push((t, e.iter().cloned().fold(f64::INFINITY, f64::min)));
        hi.push((t, e.iter().cloned().fold(f64::NEG_INFINITY, f64::max)));
    }
    line_chart(
        path,
        "induced-power saving over the steady flight",
        "time (s)",
        "saving (% of induced power)",
        &[
            Series {
                name: "most saving bird",
                points: hi,
                colour: RGBColor(44, 160, 44),
            },
            Series {
                name: "flock mean",
                points: mean,
                colour: RGBColor(0, 0, 0),
            },
            Series {
                name: "least saving bird",
                points: lo,
                colour: RGBColor(214, 39, 40),
            },
        ],
    )
}
