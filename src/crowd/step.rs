//! One simulation step of learnt agents: perceive (eq. 1 over a uniform grid of positions), build
//! the state of §4, ask the agent's action model (§5) and move. Agents decide in parallel
//! (rayon); each draws from its own seeded generator, so a run's bytes do not depend on the
//! number of threads.

use super::action::{Decision, Scratch, NO_NEXT};
use super::features::{
    alignment, formation, mean_direction, pivot_parts, to_local, to_world, unit, IntentWindow,
    StateParts, SECTORS, V2,
};
use super::layout::Layout;
use super::model::{CrowdModel, Pivot};
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// One simulated agent.
#[derive(Clone, Debug)]
pub struct Agent {
    pub id: u64,
    pub pos: V2,
    /// Unit heading (direction of the last move faster than `still_speed`).
    pub heading: V2,
    /// Recent positions, oldest first, the current one last.
    pub history: Vec<V2>,
    /// Eq. 1 at the previous step, in that step's frame.
    pub prev_formation: [f64; SECTORS],
    /// Mean of the cluster chosen at the previous step (m_prev of eq. 2).
    pub m_prev: V2,
    /// The behaviour and tree position of the sample the last step took
    /// ([`Decision::sample`]), for the action model's continuation.
    pub last_sample: (usize, u32),
    /// Index of the agent's behaviour in the model.
    pub behaviour: usize,
    /// The pivot the behaviour is taken relative to, if any.
    pub pivot: Option<Pivot>,
    /// Where the agent heads for (the intended direction points there); `None`: it keeps the
    /// mean direction of its own past steps.
    pub goal: Option<V2>,
    /// Steps left until it means to leave at its goal (the exit intent's time left,
    /// [`super::features::IntentWindow::Exit`]); `None`: no time is set.
    pub due: Option<usize>,
    /// Seeded per agent.
    pub rng: ChaCha8Rng,
    /// The walking group it belongs to ([`super::entries::walking_groups`]): its leader's id.
    pub group: Option<u64>,
}

impl Agent {
    /// An agent at `history`'s last position (at least one; positions `dt` seconds apart), with
    /// generator stream `id` of `seed`. m_prev starts as its last velocity in its own frame.
    pub fn new(
        id: u64,
        history: Vec<V2>,
        heading: V2,
        goal: Option<V2>,
        seed: u64,
        dt: f64,
    ) -> Agent {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        rng.set_stream(id);
        let pos = *history.last().expect("an agent needs a position");
        let speed_prev = match history.as_slice() {
            [.., a, b] => to_local([(b[0] - a[0]) / dt, (b[1] - a[1]) / dt], heading),
            _ => [0.0, 0.0],
        };
        Agent {
            id,
            pos,
            heading,
            history,
            prev_formation: [0.0; SECTORS],
            m_prev: speed_prev,
            last_sample: (0, NO_NEXT),
            behaviour: 0,
            pivot: None,
            goal,
            due: None,
            rng,
            group: None,
        }
    }
}

/// Positions bucketed in square cells of side `cell` for radius queries.
pub struct Grid {
    origin: V2,
    cell: f64,
    nx: usize,
    ny: usize,
    start: Vec<u32>,
    items: Vec<u32>,
}

impl Grid {
    /// A grid over `pos` (at most 512 cells a side: the cell grows for very spread-out agents).
    pub fn new(pos: &[V2], cell: f64) -> Grid {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        for p in pos {
            for a in 0..2 {
                lo[a] = lo[a].min(p[a]);
                hi[a] = hi[a].max(p[a]);
            }
        }
        if pos.is_empty() {
            lo = [0.0, 0.0];
            hi = [0.0, 0.0];
        }
        let span = (hi[0] - lo[0]).max(hi[1] - lo[1]);
        let cell = cell.max(span / 511.0).max(1e-9);
        let nx = ((hi[0] - lo[0]) / cell) as usize + 1;
        let ny = ((hi[1] - lo[1]) / cell) as usize + 1;
        let key = |p: &V2| {
            let ix = (((p[0] - lo[0]) / cell) as usize).min(nx - 1);
            let iy = (((p[1] - lo[1]) / cell) as usize).min(ny - 1);
            iy * nx + ix
        };
        let mut count = vec![0u32; nx * ny + 1];
        for p in pos {
            count[key(p) + 1] += 1;
        }
        for i in 1..count.len() {
            count[i] += count[i - 1];
        }
        let mut fill = count.clone();
        let mut items = vec![0u32; pos.len()];
        for (i, p) in pos.iter().enumerate() {
            let k = key(p);
            items[fill[k] as usize] = i as u32;
            fill[k] += 1;
        }
        Grid {
            origin: lo,
            cell,
            nx,
            ny,
            start: count,
            items,
        }
    }

    /// Indices of the points in cells within `r` of `p` (a superset of those within `r`).
    pub fn near(&self, p: V2, r: f64) -> impl Iterator<Item = usize> + '_ {
        let cell =
            |v: f64, o: f64, n: usize| (((v - o) / self.cell).floor().max(0.0) as usize).min(n - 1);
        let (x0, x1) = (
            cell(p[0] - r, self.origin[0], self.nx),
            cell(p[0] + r, self.origin[0], self.nx),
        );
        let (y0, y1) = (
            cell(p[1] - r, self.origin[1], self.ny),
            cell(p[1] + r, self.origin[1], self.ny),
        );
        (y0..=y1).flat_map(move |iy| {
            (x0..=x1).flat_map(move |ix| {
                let k = iy * self.nx + ix;
                self.items[self.start[k] as usize..self.start[k + 1] as usize]
                    .iter()
                    .map(|&i| i as usize)
            })
        })
    }
}

/// What one agent decided in a step.
#[derive(Clone, Copy, Debug)]
pub struct Planned {
    pub velocity: V2,
    pub formation: [f64; SECTORS],
    pub decision: Decision,
}

/// The state of `a` (unweighted) given the others' positions and headings; `align` computes the
/// neighbours' headings too.
pub fn perceive(
    model: &CrowdModel,
    a: &Agent,
    i: usize,
    (pos, heads): (&[V2], &[V2]),
    grid: &Grid,
    align: bool,
) -> StateParts {
    let f = &model.config.features;
    let frame = a.pivot.as_ref().map_or(a.heading, |p| p.dir());
    let now = formation(
        a.pos,
        frame,
        grid.near(a.pos, f.radius)
            .filter(|&j| j != i)
            .map(|j| pos[j]),
        f.radius,
    );
    let speed = match a.history.as_slice() {
        [.., p, q] => (q[0] - p[0]).hypot(q[1] - p[1]) / model.dt,
        _ => 0.0,
    };
    let intent = if f.intent == IntentWindow::Exit {
        exit_velocity(a, f.intent_window, model.dt)
    } else {
        let dir = match a.goal {
            Some(g) => unit([g[0] - a.pos[0], g[1] - a.pos[1]]),
            None => {
                let n = a.history.len();
                mean_direction(&a.history, n.saturating_sub(f.intent_window + 1), n - 1)
            }
        };
        dir.unwrap_or(a.heading)
    };
    StateParts {
        speed,
        now,
        prev: a.prev_formation,
        pivot: a
            .pivot
            .as_ref()
            .map(|p| pivot_parts(a.pos, a.heading, p.position, p.dir())),
        intent: to_local(intent, a.heading),
        align: align.then(|| neighbour_headings(a, i, (pos, heads), grid, f.radius)),
    }
}

/// The exit intent of a simulated agent ([`IntentWindow::Exit`]): toward its goal over the steps
/// it has left (at least one); with a goal but no time set, toward the goal at the speed of its
/// last `window` steps; with no goal, its mean velocity over those steps.
fn exit_velocity(a: &Agent, window: usize, dt: f64) -> V2 {
    let h = &a.history;
    let n = h.len();
    let back = n.saturating_sub(window + 1);
    let steps = (n - 1 - back).max(1) as f64;
    let past = [
        (h[n - 1][0] - h[back][0]) / (steps * dt),
        (h[n - 1][1] - h[back][1]) / (steps * dt),
    ];
    let Some(g) = a.goal else { return past };
    let d = [g[0] - a.pos[0], g[1] - a.pos[1]];
    match a.due {
        Some(k) => {
            let t = k.max(1) as f64 * dt;
            [d[0] / t, d[1] / t]
        }
        None => {
            let v = past[0].hypot(past[1]);
            unit(d).map_or([0.0, 0.0], |u| [u[0] * v, u[1] * v])
        }
    }
}

/// The alignment feature of `a` (out of line: most models have none).
#[inline(never)]
fn neighbour_headings(
    a: &Agent,
    i: usize,
    (pos, heads): (&[V2], &[V2]),
    grid: &Grid,
    r: f64,
) -> V2 {
    let near = grid.near(a.pos, r).filter(|&j| j != i);
    alignment(a.pos, a.heading, near.map(|j| (pos[j], heads[j])), r)
}

/// Every agent's decision for this step (in parallel; the order of the output is the agents').
pub fn plan(model: &CrowdModel, agents: &mut [Agent]) -> Vec<Planned> {
    let pos: Vec<V2> = agents.iter().map(|a| a.pos).collect();
    // The others' headings, only for a model with an alignment feature.
    let heads: Vec<V2> = if model.behaviours.iter().any(|b| b.weights.aligns()) {
        agents.iter().map(|a| a.heading).collect()
    } else {
        Vec::new()
    };
    let grid = Grid::new(&pos, model.config.features.radius);
    agents
        .par_iter_mut()
        .enumerate()
        .map_init(
            || (Scratch::default(), Vec::new(), Vec::new()),
            |(sc, raw, z), (i, a)| {
                let b = &model.behaviours[a.behaviour.min(model.behaviours.len() - 1)];
                let align = b.weights.aligns();
                let parts = perceive(model, a, i, (&pos, &heads), &grid, align);
                raw.clear();
                parts.write(&b.weights, raw);
                if raw.len() != b.pca.input() {
                    // A pivot behaviour without a pivot (or the reverse): pad or cut the state.
                    raw.resize(b.pca.input(), 0.0);
                }
                z.resize(b.pca.dims(), 0.0);
                b.pca.project(raw, z);
                let behaviour = a.behaviour.min(model.behaviours.len() - 1);
                let last = match a.last_sample {
                    (k, s) if k == behaviour => s,
                    _ => NO_NEXT,
                };
                let d =
                    b.model
                        .decide_after(z, a.m_prev, last, &model.config.action, &mut a.rng, sc);
                a.last_sample = (behaviour, d.sample);
                Planned {
                    velocity: with_inertia(
                        to_world(d.action, a.heading),
                        &a.history,
                        model.config.action.inertia,
                        model.dt,
                    ),
                    formation: parts.now,
                    decision: d,
                }
            },
        )
        .collect()
}

/// `v` blended with the last step of `history` (positions `dt` apart) by inertia `lam`:
/// (1 − λ)·v + λ·(last step / dt); `v` itself when λ = 0 or there is no last step.
pub fn with_inertia(v: V2, history: &[V2], lam: f64, dt: f64) -> V2 {
    match history {
        [.., p, q] if lam > 0.0 => {
            let last = [(q[0] - p[0]) / dt, (q[1] - p[1]) / dt];
            [
                (1.0 - lam) * v[0] + lam * last[0],
                (1.0 - lam) * v[1] + lam * last[1],
            ]
        }
        _ => v,
    }
}

/// Applies planned decisions: moves (constrained by the layout's walls and obstacles), updates
/// headings, histories (`keep` positions), formations and m_prev.
pub fn advance(
    model: &CrowdModel,
    agents: &mut [Agent],
    plans: &[Planned],
    layout: Option<(&Layout, &[[V2; 2]])>,
    keep: usize,
) {
    let still = model.config.features.still_speed * model.dt;
    for (a, p) in agents.iter_mut().zip(plans) {
        let q = [
            a.pos[0] + p.velocity[0] * model.dt,
            a.pos[1] + p.velocity[1] * model.dt,
        ];
        let q = match layout {
            Some((l, segs)) => l.constrain(segs, a.pos, q),
            None => q,
        };
        let d = [q[0] - a.pos[0], q[1] - a.pos[1]];
        if d[0].hypot(d[1]) > still {
            if let Some(h) = unit(d) {
                a.heading = h;
            }
        }
        a.pos = q;
        a.history.push(q);
        if a.history.len() > keep {
            let extra = a.history.len() - keep;
            a.history.drain(..extra);
        }
        a.prev_formation = p.formation;
        a.m_prev = p.decision.cluster_mean;
        a.due = a.due.map(|k| k.saturating_sub(1));
    }
}

/// Hard minimum-distance correction: every pair of agents closer than `min_distance` is pushed
/// apart along the line between them, each by half the overlap (pairs summed over all agents,
/// then applied at once: the result does not depend on the agents' order beyond summation
/// order, which is fixed). `iterations` passes; 0 or `min_distance = 0` does nothing. Positions
/// that move are updated in the agents' histories too, so the next step's speed and heading see
/// the corrected position; with a layout, a push never crosses its walls. Returns the number of
/// overlapping pairs found in the first pass.
pub fn separate(
    agents: &mut [Agent],
    min_distance: f64,
    iterations: usize,
    layout: Option<(&Layout, &[[V2; 2]])>,
) -> usize {
    let mut first = 0;
    if min_distance <= 0.0 || agents.len() < 2 {
        return 0;
    }
    for it in 0..iterations {
        let pos: Vec<V2> = agents.iter().map(|a| a.pos).collect();
        let grid = Grid::new(&pos, min_distance);
        let push: Vec<(V2, usize)> = pos
            .par_iter()
            .enumerate()
            .map(|(i, &p)| {
                let mut d = [0.0, 0.0];
                let mut n = 0;
                for j in grid.near(p, min_distance) {
                    if j == i {
                        continue;
                    }
                    let q = pos[j];
                    let (dx, dy) = (p[0] - q[0], p[1] - q[1]);
                    let r = dx.hypot(dy);
                    if r >= min_distance {
                        continue;
                    }
                    n += 1;
                    // Coincident agents split along x, the lower index to the left.
                    let u = if r > 1e-12 {
                        [dx / r, dy / r]
                    } else if i < j {
                        [-1.0, 0.0]
                    } else {
                        [1.0, 0.0]
                    };
                    let m = 0.5 * (min_distance - r);
                    d[0] += u[0] * m;
                    d[1] += u[1] * m;
                }
                (d, n)
            })
            .collect();
        let pairs = push.iter().map(|p| p.1).sum::<usize>() / 2;
        if it == 0 {
            first = pairs;
        }
        if pairs == 0 {
            break;
        }
        for (a, (d, _)) in agents.iter_mut().zip(push) {
            if d != [0.0, 0.0] {
                let q = [a.pos[0] + d[0], a.pos[1] + d[1]];
                a.pos = match layout {
                    Some((l, segs)) => l.constrain(segs, a.pos, q),
                    None => q,
                };
                if let Some(last) = a.history.last_mut() {
                    *last = a.pos;
                }
            }
        }
    }
    first
}

#[cfg(test)]
mod tests {
    use super::*;

    fn at(id: u64, p: V2) -> Agent {
        Agent::new(id, vec![p], [1.0, 0.0], None, 0, 0.4)
    }

    #[test]
    fn inertia_blends_the_action_with_the_last_step() {
        let hist = [[0.0, 0.0], [1.0, 0.0], [1.4, 0.2]];
        let v = [3.0, -1.0];
        // λ = 0: the action as it is; λ = 1: constant velocity (last step 0.4, 0.2 over 0.4 s).
        assert_eq!(with_inertia(v, &hist, 0.0, 0.4), v);
        let cv = with_inertia(v, &hist, 1.0, 0.4);
        assert!(
            (cv[0] - 1.0).abs() < 1e-12 && (cv[1] - 0.5).abs() < 1e-12,
            "{cv:?}"
        );
        let half = with_inertia(v, &hist, 0.5, 0.4);
        assert!((half[0] - 2.0).abs() < 1e-12 && (half[1] + 0.25).abs() < 1e-12);
        // No last step: the action.
        assert_eq!(with_inertia(v, &hist[..1], 0.5, 0.4), v);
    }

    #[test]
    fn separation_restores_the_minimum_distance_and_keeps_the_centre() {
        let mut a = vec![at(0, [0.0, 0.0]), at(1, [0.1, 0.0]), at(2, [5.0, 5.0])];
        assert_eq!(separate(&mut a, 0.3, 3, None), 1);
        let d = (a[1].pos[0] - a[0].pos[0]).hypot(a[1].pos[1] - a[0].pos[1]);
        assert!((d - 0.3).abs() < 1e-12, "{d}");
        assert!((a[0].pos[0] + a[1].pos[0] - 0.1).abs() < 1e-12);
        assert_eq!(a[0].pos[1], 0.0);
        assert_eq!(a[2].pos, [5.0, 5.0]);
        assert_eq!(a[0].history, vec![a[0].pos]);
        // Coincident agents split along x; a row of three ends at least 0.25 m apart after 3
        // passes (each pass removes half the overlap of a chain's inner pairs or more).
        let mut b = vec![at(0, [1.0, 1.0]), at(1, [1.0, 1.0])];
        separate(&mut b, 0.3, 1, None);
        assert_eq!(b[0].pos, [0.85, 1.0]);
        assert_eq!(b[1].pos, [1.15, 1.0]);
        let mut c = vec![at(0, [0.0, 0.0]), at(1, [0.1, 0.0]), at(2, [0.2, 0.0])];
        separate(&mut c, 0.3, 3, None);
        for w in c.windows(2) {
            assert!(w[1].pos[0] - w[0].pos[0] > 0.25, "{:?}", w[1].pos);
        }
        assert_eq!(separate(&mut c, 0.0, 3, None), 0);
    }
}
