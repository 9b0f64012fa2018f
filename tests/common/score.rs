//! Scores of an extraction against the trajectories of `herdfit synth` (shared by
//! `tests/extract.rs` and `tests/extract_auto.rs`).
#![allow(dead_code)]

use herdfit::data::agents::AgentRow;
use herdfit::data::{ClipFields, Grid};
use herdfit::measure::rasterise;
use ndarray::Array2;
use std::path::Path;

/// `trajectories.csv` of `herdfit synth`, frame by frame.
pub fn read_traj(path: &Path) -> Vec<Vec<AgentRow>> {
    let text = std::fs::read_to_string(path).unwrap();
    let mut frames: Vec<Vec<AgentRow>> = Vec::new();
    for l in text.lines().skip(1) {
        let c: Vec<&str> = l.split(',').collect();
        let f: usize = c[0].parse().unwrap();
        if frames.len() <= f {
            frames.push(Vec::new());
        }
        frames[f].push(AgentRow {
            id: c[2].parse().unwrap(),
            x: c[3].parse().unwrap(),
            y: c[4].parse().unwrap(),
            vx: c[5].parse().unwrap(),
            vy: c[6].parse().unwrap(),
        });
    }
    frames
}

pub fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// How an extraction compares with the truth.
#[derive(Debug, Clone, Copy)]
pub struct Score {
    /// Median over frames of |extracted animals − true animals| / true animals.
    pub count_err: f64,
    /// Median per-frame Pearson r of the density against the truth rasterised on the clip grid.
    pub r: f64,
    /// Median direction error (degrees) of the occupied cells' velocities.
    pub dir_err: f64,
    /// Median over frames of the angle (degrees) between the herd's extracted momentum
    /// (Σ density × velocity) and the true one (Σ agent velocities).
    pub heading_err: f64,
    /// |extracted mean speed − true mean speed| / true mean speed.
    pub speed_err: f64,
}

fn angle(u: [f64; 2], v: [f64; 2]) -> f64 {
    (u[0] * v[1] - u[1] * v[0])
        .abs()
        .atan2(u[0] * v[0] + u[1] * v[1])
        .to_degrees()
}

/// The [`Score`] of `extracted` against the trajectories `truth_traj` (true mean speed
/// `truth_speed`, BL/s) of a video drawn at `px_per_bl` pixels per body length.
///
/// The clip's cells are regions of the first frame, its lengths in the *estimated* body length,
/// so the truth is placed where it is in that frame: each true position (BL) is taken to video
/// pixels at `px_per_bl` and back to the clip's units at the estimated length. (Rasterised in its
/// own BL, a 5 % error in the estimated length would shift the truth by 5 % of the frame against
/// the cells it is compared with; the length's error shows in the speed error instead.)
#[allow(clippy::needless_range_loop)]
pub fn score(
    extracted: &ClipFields,
    truth_traj: &[Vec<AgentRow>],
    truth_speed: f64,
    px_per_bl: f64,
) -> Score {
    let m = &extracted.meta;
    let k = px_per_bl / m.body_length_px.unwrap_or(px_per_bl);
    let placed: Vec<Vec<AgentRow>> = truth_traj
        .iter()
        .map(|f| {
            f.iter()
                .map(|a| AgentRow {
                    x: a.x * k,
                    y: a.y * k,
                    vx: a.vx * k,
                    vy: a.vy * k,
                    ..*a
                })
                .collect()
        })
        .collect();
    let grid = Grid {
        origin: [0.0, 0.0],
        cell_size: m.cell_size,
        nx: m.nx,
        ny: m.ny,
    };
    let truth = rasterise(
        &placed,
        grid,
        m.fps,
        Array2::zeros((m.ny, m.nx)),
        serde_json::Value::Null,
    )
    .unwrap();
    let (mut rs, mut errs, mut counts, mut headings) = (vec![], vec![], vec![], vec![]);
    for f in 0..m.frames {
        let a: Vec<f64> = extracted
            .density
            .index_axis(ndarray::Axis(0), f)
            .iter()
            .map(|&v| v as f64)
            .collect();
        let b: Vec<f64> = truth
            .density
            .index_axis(ndarray::Axis(0), f)
            .iter()
            .map(|&v| v as f64)
            .collect();
        let (ma, mb) = (
            a.iter().sum::<f64>() / a.len() as f64,
            b.iter().sum::<f64>() / b.len() as f64,
        );
        let cov: f64 = a.iter().zip(&b).map(|(x, y)| (x - ma) * (y - mb)).sum();
        let va: f64 = a.iter().map(|x| (x - ma).powi(2)).sum();
        let vb: f64 = b.iter().map(|y| (y - mb).powi(2)).sum();
        rs.push(cov / (va * vb).sqrt());
        let n_true = truth_traj[f].len() as f64;
        counts.push((extracted.count(f) - n_true).abs() / n_true);
        let p_true = truth_traj[f]
            .iter()
            .fold([0.0, 0.0], |s, a| [s[0] + a.vx, s[1] + a.vy]);
        let mut p_ex = [0.0, 0.0];
        for iy in 0..m.ny {
            for ix in 0..m.nx {
                let d = extracted.density[[f, iy, ix]] as f64;
                p_ex[0] += d * extracted.velocity[[f, iy, ix, 0]] as f64;
                p_ex[1] += d * extracted.velocity[[f, iy, ix, 1]] as f64;
                if truth.density[[f, iy, ix]] > 0.0 && d > 0.0 {
                    let u = [
                        truth.velocity[[f, iy, ix, 0]] as f64,
                        truth.velocity[[f, iy, ix, 1]] as f64,
                    ];
                    let v = [
                        extracted.velocity[[f, iy, ix, 0]] as f64,
                        extracted.velocity[[f, iy, ix, 1]] as f64,
                    ];
                    if u[0].hypot(u[1]) > 1e-6 && v[0].hypot(v[1]) > 1e-6 {
                        errs.push(angle(u, v));
                    }
                }
            }
        }
        headings.push(angle(p_true, p_ex));
    }
    Score {
        count_err: median(counts),
        r: median(rs),
        dir_err: median(errs),
        heading_err: median(headings),
        speed_err: (m.speed.mean - truth_speed).abs() / truth_speed,
    }
}
