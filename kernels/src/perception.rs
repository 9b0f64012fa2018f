//! Perception of one simulation step (DESIGN §4.1–4.2): who sees whom, which obstacle points are
//! seen, how many visible neighbours lie in the front cone, and the local density. No gradients:
//! the output is plain data that the differentiable model consumes (and that can be recorded and
//! replayed).

use crate::geometry::{bearing, Capsule, P2};
use crate::grid::UniformGrid;
use crate::obstacles::ObstacleMap;
use rayon::prelude::*;

mod verlet;

pub use verlet::NeighbourLists;

/// Settings of the perception kernel.
#[derive(Clone, Debug, PartialEq)]
pub struct PerceptionConfig {
    /// Perception radius R_perc (BL).
    pub radius: f64,
    /// Body capsule used for occlusion.
    pub capsule: Capsule,
    /// Test occlusion by other agents and obstacle cells (paper §5.3).
    pub occlusion: bool,
    /// At most this many visible neighbours per agent are kept (the nearest).
    pub max_neighbours: usize,
    /// At most this many visible obstacle points per agent are kept (the nearest).
    pub max_obstacles: usize,
    /// Half-angle of the front cone used by the leader rule (radians).
    pub front_cone: f64,
}

/// Padded per-agent lists, row-major `[n, k]`.
#[derive(Clone, Debug, PartialEq, Default, serde::Serialize, serde::Deserialize)]
pub struct Perception {
    pub n: usize,
    /// Width of the neighbour lists (≥ 1).
    pub k: usize,
    /// Neighbour indices `[n, k]`; padded entries hold the agent's own index.
    pub neighbours: Vec<u32>,
    /// 1 for a real neighbour, 0 for padding `[n, k]`.
    pub neighbour_mask: Vec<u8>,
    /// Branch of the bearing of each pair `[n, k]` (see [`branch_of`]); 0 on padding.
    pub neighbour_branch: Vec<u8>,
    /// Width of the obstacle lists (≥ 1).
    pub ko: usize,
    /// Obstacle points `[n, ko]`; padded entries hold the agent's own position.
    pub obstacle_points: Vec<P2>,
    /// 1 for a real obstacle point, 0 for padding `[n, ko]`.
    pub obstacle_mask: Vec<u8>,
    /// Branch of the bearing of each obstacle point `[n, ko]`; 0 on padding.
    pub obstacle_branch: Vec<u8>,
    /// Visible neighbours within the front cone (before truncation to `k`).
    pub front_count: Vec<u32>,
    /// Agents (self included) within the perception radius per unit area, agents/BL².
    pub density: Vec<f64>,
}

/// Bit 0 of a branch code: the offset lies to the right of the heading (cross product < 0).
pub const BRANCH_RIGHT: u8 = 1;
/// Bit 1 of a branch code: the offset lies behind the agent (dot product < 0).
pub const BRANCH_BEHIND: u8 = 2;

/// The branch of the unsigned bearing φ ∈ [0, π] between heading `h` and offset `d`: which side
/// (sign of h × d) and whether behind (h · d < 0). With the branch fixed, φ has a smooth
/// continuation through φ = 0 and φ = π (where |atan2| has kinks), so replayed runs are smooth in
/// the parameters, like every other recorded decision.
#[inline]
pub fn branch_of(h: P2, d: P2) -> u8 {
    let cross = h[0] * d[1] - h[1] * d[0];
    let dot = h[0] * d[0] + h[1] * d[1];
    (if cross < 0.0 { BRANCH_RIGHT } else { 0 }) | (if dot < 0.0 { BRANCH_BEHIND } else { 0 })
}

/// Agents per rayon task (and per output chunk): chunk boundaries are fixed, so the output does
/// not depend on the thread count.
const CHUNK: usize = 64;

/// An in-range candidate: squared distance, index, offset from the perceiving agent, heading.
#[derive(Clone, Copy)]
struct Cand {
    d2: f64,
    j: u32,
    o: P2,
    h: P2,
}

/// Reused per-thread buffers (no allocation per agent).
#[derive(Default)]
struct Scratch {
    /// `d2` bits above the index: one integer compare orders by distance, then index.
    keys: Vec<u128>,
    cand: Vec<Cand>,
    pts: Vec<(f64, P2)>,
}

/// The views of one chunk of agents, flattened: agent `a` of the chunk owns
/// `nb_len[a]` neighbours (with their branch codes) and `ob_len[a]` obstacle points.
#[derive(Default)]
struct ChunkViews {
    nb: Vec<u32>,
    nb_branch: Vec<u8>,
    nb_len: Vec<u32>,
    ob: Vec<P2>,
    ob_branch: Vec<u8>,
    ob_len: Vec<u32>,
    front: Vec<u32>,
    in_range: Vec<u32>,
}

/// Runs the perception kernel for all agents (in parallel; the result does not depend on the
/// thread count).
pub fn perceive(
    positions: &[P2],
    headings: &[P2],
    obstacles: Option<&ObstacleMap>,
    cfg: &PerceptionConfig,
) -> Perception {
    let scene = Scene {
        pos: positions,
        head: headings,
    };
    perceive_rows(scene, scene, |i| Some(i as u32), obstacles, cfg)
}

/// Positions and headings of a set of agents.
#[derive(Clone, Copy)]
pub struct Scene<'a> {
    pub pos: &'a [P2],
    pub head: &'a [P2],
}

/// The perception of `queries` — agents that are not part of `scene` — among the agents of
/// `scene`: row i is what an agent at `queries.pos[i]` heading `queries.head[i]` perceives of the
/// scene, with scene agent `own[i]` (its own tracked twin, when there is one) left out, and the
/// other queries invisible to it. Neighbour indices are scene indices; padded entries hold the
/// query's index `i` (mask 0) and padded obstacle points its position. Occlusion is by closer
/// scene agents, as in [`perceive`] (which is this with the scene as its own queries); the
/// result does not depend on the thread count. The neighbour-conditioned rollout of a track fit
/// uses it: each animal is simulated among its neighbours replayed from their tracks.
pub fn perceive_among(
    queries: Scene<'_>,
    own: &[Option<u32>],
    scene: Scene<'_>,
    obstacles: Option<&ObstacleMap>,
    cfg: &PerceptionConfig,
) -> Perception {
    assert_eq!(queries.pos.len(), own.len(), "one `own` entry per query");
    perceive_rows(queries, scene, |i| own[i], obstacles, cfg)
}

/// The rows of `queries` among `scene` (agent `own(i)` of the scene excluded from row i).
fn perceive_rows(
    queries: Scene<'_>,
    scene: Scene<'_>,
    own: impl Fn(usize) -> Option<u32> + Sync,
    obstacles: Option<&ObstacleMap>,
    cfg: &PerceptionConfig,
) -> Perception {
    let positions = queries.pos;
    let n = positions.len();
    let grid = UniformGrid::build(scene.pos, 0.5 * cfg.radius);
    let obstacles = obstacles.filter(|m| m.any());
    let cone = FrontCone::new(cfg.front_cone);
    let chunks: Vec<ChunkViews> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map_init(Scratch::default, |sc, c| {
            let mut out = ChunkViews::default();
            let (start, end) = (c * CHUNK, ((c + 1) * CHUNK).min(n));
            let here = positions[start..end].iter().zip(&queries.head[start..end]);
            for (k, (&p, &h)) in here.enumerate() {
                let i = start + k;
                let ctx = Context {
                    pos: scene.pos,
                    head: scene.head,
                    obstacles,
                    cfg,
                    cone,
                };
                let q = Query { p, h, own: own(i) };
                view_of(q, &grid, &ctx, sc, &mut out);
            }
            out
        })
        .collect();
    assemble(&chunks, positions, cfg)
}

/// The padded lists of all agents from the views of their chunks.
fn assemble(chunks: &[ChunkViews], positions: &[P2], cfg: &PerceptionConfig) -> Perception {
    let n = positions.len();
    let widest = |f: fn(&ChunkViews) -> &Vec<u32>| {
        chunks
            .iter()
            .flat_map(|c| f(c).iter().copied())
            .max()
            .unwrap_or(0)
            .max(1) as usize
    };
    let (k, ko) = (widest(|c| &c.nb_len), widest(|c| &c.ob_len));
    let mut out = Perception {
        n,
        k,
        neighbours: vec![0; n * k],
        neighbour_mask: vec![0; n * k],
        neighbour_branch: vec![0; n * k],
        ko,
        obstacle_points: vec![[0.0; 2]; n * ko],
        obstacle_mask: vec![0; n * ko],
        obstacle_branch: vec![0; n * ko],
        front_count: Vec::with_capacity(n),
        density: Vec::with_capacity(n),
    };
    let area = std::f64::consts::PI * cfg.radius * cfg.radius;
    for c in chunks {
        out.front_count.extend_from_slice(&c.front);
        out.density
            .extend(c.in_range.iter().map(|&m| m as f64 / area));
    }
    // Padded rows, chunk by chunk in parallel: padding holds the agent's own index / position.
    out.neighbours
        .par_chunks_mut(CHUNK * k)
        .zip(out.neighbour_mask.par_chunks_mut(CHUNK * k))
        .zip(out.neighbour_branch.par_chunks_mut(CHUNK * k))
        .zip(chunks)
        .enumerate()
        .for_each(|(c, (((idx, mask), branch), v))| {
            let mut src = 0;
            for (a, &len) in v.nb_len.iter().enumerate() {
                let (row, len) = (a * k, len as usize);
                idx[row..row + k].fill((c * CHUNK + a) as u32);
                idx[row..row + len].copy_from_slice(&v.nb[src..src + len]);
                mask[row..row + len].fill(1);
                branch[row..row + len].copy_from_slice(&v.nb_branch[src..src + len]);
                src += len;
            }
        });
    out.obstacle_points
        .par_chunks_mut(CHUNK * ko)
        .zip(out.obstacle_mask.par_chunks_mut(CHUNK * ko))
        .zip(out.obstacle_branch.par_chunks_mut(CHUNK * ko))
        .zip(chunks)
        .enumerate()
        .for_each(|(c, (((pts, mask), branch), v))| {
            let mut src = 0;
            for (a, &len) in v.ob_len.iter().enumerate() {
                let (row, len) = (a * ko, len as usize);
                pts[row..row + ko].fill(positions[c * CHUNK + a]);
                pts[row..row + len].copy_from_slice(&v.ob[src..src + len]);
                mask[row..row + len].fill(1);
                branch[row..row + len].copy_from_slice(&v.ob_branch[src..src + len]);
                src += len;
            }
        });
    out
}

/// The front-cone test `bearing(h, u) ≤ cone` without atan2 away from the cone's edge: with
/// `(dot, |cross|)` of h and u, the bearing is within the cone iff
/// `|cross|·cos(cone) − dot·sin(cone) ≤ 0`; within a relative margin of the edge the exact
/// [`bearing`] decides, so the result is that of the atan2 form.
#[derive(Clone, Copy)]
struct FrontCone {
    cone: f64,
    cos: f64,
    sin: f64,
}

impl FrontCone {
    fn new(cone: f64) -> Self {
        FrontCone {
            cone,
            cos: cone.cos(),
            sin: cone.sin(),
        }
    }

    #[inline]
    fn contains(&self, h: P2, u: P2, d2: f64) -> bool {
        let dot = h[0] * u[0] + h[1] * u[1];
        let cross = (h[0] * u[1] - h[1] * u[0]).abs();
        let m = cross * self.cos - dot * self.sin;
        let margin = 1e-9 * d2.sqrt();
        if m < -margin {
            true
        } else if m > margin {
            false
        } else {
            bearing(h, u) <= self.cone
        }
    }
}

struct Context<'a> {
    pos: &'a [P2],
    head: &'a [P2],
    obstacles: Option<&'a ObstacleMap>,
    cfg: &'a PerceptionConfig,
    cone: FrontCone,
}

impl Context<'_> {
    /// Is the segment from agent `i` (at `p`) to `target` (offset `t`, squared length `d2`)
    /// touched by the capsule of a candidate closer than `d2`?
    ///
    /// Two division-free bounds decide most candidates; the rest go through
    /// [`Capsule::blocks`], and both bounds keep a relative margin, so every decision is exactly
    /// that test's. With `P = t × o` (the centre's distance from the line through the segment,
    /// times |t|) and `S = l·|t × h_k|` (how far the body's half-length l reaches across it):
    /// - reject if `|P| − S > r·|t|`: the body segment stays more than r from the line;
    /// - reject if the centre is more than l + r from the segment (the test's own first check);
    /// - accept if the centre is within r of the segment (it lies on the body segment).
    #[inline]
    fn blocked_by_closer(&self, p: P2, target: P2, t: P2, d2: f64, cand: &[Cand]) -> bool {
        let (l, r) = (self.cfg.capsule.half_length, self.cfg.capsule.radius);
        let reach2 = (l + r) * (l + r) * (1.0 + 1e-6) + 1e-12;
        let r2_in = r * r * (1.0 - 1e-6) - 1e-12;
        let band = r * d2.sqrt() * (1.0 + 1e-6) + 1e-12;
        cand.iter().take_while(|c| c.d2 < d2).any(|c| {
            let perp = (t[0] * c.o[1] - t[1] * c.o[0]).abs();
            let across = l * (t[0] * c.h[1] - t[1] * c.h[0]).abs();
            if perp - across > band {
                return false;
            }
            let along = c.o[0] * t[0] + c.o[1] * t[1];
            // Squared distance of the centre from the segment, times d2 (a closer candidate
            // projects inside the segment when `along` > 0).
            let dist2_d2 = if along <= 0.0 {
                c.d2 * d2
            } else {
                c.d2 * d2 - along * along
            };
            if dist2_d2 > reach2 * d2 {
                false
            } else if dist2_d2 < r2_in * d2 {
                true
            } else {
                self.cfg
                    .capsule
                    .blocks(p, target, self.pos[c.j as usize], c.h)
            }
        })
    }
}

/// The perceiving agent: position, heading and the scene index it stands for, if any.
struct Query {
    p: P2,
    h: P2,
    own: Option<u32>,
}

/// The sort key of candidate `j` at squared distance `d2`: `d2 > 0`, so its bit pattern orders
/// like the value, and one integer compare orders by distance, then index (deterministic).
#[inline]
fn key_of(d2: f64, j: u32) -> u128 {
    (d2.to_bits() as u128) << 32 | j as u128
}

/// Squared distance from `p` to `q`.
#[inline]
fn dist2(p: P2, q: P2) -> f64 {
    (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2)
}

/// Is `j` at squared distance `d2` perceived by a query whose own scene entry is `own`?
/// Coincident agents have no bearing: they are not perceived.
#[inline]
fn in_range(d2: f64, r2: f64, j: u32, own: Option<u32>) -> bool {
    d2 < r2 && d2 > 1e-18 && Some(j) != own
}

/// The view of one query: its in-range candidates from the grid, sorted, then [`view_sorted`].
fn view_of(
    me: Query,
    grid: &UniformGrid,
    ctx: &Context<'_>,
    sc: &mut Scratch,
    out: &mut ChunkViews,
) {
    let (pos, p) = (ctx.pos, me.p);
    let r2 = ctx.cfg.radius * ctx.cfg.radius;
    let keys = &mut sc.keys;
    keys.clear();
    grid.for_each_candidate(p, ctx.cfg.radius, |j| {
        let d2 = dist2(p, pos[j]);
        if in_range(d2, r2, j as u32, me.own) {
            keys.push(key_of(d2, j as u32));
        }
    });
    keys.sort_unstable();
    view_sorted(me, ctx, sc, out);
}

/// The view of one query from its in-range candidates, sorted by [`key_of`], in `sc.keys`:
/// occlusion, front cone, the kept neighbours and obstacle points.
fn view_sorted(me: Query, ctx: &Context<'_>, sc: &mut Scratch, out: &mut ChunkViews) {
    let (pos, cfg) = (ctx.pos, ctx.cfg);
    let (p, h) = (me.p, me.h);
    let keys = &sc.keys;
    sc.cand.clear();
    sc.cand.extend(keys.iter().map(|&key| {
        let (b, j) = ((key >> 32) as u64, key as u32);
        let q = pos[j as usize];
        Cand {
            d2: f64::from_bits(b),
            j,
            o: [q[0] - p[0], q[1] - p[1]],
            h: ctx.head[j as usize],
        }
    }));
    let (cand, pts) = (&sc.cand, &mut sc.pts);
    out.in_range.push(cand.len() as u32 + 1);
    let mut kept = 0u32;
    let mut front = 0u32;
    for c in cand {
        let q = pos[c.j as usize];
        let visible = !cfg.occlusion
            || (!ctx.blocked_by_closer(p, q, c.o, c.d2, cand)
                && !ctx.obstacles.is_some_and(|o| o.segment_blocked(p, q)));
        if !visible {
            continue;
        }
        if ctx.cone.contains(h, c.o, c.d2) {
            front += 1;
        }
        if (kept as usize) < cfg.max_neighbours {
            out.nb.push(c.j);
            out.nb_branch.push(branch_of(h, c.o));
            kept += 1;
        }
    }
    out.nb_len.push(kept);
    out.front.push(front);
    let mut kept_obs = 0u32;
    if let Some(map) = ctx.obstacles {
        pts.clear();
        map.blocked_in_range(p, cfg.radius, pts);
        pts.sort_unstable_by(|a, b| {
            a.0.total_cmp(&b.0)
                .then(a.1[0].total_cmp(&b.1[0]))
                .then(a.1[1].total_cmp(&b.1[1]))
        });
        for &(d2, q) in pts.iter() {
            if kept_obs as usize >= cfg.max_obstacles {
                break;
            }
            let t = [q[0] - p[0], q[1] - p[1]];
            let visible = !cfg.occlusion
                || (!map.segment_blocked(p, q) && !ctx.blocked_by_closer(p, q, t, d2, cand));
            if visible {
                out.ob.push(q);
                out.ob_branch.push(branch_of(h, t));
                kept_obs += 1;
            }
        }
    }
    out.ob_len.push(kept_obs);
}

#[cfg(test)]
pub(crate) mod tests;
