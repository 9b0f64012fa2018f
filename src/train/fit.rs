//! Fitting the 12 force parameters to clip fields by gradient descent through unrolled steps
//! (paper §6, DESIGN §5), then the speed model from the clip (§6.2).
//!
//! An epoch starts a herd from the fields of the first frame of the range and walks through the
//! frames in windows of W steps. Each step is first *planned* without gradient — perception and
//! roles (leaders follow the clip's velocity field propagated into empty cells), OU noise, each
//! agent's cell and the target direction U of every cell (eq. 10–11) — then *evaluated* as tensor
//! ops; the window's mean loss E_mean + λ_var E_var is back-propagated through its W steps to θ,
//! the optimiser updates θ, and the state is detached. Between windows agents that left the grid
//! are removed and, when the density error exceeds a threshold or the clip has more agents than
//! the simulation, the population is rebalanced from the fields.

use super::loss::{step_loss, StepTarget};
use super::target::{target_directions, Stencil};
use crate::backend::{cpu_device, Precision};
use crate::error::{Error, Result};
use crate::fields::ClipFields;
use crate::io::{write_atomic, AgentRow};
use crate::params::{param_names, Params, N_PARAMS};
use crate::sim::{theta_tensor, ForceTensors, Guidance, HerdState, Model, StepDecisions, World};
use crate::synth::obstacle_map;
use burn::tensor::{Device, Tensor};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};
use std::ops::Range;
use std::path::{Path, PathBuf};

/// The optimiser.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Optimizer {
    /// Adam (β₁ 0.9, β₂ 0.999, ε 1e-8).
    Adam,
    /// The paper's normalised gradient step θ ← θ − lr · g/‖g‖.
    Normalized,
    /// The normalised step on averaged gradients, scaled by their agreement:
    /// θ ← θ − lr · (‖m‖/√s) · m/√s, m the running mean of g (β 0.98, about one epoch of 50
    /// windows), s that of ‖g‖² (β 0.999), both bias-corrected. Where successive gradients agree
    /// it steps lr along them, as the normalised step does; where they are noise about a minimum,
    /// ‖m‖/√s falls to about 0.1 and the steps to a hundredth of lr (averaging alone would not
    /// do: the sum of averaged noise random-walks as far as the noise itself).
    #[value(
        help = "The normalised step on a running mean of the gradients, scaled by how well they agree (about lr where they agree, a hundredth of it where they are noise)"
    )]
    Averaged,
}

/// Settings of a fit (the `fit` command's flags).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitConfig {
    /// Unrolled steps per gradient update (1 = the paper's greedy per-frame scheme).
    pub window: usize,
    pub epochs: usize,
    /// β of eq. 11.
    pub beta: f64,
    /// λ_var: weight of E_var.
    pub var_weight: f64,
    pub lr: f64,
    pub optimizer: Optimizer,
    /// Frames of the clip used (start..end, end exclusive).
    pub frames: Range<usize>,
    pub seed: u64,
    /// Density error Σ|ρ' − ρ| / Σρ above which the population is rebalanced.
    pub density_threshold: f64,
    /// Size of the random step taken when the gradient vanishes.
    pub zero_grad_step: f64,
    pub precision: Precision,
    /// The paper's split (§6.1): alignment parameters follow ∇E_var, the others ∇E_mean.
    /// Off: every parameter follows ∇(E_mean + λ E_var).
    pub split_gradients: bool,
    /// E_mean on cell means rather than per agent (see [`StepTarget::cell_mean`]).
    pub cell_mean: bool,
    /// The objective: the paper's E_mean + λ E_var, or field matching.
    #[serde(default)]
    pub loss: LossKind,
    /// burn's balanced gradient checkpointing (less memory for long windows, more time).
    #[serde(default)]
    pub checkpointing: bool,
    /// How each epoch's starting herd is settled (see [`settle`]).
    #[serde(default)]
    pub settle: Settle,
    /// Independent herds simulated side by side from the same fields (each its own sampling and
    /// noise); the losses are averaged over them, and `--loss ensemble` compares their mean.
    #[serde(default = "one_replica")]
    pub replicas: usize,
    /// σ (cells) of the smoothing that turns the clip's momentum into leader guidance
    /// ([`guidance_field`]).
    #[serde(default = "default_guidance_scale")]
    pub guidance_scale: f64,
    /// How the forces of eq. 3–5 are computed in the training loop (fused op by default; not
    /// written when it is the default, so checkpoints keep their bytes).
    #[serde(default, skip_serializing_if = "crate::sim::ForceKernel::is_fused")]
    pub force_kernel: crate::sim::ForceKernel,
}

fn default_guidance_scale() -> f64 {
    GUIDANCE_SCALE
}

fn one_replica() -> usize {
    1
}

/// What the fit minimises.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum LossKind {
    /// E_mean (eq. 7) + λ_var E_var (eq. 8) against the target field U (eq. 10–11).
    #[default]
    Paper,
    /// Field matching: after every step, the simulated density and momentum fields (bilinear
    /// splatting of the agents and of their velocities) against the clip's,
    /// Σ(ρ' − Kρ)² / Σ(Kρ)² + Σ‖ρ'V' − K(ρV)‖² / Σ‖K(ρV)‖², plus λ_var E_var, where K blurs the
    /// clip's box-binned fields as splatting blurs points ([`super::target::blur_like_splat`]).
    Fields,
    /// Field matching of the *expected* simulated fields: the replicas' mean fields against the
    /// clip's, minus the replicas' own spread (an unbiased estimate of ‖E[ρ'] − ρ‖², see
    /// [`ensemble_loss`]), plus λ_var E_var. Needs `replicas` ≥ 2.
    Ensemble,
}

/// Indices of the alignment parameters in the θ vector.
pub const ALIGNMENT: [usize; 3] = [6, 7, 8];

impl Default for FitConfig {
    fn default() -> Self {
        FitConfig {
            window: 4,
            epochs: 8,
            beta: 0.7,
            var_weight: 1.0,
            lr: 0.02,
            optimizer: Optimizer::Adam,
            frames: 0..0,
            seed: 0,
            density_threshold: 0.3,
            zero_grad_step: 0.02,
            precision: Precision::F32,
            split_gradients: true,
            cell_mean: false,
            loss: LossKind::Paper,
            checkpointing: false,
            settle: Settle::default(),
            replicas: 1,
            guidance_scale: GUIDANCE_SCALE,
            force_kernel: crate::sim::ForceKernel::Fused,
        }
    }
}

impl FitConfig {
    /// Checks the settings against a clip.
    pub fn check(&self, clip: &ClipFields) -> Result<()> {
        let f = clip.frames();
        if self.frames.start >= self.frames.end || self.frames.end > f {
            return Err(Error::invalid(format!(
                "--frames {}..{} is out of range: the clip has frames 0..{f}",
                self.frames.start, self.frames.end
            )));
        }
        if self.frames.end - self.frames.start < 2 {
            return Err(Error::invalid("--frames must span at least 2 frames"));
        }
        if self.loss == LossKind::Ensemble && self.replicas < 2 {
            return Err(Error::invalid(
                "--loss ensemble compares several herds: set --replicas to 2 or more",
            ));
        }
        if self.replicas == 0 || self.replicas > 64 {
            return Err(Error::invalid(format!(
                "--replicas {} is out of range 1..=64",
                self.replicas
            )));
        }
        if self.window == 0 || self.epochs == 0 {
            return Err(Error::invalid("--window and --epochs must be ≥ 1"));
        }
        check_guidance_scale(self.guidance_scale)?;
        for (name, v, lo, hi) in [
            ("--beta", self.beta, 0.0, 1.0),
            ("--var-weight", self.var_weight, 0.0, f64::INFINITY),
            ("--lr", self.lr, 1e-12, 1.0),
        ] {
            if !(v.is_finite() && v >= lo && v <= hi) {
                return Err(Error::invalid(format!("{name} {v} is out of range")));
            }
        }
        let total: f64 = (self.frames.start..self.frames.end)
            .map(|k| clip.count(k))
            .sum();
        if total < 1.0 {
            return Err(Error::invalid(
                "the clip's density is zero everywhere in the frames used: nothing to fit",
            ));
        }
        if clip.count(self.frames.start) < 1.0 {
            return Err(Error::invalid(format!(
                "frame {} of the clip holds no agents: start the fit where the herd is",
                self.frames.start
            )));
        }
        Ok(())
    }
}

/// One row of the training log.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LogRow {
    pub epoch: usize,
    /// Frame reached at the end of the window.
    pub frame: usize,
    pub e_mean: f64,
    pub e_var: f64,
    /// The field-matching loss: the objective of `--loss fields` (logged with `--loss paper`), or
    /// the ensemble objective with `--loss ensemble`.
    #[serde(default)]
    pub e_fields: f64,
    pub density_error: f64,
    pub velocity_error: f64,
    pub agents: usize,
    pub theta: [f64; N_PARAMS],
    /// Index of the clip (in the order given) the window belongs to.
    #[serde(default)]
    pub clip: usize,
}

/// The log as CSV.
pub fn log_csv(rows: &[LogRow]) -> String {
    let mut s =
        String::from("epoch,frame,e_mean,e_var,e_fields,density_error,velocity_error,agents");
    for n in param_names() {
        s.push(',');
        s.push_str(&n);
    }
    s.push_str(",clip\n");
    for r in rows {
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{}",
            r.epoch,
            r.frame,
            r.e_mean,
            r.e_var,
            r.e_fields,
            r.density_error,
            r.velocity_error,
            r.agents
        ));
        for v in r.theta {
            s.push_str(&format!(",{v}"));
        }
        s.push_str(&format!(",{}", r.clip));
        s.push('\n');
    }
    s
}

/// The model of a clip: its obstacle cells, its frame rate, and `params` (the guidance is set per
/// frame by the caller).
pub fn clip_model(params: Params, clip: &ClipFields) -> Model {
    let g = clip.grid();
    Model {
        params,
        world: World {
            obstacles: Some(obstacle_map(&g, &clip.obstacles)),
            guidance: Guidance::None,
        },
        dt: 1.0 / clip.meta.fps,
        force_kernel: crate::sim::ForceKernel::default(),
    }
}

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
    super::target::separable_filter(v, nx, ny, &w)
}

/// Checks a `--guidance-scale` value: ≥ 0, ∞ allowed.
pub fn check_guidance_scale(v: f64) -> Result<()> {
    if v.is_nan() || v < 0.0 {
        return Err(Error::invalid(format!(
            "--guidance-scale {v} is out of range: it must be ≥ 0 (or inf)"
        )));
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

fn cell_counts(clip: &ClipFields, rows: &[AgentRow]) -> (Vec<f64>, Vec<[f64; 2]>) {
    let g = clip.grid();
    let mut n = vec![0.0; g.nx * g.ny];
    let mut v = vec![[0.0; 2]; g.nx * g.ny];
    for r in rows {
        if let Some((ix, iy)) = g.cell_of([r.x, r.y]) {
            let c = iy * g.nx + ix;
            n[c] += 1.0;
            v[c][0] += r.vx;
            v[c][1] += r.vy;
        }
    }
    (n, v)
}

/// Density and velocity errors of a herd against frame `f` of the clip, by cell counts:
/// density Σ|n'_c − n_c| / Σ n_c (n = ρ·area), velocity Σ n_c ‖V'_c − V_c‖ / Σ n_c ‖V_c‖ over the
/// clip's occupied cells (V'_c = 0 where the simulation has nobody).
pub fn field_errors(clip: &ClipFields, f: usize, rows: &[AgentRow]) -> (f64, f64) {
    let g = clip.grid();
    let a = g.cell_area();
    let (n_sim, v_sum) = cell_counts(clip, rows);
    let (mut dn, mut tn, mut dv, mut tv) = (0.0, 0.0, 0.0, 0.0);
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            let c = iy * g.nx + ix;
            let n = clip.density[[f, iy, ix]] as f64 * a;
            dn += (n_sim[c] - n).abs();
            tn += n;
            if n > 0.0 {
                let v = [
                    clip.velocity[[f, iy, ix, 0]] as f64,
                    clip.velocity[[f, iy, ix, 1]] as f64,
                ];
                let vs = if n_sim[c] > 0.0 {
                    [v_sum[c][0] / n_sim[c], v_sum[c][1] / n_sim[c]]
                } else {
                    [0.0, 0.0]
                };
                dv += n * ((vs[0] - v[0]).powi(2) + (vs[1] - v[1]).powi(2)).sqrt();
                tv += n * (v[0] * v[0] + v[1] * v[1]).sqrt();
            }
        }
    }
    (
        if tn > 0.0 { dn / tn } else { 0.0 },
        if tv > 0.0 { dv / tv } else { 0.0 },
    )
}

fn new_agent(
    clip: &ClipFields,
    f: usize,
    ix: usize,
    iy: usize,
    id: u64,
    speed: f64,
    rng: &mut impl Rng,
) -> AgentRow {
    let g = clip.grid();
    let c = g.centre(ix, iy);
    let h = g.cell_size / 2.0;
    let x = c[0] + (rng.gen::<f64>() * 2.0 - 1.0) * h * 0.999;
    let y = c[1] + (rng.gen::<f64>() * 2.0 - 1.0) * h * 0.999;
    let v = [
        clip.velocity[[f, iy, ix, 0]] as f64,
        clip.velocity[[f, iy, ix, 1]] as f64,
    ];
    let l = (v[0] * v[0] + v[1] * v[1]).sqrt();
    let d = if l > 1e-9 {
        // The cell's mean direction, spread by the clip's direction variance.
        let spread = (clip.dir_variance[[f, iy, ix]] as f64).max(0.0).sqrt();
        let z: f64 = rng.sample(StandardNormal);
        let a = v[1].atan2(v[0]) + spread * z;
        [a.cos(), a.sin()]
    } else {
        let a = rng.gen::<f64>() * std::f64::consts::TAU;
        [a.cos(), a.sin()]
    };
    AgentRow {
        id,
        x,
        y,
        vx: speed * d[0],
        vy: speed * d[1],
    }
}

/// The initial herd of frame `f`: round(Σ ρ·area) agents, allocated to cells in proportion to
/// their expected counts (integer parts, then the largest remainders), uniform inside the cell,
/// heading along the cell's mean velocity with a normal angular spread of the cell's direction
/// variance (random where the velocity is zero), speed from the speed model.
pub fn init_herd(
    clip: &ClipFields,
    f: usize,
    speed: &crate::params::SpeedModel,
    rng: &mut impl Rng,
) -> Vec<AgentRow> {
    let g = clip.grid();
    let a = g.cell_area();
    let mut want: Vec<(usize, usize, f64)> = Vec::new();
    for iy in 0..g.ny {
        for ix in 0..g.nx {
            let n = clip.density[[f, iy, ix]] as f64 * a;
            if n > 0.0 && clip.obstacles[[iy, ix]] == 0 {
                want.push((ix, iy, n));
            }
        }
    }
    let total = want.iter().map(|w| w.2).sum::<f64>().round() as usize;
    let mut counts: Vec<usize> = want.iter().map(|w| w.2.floor() as usize).collect();
    let mut rest: Vec<(f64, usize)> = want
        .iter()
        .enumerate()
        .map(|(k, w)| (w.2 - w.2.floor(), k))
        .collect();
    rest.sort_by(|p, q| q.0.total_cmp(&p.0).then(p.1.cmp(&q.1)));
    let have: usize = counts.iter().sum();
    for &(_, k) in rest.iter().take(total.saturating_sub(have)) {
        counts[k] += 1;
    }
    let mut rows = Vec::with_capacity(total);
    for (k, &(ix, iy, _)) in want.iter().enumerate() {
        for _ in 0..counts[k] {
            let z: f64 = rng.sample(StandardNormal);
            let s = (speed.mean + speed.stationary_std() * z).clamp(0.0, speed.max);
            let id = rows.len() as u64;
            rows.push(new_agent(clip, f, ix, iy, id, s, rng));
        }
    }
    rows
}

/// Between windows: drop agents outside the grid; when the density error exceeds `threshold`,
/// move agents from the most over-filled cells to the most under-filled ones; and add agents where
/// the clip holds more than the simulation (entries), seeded from the fields.
pub fn population_control(
    clip: &ClipFields,
    f: usize,
    mut rows: Vec<AgentRow>,
    threshold: f64,
    speed: &crate::params::SpeedModel,
    next_id: &mut u64,
    rng: &mut impl Rng,
) -> Vec<AgentRow> {
    let g = clip.grid();
    rows.retain(|r| g.cell_of([r.x, r.y]).is_some());
    let a = g.cell_area();
    let target: Vec<f64> = (0..g.ny * g.nx)
        .map(|c| clip.density[[f, c / g.nx, c % g.nx]] as f64 * a)
        .collect();
    let total = target.iter().sum::<f64>().round() as usize;
    let (err, _) = field_errors(clip, f, &rows);
    let rebalance = err > threshold;
    let (mut n_sim, _) = cell_counts(clip, &rows);
    if rebalance {
        // Remove from surplus cells (largest surplus first) while the surplus is ≥ 1.
        while let Some((c, s)) = (0..n_sim.len())
            .map(|c| (c, n_sim[c] - target[c]))
            .max_by(|p, q| p.1.total_cmp(&q.1).then(q.0.cmp(&p.0)))
        {
            if s < 1.0 || rows.len() <= total {
                break;
            }
            let members: Vec<usize> = rows
                .iter()
                .enumerate()
                .filter(|(_, r)| g.cell_of([r.x, r.y]).map(|(ix, iy)| iy * g.nx + ix) == Some(c))
                .map(|(i, _)| i)
                .collect();
            let k = members[rng.gen_range(0..members.len())];
            rows.remove(k);
            n_sim[c] -= 1.0;
        }
    }
    // Add to deficit cells (largest first) while agents are missing overall.
    while rows.len() < total {
        let Some((c, d)) = (0..n_sim.len())
            .filter(|&c| clip.obstacles[[c / g.nx, c % g.nx]] == 0)
            .map(|c| (c, target[c] - n_sim[c]))
            .max_by(|p, q| p.1.total_cmp(&q.1).then(q.0.cmp(&p.0)))
        else {
            break;
        };
        if d <= 0.0 {
            break;
        }
        let z: f64 = rng.sample(StandardNormal);
        let s = (speed.mean + speed.stationary_std() * z).clamp(0.0, speed.max);
        rows.push(new_agent(clip, f, c % g.nx, c / g.nx, *next_id, s, rng));
        *next_id += 1;
        n_sim[c] += 1.0;
    }
    rows
}

/// Plans one step without gradient: leader guidance from frame `f`, perception, roles and noise,
/// each agent's cell and the target directions toward frame `f + 1`.
#[allow(clippy::too_many_arguments)]
pub fn plan_step(
    model: &mut Model,
    clip: &ClipFields,
    guidance: &[Guidance],
    stencil: &Stencil,
    beta: f64,
    cell_mean: bool,
    state: &HerdState,
    f: usize,
    rng: &mut impl Rng,
) -> Result<(StepDecisions, StepTarget)> {
    let snap = state.snapshot()?;
    model.world.guidance = guidance[f].clone();
    let dec = model.decide(&snap, rng);
    let g = clip.grid();
    let cell = snap
        .pos
        .iter()
        .map(|p| g.cell_of(*p).map_or(-1, |(ix, iy)| (iy * g.nx + ix) as i64))
        .collect();
    let u = target_directions(clip, stencil, beta, &state.x, &state.y, &snap.pos, f + 1)?;
    let s = clip
        .dir_variance
        .index_axis(ndarray::Axis(0), f + 1)
        .iter()
        .map(|&v| v as f64)
        .collect();
    let follower = dec.leader.iter().map(|&l| !l).collect();
    Ok((
        dec,
        StepTarget {
            cell,
            follower,
            u,
            s,
            cell_mean,
        },
    ))
}

/// Loss of one window: mean over its steps of a·E_mean + b·E_var with `(a, b)` = `weights`. Returns the end state, the loss
/// tensor and the mean E_mean and E_var values.
pub fn window_loss(
    model: &Model,
    f: &ForceTensors,
    mut state: HerdState,
    plans: &[(StepDecisions, StepTarget)],
    (mean_weight, var_weight): (f64, f64),
) -> Result<(HerdState, Tensor<1>, f64, f64)> {
    let mut total: Option<Tensor<1>> = None;
    let (mut em, mut ev) = (0.0, 0.0);
    for (dec, tgt) in plans {
        state = model.step(f, &state, dec)?;
        let l = step_loss(&state.hx, &state.hy, tgt);
        em += crate::sim::read_vec(&l.e_mean.clone().detach())?[0];
        ev += crate::sim::read_vec(&l.e_var.clone().detach())?[0];
        let step = l.e_mean.mul_scalar(mean_weight) + l.e_var.mul_scalar(var_weight);
        total = Some(match total {
            None => step,
            Some(t) => t + step,
        });
    }
    let k = plans.len().max(1) as f64;
    let total = total
        .ok_or_else(|| Error::invalid("empty window"))?
        .div_scalar(k);
    Ok((state, total, em / k, ev / k))
}

/// Optimiser state: Adam's moments; the averaged step's mean gradient (`m`) and mean ‖g‖²
/// (`v[0]`); nothing for the normalised step.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize, Default)]
pub struct OptState {
    pub m: [f64; N_PARAMS],
    pub v: [f64; N_PARAMS],
    pub t: u64,
}

/// One optimiser step on `theta` with gradient `g` and step size `lr` (then clamped to the
/// parameters' ranges); a vanishing gradient takes `cfg.zero_grad_step` in a random direction.
pub fn update(
    theta: &mut [f64; N_PARAMS],
    g: &[f64; N_PARAMS],
    opt: &mut OptState,
    cfg: &FitConfig,
    lr: f64,
    rng: &mut impl Rng,
) {
    let norm = g.iter().map(|x| x * x).sum::<f64>().sqrt();
    if norm.is_nan() || norm <= 1e-12 || !norm.is_finite() {
        // Flat region (§6.1): a fixed-size step in a random direction.
        let d: Vec<f64> = (0..N_PARAMS).map(|_| rng.sample(StandardNormal)).collect();
        let l = d.iter().map(|x| x * x).sum::<f64>().sqrt().max(1e-12);
        for (t, x) in theta.iter_mut().zip(d) {
            *t += cfg.zero_grad_step * x / l;
        }
    } else {
        match cfg.optimizer {
            Optimizer::Normalized => {
                for (t, x) in theta.iter_mut().zip(g) {
                    *t -= lr * x / norm;
                }
            }
            Optimizer::Averaged => {
                let (b1, b2): (f64, f64) = (0.98, 0.999);
                opt.t += 1;
                let (c1, c2) = (1.0 - b1.powi(opt.t as i32), 1.0 - b2.powi(opt.t as i32));
                // One running mean of ‖g‖² for all parameters (kept in v[0]): each parameter
                // moves by its share of the averaged gradient, as in the normalised step.
                opt.v[0] = b2 * opt.v[0] + (1.0 - b2) * norm * norm;
                let rms = (opt.v[0] / c2).sqrt();
                for (m, x) in opt.m.iter_mut().zip(g) {
                    *m = b1 * *m + (1.0 - b1) * x;
                }
                // Signal-to-noise of the averaged gradient, ‖m‖/√s: 1 for a steady gradient,
                // about √((1 − β₁)/(1 + β₁)) = 0.1 for pure noise.
                let snr = opt.m.iter().map(|m| (m / c1).powi(2)).sum::<f64>().sqrt() / rms;
                for (t, m) in theta.iter_mut().zip(&opt.m) {
                    *t -= lr * snr * (m / c1) / rms;
                }
            }
            Optimizer::Adam => {
                let (b1, b2, eps): (f64, f64, f64) = (0.9, 0.999, 1e-8);
                opt.t += 1;
                let (c1, c2) = (1.0 - b1.powi(opt.t as i32), 1.0 - b2.powi(opt.t as i32));
                for p in 0..N_PARAMS {
                    opt.m[p] = b1 * opt.m[p] + (1.0 - b1) * g[p];
                    opt.v[p] = b2 * opt.v[p] + (1.0 - b2) * g[p] * g[p];
                    theta[p] -= lr * (opt.m[p] / c1) / ((opt.v[p] / c2).sqrt() + eps);
                }
            }
        }
    }
    Params::clamp_vec(theta);
}

/// Checkpoint of a fit, written after every epoch.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checkpoint {
    pub schema: String,
    pub epochs_done: usize,
    pub theta: [f64; N_PARAMS],
    pub opt: OptState,
    pub log: Vec<LogRow>,
    /// The settings and start the run was made with (a resume must match).
    pub config: FitConfig,
    pub start: [f64; N_PARAMS],
}

const CHECKPOINT_SCHEMA: &str = "herdfit.checkpoint/1";

/// Result of a fit.
#[derive(Clone, Debug)]
pub struct FitResult {
    pub params: Params,
    pub start: [f64; N_PARAMS],
    pub log: Vec<LogRow>,
}

/// Where checkpoints go.
pub struct CheckpointDir {
    pub dir: PathBuf,
    pub resume: bool,
}

impl CheckpointDir {
    fn file(&self) -> PathBuf {
        self.dir.join("checkpoint.json")
    }
}

fn epoch_rng(seed: u64, epoch: usize) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(seed ^ (epoch as u64 + 1).wrapping_mul(0x9E37_79B9_7F4A_7C15))
}

/// Runs the fit. `progress(epoch, frame, e_mean, ms_per_step)` is called after every window.
pub fn fit(
    clip: &ClipFields,
    init: &Params,
    cfg: &FitConfig,
    ckpt: Option<&CheckpointDir>,
    progress: impl FnMut(usize, usize, f64, f64),
) -> Result<FitResult> {
    fit_inner(&[clip], init, cfg, ckpt, true, progress)
}

/// [`fit`] to several clips of one kind of herd at once (paper §7.6): every epoch walks through
/// the clips in turn, each with its own herds, obstacles, frame rate and speed model, and one set
/// of 12 parameters learns from all of them. `cfg.frames` applies to every clip. The exported
/// speed model is the first clip's.
pub fn fit_clips(
    clips: &[&ClipFields],
    init: &Params,
    cfg: &FitConfig,
    ckpt: Option<&CheckpointDir>,
    progress: impl FnMut(usize, usize, f64, f64),
) -> Result<FitResult> {
    fit_inner(clips, init, cfg, ckpt, true, progress)
}

/// The loss of a parameter set on a clip without learning: one epoch of the fit's schedule
/// (epoch-0 herd and noise) with no updates; returns the mean E_mean, E_var and field-matching
/// loss over its windows. Comparing two parameter sets this way uses the same herd, noise and
/// population control seed.
pub fn loss_of(clips: &[&ClipFields], params: &Params, cfg: &FitConfig) -> Result<(f64, f64, f64)> {
    let one = FitConfig {
        epochs: 1,
        ..cfg.clone()
    };
    let r = fit_inner(clips, params, &one, None, false, |_, _, _, _| {})?;
    let n = r.log.len().max(1) as f64;
    Ok((
        r.log.iter().map(|x| x.e_mean).sum::<f64>() / n,
        r.log.iter().map(|x| x.e_var).sum::<f64>() / n,
        r.log.iter().map(|x| x.e_fields).sum::<f64>() / n,
    ))
}

fn fit_inner(
    clips: &[&ClipFields],
    init: &Params,
    cfg: &FitConfig,
    ckpt: Option<&CheckpointDir>,
    learn: bool,
    mut progress: impl FnMut(usize, usize, f64, f64),
) -> Result<FitResult> {
    if clips.is_empty() {
        return Err(Error::invalid("no clip to fit"));
    }
    for clip in clips {
        cfg.check(clip)?;
    }
    init.validate()?;
    let device = cpu_device(cfg.precision)?;
    // Long windows can trade time for memory with burn's balanced gradient checkpointing.
    let ad: Device = if cfg.checkpointing {
        device.clone().autodiff().gradient_checkpointing()
    } else {
        device.clone().autodiff()
    };
    let mut params = init.clone();
    // Stage 2 (§6.2) first: the forces are learnt with each clip's own speeds; the exported speed
    // model is the first clip's.
    params.speed = clips[0].speed_model(&init.speed);
    let per_clip: Vec<(Vec<Guidance>, Stencil)> = clips
        .iter()
        .map(|clip| {
            (
                guidance_fields(clip, cfg.guidance_scale),
                Stencil::new(clip),
            )
        })
        .collect();
    let start = init.to_vec();
    let (mut theta, mut opt, mut log, first_epoch) = match ckpt {
        Some(c) if c.resume && c.file().exists() => {
            let text = std::fs::read_to_string(c.file())
                .map_err(|e| Error::file(c.file(), format!("cannot read: {e}")))?;
            let k: Checkpoint = serde_json::from_str(&text).map_err(|e| {
                Error::file(c.file(), format!("not a {CHECKPOINT_SCHEMA} file: {e}"))
            })?;
            if k.config != *cfg || k.start != start {
                return Err(Error::file(
                    c.file(),
                    "was written by a fit with other settings or another start; resume with the same flags",
                ));
            }
            (k.theta, k.opt, k.log, k.epochs_done)
        }
        _ => (
            start,
            OptState {
                m: [0.0; N_PARAMS],
                v: [0.0; N_PARAMS],
                t: 0,
            },
            Vec::new(),
            0,
        ),
    };
    let (a, b) = (cfg.frames.start, cfg.frames.end);
    let replicas = cfg.replicas.max(1);
    for epoch in first_epoch..cfg.epochs {
        let mut rng = epoch_rng(cfg.seed, epoch);
        for (ci, (clip, (guidance, stencil))) in clips.iter().zip(&per_clip).enumerate() {
            let mut speed_params = params.clone();
            speed_params.speed = clip.speed_model(&init.speed);
            let mut model = clip_model(speed_params.with_vec(&theta), clip);
            model.force_kernel = cfg.force_kernel;
            // K independent herds (replicas) from the same fields, side by side.
            let mut herds: Vec<Vec<AgentRow>> = Vec::with_capacity(replicas);
            for _ in 0..replicas {
                herds.push(start_herd(&model, clip, a, &cfg.settle, &mut rng, &device)?);
            }
            let mut next_ids: Vec<u64> = herds.iter().map(|h| h.len() as u64).collect();
            let mut f = a;
            while f + 1 < b {
                let w = cfg.window.min(b - 1 - f);
                let t0 = std::time::Instant::now();
                for (rows, next_id) in herds.iter_mut().zip(next_ids.iter_mut()) {
                    if rows.is_empty() {
                        *rows = population_control(
                            clip,
                            f,
                            std::mem::take(rows),
                            0.0,
                            &model.params.speed,
                            next_id,
                            &mut rng,
                        );
                    }
                }
                if herds.iter().all(|h| h.is_empty()) {
                    f += w;
                    continue;
                }
                // Weights of (E_mean, E_var) in the back-propagated loss: the paper's split takes
                // E_var's gradient in a second pass; field matching replaces E_mean.
                let weights = match (cfg.loss, cfg.split_gradients) {
                    (LossKind::Fields | LossKind::Ensemble, _) => (0.0, cfg.var_weight),
                    (LossKind::Paper, true) => (1.0, 0.0),
                    (LossKind::Paper, false) => (1.0, cfg.var_weight),
                };
                let th = theta_tensor(&theta, &ad).require_grad();
                let forces = ForceTensors::new(&th, &model.params.constants);
                let mut total: Option<Tensor<1>> = None;
                let (mut em, mut ev, mut ef) = (0.0, 0.0, 0.0);
                let mut all_plans = Vec::with_capacity(replicas);
                let mut ends = Vec::with_capacity(replicas);
                // Per step, each replica's end-of-step state (for the ensemble loss).
                let mut per_step: Vec<Vec<HerdState>> = vec![Vec::new(); w];
                let live: Vec<usize> = (0..replicas).filter(|&r| !herds[r].is_empty()).collect();
                let kr = live.len() as f64;
                for &r in &live {
                    let mut state = HerdState::from_rows(&herds[r], &ad);
                    let mut plans = Vec::with_capacity(w);
                    for (s, slot) in per_step.iter_mut().enumerate() {
                        let plan = plan_step(
                            &mut model,
                            clip,
                            guidance,
                            stencil,
                            cfg.beta,
                            cfg.cell_mean,
                            &state,
                            f + s,
                            &mut rng,
                        )?;
                        let (next, loss, e_m, e_v) = window_loss(
                            &model,
                            &forces,
                            state,
                            std::slice::from_ref(&plan),
                            weights,
                        )?;
                        plans.push(plan);
                        state = next;
                        em += e_m / (w as f64 * kr);
                        ev += e_v / (w as f64 * kr);
                        let loss = match cfg.loss {
                            LossKind::Fields => {
                                let fl = fields_loss(clip, &state, f + s + 1)?;
                                ef += crate::sim::read_vec(&fl.clone().detach())?[0]
                                    / (w as f64 * kr);
                                loss + fl
                            }
                            LossKind::Ensemble => {
                                slot.push(state.clone());
                                loss
                            }
                            LossKind::Paper => {
                                // Logged only: evaluated off the autodiff graph.
                                let fl = fields_loss(clip, &state.clone().detach(), f + s + 1)?;
                                ef += crate::sim::read_vec(&fl)?[0] / (w as f64 * kr);
                                loss
                            }
                        };
                        add(&mut total, loss.div_scalar(kr));
                    }
                    all_plans.push(plans);
                    ends.push(state);
                }
                if cfg.loss == LossKind::Ensemble {
                    for (s, states) in per_step.iter().enumerate() {
                        let l = ensemble_loss(clip, states, f + s + 1)?;
                        ef += crate::sim::read_vec(&l.clone().detach())?[0] / w as f64;
                        add(&mut total, l);
                    }
                }
                let loss = total
                    .ok_or_else(|| Error::invalid("empty window"))?
                    .div_scalar(w as f64);
                let grad_of = |loss: Tensor<1>, th: &Tensor<1>| -> Result<[f64; N_PARAMS]> {
                    let grads = loss.backward();
                    let gv = th
                        .grad(&grads)
                        .map(|t| crate::sim::read_vec(&t))
                        .transpose()?
                        .unwrap_or_else(|| vec![0.0; N_PARAMS]);
                    let mut g = [0.0; N_PARAMS];
                    g.copy_from_slice(&gv);
                    Ok(g)
                };
                let mut garr = grad_of(loss, &th)?;
                if cfg.split_gradients && cfg.loss == LossKind::Paper {
                    // Pass 2 (§6.1): the alignment parameters learn from E_var alone, on the same
                    // (replayed) decisions and targets.
                    let th2 = theta_tensor(&theta, &ad).require_grad();
                    let forces2 = ForceTensors::new(&th2, &model.params.constants);
                    let mut total2: Option<Tensor<1>> = None;
                    for (k, &r) in live.iter().enumerate() {
                        let mut s2 = HerdState::from_rows(&herds[r], &ad);
                        for (dec, tgt) in &all_plans[k] {
                            s2 = model.step(&forces2, &s2, dec)?;
                            let l = step_loss(&s2.hx, &s2.hy, tgt).e_var;
                            add(&mut total2, l.div_scalar(kr));
                        }
                    }
                    let loss2 = total2
                        .ok_or_else(|| Error::invalid("empty window"))?
                        .div_scalar(w as f64);
                    let gvar = grad_of(loss2, &th2)?;
                    for p in ALIGNMENT {
                        garr[p] = cfg.var_weight * gvar[p];
                    }
                }
                if learn {
                    // Learning rate decays linearly to 10 % over the epochs.
                    let lr = cfg.lr * (1.0 - 0.9 * epoch as f64 / cfg.epochs.max(1) as f64);
                    update(&mut theta, &garr, &mut opt, cfg, lr, &mut rng);
                }
                model.params = model.params.with_vec(&theta);
                f += w;
                let (mut de, mut ve, mut agents) = (0.0, 0.0, 0usize);
                for (k, &r) in live.iter().enumerate() {
                    let ids: Vec<u64> = herds[r].iter().map(|x| x.id).collect();
                    let rows = ends[k].clone().detach().rows(&ids)?;
                    herds[r] = population_control(
                        clip,
                        f,
                        rows,
                        cfg.density_threshold,
                        &model.params.speed,
                        &mut next_ids[r],
                        &mut rng,
                    );
                    let (d, v) = field_errors(clip, f, &herds[r]);
                    de += d / kr;
                    ve += v / kr;
                    agents += herds[r].len();
                }
                log.push(LogRow {
                    epoch,
                    frame: f,
                    e_mean: em,
                    e_var: ev,
                    e_fields: ef,
                    density_error: de,
                    velocity_error: ve,
                    agents: agents / live.len(),
                    theta,
                    clip: ci,
                });
                progress(epoch, f, em, t0.elapsed().as_secs_f64() * 1e3 / w as f64);
            }
        }
        if let Some(c) = ckpt {
            let k = Checkpoint {
                schema: CHECKPOINT_SCHEMA.into(),
                epochs_done: epoch + 1,
                theta,
                opt: opt.clone(),
                log: log.clone(),
                config: cfg.clone(),
                start,
            };
            let text = serde_json::to_string(&k)
                .map_err(|e| Error::Internal(format!("serialising checkpoint: {e}")))?;
            write_atomic(&c.file(), text.as_bytes())?;
        }
    }
    let mut out = params.with_vec(&theta);
    out.speed = params.speed.clone();
    Ok(FitResult {
        params: out,
        start,
        log,
    })
}

/// Simulates the frames `range` of the clip from its first frame's fields with `params`
/// (leaders following the clip's velocity field, no population control) and returns the mean
/// density and velocity errors over the frames after the first. `guidance` holds the leaders'
/// guidance of every frame ([`guidance_fields`]).
pub fn evaluate(
    clip: &ClipFields,
    params: &Params,
    range: Range<usize>,
    seed: u64,
    precision: Precision,
    settle: &Settle,
    guidance: &[Guidance],
) -> Result<(f64, f64)> {
    let device = cpu_device(precision)?;
    let mut model = clip_model(params.clone(), clip);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let rows = start_herd(&model, clip, range.start, settle, &mut rng, &device)?;
    if rows.is_empty() {
        return Err(Error::invalid("the first frame holds no agents"));
    }
    let ids: Vec<u64> = rows.iter().map(|r| r.id).collect();
    let theta = theta_tensor(&params.to_vec(), &device);
    let f = ForceTensors::new(&theta, &params.constants);
    let mut state = HerdState::from_rows(&rows, &device);
    let (mut de, mut ve, mut n): (f64, f64, f64) = (0.0, 0.0, 0.0);
    let last = range.end.saturating_sub(1);
    for (fr, lead) in guidance.iter().enumerate().take(last).skip(range.start) {
        let snap = state.snapshot()?;
        model.world.guidance = lead.clone();
        let dec = model.decide(&snap, &mut rng);
        state = model.step(&f, &state, &dec)?;
        let (d, v) = field_errors(clip, fr + 1, &state.rows(&ids)?);
        de += d;
        ve += v;
        n += 1.0;
    }
    Ok((de / n.max(1.0), ve / n.max(1.0)))
}

/// Writes the training log CSV atomically.
pub fn write_log(path: &Path, rows: &[LogRow]) -> Result<()> {
    write_atomic(path, log_csv(rows).as_bytes())
}

/// Field-matching loss of a state against frame `f` of the clip:
/// Σ(ρ' − Kρ)² / Σ(Kρ)² + Σ‖ρ'V' − K(ρV)‖² / Σ‖K(ρV)‖² with ρ' and ρ'V' by bilinear
/// splatting and K the blur that splatting applies to points uniform in a cell
/// ([`super::target::blur_like_splat`]), so that a herd matching the clip scores 0 on average.
pub fn fields_loss(clip: &ClipFields, state: &HerdState, f: usize) -> Result<Tensor<1>> {
    let ([rho, mx, my], norm_d, norm_m) = field_targets(clip, f, &state.x.device())?;
    let [rho_s, mx_s, my_s] = splatted_fields(state, &clip.grid())?;
    let ed = (rho_s - rho).square().sum().div_scalar(norm_d);
    let em = ((mx_s - mx).square() + (my_s - my).square())
        .sum()
        .div_scalar(norm_m);
    Ok(ed + em)
}

/// The clip's splat-comparable density and momentum of frame `f`
/// ([`super::target::splat_comparable_targets`]) and their normalisers Σρ², Σ‖m‖².
fn field_targets(
    clip: &ClipFields,
    f: usize,
    device: &Device,
) -> Result<([Tensor<1>; 3], f64, f64)> {
    let [rho, mx, my] = super::target::splat_comparable_targets(clip, f, device);
    let norm_d = crate::sim::read_vec(&rho.clone().square().sum())?[0].max(1e-12);
    let norm_m =
        crate::sim::read_vec(&(mx.clone().square() + my.clone().square()).sum())?[0].max(1e-12);
    Ok(([rho, mx, my], norm_d, norm_m))
}

/// A herd's density and momentum fields by bilinear splatting (differentiable in positions,
/// headings and speeds).
fn splatted_fields(state: &HerdState, g: &crate::fields::Grid) -> Result<[Tensor<1>; 3]> {
    use super::target::splat;
    let snap = state.snapshot()?;
    let vx = state.hx.clone() * state.speed.clone();
    let vy = state.hy.clone() * state.speed.clone();
    Ok([
        splat(&state.x, &state.y, &snap.pos, g, None),
        splat(&state.x, &state.y, &snap.pos, g, Some(&vx)),
        splat(&state.x, &state.y, &snap.pos, g, Some(&vy)),
    ])
}

/// How a herd initialised from fields is settled (see [`settle`]; off by default).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Settle {
    /// Iterations (0: no settling).
    pub iterations: usize,
    /// Step per unit force (s²): an agent moves by `eta · |F|` BL …
    pub eta: f64,
    /// … at most this many BL per iteration.
    pub max_move: f64,
}

impl Settle {
    /// `iterations` iterations with the default step sizes.
    pub fn with_iterations(iterations: usize) -> Self {
        Settle {
            iterations,
            ..Default::default()
        }
    }
}

impl Default for Settle {
    fn default() -> Self {
        Settle {
            iterations: 0,
            eta: 0.01,
            max_move: 0.1,
        }
    }
}

/// Settles a herd initialised from fields into the model's own spacing before it is simulated:
/// each iteration moves every agent along its cohesion + avoidance + obstacle force F of eq. 3
/// (alignment left out: it turns headings, it does not place agents) by `eta·|F|`, at most
/// `max_move`, keeping it inside its grid cell (cell counts unchanged), headings unchanged. No
/// gradient: this chooses the starting positions, as perception chooses neighbour lists.
///
/// Fields say how many agents a cell holds, not where in the cell they stand. Sampled uniformly,
/// neighbours sit far from the balance of cohesion and avoidance that a moving herd keeps, and
/// the first steps of a simulation turn their headings whatever the parameters: on the demo's
/// synthetic clip, the true parameters started from the fields of frame 60 lose polarization
/// (0.973 → 0.949 in 10 frames) while the clip keeps 0.975, and started from the clip's own
/// positions they do not; settled (200 iterations) the run stays at 0.971–0.974
/// (`cargo run --release --example init_bias -- out/demo/synthetic 60 200`). The price: a static
/// balance packs agents tighter than a moving herd does, and the held-out density error of the
/// true parameters rises (0.24 → 0.44, RESULTS.md §1, held-out validation). Off by default.
pub fn settle(
    model: &Model,
    clip: &ClipFields,
    rows: &mut [AgentRow],
    cfg: &Settle,
    device: &Device,
) -> Result<()> {
    if rows.is_empty() || cfg.iterations == 0 {
        return Ok(());
    }
    let g = clip.grid();
    let h = g.cell_size / 2.0 * 0.999;
    let bounds: Vec<[f64; 4]> = rows
        .iter()
        .map(|r| match g.cell_of([r.x, r.y]) {
            Some((ix, iy)) => {
                let c = g.centre(ix, iy);
                [c[0] - h, c[1] - h, c[0] + h, c[1] + h]
            }
            None => [r.x, r.y, r.x, r.y],
        })
        .collect();
    let mut theta = model.params.to_vec();
    theta[ALIGNMENT[0]] = 0.0;
    let th = theta_tensor(&theta, device);
    let forces = ForceTensors::new(&th, &model.params.constants);
    let mut quiet = model.clone();
    quiet.world.guidance = Guidance::None;
    // Perception draws no random numbers that matter here (ξ is unused).
    let mut rng = ChaCha8Rng::seed_from_u64(0);
    let n = rows.len();
    for _ in 0..cfg.iterations {
        let state = HerdState::from_rows(rows, device);
        let dec = quiet.decide(&state.snapshot()?, &mut rng);
        let (fx, fy) = quiet.forces(&forces, &state, &dec);
        let fx = crate::sim::read_vec(&fx.reshape([n]))?;
        let fy = crate::sim::read_vec(&fy.reshape([n]))?;
        for (i, r) in rows.iter_mut().enumerate() {
            let b = bounds[i];
            let fl = (fx[i] * fx[i] + fy[i] * fy[i]).sqrt();
            if !(fl > 1e-12 && fl.is_finite()) {
                continue;
            }
            let k = (cfg.eta * fl).min(cfg.max_move) / fl;
            r.x = (r.x + k * fx[i]).clamp(b[0], b[2]);
            r.y = (r.y + k * fy[i]).clamp(b[1], b[3]);
        }
    }
    Ok(())
}

/// The herd a simulation of frame `f` starts from: [`init_herd`] then [`settle`] with `model`.
pub fn start_herd(
    model: &Model,
    clip: &ClipFields,
    f: usize,
    settle_cfg: &Settle,
    rng: &mut impl Rng,
    device: &Device,
) -> Result<Vec<AgentRow>> {
    let mut rows = init_herd(clip, f, &model.params.speed, rng);
    settle(model, clip, &mut rows, settle_cfg, device)?;
    Ok(rows)
}

/// Adds a loss term to a running total (the first term starts it).
pub(crate) fn add(total: &mut Option<Tensor<1>>, l: Tensor<1>) {
    *total = Some(match total.take() {
        None => l,
        Some(t) => t + l,
    });
}

/// The ensemble objective for one frame: with ρ_k, m_k the density and momentum fields splatted
/// from replica k (k = 1..K) and ρ̄, m̄ their means,
///
/// L = [‖ρ̄ − ρ‖² − S_ρ / K] / Σρ² + [‖m̄ − m‖² − S_m / K] / Σ‖m‖²,
/// S = Σ_k ‖x_k − x̄‖² / (K − 1),
///
/// an unbiased estimate of ‖E[ρ'] − ρ‖² / Σρ² + … : the replicas' own spread is subtracted, so a
/// parameter set is not rewarded for making the herd less variable (which matching one
/// simulated herd to one clip does: E‖ρ' − ρ‖² = ‖E ρ' − ρ‖² + Var ρ' + …; RESULTS.md §1).
pub fn ensemble_loss(clip: &ClipFields, states: &[HerdState], f: usize) -> Result<Tensor<1>> {
    let k = states.len();
    if k < 2 {
        return Err(Error::invalid(
            "the ensemble loss needs at least 2 replicas",
        ));
    }
    let ([rho, mx, my], norm_d, norm_m) = field_targets(clip, f, &states[0].x.device())?;
    let g = clip.grid();
    let fields = states
        .iter()
        .map(|st| splatted_fields(st, &g))
        .collect::<Result<Vec<_>>>()?;
    let kf = k as f64;
    // k ≥ 2: sums start from zeros shaped like the first replica's.
    let mean = |i: usize| {
        fields
            .iter()
            .fold(fields[0][i].zeros_like(), |a, x| a + x[i].clone())
            .div_scalar(kf)
    };
    let (rb, mxb, myb) = (mean(0), mean(1), mean(2));
    let spread = |i: usize, m: &Tensor<1>| {
        fields
            .iter()
            .map(|x| (x[i].clone() - m.clone()).square().sum())
            .fold(fields[0][i].zeros_like().sum(), |a, b| a + b)
            .div_scalar((kf - 1.0) * kf)
    };
    let sd = spread(0, &rb);
    let sm = spread(1, &mxb) + spread(2, &myb);
    let ed = ((rb - rho).square().sum() - sd).div_scalar(norm_d);
    let em = ((mxb - mx).square().sum() + (myb - my).square().sum() - sm).div_scalar(norm_m);
    Ok(ed + em)
}
