//! Starting and maintaining a herd from a clip's fields: the initial herd of a frame (counts per
//! cell, headings from the cell's velocity and direction variance, speeds from the speed model),
//! settling it into the model's own spacing, and population control between fit windows.

use crate::data::agents::AgentRow;
use crate::data::ClipFields;
use crate::error::{Error, Result};
use crate::herd::params::{SpeedModel, ALIGNMENT};
use crate::herd::sim::{theta_tensor, ForceTensors, Guidance, HerdState, Model};
use crate::measure::fields::{cell_counts, field_errors};
use burn::tensor::Device;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::{Deserialize, Serialize};

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
    speed: &crate::herd::params::SpeedModel,
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
    speed: &crate::herd::params::SpeedModel,
    next_id: &mut u64,
    rng: &mut impl Rng,
) -> Vec<AgentRow> {
    let g = clip.grid();
    rows.retain(|r| g.cell_of([r.x, r.y]).is_some());
    let target = cell_targets(clip, f);
    let total = target.iter().sum::<f64>().round() as usize;
    let (err, _) = field_errors(clip, f, &rows);
    let rebalance = err > threshold;
    let (mut n_sim, _) = cell_counts(clip, &rows);
    if rebalance {
        // Remove from surplus cells (largest surplus first) while the surplus is ≥ 1.
        while let Some((c, s)) = largest(0..n_sim.len(), |c| n_sim[c] - target[c]) {
            if s < 1.0 || rows.len() <= total {
                break;
            }
            let k = random_member(&rows, &g, c, rng);
            rows.remove(k);
            n_sim[c] -= 1.0;
        }
    }
    // Add to deficit cells (largest first) while agents are missing overall.
    while rows.len() < total {
        let open = (0..n_sim.len()).filter(|&c| clip.obstacles[[c / g.nx, c % g.nx]] == 0);
        let Some((c, d)) = largest(open, |c| target[c] - n_sim[c]) else {
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

/// Between windows through the open boundary `gates` ([`crate::herd::boundary`]): agents that
/// left the grid are removed, and the excess over frame `f`'s count leaves at the exit gates; when the density error exceeds `threshold`, agents move from the
/// most over-filled cells to the most under-filled ones (the paper's §6.1 control, the count
/// unchanged); then the count's shortfall against frame `f` enters at the entry gates, each new
/// agent placed to cross its gate within `ahead` seconds. Returns the rows and what crossed.
#[allow(clippy::too_many_arguments)]
pub fn population_control_open(
    clip: &ClipFields,
    gates: &crate::data::boundary::Gates,
    f: usize,
    rows: Vec<AgentRow>,
    threshold: f64,
    speed: &crate::herd::params::SpeedModel,
    next_id: &mut u64,
    rng: &mut impl Rng,
    ahead: f64,
) -> (Vec<AgentRow>, crate::herd::boundary::Crossings) {
    use crate::herd::boundary::{edit_rows, Stream};
    let mut stream = Stream::new(clip, gates, speed.clone(), rng.gen(), *next_id);
    let mut rows = edit_rows(rows, |a| stream.leave(a) + stream.trim(f, a) > 0);
    let (err, _) = field_errors(clip, f, &rows);
    if err > threshold {
        let g = clip.grid();
        let target = cell_targets(clip, f);
        let (mut n_sim, _) = cell_counts(clip, &rows);
        // Move one agent at a time from the largest surplus (≥ 1) to the largest deficit.
        loop {
            let best = |sign: f64| {
                let open = (0..n_sim.len()).filter(|&c| clip.obstacles[[c / g.nx, c % g.nx]] == 0);
                largest(open, |c| sign * (n_sim[c] - target[c]))
            };
            let (Some((from, s)), Some((to, d))) = (best(1.0), best(-1.0)) else {
                break;
            };
            if s < 1.0 || d <= 0.0 {
                break;
            }
            let k = random_member(&rows, &g, from, rng);
            let old = rows.remove(k);
            let v = old.vx.hypot(old.vy);
            rows.push(new_agent(clip, f, to % g.nx, to / g.nx, old.id, v, rng));
            n_sim[from] -= 1.0;
            n_sim[to] += 1.0;
        }
    }
    stream.next_id = (*next_id).max(stream.next_id);
    let rows = edit_rows(rows, |a| stream.enter(f, ahead, a) > 0);
    *next_id = stream.next_id;
    (rows, stream.crossings)
}

/// Frame `f`'s animals per cell (density × cell area), cells in row-major order.
fn cell_targets(clip: &ClipFields, f: usize) -> Vec<f64> {
    let g = clip.grid();
    let a = g.cell_area();
    (0..g.ny * g.nx)
        .map(|c| clip.density[[f, c / g.nx, c % g.nx]] as f64 * a)
        .collect()
}

/// The cell of `cells` with the largest `value` (the lowest index among equals) and its value.
fn largest(
    cells: impl Iterator<Item = usize>,
    value: impl Fn(usize) -> f64,
) -> Option<(usize, f64)> {
    cells
        .map(|c| (c, value(c)))
        .max_by(|p, q| p.1.total_cmp(&q.1).then(q.0.cmp(&p.0)))
}

/// The index in `rows` of a random agent in cell `c` (row-major) of `g`; `c` must hold one.
fn random_member(rows: &[AgentRow], g: &crate::data::Grid, c: usize, rng: &mut impl Rng) -> usize {
    let members: Vec<usize> = rows
        .iter()
        .enumerate()
        .filter(|(_, r)| g.cell_of([r.x, r.y]).map(|(ix, iy)| iy * g.nx + ix) == Some(c))
        .map(|(i, _)| i)
        .collect();
    members[rng.gen_range(0..members.len())]
}

/// How a herd initialised from fields is settled (see [`settle`]; off by default).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Settle {
    /// Iterations (0: no settling).
    pub iterations: usize,
    /// Step per unit force (s²): an agent moves by `eta · |F|` BL …
    pub eta: f64,
    /// … at most this many BL per iteration.
    pub max_move: f64,
}

impl Settle {
    /// Checks the step sizes (finite, ≥ 0); errors name the key (`settle` is a table of a
    /// config: `iterations`, `eta`, `max_move`).
    pub fn check(&self) -> Result<()> {
        for (key, v) in [("settle.eta", self.eta), ("settle.max_move", self.max_move)] {
            if !(v.is_finite() && v >= 0.0) {
                return Err(Error::config(key, format!("{v} must be ≥ 0")));
            }
        }
        // The CLI's `--settle N` sets the iterations: named `settle`.
        crate::limits::check_count("settle", self.iterations, crate::limits::MAX_ITERATIONS)
    }

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
        let fx = crate::herd::sim::read_vec(&fx.reshape([n]))?;
        let fy = crate::herd::sim::read_vec(&fy.reshape([n]))?;
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
    if let Some(m) = &model.world.fixed_speed {
        fix_speeds(&mut rows, m, &model.params.speed);
    }
    settle(model, clip, &mut rows, settle_cfg, device)?;
    Ok(rows)
}

/// Agents standing in a zone of fixed speed (§7.2.4) start around that speed instead of the
/// clip's mean: the same deviation from the mean, the zone's speed as the mean (eq. 6's
/// stationary spread kept).
pub fn fix_speeds(rows: &mut [AgentRow], map: &crate::herd::sim::SpeedMap, sm: &SpeedModel) {
    for r in rows {
        let Some(m) = map.at([r.x, r.y]) else {
            continue;
        };
        let s = r.vx.hypot(r.vy);
        if s > 0.0 {
            let k = (s - sm.mean + m).clamp(0.0, sm.cap_with_fixed(m)) / s;
            r.vx *= k;
            r.vy *= k;
        }
    }
}
