//! Open boundaries (paper §7.1.3, DESIGN §5): a clip that shows part of a herd — a stream of
//! animals flowing through the view — loses animals across the edge of its grid and gains new
//! ones there. One mechanism serves `fit`, `validate`, `ablate` (and `synth`-made streams):
//!
//! - **Gates.** The clip's entry and exit cells ([`gates_of_clip`]): accessible cells on the
//!   grid's edge through which the video's flux `ρ · max(0, ∓v·n) · cell side` (agents/s, `n` the
//!   edge's outward normal) carries animals in (entries) or out (exits), averaged over the clip.
//!   A clip is open when at least [`OPEN_SHARE`] of its mean count crosses its edge over the clip;
//!   a closed clip has no gates and every run is exactly what it was without this module.
//!   `--boundary FILE` overrides the derived gates (`herdfit.boundary/1`).
//! - **Exits.** After each step an agent outside the grid is removed when it moves away from the
//!   grid (its heading has a non-negative component along the way out) or is more than a cell out.
//!   A clip's run also keeps the video's count on the way down: while it holds more agents than
//!   the video's count, the excess leaves early from the exit gates' cells, nearest the edge
//!   first ([`Stream::trim`]). Without this the herd's tail trails a stream draining faster than
//!   its own flux through the exit says (the video's count is not conserved by its fields).
//! - **Entries.** New agents enter only at entry gates, never inside the view: the run keeps the
//!   count the video holds at each frame (the paper: "new agents are generated in predefined entry
//!   cells to maintain a population count consistent with the video"), so after each step the
//!   shortfall against the video's count enters, spread over the entry gates in proportion to the
//!   video's inward flux there at that frame (none enters at a frame whose entry gates carry no
//!   inward flux). Each new agent stands just outside its gate, heading along the gate cell's
//!   velocity (spread by its direction variance, turned inward when the spread points it out),
//!   speed from the speed model, so that it crosses the edge within the next step. Only the
//!   count and the edge cells' fields are read: no agent is ever placed inside the view from a
//!   frame's density.
//!
//! The agents that entered and left are counted ([`Crossings`]) and reported.

use crate::data::boundary::{Gate, Gates, Side};
use crate::data::{ClipFields, Grid};
use crate::error::Result;
use crate::herd::params::SpeedModel;
use crate::herd::sim::{ForceTensors, Model};
use crate::herd::sim::{HerdState, Snapshot, StepDecisions, StepHooks};
use burn::tensor::Device;
use herdfit_kernels::P2;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::Serialize;
use std::cell::RefCell;
use std::rc::Rc;

mod choice;
pub use choice::BoundaryChoice;

/// Share of a clip's mean count that must cross its edge over the clip (in or out) for the clip
/// to be open.
pub const OPEN_SHARE: f64 = 0.1;

/// A gate must carry at least this share of the busiest gate's flux, and at least one animal over
/// the clip, to be an entry (or exit).
pub const GATE_SHARE: f64 = 0.05;

/// An entering agent's heading makes at most this angle with the inward normal (rad): the cosine
/// 0.2 keeps every entrant crossing the edge within its first step.
const MAX_ENTRY_ANGLE: f64 = 1.369_438_406_004_566; // acos(0.2)

/// The video's flux through `gate` at frame `f`: (inward, outward), agents/s.
pub fn gate_flux(clip: &ClipFields, f: usize, gate: &Gate) -> (f64, f64) {
    let [ix, iy] = gate.cell;
    let rho = clip.density[[f, iy, ix]] as f64;
    let v = [
        clip.velocity[[f, iy, ix, 0]] as f64,
        clip.velocity[[f, iy, ix, 1]] as f64,
    ];
    let n = gate.side.normal();
    let vn = v[0] * n[0] + v[1] * n[1];
    let k = rho * clip.meta.cell_size;
    (k * (-vn).max(0.0), k * vn.max(0.0))
}

/// Every edge of an accessible border cell, in grid order (corner cells twice).
fn border_gates(clip: &ClipFields) -> Vec<Gate> {
    let (nx, ny) = (clip.meta.nx, clip.meta.ny);
    let mut gates = Vec::new();
    for iy in 0..ny {
        for ix in 0..nx {
            if clip.obstacles[[iy, ix]] != 0 {
                continue;
            }
            for side in Side::ALL {
                if side.holds(ix, iy, nx, ny) {
                    gates.push(Gate {
                        cell: [ix, iy],
                        side,
                    });
                }
            }
        }
    }
    gates
}

/// The entry and exit gates of a clip, from the video's flux across the grid's edge averaged
/// over the clip (see the module). A still or a clip that nothing crosses is closed.
pub fn gates_of_clip(clip: &ClipFields) -> Gates {
    let nf = clip.frames();
    if nf < 2 || clip.meta.fps <= 0.0 {
        return Gates::closed();
    }
    let gates = border_gates(clip);
    let mut inflow = vec![0.0f64; gates.len()];
    let mut outflow = vec![0.0f64; gates.len()];
    for f in 0..nf {
        for (k, g) in gates.iter().enumerate() {
            let (i, o) = gate_flux(clip, f, g);
            inflow[k] += i / nf as f64;
            outflow[k] += o / nf as f64;
        }
    }
    let duration = nf as f64 / clip.meta.fps;
    let mean_count = (0..nf).map(|f| clip.count(f)).sum::<f64>() / nf as f64;
    let crossing = inflow.iter().sum::<f64>().max(outflow.iter().sum::<f64>()) * duration;
    if !(mean_count > 0.0 && crossing >= OPEN_SHARE * mean_count) {
        return Gates::closed();
    }
    let pick = |mine: &[f64], other: &[f64]| -> Vec<Gate> {
        let top = mine.iter().copied().fold(0.0, f64::max);
        gates
            .iter()
            .enumerate()
            .filter(|&(k, _)| {
                mine[k] > other[k] && mine[k] >= GATE_SHARE * top && mine[k] * duration >= 1.0
            })
            .map(|(_, g)| *g)
            .collect()
    };
    Gates::new(pick(&inflow, &outflow), pick(&outflow, &inflow))
}

/// Agents that crossed the edge of the grid during a run.
#[derive(Clone, Debug, Default, PartialEq, Serialize)]
pub struct Crossings {
    /// Agents that entered at the entry gates.
    pub entered: usize,
    /// Agents removed after leaving the grid, per side (left, right, bottom, top), including
    /// those removed early.
    pub left: [usize; 4],
    /// Of those, agents removed in an exit cell before crossing its edge, the run holding more
    /// than the video's count ([`Stream::trim`]).
    pub early: usize,
}

impl Crossings {
    /// Agents removed, all sides.
    pub fn left_total(&self) -> usize {
        self.left.iter().sum()
    }

    /// Adds another run's crossings.
    pub fn add(&mut self, o: &Crossings) {
        self.entered += o.entered;
        self.early += o.early;
        for (a, b) in self.left.iter_mut().zip(o.left) {
            *a += b;
        }
    }
}

/// Agent state on plain values, as the boundary edits it.
pub struct Agents<'a> {
    pub pos: &'a mut Vec<P2>,
    pub head: &'a mut Vec<P2>,
    pub speed: &'a mut Vec<f64>,
    pub ids: &'a mut Vec<u64>,
}

impl Agents<'_> {
    /// Removes the agents marked in `drop`, keeping the others in order; returns how many.
    fn remove(&mut self, drop: &[bool]) -> usize {
        let before = self.ids.len();
        let mut keep = 0;
        for (i, &gone) in drop.iter().enumerate() {
            if gone {
                continue;
            }
            self.pos[keep] = self.pos[i];
            self.head[keep] = self.head[i];
            self.speed[keep] = self.speed[i];
            self.ids[keep] = self.ids[i];
            keep += 1;
        }
        self.pos.truncate(keep);
        self.head.truncate(keep);
        self.speed.truncate(keep);
        self.ids.truncate(keep);
        before - keep
    }
}

/// Where a run's new agents come from.
pub enum Inflow<'a> {
    /// A clip: the count the video holds at each frame, entering in proportion to the video's
    /// inward flux at each entry gate, with the gate cell's velocity (see the module).
    Clip(&'a ClipFields),
    /// An authored scene: `count` agents kept in the world (the shortfall enters) or `rate`
    /// agents/s, spread evenly over the entry gates, heading along `heading` at the gate's cell
    /// (the inward normal where it is zero or points out) within ±15°.
    Scene {
        grid: Grid,
        /// One direction per grid cell (row-major, row 0 at the bottom): the navigation field.
        heading: &'a [P2],
        count: Option<usize>,
        rate: f64,
    },
}

/// The open boundary of one run: removes agents that left, lets new ones in.
pub struct Stream<'a> {
    inflow: Inflow<'a>,
    gates: &'a Gates,
    speed: SpeedModel,
    rng: ChaCha8Rng,
    /// Expected entries not yet entered (a scene's rate between steps).
    carry: f64,
    /// The id of the next agent to enter.
    pub next_id: u64,
    pub crossings: Crossings,
}

impl<'a> Stream<'a> {
    /// The boundary of a run of `clip` with seed `seed` (the entries draw from a stream of their
    /// own, so that the model's noise is the same whatever enters), first new id `next_id`.
    pub fn new(
        clip: &'a ClipFields,
        gates: &'a Gates,
        speed: SpeedModel,
        seed: u64,
        next_id: u64,
    ) -> Self {
        Stream::of(Inflow::Clip(clip), gates, speed, seed, next_id)
    }

    /// The boundary of a run fed by `inflow`.
    pub fn of(
        inflow: Inflow<'a>,
        gates: &'a Gates,
        speed: SpeedModel,
        seed: u64,
        next_id: u64,
    ) -> Self {
        Stream {
            inflow,
            gates,
            speed,
            rng: ChaCha8Rng::seed_from_u64(seed ^ 0x0B0D_A7E5_0B0D_A7E5),
            carry: 0.0,
            next_id,
            crossings: Crossings::default(),
        }
    }

    fn grid(&self) -> Grid {
        match &self.inflow {
            Inflow::Clip(c) => c.grid(),
            Inflow::Scene { grid, .. } => *grid,
        }
    }

    /// After the steps that brought the herd to frame `f` (`dt` seconds since the last call):
    /// removes the agents that left the grid and lets new ones in, each placed to cross its
    /// gate within `dt` seconds. Returns whether anything changed.
    pub fn apply(&mut self, f: usize, dt: f64, a: &mut Agents) -> bool {
        let removed = self.leave(a) + self.trim(f, a);
        let entered = self.enter(f, dt, a);
        removed > 0 || entered > 0
    }

    /// Removes the agents that left the grid: outside it and heading away from it, or more
    /// than a cell out. Returns how many.
    pub fn leave(&mut self, a: &mut Agents) -> usize {
        let g = self.grid();
        let [w, h] = g.size();
        let (x0, y0) = (g.origin[0], g.origin[1]);
        let mut drop = vec![false; a.ids.len()];
        for (i, gone) in drop.iter_mut().enumerate() {
            let p = a.pos[i];
            let q = [p[0].clamp(x0, x0 + w), p[1].clamp(y0, y0 + h)];
            let out = [p[0] - q[0], p[1] - q[1]];
            let dist = out[0].hypot(out[1]);
            let leaving = dist > 0.0
                && (a.head[i][0] * out[0] + a.head[i][1] * out[1] >= 0.0 || dist > g.cell_size);
            if leaving {
                let side = if p[0] < x0 {
                    0
                } else if p[0] > x0 + w {
                    1
                } else if p[1] < y0 {
                    2
                } else {
                    3
                };
                self.crossings.left[side] += 1;
                *gone = true;
            }
        }
        a.remove(&drop)
    }

    /// The count the run keeps at frame `f`: the video's, for a clip; none for a scene (whose
    /// count only entries keep).
    fn target(&self, f: usize) -> Option<f64> {
        match &self.inflow {
            Inflow::Clip(clip) if f < clip.frames() => Some(clip.count(f)),
            _ => None,
        }
    }

    /// While the run holds more agents than the video's count at frame `f`, the excess leaves
    /// through the exit gates: agents in an exit gate's cell heading out through its edge (a
    /// non-negative component along the outward normal), nearest the edge first, are removed
    /// (and counted in [`Crossings::early`]). The count then falls with the video's where it falls
    /// faster than the herd's flux through the exit carries it, as entries raise it where it
    /// rises faster; no agent elsewhere is touched. Returns how many.
    pub fn trim(&mut self, f: usize, a: &mut Agents) -> usize {
        let Some(target) = self.target(f) else {
            return 0;
        };
        let excess = a.ids.len() as f64 - target;
        if excess.is_nan() || excess <= 0.0 || self.gates.exits.is_empty() {
            return 0;
        }
        // Rounded stochastically, as the entries' shortfall is.
        let n =
            excess.floor() as usize + usize::from(self.rng.gen::<f64>() < excess - excess.floor());
        let g = self.grid();
        let far = [g.origin[0] + g.size()[0], g.origin[1] + g.size()[1]];
        // (distance to the edge, agent, side) of every agent that may leave early.
        let mut out: Vec<(f64, usize, usize)> = Vec::new();
        for i in 0..a.ids.len() {
            let Some((ix, iy)) = g.cell_of(a.pos[i]) else {
                continue;
            };
            for gate in self.gates.exits.iter().filter(|e| e.cell == [ix, iy]) {
                let n = gate.side.normal();
                if a.head[i][0] * n[0] + a.head[i][1] * n[1] < 0.0 {
                    continue;
                }
                let p = a.pos[i];
                let (d, side) = match gate.side {
                    Side::Left => (p[0] - g.origin[0], 0),
                    Side::Right => (far[0] - p[0], 1),
                    Side::Bottom => (p[1] - g.origin[1], 2),
                    Side::Top => (far[1] - p[1], 3),
                };
                out.push((d, i, side));
            }
        }
        out.sort_by(|p, q| p.0.total_cmp(&q.0).then(p.1.cmp(&q.1)));
        let mut drop = vec![false; a.ids.len()];
        let mut taken = 0;
        for &(_, i, side) in &out {
            // A corner cell may be two exits: each agent leaves once.
            if taken == n || drop[i] {
                continue;
            }
            drop[i] = true;
            taken += 1;
            self.crossings.left[side] += 1;
            self.crossings.early += 1;
        }
        a.remove(&drop)
    }

    /// How many enter after the steps that brought the run to frame `f` (`dt` seconds), and
    /// each entry gate's weight.
    fn due(&mut self, f: usize, dt: f64, present: usize) -> (usize, Vec<f64>) {
        let gates = &self.gates.entries;
        let (expected, weights) = match &self.inflow {
            Inflow::Clip(clip) => {
                if f >= clip.frames() {
                    return (0, Vec::new());
                }
                let w: Vec<f64> = gates.iter().map(|g| gate_flux(clip, f, g).0).collect();
                (clip.count(f) - present as f64, w)
            }
            Inflow::Scene { count, rate, .. } => {
                let e = match count {
                    Some(c) => *c as f64 - present as f64,
                    None => {
                        self.carry += rate * dt;
                        self.carry
                    }
                };
                (e, vec![1.0; gates.len()])
            }
        };
        let total: f64 = weights.iter().sum();
        if !(expected > 0.0 && total > 0.0) {
            return (0, weights);
        }
        // A scene's rate carries its fraction to the next step; a count rounds stochastically
        // so that the expected count is the target.
        let n = match self.inflow {
            Inflow::Scene { count: None, .. } => {
                // The rate's sum over steps is exact only to rounding: 0.08 × 25 = 1.9999….
                let n = (expected + 1e-9).floor();
                self.carry -= n;
                n as usize
            }
            _ => {
                expected.floor() as usize
                    + usize::from(self.rng.gen::<f64>() < expected - expected.floor())
            }
        };
        (n, weights)
    }

    /// Lets in the agents due at frame `f`, each new agent placed to cross its gate within
    /// `dt` seconds; returns how many entered.
    pub fn enter(&mut self, f: usize, dt: f64, a: &mut Agents) -> usize {
        if self.gates.entries.is_empty() {
            return 0;
        }
        let (n, weights) = self.due(f, dt, a.ids.len());
        let total: f64 = weights.iter().sum();
        for _ in 0..n {
            let mut pick = self.rng.gen::<f64>() * total;
            let mut k = 0;
            while k + 1 < weights.len() && pick >= weights[k] {
                pick -= weights[k];
                k += 1;
            }
            let gate = self.gates.entries[k];
            let (p, h, s) = self.entrant(f, &gate, dt);
            a.pos.push(p);
            a.head.push(h);
            a.speed.push(s);
            a.ids.push(self.next_id);
            self.next_id += 1;
        }
        self.crossings.entered += n;
        n
    }

    /// The heading angle (before it is turned inward), its spread (rad) and the local density
    /// of an entrant at `gate` in frame `f`.
    fn heading_of(&self, f: usize, gate: &Gate, inward: f64) -> (f64, f64, f64) {
        let [ix, iy] = gate.cell;
        match &self.inflow {
            Inflow::Clip(clip) => {
                let v = [
                    clip.velocity[[f, iy, ix, 0]] as f64,
                    clip.velocity[[f, iy, ix, 1]] as f64,
                ];
                let spread = (clip.dir_variance[[f, iy, ix]] as f64).max(0.0).sqrt();
                (v[1].atan2(v[0]), spread, clip.density[[f, iy, ix]] as f64)
            }
            Inflow::Scene { grid, heading, .. } => {
                let d = heading[iy * grid.nx + ix];
                let n = [inward.cos(), inward.sin()];
                let a = if d[0] * n[0] + d[1] * n[1] > 0.0 {
                    d[1].atan2(d[0])
                } else {
                    inward
                };
                (a, 15f64.to_radians(), 0.0)
            }
        }
    }

    /// A new agent at `gate` in frame `f`: position just outside the gate, heading and speed.
    fn entrant(&mut self, f: usize, gate: &Gate, ahead: f64) -> (P2, P2, f64) {
        let g = self.grid();
        let [ix, iy] = gate.cell;
        let n = gate.side.normal();
        let inward = (-n[1]).atan2(-n[0]);
        let (a0, spread, rho) = self.heading_of(f, gate, inward);
        let z: f64 = self.rng.sample(StandardNormal);
        let mut a = a0 + spread * z;
        // The angle from the inward normal, wrapped to (−π, π], limited so the agent comes in.
        let mut off = (a - inward).rem_euclid(std::f64::consts::TAU);
        if off > std::f64::consts::PI {
            off -= std::f64::consts::TAU;
        }
        if off.abs() > MAX_ENTRY_ANGLE {
            a = inward + MAX_ENTRY_ANGLE * off.signum();
            off = MAX_ENTRY_ANGLE * off.signum();
        }
        let h = [a.cos(), a.sin()];
        let zs: f64 = self.rng.sample(StandardNormal);
        let s =
            (self.speed.mean_at(rho) + self.speed.stationary_std() * zs).clamp(0.0, self.speed.max);
        // Along the gate's edge, then out by a fraction of what the agent covers inward in
        // `ahead` seconds.
        let c = g.centre(ix, iy);
        let half = g.cell_size / 2.0;
        let along = (self.rng.gen::<f64>() * 2.0 - 1.0) * half * 0.999;
        let depth = self.rng.gen::<f64>() * ahead * s * off.cos();
        let p = match gate.side {
            Side::Left | Side::Right => [c[0] + n[0] * (half + depth), c[1] + along],
            Side::Bottom | Side::Top => [c[0] + along, c[1] + n[1] * (half + depth)],
        };
        (p, h, s)
    }
}

/// [`StepHooks`] `inner` with the open boundary applied after every step: step `t` ends at frame
/// `first + t + 1`; the current agents' ids are shared with the caller (`ids`), who reads them
/// when observing a state.
pub struct Open<'a, H> {
    pub inner: H,
    pub stream: Stream<'a>,
    pub first: usize,
    /// The step (s): entrants cross their gate within the next step.
    pub dt: f64,
    pub ids: Rc<RefCell<Vec<u64>>>,
    pub device: Device,
}

impl<H: StepHooks> StepHooks for Open<'_, H> {
    fn before_decide(&mut self, t: usize, model: &mut Model) -> Result<()> {
        self.inner.before_decide(t, model)
    }

    fn forces(&mut self, t: usize, state: &HerdState) -> Result<Option<ForceTensors>> {
        self.inner.forces(t, state)
    }

    fn extra(&mut self, t: usize, state: &HerdState) -> Result<Option<Vec<P2>>> {
        self.inner.extra(t, state)
    }

    fn after(&mut self, t: usize, dec: &StepDecisions, next: HerdState) -> Result<HerdState> {
        let mut s = next.snapshot()?;
        let changed = {
            let mut ids = self.ids.borrow_mut();
            let mut a = Agents {
                pos: &mut s.pos,
                head: &mut s.head,
                speed: &mut s.speed,
                ids: &mut ids,
            };
            self.stream.apply(self.first + t + 1, self.dt, &mut a)
        };
        let next = if changed {
            HerdState::from_snapshot(&s, &self.device)
        } else {
            next
        };
        self.inner.after(t, dec, next)
    }
}

/// Runs `edit` on agent rows as [`Agents`] (between fit windows) and returns the edited rows;
/// rows come back unchanged when `edit` changes nothing.
pub fn edit_rows(
    rows: Vec<crate::data::AgentRow>,
    edit: impl FnOnce(&mut Agents) -> bool,
) -> Vec<crate::data::AgentRow> {
    let mut s = Snapshot::of_rows(&rows);
    let mut ids: Vec<u64> = rows.iter().map(|r| r.id).collect();
    let mut a = Agents {
        pos: &mut s.pos,
        head: &mut s.head,
        speed: &mut s.speed,
        ids: &mut ids,
    };
    if !edit(&mut a) {
        return rows;
    }
    s.rows(&ids)
}
