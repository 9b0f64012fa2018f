//! k nearest samples in the PCA state space (§5.1; the paper keeps its samples in kd-trees, §8),
//! an exact brute-force search to check against, and `kiddo`'s immutable kd-tree as the peer the
//! benchmark compares with.
//!
//! [`StateTree`] is a bucketed kd-tree that splits each node on its widest dimension, at the
//! multiple of 16 points nearest the median (so that every leaf is one 16-point block). The PCA
//! states have most of their variance in the leading components, so splitting the widest
//! dimension prunes far more than the round-robin splits of kiddo's trees (which, at ~9 levels
//! over 10–12 dimensions, split each dimension about once); the query keeps its candidates as
//! integer keys in per-thread buffers, cut by selection, and allocates nothing once those
//! buffers have grown. The dimension is a const generic; [`StateTree`] picks one of 1–12 at run
//! time (the paper's PCA keeps 8–12). Ties in distance are ordered by row, so the result equals
//! [`brute_force`]'s exactly.
//!
//! The search works in f32 and proves its way back to f64. A leaf's points are also stored as
//! f32, column by column, and their distances computed in SIMD lanes (AVX2 where the CPU has it,
//! through `pulp`'s run-time dispatch). Candidates are kept by their f32 distance, and a subtree
//! is skipped when its bounding box lies beyond what the k-th f32 distance so far proves about
//! the k-th f64 distance. At the end, only the points whose f32 distance lies within the
//! roundings' allowance of the k-th get their exact f64 distance (typically k and a few), so
//! the neighbours and distances are the f64 search's, bit for bit.

use crate::error::{Error, Result};
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use std::cmp::Ordering;
use std::num::NonZeroUsize;

/// Largest PCA dimension a tree supports.
pub const MAX_DIMS: usize = 12;

/// Most points in a leaf; leaves start at multiples of it, so that each leaf is one block of
/// [`Tree::cols`].
const LEAF: usize = 16;
const _: () = assert!(LEAF <= 32, "a leaf's candidates are bits of a u32");

/// Relative rounding allowance of a leaf's f32 distances (sums of ≤ 12 squares in f32, each
/// coordinate rounded once to f32: far below 1e-5 relative).
const F32_SLACK: f64 = 1e-5;

/// A node: inner (`dim` < D, children `a`, `b` holding coordinates ≤ / ≥ `split`) or leaf
/// (`dim` = u32::MAX, points `a..b`).
#[derive(Clone, Copy, Debug)]
struct Node {
    dim: u32,
    split: f64,
    a: u32,
    b: u32,
}

/// A kd-tree over points of dimension `D` (split on the widest dimension, median split).
pub struct Tree<const D: usize> {
    /// Points in tree order.
    pts: Vec<[f64; D]>,
    /// The same points as f32, leaf by leaf column by column: coordinate `d` of position `p` at
    /// `(p / LEAF) * LEAF * D + d * LEAF + p % LEAF` (the last leaf padded with zeros). A leaf's
    /// distances are first computed from them in SIMD lanes; only the points that may lie
    /// within the bound get their exact f64 distance.
    cols: Vec<f32>,
    /// Largest point norm, for the f32 filter's allowance.
    max_norm: f64,
    /// The instruction set the f32 distances are compiled for (chosen at run time).
    arch: pulp::Arch,
    /// Row of each point in the input.
    rows: Vec<u32>,
    nodes: Vec<Node>,
    /// Each node's bounding box (its points' lowest and highest coordinates, rounded outward
    /// to f32), indexed like `nodes`: the search's lower bound on a subtree's distances.
    boxes: Vec<([f32; D], [f32; D])>,
}

/// (squared distance, row) ordered by distance, then row.
fn cmp_rows(a: &(f64, u32), b: &(f64, u32)) -> Ordering {
    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
}

impl<const D: usize> Tree<D> {
    /// A tree over `pts`; items are indices into `pts`.
    pub fn new(pts: &[[f64; D]]) -> Tree<D> {
        let mut perm: Vec<u32> = (0..pts.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * pts.len() / LEAF + 1);
        let mut boxes = Vec::with_capacity(2 * pts.len() / LEAF + 1);
        if !pts.is_empty() {
            Self::build(pts, &mut perm, 0, &mut nodes, &mut boxes);
        }
        let mut cols = vec![0.0f32; pts.len().div_ceil(LEAF) * LEAF * D];
        for (pos, &i) in perm.iter().enumerate() {
            for (d, &v) in pts[i as usize].iter().enumerate() {
                cols[(pos / LEAF) * LEAF * D + d * LEAF + pos % LEAF] = v as f32;
            }
        }
        let max_norm = pts
            .iter()
            .map(|p| p.iter().map(|v| v * v).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        Tree {
            pts: perm.iter().map(|&i| pts[i as usize]).collect(),
            rows: perm,
            nodes,
            boxes,
            cols,
            max_norm,
            arch: pulp::Arch::new(),
        }
    }

    /// Builds the subtree of `perm` (which starts at tree position `at`); returns its node.
    fn build(
        pts: &[[f64; D]],
        perm: &mut [u32],
        at: usize,
        nodes: &mut Vec<Node>,
        boxes: &mut Vec<([f32; D], [f32; D])>,
    ) -> u32 {
        let me = nodes.len();
        nodes.push(Node {
            dim: u32::MAX,
            split: 0.0,
            a: at as u32,
            b: (at + perm.len()) as u32,
        });
        let (mut lo, mut hi) = ([f64::INFINITY; D], [f64::NEG_INFINITY; D]);
        for &i in perm.iter() {
            for ((l, h), v) in lo.iter_mut().zip(hi.iter_mut()).zip(&pts[i as usize]) {
                *l = l.min(*v);
                *h = h.max(*v);
            }
        }
        boxes.push((lo.map(|v| -up32(-v)), hi.map(up32)));
        if perm.len() <= LEAF {
            return me as u32;
        }
        let mut dim = 0;
        for j in 1..D {
            if hi[j] - lo[j] > hi[dim] - lo[dim] {
                dim = j;
            }
        }
        // The left part a whole number of leaves (at least one, short of all the points), so
        // that every leaf starts at a multiple of LEAF. Points that all coincide still split:
        // the search then visits both sides.
        let mid = (perm.len().div_ceil(LEAF) / 2).max(1) * LEAF;
        perm.select_nth_unstable_by(mid, |&x, &y| {
            pts[x as usize][dim]
                .total_cmp(&pts[y as usize][dim])
                .then(x.cmp(&y))
        });
        let split = pts[perm[mid] as usize][dim];
        let (l, r) = perm.split_at_mut(mid);
        let a = Self::build(pts, l, at, nodes, boxes);
        let b = Self::build(pts, r, at + mid, nodes, boxes);
        nodes[me] = Node {
            dim: dim as u32,
            split,
            a,
            b,
        };
        me as u32
    }

    /// The `k` nearest points to `q` as (squared distance, index), nearest first, ties by index.
    pub fn nearest(&self, q: &[f64; D], k: usize, out: &mut Vec<(f64, u32)>) {
        self.nearest_pos(q, k, out);
        out.iter_mut().for_each(|h| h.1 = self.rows[h.1 as usize]);
    }

    /// As [`Tree::nearest`] with each point given by its position in tree order (see
    /// [`Tree::points`]); the order is still by distance, then index.
    ///
    /// The search keeps its candidates by their f32 distances; the points that may be among
    /// the `k` nearest in f64 (their f32 distance within the roundings' allowance of the k-th
    /// f32 distance) then get their exact distance, so the result is [`brute_force`]'s.
    pub fn nearest_pos(&self, q: &[f64; D], k: usize, out: &mut Vec<(f64, u32)>) {
        out.clear();
        if k == 0 || self.nodes.is_empty() {
            return;
        }
        let k = k.min(self.pts.len());
        let qn = q.iter().map(|v| v * v).sum::<f64>().sqrt();
        let q32 = q.map(|v| v as f32);
        // |‖x̃ − q̃‖ − ‖x − q‖| ≤ 2⁻²⁴ (‖x‖ + ‖q‖) for the f32 roundings x̃, q̃. Norms from 10¹⁸
        // up may overflow f32's squares or its range (NaN distances): every point is then a
        // candidate.
        let huge = (self.max_norm + qn).partial_cmp(&1e18) != Some(Ordering::Less);
        let delta = 1.2e-7 * (self.max_norm + qn);
        CANDIDATES.with_borrow_mut(|cands| {
            cands.clear();
            let mut best = Best {
                k,
                huge,
                delta,
                prune: f64::INFINITY,
                reach: f32::INFINITY,
                cut_at: if huge { usize::MAX } else { 2 * k },
                buf: cands,
            };
            let query = Query { q, q32: &q32 };
            self.search(0, &query, &mut [0.0; D], 0.0, &mut best);
            best.cut();
            let reach = best.reach;
            KEYS.with_borrow_mut(|keys| {
                keys.clear();
                for &c in best.buf.iter() {
                    let (d32, pos) = (f32::from_bits((c >> 32) as u32), c as u32);
                    if huge || d32 <= reach {
                        let mut d = 0.0;
                        for (x, y) in self.pts[pos as usize].iter().zip(q) {
                            d += (x - y) * (x - y);
                        }
                        keys.push(key(d, self.rows[pos as usize], pos));
                    }
                }
                if keys.len() > k {
                    keys.select_nth_unstable(k - 1);
                    keys.truncate(k);
                }
                keys.sort_unstable();
                out.extend(keys.iter().map(|&key| unkey(key)));
            });
        });
    }

    /// The points in tree order, row-major.
    pub fn points(&self) -> &[f64] {
        self.pts.as_flattened()
    }

    /// The input index of each point in tree order.
    pub fn order(&self) -> &[u32] {
        &self.rows
    }

    fn search(&self, node: u32, qq: &Query<D>, off: &mut [f64; D], rd: f64, best: &mut Best) {
        let q = qq.q;
        let n = self.nodes[node as usize];
        if n.dim == u32::MAX {
            let (a, b) = (n.a as usize, n.b as usize);
            let block = &self.cols[a * D..(a + LEAF) * D];
            let d32 = self.arch.dispatch(|| block_distances::<D>(block, qq.q32));
            let reach = best.reach;
            let mut inside = if best.huge {
                u32::MAX
            } else {
                d32.iter()
                    .enumerate()
                    .fold(0u32, |m, (j, &d)| m | (u32::from(d <= reach) << j))
            } & (u32::MAX >> (32 - (b - a)));
            while inside != 0 {
                let j = inside.trailing_zeros() as usize;
                inside &= inside - 1;
                best.offer(d32[j], (a + j) as u32);
            }
            return;
        }
        let dim = n.dim as usize;
        let diff = q[dim] - n.split;
        let (near, far) = if diff < 0.0 { (n.a, n.b) } else { (n.b, n.a) };
        self.search(near, qq, off, rd, best);
        // The far side: first the cheap bound (the distance to its half-space, built up
        // dimension by dimension), then its box's.
        let old = off[dim];
        let far_rd = rd - old * old + diff * diff;
        if far_rd <= best.prune && self.box_dist(far, q) <= best.prune {
            off[dim] = diff;
            self.search(far, qq, off, far_rd, best);
            off[dim] = old;
        }
    }

    /// Squared distance from `q` to node `node`'s bounding box: no more than the distance to
    /// any of its points (each term is, and the terms are summed in the same order).
    #[inline]
    fn box_dist(&self, node: u32, q: &[f64; D]) -> f64 {
        let (lo, hi) = &self.boxes[node as usize];
        let mut d = 0.0;
        for ((&l, &h), x) in lo.iter().zip(hi).zip(q) {
            let t = (f64::from(l) - x).max(x - f64::from(h)).max(0.0);
            d += t * t;
        }
        d
    }

    /// Memory held by the tree, in bytes (linear in the number of points).
    pub fn bytes(&self) -> usize {
        self.pts.len() * std::mem::size_of::<[f64; D]>()
            + self.cols.len() * 4
            + self.rows.len() * 4
            + self.nodes.len() * std::mem::size_of::<Node>()
            + self.boxes.len() * std::mem::size_of::<([f32; D], [f32; D])>()
    }
}

/// The smallest f32 no less than `v` (+∞ above f32's range).
fn up32(v: f64) -> f32 {
    let r = v as f32;
    if f64::from(r) >= v {
        r
    } else if r == 0.0 {
        f32::from_bits(1)
    } else if r > 0.0 {
        f32::from_bits(r.to_bits() + 1)
    } else {
        f32::from_bits(r.to_bits() - 1)
    }
}

/// A query in f64 and f32.
struct Query<'a, const D: usize> {
    q: &'a [f64; D],
    q32: &'a [f32; D],
}

/// Squared f32 distances of one leaf's points (column by column, [`LEAF`] lanes) to `q`.
#[inline(always)]
fn block_distances<const D: usize>(block: &[f32], q: &[f32; D]) -> [f32; LEAF] {
    let mut acc = [0.0f32; LEAF];
    for (col, &qd) in block.chunks_exact(LEAF).zip(q) {
        for (a, &x) in acc.iter_mut().zip(col) {
            let t = x - qd;
            *a += t * t;
        }
    }
    acc
}

/// The candidates of one query, kept by their f32 distances d̃ as keys (d̃ bits, position):
/// every point offered with d̃ ≤ `reach` is kept in `buf`; when `buf` holds `cut_at`, a selection
/// finds the k-th d̃, t, and the bounds tighten to what t proves (see [`Best::cut`]). Cheaper
/// than a heap when many candidates arrive (a query outside the samples' range), and exact: a
/// point dropped or pruned cannot be among the k nearest in f64.
struct Best<'a> {
    k: usize,
    /// Coordinates so large that f32 squares may overflow: keep every point.
    huge: bool,
    /// The f32 distances' allowance, in distance (not squared).
    delta: f64,
    /// A subtree whose box is farther than this (squared, f64) holds none of the k nearest.
    prune: f64,
    /// A point whose f32 distance is beyond this cannot be among the k nearest.
    reach: f32,
    cut_at: usize,
    buf: &'a mut Vec<u64>,
}

thread_local! {
    /// The f32 candidate keys of this thread's queries (no allocation once they hold `2k`).
    static CANDIDATES: std::cell::RefCell<Vec<u64>> = const { std::cell::RefCell::new(Vec::new()) };
    /// The exact candidate keys of this thread's queries.
    static KEYS: std::cell::RefCell<Vec<u128>> = const { std::cell::RefCell::new(Vec::new()) };
}

/// A candidate as one integer ordered by distance, then row: a squared distance is never
/// negative, so its bits order like its value; then the row, then the position (which the row
/// determines), each in its own bits.
#[inline]
fn key(d: f64, row: u32, pos: u32) -> u128 {
    (u128::from(d.to_bits()) << 64) | (u128::from(row) << 32) | u128::from(pos)
}

/// (squared distance, position) of a [`key`].
#[inline]
fn unkey(k: u128) -> (f64, u32) {
    (f64::from_bits((k >> 64) as u64), k as u32)
}

impl Best<'_> {
    #[inline]
    fn offer(&mut self, d32: f32, pos: u32) {
        self.buf
            .push((u64::from(d32.to_bits()) << 32) | u64::from(pos));
        if self.buf.len() >= self.cut_at {
            self.cut();
        }
    }

    /// With t the k-th smallest f32 distance kept (once `k` are known): at least k points lie
    /// within f64 distance² `prune` = (√t (1 + ε) + δ)², so the k nearest do; a point within
    /// that has f32 distance² at most `reach` = ((√prune + δ)(1 + ε))². Keeps the candidates
    /// within `reach` and grows the buffer's limit when many tie near t.
    fn cut(&mut self) {
        let k = self.k;
        if self.huge || self.buf.len() < k {
            return;
        }
        let (_, kth, _) = self.buf.select_nth_unstable(k - 1);
        let t = f64::from(f32::from_bits((*kth >> 32) as u32));
        let prune = ((t.sqrt() * (1.0 + F32_SLACK) + self.delta).powi(2)) * (1.0 + 1e-12);
        let reach = ((prune.sqrt() + self.delta) * (1.0 + F32_SLACK)).powi(2);
        // Rounded up to f32, so that the comparison in f32 keeps everything within it.
        let r32 = up32(reach);
        if r32 < self.reach {
            self.reach = r32;
            self.prune = prune;
        }
        let r = self.reach;
        self.buf.retain(|&c| f32::from_bits((c >> 32) as u32) <= r);
        self.cut_at = (2 * self.buf.len()).max(2 * k);
    }
}

macro_rules! state_tree {
    ($($v:ident => $k:literal),*) => {
        /// A [`Tree`] over points of one of the supported dimensions.
        pub enum StateTree {
            $($v(Tree<$k>),)*
        }

        /// kiddo's immutable kd-tree over points of one of the supported dimensions (the
        /// benchmark's and the tests' peer).
        #[allow(clippy::large_enum_variant)]
        pub enum KiddoTree {
            $($v(ImmutableKdTree<f64, u32, $k, 32>),)*
        }

        impl StateTree {
            /// A tree over `points` (row-major, `dims` columns); items are row indices.
            pub fn build(points: &[f64], dims: usize) -> Result<StateTree> {
                check(points, dims)?;
                match dims {
                    $($k => Ok(StateTree::$v(Tree::new(&rows::<$k>(points)))),)*
                    _ => unreachable!("checked"),
                }
            }

            /// The `k` nearest rows to `q` as (squared distance, row), nearest first; ties in
            /// distance are ordered by row. Allocates nothing once `out` holds `k`.
            pub fn nearest(&self, q: &[f64], k: usize, out: &mut Vec<(f64, u32)>) {
                match self {
                    $(StateTree::$v(t) => {
                        let q: &[f64; $k] = q.try_into().expect("query of the tree's dimension");
                        t.nearest(q, k, out);
                    })*
                }
            }

            /// As [`Tree::nearest_pos`].
            pub fn nearest_pos(&self, q: &[f64], k: usize, out: &mut Vec<(f64, u32)>) {
                match self {
                    $(StateTree::$v(t) => {
                        let q: &[f64; $k] = q.try_into().expect("query of the tree's dimension");
                        t.nearest_pos(q, k, out);
                    })*
                }
            }

            /// As [`Tree::points`].
            pub fn points(&self) -> &[f64] {
                match self {
                    $(StateTree::$v(t) => t.points(),)*
                }
            }

            /// As [`Tree::order`].
            pub fn order(&self) -> &[u32] {
                match self {
                    $(StateTree::$v(t) => t.order(),)*
                }
            }

            /// Memory held by the tree, in bytes.
            pub fn bytes(&self) -> usize {
                match self {
                    $(StateTree::$v(t) => t.bytes(),)*
                }
            }
        }

        impl KiddoTree {
            /// As [`StateTree::build`].
            pub fn build(points: &[f64], dims: usize) -> Result<KiddoTree> {
                check(points, dims)?;
                match dims {
                    $($k => Ok(KiddoTree::$v(ImmutableKdTree::new_from_slice(&rows::<$k>(points)))),)*
                    _ => unreachable!("checked"),
                }
            }

            /// As [`StateTree::nearest`].
            pub fn nearest(&self, q: &[f64], k: usize, out: &mut Vec<(f64, u32)>) {
                out.clear();
                let Some(k) = NonZeroUsize::new(k) else { return };
                match self {
                    $(KiddoTree::$v(t) => {
                        let q: &[f64; $k] = q.try_into().expect("query of the tree's dimension");
                        out.extend(
                            t.nearest_n::<SquaredEuclidean>(q, k)
                                .into_iter()
                                .map(|n| (n.distance, n.item)),
                        );
                    })*
                }
                out.sort_by(cmp_rows);
            }
        }
    };
}

state_tree!(D1 => 1, D2 => 2, D3 => 3, D4 => 4, D5 => 5, D6 => 6, D7 => 7, D8 => 8, D9 => 9,
    D10 => 10, D11 => 11, D12 => 12);

fn check(points: &[f64], dims: usize) -> Result<()> {
    if dims == 0 || dims > MAX_DIMS {
        return Err(Error::invalid(format!(
            "pca_dims = {dims} must be in 1..={MAX_DIMS}"
        )));
    }
    if points.len() / dims > u32::MAX as usize {
        return Err(Error::invalid("too many samples for one tree"));
    }
    Ok(())
}

fn rows<const D: usize>(points: &[f64]) -> Vec<[f64; D]> {
    points
        .chunks_exact(D)
        .map(|c| c.try_into().expect("chunk of the tree's dimension"))
        .collect()
}

/// The `k` nearest rows to `q` by exhaustive search, as [`StateTree::nearest`] returns them.
pub fn brute_force(points: &[f64], dims: usize, q: &[f64], k: usize) -> Vec<(f64, u32)> {
    let mut all: Vec<(f64, u32)> = points
        .chunks_exact(dims)
        .enumerate()
        .map(|(i, p)| {
            (
                p.iter().zip(q).map(|(a, b)| (a - b) * (a - b)).sum(),
                i as u32,
            )
        })
        .collect();
    all.sort_by(cmp_rows);
    all.truncate(k);
    all
}
