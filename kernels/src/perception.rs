//! Perception of one simulation step (DESIGN §4.1–4.2): who sees whom, which obstacle points are
//! seen, how many visible neighbours lie in the front cone, and the local density. No gradients:
//! the output is plain data that the differentiable model consumes (and that can be recorded and
//! replayed).

use crate::geometry::{bearing, Capsule, P2};
use crate::grid::UniformGrid;
use crate::obstacles::ObstacleMap;
use rayon::prelude::*;

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
    let n = positions.len();
    let grid = UniformGrid::build(positions, 0.5 * cfg.radius);
    let obstacles = obstacles.filter(|m| m.any());
    let cone = FrontCone::new(cfg.front_cone);
    let chunks: Vec<ChunkViews> = (0..n.div_ceil(CHUNK))
        .into_par_iter()
        .map_init(Scratch::default, |sc, c| {
            let mut out = ChunkViews::default();
            for i in c * CHUNK..((c + 1) * CHUNK).min(n) {
                let ctx = Context {
                    pos: positions,
                    head: headings,
                    grid: &grid,
                    obstacles,
                    cfg,
                    cone,
                };
                view_of(i, &ctx, sc, &mut out);
            }
            out
        })
        .collect();
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
    for c in &chunks {
        out.front_count.extend_from_slice(&c.front);
        out.density
            .extend(c.in_range.iter().map(|&m| m as f64 / area));
    }
    // Padded rows, chunk by chunk in parallel: padding holds the agent's own index / position.
    out.neighbours
        .par_chunks_mut(CHUNK * k)
        .zip(out.neighbour_mask.par_chunks_mut(CHUNK * k))
        .zip(out.neighbour_branch.par_chunks_mut(CHUNK * k))
        .zip(&chunks)
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
        .zip(&chunks)
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
    grid: &'a UniformGrid,
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

fn view_of(i: usize, ctx: &Context<'_>, sc: &mut Scratch, out: &mut ChunkViews) {
    let (pos, cfg) = (ctx.pos, ctx.cfg);
    let p = pos[i];
    let h = ctx.head[i];
    let r2 = cfg.radius * cfg.radius;
    // In-range candidates sorted by distance (ties by index: deterministic). d2 > 0, so its
    // bit pattern orders like the value.
    let keys = &mut sc.keys;
    keys.clear();
    ctx.grid.for_each_candidate(p, cfg.radius, |j| {
        let d2 = (pos[j][0] - p[0]).powi(2) + (pos[j][1] - p[1]).powi(2);
        // Coincident agents have no bearing: they are not perceived.
        if d2 < r2 && d2 > 1e-18 && j != i {
            keys.push((d2.to_bits() as u128) << 32 | j as u128);
        }
    });
    keys.sort_unstable();
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
pub(crate) mod tests {
    use super::*;
    use rand::{Rng, SeedableRng};

    fn cfg(occlusion: bool) -> PerceptionConfig {
        PerceptionConfig {
            radius: 4.0,
            capsule: Capsule {
                half_length: 0.3,
                radius: 0.2,
            },
            occlusion,
            max_neighbours: usize::MAX,
            max_obstacles: usize::MAX,
            front_cone: 60f64.to_radians(),
        }
    }

    /// A random herd at one agent per 2 BL², random headings, and 12 blocked cells of a 14 × 14
    /// obstacle map (also the force kernel's test scene).
    pub(crate) fn scene(seed: u64, n: usize) -> (Vec<P2>, Vec<P2>, ObstacleMap) {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
        let side = (2.0 * n as f64).sqrt();
        let pos: Vec<P2> = (0..n)
            .map(|_| [rng.gen_range(0.0..side), rng.gen_range(0.0..side)])
            .collect();
        let head: Vec<P2> = (0..n)
            .map(|_| {
                let a: f64 = rng.gen_range(-3.2..3.2);
                [a.cos(), a.sin()]
            })
            .collect();
        let mut map = ObstacleMap::empty([0.0, 0.0], 1.5, 14, 14);
        for _ in 0..12 {
            let c = rng.gen_range(0..map.blocked.len());
            map.blocked[c] = true;
        }
        (pos, head, map)
    }

    /// The definition, pair by pair, with no grid and no sorting.
    fn brute(pos: &[P2], head: &[P2], map: &ObstacleMap, c: &PerceptionConfig) -> Vec<Vec<u32>> {
        let d2 = |a: P2, b: P2| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
        (0..pos.len())
            .map(|i| {
                let mut v: Vec<(f64, u32)> = vec![];
                for j in 0..pos.len() {
                    let dij = d2(pos[i], pos[j]);
                    if j == i || dij >= c.radius * c.radius {
                        continue;
                    }
                    let hidden = c.occlusion
                        && ((0..pos.len()).any(|k| {
                            k != i
                                && k != j
                                && d2(pos[i], pos[k]) < dij
                                && c.capsule.blocks(pos[i], pos[j], pos[k], head[k])
                        }) || map.segment_blocked(pos[i], pos[j]));
                    if !hidden {
                        v.push((dij, j as u32));
                    }
                }
                v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
                v.into_iter().map(|x| x.1).collect()
            })
            .collect()
    }

    fn lists(p: &Perception) -> Vec<Vec<u32>> {
        (0..p.n)
            .map(|i| {
                (0..p.k)
                    .filter(|&s| p.neighbour_mask[i * p.k + s] == 1)
                    .map(|s| p.neighbours[i * p.k + s])
                    .collect()
            })
            .collect()
    }

    #[test]
    fn neighbour_lists_match_brute_force_on_random_scenes() {
        for seed in 0..4 {
            for occ in [false, true] {
                let (pos, head, map) = scene(seed, 300);
                let c = cfg(occ);
                let got = perceive(&pos, &head, Some(&map), &c);
                assert_eq!(
                    lists(&got),
                    brute(&pos, &head, &map, &c),
                    "seed {seed} occ {occ}"
                );
                assert_eq!(got.neighbours.len(), got.n * got.k);
            }
        }
    }

    /// Branch codes, front-cone counts (atan2 bearing) and densities by their definitions, on the
    /// brute-force lists.
    #[test]
    fn branches_front_counts_and_density_match_definitions() {
        for seed in 20..23 {
            let (pos, head, map) = scene(seed, 300);
            let c = cfg(true);
            let got = perceive(&pos, &head, Some(&map), &c);
            let want = brute(&pos, &head, &map, &c);
            for (i, w) in want.iter().enumerate() {
                let off = |j: u32| {
                    [
                        pos[j as usize][0] - pos[i][0],
                        pos[j as usize][1] - pos[i][1],
                    ]
                };
                let front = w
                    .iter()
                    .filter(|&&j| bearing(head[i], off(j)) <= c.front_cone)
                    .count();
                assert_eq!(got.front_count[i] as usize, front, "agent {i}");
                for (s, &j) in w.iter().enumerate() {
                    assert_eq!(
                        got.neighbour_branch[i * got.k + s],
                        branch_of(head[i], off(j))
                    );
                }
                let in_range = (0..pos.len())
                    .filter(|&j| {
                        let d2 = (pos[j][0] - pos[i][0]).powi(2) + (pos[j][1] - pos[i][1]).powi(2);
                        d2 < 16.0 && (j == i || d2 > 1e-18)
                    })
                    .count();
                let area = std::f64::consts::PI * 16.0;
                assert_eq!(got.density[i], in_range as f64 / area);
            }
        }
    }

    #[test]
    fn occlusion_hides_some_but_not_all() {
        let (pos, head, map) = scene(11, 400);
        let open = perceive(&pos, &head, Some(&map), &cfg(false));
        let occl = perceive(&pos, &head, Some(&map), &cfg(true));
        let count = |p: &Perception| p.neighbour_mask.iter().map(|&m| m as usize).sum::<usize>();
        assert!(count(&occl) < count(&open));
        assert!(count(&occl) * 3 > count(&open));
    }

    #[test]
    fn obstacle_points_match_brute_force() {
        let (pos, head, map) = scene(5, 200);
        let c = cfg(true);
        let got = perceive(&pos, &head, Some(&map), &c);
        for i in 0..pos.len() {
            let p = pos[i];
            let mut want = vec![];
            for iy in 0..map.ny {
                for ix in 0..map.nx {
                    if !map.blocked[iy * map.nx + ix] {
                        continue;
                    }
                    let q = map.centre(ix, iy);
                    let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                    if d2 >= 16.0 || d2 == 0.0 || map.segment_blocked(p, q) {
                        continue;
                    }
                    let hidden = (0..pos.len()).any(|k| {
                        let dk = (pos[k][0] - p[0]).powi(2) + (pos[k][1] - p[1]).powi(2);
                        k != i && dk < d2 && c.capsule.blocks(p, q, pos[k], head[k])
                    });
                    if !hidden {
                        want.push(q);
                    }
                }
            }
            let mut have: Vec<P2> = (0..got.ko)
                .filter(|&s| got.obstacle_mask[i * got.ko + s] == 1)
                .map(|s| got.obstacle_points[i * got.ko + s])
                .collect();
            let key = |a: &P2, b: &P2| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1]));
            want.sort_by(key);
            have.sort_by(key);
            assert_eq!(have, want, "agent {i}");
        }
    }

    #[test]
    fn front_cone_counts_and_truncation() {
        // Agent 0 at the origin heading +x; agents ahead at 0°, 45°, 90° and behind.
        let pos = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.5], [-2.0, 0.0]];
        let head = vec![[1.0, 0.0]; 5];
        let mut c = cfg(false);
        let p = perceive(&pos, &head, None, &c);
        assert_eq!(p.front_count[0], 2);
        assert_eq!(&p.neighbours[..4], &[1, 2, 3, 4]);
        c.max_neighbours = 2;
        let p = perceive(&pos, &head, None, &c);
        assert_eq!(p.k, 2);
        assert_eq!(&p.neighbours[..2], &[1, 2]);
        // Truncation keeps the cone count of all visible neighbours.
        assert_eq!(p.front_count[0], 2);
    }

    #[test]
    fn thread_count_does_not_change_the_output() {
        let (pos, head, map) = scene(9, 500);
        let c = cfg(true);
        let one = rayon::ThreadPoolBuilder::new()
            .num_threads(1)
            .build()
            .unwrap()
            .install(|| perceive(&pos, &head, Some(&map), &c));
        let two = rayon::ThreadPoolBuilder::new()
            .num_threads(2)
            .build()
            .unwrap()
            .install(|| perceive(&pos, &head, Some(&map), &c));
        assert_eq!(one, two);
    }
}
