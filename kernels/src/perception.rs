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

struct AgentView {
    neighbours: Vec<u32>,
    obstacles: Vec<P2>,
    front: u32,
    in_range: u32,
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
    let grid = UniformGrid::build(positions, cfg.radius);
    let obstacles = obstacles.filter(|m| m.any());
    let views: Vec<AgentView> = (0..n)
        .into_par_iter()
        .with_min_len(64)
        .map(|i| view_of(i, positions, headings, &grid, obstacles, cfg))
        .collect();
    let k = views
        .iter()
        .map(|v| v.neighbours.len())
        .max()
        .unwrap_or(0)
        .max(1);
    let ko = views
        .iter()
        .map(|v| v.obstacles.len())
        .max()
        .unwrap_or(0)
        .max(1);
    let mut out = Perception {
        n,
        k,
        neighbours: Vec::with_capacity(n * k),
        neighbour_mask: Vec::with_capacity(n * k),
        neighbour_branch: Vec::with_capacity(n * k),
        ko,
        obstacle_points: Vec::with_capacity(n * ko),
        obstacle_mask: Vec::with_capacity(n * ko),
        obstacle_branch: Vec::with_capacity(n * ko),
        front_count: Vec::with_capacity(n),
        density: Vec::with_capacity(n),
    };
    let area = std::f64::consts::PI * cfg.radius * cfg.radius;
    for (i, v) in views.into_iter().enumerate() {
        for s in 0..k {
            match v.neighbours.get(s) {
                Some(&j) => {
                    out.neighbours.push(j);
                    out.neighbour_mask.push(1);
                    let (p, q) = (positions[i], positions[j as usize]);
                    out.neighbour_branch
                        .push(branch_of(headings[i], [q[0] - p[0], q[1] - p[1]]));
                }
                None => {
                    out.neighbours.push(i as u32);
                    out.neighbour_mask.push(0);
                    out.neighbour_branch.push(0);
                }
            }
        }
        for s in 0..ko {
            match v.obstacles.get(s) {
                Some(&q) => {
                    out.obstacle_points.push(q);
                    out.obstacle_mask.push(1);
                    let p = positions[i];
                    out.obstacle_branch
                        .push(branch_of(headings[i], [q[0] - p[0], q[1] - p[1]]));
                }
                None => {
                    out.obstacle_points.push(positions[i]);
                    out.obstacle_mask.push(0);
                    out.obstacle_branch.push(0);
                }
            }
        }
        out.front_count.push(v.front);
        out.density.push(v.in_range as f64 / area);
    }
    out
}

fn view_of(
    i: usize,
    pos: &[P2],
    head: &[P2],
    grid: &UniformGrid,
    obstacles: Option<&ObstacleMap>,
    cfg: &PerceptionConfig,
) -> AgentView {
    let p = pos[i];
    let r2 = cfg.radius * cfg.radius;
    // In-range candidates sorted by distance (ties by index: deterministic).
    let mut cand: Vec<(f64, u32)> = Vec::with_capacity(32);
    grid.for_each_candidate(p, cfg.radius, |j| {
        if j != i {
            let d2 = (pos[j][0] - p[0]).powi(2) + (pos[j][1] - p[1]).powi(2);
            // Coincident agents have no bearing: they are not perceived.
            if d2 < r2 && d2 > 1e-18 {
                cand.push((d2, j as u32));
            }
        }
    });
    cand.sort_unstable_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let in_range = cand.len() as u32 + 1;
    let blocked_by_closer = |target: P2, d2: f64| -> bool {
        cand.iter().take_while(|c| c.0 < d2).any(|&(_, k)| {
            cfg.capsule
                .blocks(p, target, pos[k as usize], head[k as usize])
        })
    };
    let mut neighbours = Vec::with_capacity(cand.len().min(cfg.max_neighbours));
    let mut front = 0u32;
    for &(d2, j) in &cand {
        let q = pos[j as usize];
        let visible = !cfg.occlusion
            || (!blocked_by_closer(q, d2) && !obstacles.is_some_and(|o| o.segment_blocked(p, q)));
        if !visible {
            continue;
        }
        if bearing(head[i], [q[0] - p[0], q[1] - p[1]]) <= cfg.front_cone {
            front += 1;
        }
        if neighbours.len() < cfg.max_neighbours {
            neighbours.push(j);
        }
    }
    let mut obs = Vec::new();
    if let Some(map) = obstacles {
        let mut pts = Vec::new();
        map.blocked_in_range(p, cfg.radius, &mut pts);
        pts.sort_unstable_by(|a, b| {
            a.0.total_cmp(&b.0)
                .then(a.1[0].total_cmp(&b.1[0]))
                .then(a.1[1].total_cmp(&b.1[1]))
        });
        for (d2, q) in pts {
            if obs.len() >= cfg.max_obstacles {
                break;
            }
            let visible =
                !cfg.occlusion || (!map.segment_blocked(p, q) && !blocked_by_closer(q, d2));
            if visible {
                obs.push(q);
            }
        }
    }
    AgentView {
        neighbours,
        obstacles: obs,
        front,
        in_range,
    }
}

#[cfg(test)]
mod tests {
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

    fn scene(seed: u64, n: usize) -> (Vec<P2>, Vec<P2>, ObstacleMap) {
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
