//! The reference implementation's measures (HerdFromVideo, `HerdController.cs`: `ErrorDensity`,
//! `ErrorVelocity`, `ErrorPolarization`, `ErrorAngularMomentum`, `ErrorAspectRatio`), computed
//! on a run's agents against a clip frame, so that a herdfit run can be put line by line beside
//! the reference's error logs (`validate --measures reference`). Re-implemented from their
//! definitions:
//!
//! - **density**: over the cells holding at least one simulated agent, the mean of
//!   |ρ − ρ'| / (ρ + 0.1), densities in agents/BL² (so a simulated agent in a cell the video holds
//!   empty costs 1/(0.1 A), A the cell's area);
//! - **velocity**: over the simulated agents in cells whose target velocity is not zero
//!   (|V|² > 10⁻³), the mean of ‖N(v_i) − N(V)‖, V the frame's velocity field propagated into
//!   empty cells ([`propagate`], radius 10, as `GetPropagatedVelocityField`);
//! - **polarization** (eq. 12): ‖Σ N(v_i)‖ / N;
//! - **angular momentum** (eq. 13 about the herd's centroid): ‖Σ (v_i × r_i) / (|v_i||r_i| +
//!   10⁻⁵)‖ / N;
//! - **aspect ratio**: the extent across the mean direction over the extent along it, of the
//!   agents (simulation) or of the occupied cells' centres (video); 1 when undefined.
//!
//! Targets of polarization and angular momentum are the video's own per-frame values when the
//! clip carries them (the reference extractor's frame headers, computed from the body pixels'
//! flow; `import-reference` keeps them), else the same formulas on the cells (each cell's mean
//! velocity weighted by its count). Errors are |simulation − target|. Agents outside the grid
//! are not in view and not measured.

use crate::data::agents::AgentRow;
use crate::data::ClipFields;

type P2 = [f64; 2];

/// The reference's measures of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefFrame {
    pub density_error: f64,
    pub velocity_error: f64,
    /// (target, simulation) of each emergent measure.
    pub polarization: [f64; 2],
    pub angular_momentum: [f64; 2],
    pub aspect_ratio: [f64; 2],
}

/// Names of the reference's five error columns, in log order.
pub const REFERENCE_MEASURES: [&str; 5] = [
    "density",
    "velocity",
    "polarization",
    "angular_momentum",
    "aspect_ratio",
];

impl RefFrame {
    /// The five errors in [`REFERENCE_MEASURES`] order.
    pub fn errors(&self) -> [f64; 5] {
        let e = |m: [f64; 2]| (m[1] - m[0]).abs();
        [
            self.density_error,
            self.velocity_error,
            e(self.polarization),
            e(self.angular_momentum),
            e(self.aspect_ratio),
        ]
    }

    /// One line of the reference's error log (`Frame DensityError VelocityError
    /// TargetPolarization SimulatedPolarization PolarizationError …`), four decimals.
    pub fn log_line(&self, frame: usize) -> String {
        let e = self.errors();
        let m = [self.polarization, self.angular_momentum, self.aspect_ratio];
        let mut s = format!("{frame} {:.4} {:.4}", e[0], e[1]);
        for (k, v) in m.iter().enumerate() {
            s.push_str(&format!(" {:.4} {:.4} {:.4}", v[0], v[1], e[2 + k]));
        }
        s
    }
}

/// Header of the reference's error logs.
pub const LOG_HEADER: &str = "Frame DensityError VelocityError TargetPolarization \
SimulatedPolarization PolarizationError TargetAngularMomentum SimulatedAngularMomentum \
AngularMomentumError TargetAspectRatio SimulatedAspectRatio AspectRatioError";

fn norm(v: P2) -> P2 {
    let l = v[0].hypot(v[1]);
    if l > 0.0 {
        [v[0] / l, v[1] / l]
    } else {
        [0.0, 0.0]
    }
}

/// Propagates a vector field into the cells it leaves empty, as the reference's
/// `GetPropagatedVelocityField`: the cells with |v|² > 10⁻³ seed it; ring by ring (up to
/// `radius` − 1 rings, neighbours right, up, left, down), each cell not yet reached takes the
/// running mean of (r − 1)/r times its reached neighbours' vectors, r the radius left; a reached
/// cell facing an inaccessible neighbour within 90° of its vector gets a correction that removes
/// that component, propagated the same way over half the radius through accessible cells only.
/// `field` and `accessible` are row-major `ny × nx`, row 0 at the bottom.
pub fn propagate(
    field: &[P2],
    accessible: &[bool],
    nx: usize,
    ny: usize,
    radius: usize,
) -> Vec<P2> {
    let n = nx * ny;
    let mut buf = vec![[0.0; 2]; n];
    let mut visits = vec![0u32; n];
    let mut checked = vec![false; n];
    let mut frontier = Vec::new();
    for c in 0..n {
        let v = field[c];
        if v[0] * v[0] + v[1] * v[1] > 1e-3 {
            buf[c] = v;
            visits[c] = 1;
            checked[c] = true;
            frontier.push(c);
        }
    }
    let mut corr = vec![[0.0; 2]; n];
    let mut corr_visits = vec![0u32; n];
    let mut corr_checked = vec![false; n];
    let mut corr_frontier = Vec::new();
    spread(
        &mut buf,
        &mut visits,
        &mut checked,
        frontier,
        radius,
        (nx, ny),
        None,
        Some((
            accessible,
            (
                &mut corr,
                &mut corr_visits,
                &mut corr_checked,
                &mut corr_frontier,
            ),
        )),
    );
    spread(
        &mut corr,
        &mut corr_visits,
        &mut corr_checked,
        corr_frontier,
        radius / 2,
        (nx, ny),
        Some(accessible),
        None,
    );
    buf.iter()
        .zip(&corr)
        .map(|(a, b)| [a[0] + b[0], a[1] + b[1]])
        .collect()
}

type Correction<'a> = (
    &'a mut Vec<P2>,
    &'a mut Vec<u32>,
    &'a mut Vec<bool>,
    &'a mut Vec<usize>,
);

/// One propagation of [`propagate`]: rings from `frontier` while the radius left exceeds 1,
/// reaching only `reach` cells when given; with `corr`, corrections at inaccessible neighbours.
#[allow(clippy::too_many_arguments)]
fn spread(
    buf: &mut [P2],
    visits: &mut [u32],
    checked: &mut [bool],
    mut frontier: Vec<usize>,
    radius: usize,
    (nx, ny): (usize, usize),
    reach: Option<&[bool]>,
    mut corr: Option<(&[bool], Correction)>,
) {
    // Right, up, left, down (the reference's order; y up).
    const STEPS: [(i64, i64); 4] = [(1, 0), (0, 1), (-1, 0), (0, -1)];
    let mut r = radius;
    while r > 1 {
        let mut reached: Vec<usize> = Vec::new();
        let mut in_reached = vec![false; buf.len()];
        for &c in &frontier {
            let (cx, cy) = ((c % nx) as i64, (c / nx) as i64);
            for (dx, dy) in STEPS {
                let (x, y) = (cx + dx, cy + dy);
                if x < 0 || y < 0 || x >= nx as i64 || y >= ny as i64 {
                    continue;
                }
                let m = y as usize * nx + x as usize;
                let open = reach.is_none_or(|a| a[m]);
                if !checked[m] && open {
                    visits[m] += 1;
                    let k = (r as f64 - 1.0) / r as f64;
                    let (src, dst) = (buf[c], buf[m]);
                    for j in 0..2 {
                        buf[m][j] = dst[j] + (k * src[j] - dst[j]) / visits[m] as f64;
                    }
                    if !in_reached[m] {
                        in_reached[m] = true;
                        reached.push(m);
                    }
                }
                if let Some((a, (cf, cv, cc, cfr))) = corr.as_mut() {
                    if !a[m] {
                        let d = norm([dx as f64, dy as f64]);
                        let g = buf[c];
                        let dot = d[0] * g[0] + d[1] * g[1];
                        // Within 90° of the cell's vector: take that component away.
                        if g[0].hypot(g[1]) > 0.0 && dot > 0.0 {
                            if !cc[c] {
                                cc[c] = true;
                                cfr.push(c);
                            }
                            cf[c][0] -= d[0] * dot;
                            cf[c][1] -= d[1] * dot;
                            cv[c] = 1;
                        }
                    }
                }
            }
        }
        for &m in &reached {
            checked[m] = true;
        }
        frontier = reached;
        r -= 1;
    }
}

/// The frame's velocity field propagated as the reference's velocity error targets it.
pub fn target_velocity(clip: &ClipFields, f: usize) -> Vec<P2> {
    let (nx, ny) = (clip.meta.nx, clip.meta.ny);
    let field: Vec<P2> = (0..nx * ny)
        .map(|c| {
            let (ix, iy) = (c % nx, c / nx);
            [
                clip.velocity[[f, iy, ix, 0]] as f64,
                clip.velocity[[f, iy, ix, 1]] as f64,
            ]
        })
        .collect();
    let accessible: Vec<bool> = (0..nx * ny)
        .map(|c| clip.obstacles[[c / nx, c % nx]] == 0)
        .collect();
    propagate(&field, &accessible, nx, ny, 10)
}

/// Polarization and angular momentum of weighted points with velocities (eq. 12–13 as the
/// reference computes them): ‖Σ w N(v)‖ / Σ w and ‖Σ w (v × r)/(|v||r| + 10⁻⁵)‖ / Σ w, r from the
/// weighted centroid.
fn order(points: &[(P2, P2, f64)]) -> (f64, f64) {
    let wsum: f64 = points.iter().map(|p| p.2).sum();
    if wsum.is_nan() || wsum <= 0.0 {
        return (f64::NAN, f64::NAN);
    }
    let mut c = [0.0; 2];
    let mut pol = [0.0; 2];
    for &(p, v, w) in points {
        c[0] += w * p[0] / wsum;
        c[1] += w * p[1] / wsum;
        let n = norm(v);
        pol[0] += w * n[0];
        pol[1] += w * n[1];
    }
    let mut am = 0.0;
    for &(p, v, w) in points {
        let r = [p[0] - c[0], p[1] - c[1]];
        let cross = v[0] * r[1] - v[1] * r[0];
        am += w * cross / (v[0].hypot(v[1]) * r[0].hypot(r[1]) + 1e-5);
    }
    (pol[0].hypot(pol[1]) / wsum, am.abs() / wsum)
}

/// The aspect ratio of points about their centroid: extent across `forward` over extent along
/// it (the reference's `ErrorAspectRatio`; `forward` = +y when the mean direction is zero); 1
/// with fewer than two points or when undefined.
fn aspect(points: &[P2], dirs: &[P2]) -> f64 {
    if points.len() < 2 {
        return 1.0;
    }
    let n = points.len() as f64;
    let c = points
        .iter()
        .fold([0.0; 2], |a, p| [a[0] + p[0] / n, a[1] + p[1] / n]);
    let sum = dirs.iter().fold([0.0; 2], |a, d| {
        let u = norm(*d);
        [a[0] + u[0], a[1] + u[1]]
    });
    let fwd = if sum[0] * sum[0] + sum[1] * sum[1] > f64::EPSILON {
        norm(sum)
    } else {
        [0.0, 1.0]
    };
    // Unity's Cross(up, forward) in the ground plane.
    let right = [fwd[1], -fwd[0]];
    let (mut lo, mut hi) = ([f64::MAX; 2], [f64::MIN; 2]);
    for p in points {
        let r = [p[0] - c[0], p[1] - c[1]];
        let a = [
            r[0] * fwd[0] + r[1] * fwd[1],
            r[0] * right[0] + r[1] * right[1],
        ];
        for k in 0..2 {
            lo[k] = lo[k].min(a[k]);
            hi[k] = hi[k].max(a[k]);
        }
    }
    let (along, across) = (hi[0] - lo[0], hi[1] - lo[1]);
    let ar = if along > 1e-6 {
        across / along
    } else if across > 1e-6 {
        f64::INFINITY
    } else {
        1.0
    };
    if ar.is_finite() {
        ar
    } else {
        1.0
    }
}

/// The reference's measures of the agents `agents` against frame `f` of `clip`, the velocity
/// error against `target` ([`target_velocity`] of that frame).
pub fn reference_frame(
    clip: &ClipFields,
    f: usize,
    agents: &[AgentRow],
    target: &[P2],
) -> RefFrame {
    let g = clip.grid();
    let (nx, ny) = (g.nx, g.ny);
    let area = g.cell_area();
    let seen: Vec<(usize, &AgentRow)> = agents
        .iter()
        .filter_map(|a| g.cell_of([a.x, a.y]).map(|(ix, iy)| (iy * nx + ix, a)))
        .collect();
    let mut counts = vec![0.0f64; nx * ny];
    for &(c, _) in &seen {
        counts[c] += 1.0;
    }
    let (mut de, mut dn) = (0.0, 0.0);
    for (c, &k) in counts.iter().enumerate() {
        if k >= 1.0 {
            let rho = clip.density[[f, c / nx, c % nx]] as f64;
            de += (rho - k / area).abs() / (rho + 0.1);
            dn += 1.0;
        }
    }
    let (mut ve, mut vn) = (0.0, 0.0);
    for &(c, a) in &seen {
        let t = target[c];
        if t[0] * t[0] + t[1] * t[1] > 1e-3 {
            let (u, w) = (norm([a.vx, a.vy]), norm(t));
            ve += (u[0] - w[0]).hypot(u[1] - w[1]);
            vn += 1.0;
        }
    }
    let sim: Vec<(P2, P2, f64)> = seen
        .iter()
        .map(|&(_, a)| ([a.x, a.y], [a.vx, a.vy], 1.0))
        .collect();
    let (sim_pol, sim_am) = order(&sim);
    // The video: each occupied cell's centre and mean velocity, weighted by its count.
    let cells: Vec<(P2, P2, f64)> = (0..nx * ny)
        .filter_map(|c| {
            let (ix, iy) = (c % nx, c / nx);
            let n = clip.density[[f, iy, ix]] as f64 * area;
            let v = [
                clip.velocity[[f, iy, ix, 0]] as f64,
                clip.velocity[[f, iy, ix, 1]] as f64,
            ];
            (n > 0.0).then(|| (g.centre(ix, iy), v, n))
        })
        .collect();
    let (cell_pol, cell_am) = order(&cells);
    let header = clip.meta.frame_measures.as_ref();
    let video_pol = header.map_or(cell_pol, |h| h.polarization[f]);
    let video_am = header.map_or(cell_am, |h| h.angular_momentum[f]);
    let sim_points: Vec<P2> = sim.iter().map(|s| s.0).collect();
    let sim_dirs: Vec<P2> = sim.iter().map(|s| s.1).collect();
    let cell_points: Vec<P2> = cells.iter().map(|s| s.0).collect();
    let cell_dirs: Vec<P2> = cells
        .iter()
        .map(|s| s.1)
        .filter(|v| v[0] * v[0] + v[1] * v[1] > f64::EPSILON)
        .collect();
    RefFrame {
        density_error: if dn > 0.0 { de / dn } else { f64::NAN },
        velocity_error: if vn > 0.0 { ve / vn } else { f64::NAN },
        polarization: [video_pol, sim_pol],
        angular_momentum: [video_am, sim_am],
        aspect_ratio: [
            aspect(&cell_points, &cell_dirs),
            aspect(&sim_points, &sim_dirs),
        ],
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::{ClipMeta, ClipSpeed, Grid};
    use ndarray::{Array2, Array3, Array4};

    /// Two 1-BL cells side by side: two animals in the left one moving +x, none in the right.
    fn two_cells() -> ClipFields {
        let mut density = Array3::zeros((1, 1, 2));
        density[[0, 0, 0]] = 2.0;
        let mut velocity = Array4::zeros((1, 1, 2, 2));
        velocity[[0, 0, 0, 0]] = 1.0;
        ClipFields {
            meta: ClipMeta::of_grid(
                &Grid {
                    origin: [0.0, 0.0],
                    cell_size: 1.0,
                    nx: 2,
                    ny: 1,
                },
                10.0,
                1,
                ClipSpeed {
                    mean: 1.0,
                    std: 0.1,
                    density_table: vec![],
                },
            ),
            density,
            velocity,
            dir_variance: Array3::zeros((1, 1, 2)),
            obstacles: Array2::zeros((1, 2)),
        }
    }

    #[test]
    fn three_agents_by_hand() {
        let clip = two_cells();
        let row = |id, x, y, vx, vy| AgentRow { id, x, y, vx, vy };
        let agents = [
            row(0, 0.5, 0.5, 1.0, 0.0),
            row(1, 0.2, 0.8, 0.0, 1.0),
            row(2, 1.5, 0.5, 1.0, 1.0),
        ];
        let target = target_velocity(&clip, 0);
        // The right cell is reached in the first ring: 9/10 of its neighbour's velocity.
        assert_eq!(target, vec![[1.0, 0.0], [0.9, 0.0]]);
        let m = reference_frame(&clip, 0, &agents, &target);
        // Density: the left cell matches (2 = 2 per BL²); the right one holds an agent the video
        // has not: |0 − 1| / (0 + 0.1) = 10; mean over the two occupied cells 5.
        assert!((m.density_error - 5.0).abs() < 1e-12, "{m:?}");
        // Velocity: 0, ‖(0, 1) − (1, 0)‖ = √2 and ‖(1, 1)/√2 − (1, 0)‖, over three agents.
        assert!((m.velocity_error - 0.726_526_809_034_424_9).abs() < 1e-12);
        // ‖(1, 0) + (0, 1) + (1, 1)/√2‖ / 3.
        assert!((m.polarization[1] - 0.804_737_854_124_364_9).abs() < 1e-12);
        assert!((m.angular_momentum[1] - 0.083_402_594_182_604_43).abs() < 1e-12);
        // Across the mean direction (1, 1)/√2 the agents spread 1.6 times as far as along it.
        assert!((m.aspect_ratio[1] - 1.6).abs() < 1e-12);
        // The video: one occupied cell moving +x: polarization 1, no rotation, one point.
        assert_eq!(m.polarization[0], 1.0);
        assert_eq!(m.angular_momentum[0], 0.0);
        assert_eq!(m.aspect_ratio[0], 1.0);
        let e = m.errors();
        assert!((e[2] - (1.0 - 0.804_737_854_124_364_9)).abs() < 1e-12);
        assert!(m
            .log_line(1)
            .starts_with("1 5.0000 0.7265 1.0000 0.8047 0.1953 0.0000 0.0834"));
    }

    #[test]
    fn propagation_decays_ring_by_ring_and_averages_meeting_fronts() {
        // A 5 × 1 strip seeded at both ends: the middle cell is reached from both sides in the
        // same ring and takes the mean of the two; each ring scales by (r − 1)/r.
        let mut field = vec![[0.0; 2]; 5];
        field[0] = [1.0, 0.0];
        field[4] = [0.0, 1.0];
        let out = propagate(&field, &[true; 5], 5, 1, 10);
        let k9 = 9.0 / 10.0;
        assert_eq!(out[1], [k9, 0.0]);
        assert_eq!(out[3], [0.0, k9]);
        let k8 = 8.0 / 9.0;
        assert!((out[2][0] - k8 * k9 / 2.0).abs() < 1e-12);
        assert!((out[2][1] - k8 * k9 / 2.0).abs() < 1e-12);
        // Radius 2: one ring only.
        let near = propagate(&[[1.0, 0.0], [0.0; 2], [0.0; 2]], &[true; 3], 3, 1, 2);
        assert_eq!(near[1], [0.5, 0.0]);
        assert_eq!(near[2], [0.0, 0.0]);
    }
}
