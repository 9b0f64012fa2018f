//! Neighbour candidates that last several steps (Verlet lists with a skin). Each agent keeps the
//! agents within `R_perc + s` of it at the last build; while no agent has moved more than `s / 2`
//! since then, every pair now within `R_perc` is on the kept lists (each end moved at most
//! `s / 2`), so perception filters the kept lists instead of searching the grid. The lists stay
//! sorted by the last step's distances, so this step's sort starts nearly sorted. The in-range
//! candidates, their order and everything decided from them (occlusion every step, front cone,
//! density) are exactly those of [`perceive`](super::perceive).

use super::{
    assemble, dist2, in_range, key_of, view_sorted, ChunkViews, Context, FrontCone, Perception,
    PerceptionConfig, Query, Scratch, CHUNK,
};
use crate::geometry::P2;
use crate::grid::UniformGrid;
use crate::obstacles::ObstacleMap;
use rayon::prelude::*;

/// The kept candidate lists of one chunk of agents: agent `a` of the chunk owns
/// `items[starts[a]..starts[a + 1]]`.
#[derive(Clone, Debug, Default)]
struct ChunkLists {
    starts: Vec<u32>,
    items: Vec<u32>,
}

/// Verlet neighbour lists kept between the steps of one run: [`NeighbourLists::perceive`] gives
/// the same [`Perception`] as [`perceive`](super::perceive), rebuilding the lists only when an agent has moved more
/// than half the skin since the last build (or the herd's size or the radius changed).
#[derive(Clone, Debug)]
pub struct NeighbourLists {
    skin: f64,
    /// The perception radius the lists were built for.
    radius: f64,
    /// Positions at the last build.
    anchor: Vec<P2>,
    chunks: Vec<ChunkLists>,
    builds: usize,
    steps: usize,
}

impl NeighbourLists {
    /// Empty lists with skin `s` (BL; 0 rebuilds every step). A negative or non-finite skin is
    /// taken as 0.
    pub fn new(skin: f64) -> Self {
        NeighbourLists {
            skin: if skin.is_finite() { skin.max(0.0) } else { 0.0 },
            radius: f64::NAN,
            anchor: Vec::new(),
            chunks: Vec::new(),
            builds: 0,
            steps: 0,
        }
    }

    /// The skin s (BL).
    pub fn skin(&self) -> f64 {
        self.skin
    }

    /// Lists built and steps perceived so far.
    pub fn builds_and_steps(&self) -> (usize, usize) {
        (self.builds, self.steps)
    }

    /// Must the lists be rebuilt before perceiving `positions` with radius `radius`? Yes when
    /// the herd's size or the radius changed, or some agent moved more than half the skin (less
    /// a margin over rounding; a non-finite position always rebuilds).
    fn stale(&self, positions: &[P2], radius: f64) -> bool {
        if positions.len() != self.anchor.len() || radius != self.radius {
            return true;
        }
        // A margin over the rounding of the distances (an unmoved herd always keeps its lists).
        let half = (0.5 * self.skin - 1e-9 * (radius + self.skin)).max(0.0);
        let limit = half * half;
        !positions
            .par_iter()
            .zip(&self.anchor)
            .with_min_len(4096)
            .all(|(&p, &a)| dist2(p, a) <= limit)
    }

    /// Candidates within `radius + skin` of each agent (itself left out), in index order.
    fn build(&mut self, positions: &[P2], radius: f64) {
        let n = positions.len();
        let reach = radius + self.skin;
        let reach2 = reach * reach;
        let grid = UniformGrid::build(positions, 0.5 * reach);
        self.chunks = (0..n.div_ceil(CHUNK))
            .into_par_iter()
            .map(|c| {
                let (start, end) = (c * CHUNK, ((c + 1) * CHUNK).min(n));
                let mut l = ChunkLists {
                    starts: Vec::with_capacity(end - start + 1),
                    items: Vec::new(),
                };
                l.starts.push(0);
                for (i, &p) in positions.iter().enumerate().take(end).skip(start) {
                    grid.for_each_candidate(p, reach, |j| {
                        if j != i && dist2(p, positions[j]) < reach2 {
                            l.items.push(j as u32);
                        }
                    });
                    l.starts.push(l.items.len() as u32);
                }
                l
            })
            .collect();
        self.anchor = positions.to_vec();
        self.radius = radius;
        self.builds += 1;
    }

    /// Perception of this step (what [`perceive`](super::perceive) returns for the same arguments).
    pub fn perceive(
        &mut self,
        positions: &[P2],
        headings: &[P2],
        obstacles: Option<&ObstacleMap>,
        cfg: &PerceptionConfig,
    ) -> Perception {
        let fresh = self.stale(positions, cfg.radius);
        if fresh {
            self.build(positions, cfg.radius);
        }
        self.steps += 1;
        let obstacles = obstacles.filter(|m| m.any());
        let ctx = Context {
            pos: positions,
            head: headings,
            obstacles,
            cfg,
            cone: FrontCone::new(cfg.front_cone),
        };
        let r2 = cfg.radius * cfg.radius;
        let views: Vec<ChunkViews> = self
            .chunks
            .par_iter_mut()
            .enumerate()
            .map_init(Scratch::default, |sc, (c, lists)| {
                let mut out = ChunkViews::default();
                for a in 0..lists.starts.len() - 1 {
                    let i = c * CHUNK + a;
                    let (s, e) = (lists.starts[a] as usize, lists.starts[a + 1] as usize);
                    let kept = &mut lists.items[s..e];
                    sort_by_distance(positions[i], positions, kept, fresh, sc);
                    sc.keys.retain(|&k| {
                        in_range(
                            f64::from_bits((k >> 32) as u64),
                            r2,
                            k as u32,
                            Some(i as u32),
                        )
                    });
                    let q = Query {
                        p: positions[i],
                        h: headings[i],
                        own: Some(i as u32),
                    };
                    view_sorted(q, &ctx, sc, &mut out);
                }
                out
            })
            .collect();
        assemble(&views, positions, cfg)
    }
}

/// Sorts the kept candidates of the agent at `p` by this step's distance (ties by index) and
/// leaves their keys in `sc.keys`. The list is in the last step's order, so insertion sort does
/// little work (a fresh list, in grid order, is sorted in full); the keys are distinct, so the
/// order is the one any sort gives.
fn sort_by_distance(p: P2, positions: &[P2], kept: &mut [u32], fresh: bool, sc: &mut Scratch) {
    let keys = &mut sc.keys;
    keys.clear();
    keys.extend(
        kept.iter()
            .map(|&j| key_of(dist2(p, positions[j as usize]), j)),
    );
    if fresh {
        // Just built, in grid order: a full sort.
        keys.sort_unstable();
    }
    for a in 1..keys.len() {
        let k = keys[a];
        let mut b = a;
        while b > 0 && keys[b - 1] > k {
            keys[b] = keys[b - 1];
            b -= 1;
        }
        keys[b] = k;
    }
    for (slot, &k) in kept.iter_mut().zip(keys.iter()) {
        *slot = k as u32;
    }
}
