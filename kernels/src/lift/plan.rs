//! How the whole-sequence energy's lists are cut into cache-sized tiles and parallel chunks
//! ([`SeqPlan`]).

use super::SeqStructure;

/// Observations per tile at least (tiles end at a clean cut: see [`SeqPlan`]).
const TILE: usize = 512;
/// Observations per chunk at least (chunks are runs of whole tiles, fixed by the problem, so
/// results do not depend on the thread count).
const CHUNK: usize = 8192;

/// How one problem's lists are cut for evaluation, built once ([`SeqPlan::new`]) and reused by
/// every evaluation.
///
/// The observations are cut into **tiles**, consecutive ranges ending where no same-frame pair
/// (of observations, or of velocities by their later observation) crosses — with frame-major
/// observations, at frame boundaries. Every entry belongs to the tile of its later index
/// (velocity: its observation at f; acceleration: its later velocity; pair: both). The plan
/// requires that a velocity reaches back at most one tile for its earlier observation, and an
/// acceleration at most one tile for its earlier velocity. Then one sweep over the tiles does
/// every pass of a tile while its data is in cache: tile t's forward passes, the velocity
/// backward of tile t − 1 (whose ∂E/∂v is complete once tile t's accelerations are in) and the
/// pairs and ∂E/∂u of tile t − 2 — instead of one pass over the whole problem per term, which
/// streams it from memory a dozen times (BENCHMARKS.md, "Lift").
///
/// Tiles are grouped into **chunks** of at least 8192 observations and two tiles, swept in
/// parallel. A chunk's first tile reaches into the previous chunk's last one: it recomputes the
/// positions and velocities it reads there from the log-depths, and its gradient contributions
/// there are handed over in order and added by their owner after the sweep. Each entry's
/// contributions are thus added in list order, as one sequential pass would, and the energy's
/// partial sums are summed in chunk order: the same bytes for any thread count, and for a single
/// chunk the same bytes as a plain sequential pass over each list.
///
/// Lists that break the requirements (out of order, or reaching further) get one tile: a
/// sequential evaluation, with the same result.
#[derive(Clone, Debug, Default)]
pub struct SeqPlan {
    pub(super) n: usize,
    pub(super) nv: usize,
    /// Tile starts (and the end, last) in observations, velocities, and the entries of the
    /// acceleration, pair and alignment lists.
    pub(super) obs: Vec<usize>,
    pub(super) vel: Vec<usize>,
    pub(super) acc: Vec<usize>,
    pub(super) pairs: Vec<usize>,
    pub(super) align: Vec<usize>,
    /// Chunk starts in tiles, and the tile count last.
    pub(super) chunks: Vec<usize>,
}

/// Which index of an entry decides its tile, and how far back the other may lie.
#[derive(Clone, Copy)]
enum Rule {
    /// The second (the later velocity or observation); the first in that tile or the one before.
    Later,
    /// The first; the second in the same tile.
    Same,
}

/// Tile starts of a list of index pairs, the tile of index i being `tile(i)`, if every entry
/// follows `rule` and the entries' tiles never decrease.
fn starts_of(
    list: &[(usize, usize)],
    tiles: usize,
    tile: impl Fn(usize) -> Option<usize>,
    rule: Rule,
) -> Option<Vec<usize>> {
    let mut starts = Vec::with_capacity(tiles + 1);
    let mut last = 0;
    for (i, &(a, b)) in list.iter().enumerate() {
        let (t, o) = match rule {
            Rule::Later => (tile(b)?, tile(a)?),
            Rule::Same => (tile(a)?, tile(b)?),
        };
        let ok = match rule {
            Rule::Later => o <= t && o + 1 >= t,
            Rule::Same => o == t,
        };
        if t < last || !ok {
            return None;
        }
        while starts.len() <= t {
            starts.push(i);
        }
        last = t;
    }
    while starts.len() <= tiles {
        starts.push(list.len());
    }
    Some(starts)
}

impl SeqPlan {
    /// The plan of `st` (lists as herdfit builds them: frame-major observations, each list sorted
    /// by its entries' tiles).
    pub fn new(st: &SeqStructure) -> SeqPlan {
        SeqPlan::with_sizes(st, TILE, CHUNK)
    }

    /// The plan with tiles of at least `tile` and chunks of at least `chunk` observations (tests
    /// cut small problems into many of both).
    pub fn with_sizes(st: &SeqStructure, tile: usize, chunk: usize) -> SeqPlan {
        let (n, nv) = (st.ray.len(), st.vel.len());
        SeqPlan::tiled(st, tile.max(1), chunk.max(1)).unwrap_or_else(|| SeqPlan {
            n,
            nv,
            obs: vec![0, n],
            vel: vec![0, nv],
            acc: vec![0, st.acc.len()],
            pairs: vec![0, st.pairs.len()],
            align: vec![0, st.align.len()],
            chunks: vec![0, 1],
        })
    }

    fn tiled(st: &SeqStructure, tile: usize, chunk: usize) -> Option<SeqPlan> {
        let (n, nv) = (st.ray.len(), st.vel.len());
        // A cut at o (between o − 1 and o) is clean when no pair has lo < o ≤ hi.
        let mut cover = vec![0i64; n + 2];
        let mut span = |a: usize, b: usize| {
            let (lo, hi) = (a.min(b), a.max(b).min(n));
            if lo < hi {
                cover[lo + 1] += 1;
                cover[hi + 1] -= 1;
            }
        };
        for &(i, j) in st.pairs {
            span(i, j);
        }
        for &(a, b) in st.align {
            span(st.vel.get(a)?.1, st.vel.get(b)?.1);
        }
        let mut obs = vec![0];
        let mut open = 0i64;
        for (o, c) in cover.iter().enumerate().take(n).skip(1) {
            open += c;
            if open == 0 && o - obs[obs.len() - 1] >= tile {
                obs.push(o);
            }
        }
        obs.push(n);
        let tiles = obs.len() - 1;
        let mut tile_of = vec![0; n];
        for t in 0..tiles {
            tile_of[obs[t]..obs[t + 1]].fill(t);
        }
        let of = |i: usize| tile_of.get(i).copied();
        let vel = starts_of(st.vel, tiles, of, Rule::Later)?;
        let mut vtile = vec![0; nv];
        for t in 0..tiles {
            vtile[vel[t]..vel[t + 1]].fill(t);
        }
        let vof = |k: usize| vtile.get(k).copied();
        let acc = starts_of(st.acc, tiles, vof, Rule::Later)?;
        let pairs = starts_of(st.pairs, tiles, of, Rule::Same)?;
        let align = starts_of(st.align, tiles, vof, Rule::Same)?;
        // Chunks of ≥ `chunk` observations and ≥ 2 tiles (a chunk's first tile must finish its
        // velocity backward within the chunk's own sweep: its hand-over is read by the previous
        // chunk).
        let mut chunks = vec![0];
        for t in 1..tiles {
            let c0 = chunks[chunks.len() - 1];
            if obs[t] - obs[c0] >= chunk && t - c0 >= 2 {
                chunks.push(t);
            }
        }
        if chunks.len() > 1 && tiles - chunks[chunks.len() - 1] < 2 {
            chunks.pop();
        }
        chunks.push(tiles);
        Some(SeqPlan {
            n,
            nv,
            obs,
            vel,
            acc,
            pairs,
            align,
            chunks,
        })
    }

    /// Tiles and chunks of the plan.
    pub fn cuts(&self) -> [usize; 2] {
        [self.obs.len() - 1, self.chunks.len() - 1]
    }
}
