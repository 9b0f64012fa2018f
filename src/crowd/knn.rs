//! k nearest samples in the PCA state space (§5.1; the paper keeps its samples in kd-trees, §8),
//! an exact brute-force search to check against, and `kiddo`'s immutable kd-tree as the peer the
//! benchmark compares with.
//!
//! [`StateTree`] is a bucketed kd-tree: the samples are ordered by splitting on the widest
//! dimension at the multiple of 16 points nearest the median (so that every leaf is one 16-point
//! block), and each leaf keeps its bounding box. The PCA states have most of their variance in
//! the leading components, so splitting the widest dimension makes tighter leaves than the
//! round-robin splits of kiddo's trees (which, at ~9 levels over 10–12 dimensions, split each
//! dimension about once). A query does not descend the tree: it computes a lower bound on the
//! distance to every leaf's box, eight boxes per SIMD row, visits the ⌈2k/16⌉ leaves with the
//! smallest bounds (found by selection), and then every other leaf whose bound is within what
//! the k-th distance so far allows. For queries far from the samples, where a descent visits a
//! third of the leaves through branchy recursion, this flat pass is branch-free and cheap; for
//! queries among the samples it costs about as much as the descent. Candidates are integer keys
//! in per-thread buffers, cut by selection; nothing is allocated once those buffers have grown.
//! The dimension is a const generic; [`StateTree`] picks one of 1–12 at run time (the paper's
//! PCA keeps 8–12). Ties in distance are ordered by row, so the result equals
//! [`brute_force`]'s exactly.
//!
//! The search works in f32 and proves its way back to f64. A leaf's points are also stored as
//! f32, column by column, and their distances computed in SIMD lanes (AVX2 where the CPU has it,
//! through `pulp`'s run-time dispatch). A leaf's bound is computed in f32 with the same
//! operations in the same order as its points' distances, on coordinates no nearer the query,
//! so it is no more than any of them (rounding is monotone) and skipping a leaf beyond the
//! bound loses nothing. Candidates are kept by their f32 distance; at the end only the points
//! whose f32 distance lies within the roundings' allowance of the k-th get their exact f64
//! distance (typically k and a few), so the neighbours and distances are the f64 search's, bit
//! for bit.

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

/// A kd-tree's leaves over points of dimension `D` (split on the widest dimension, median
/// split), with their bounding boxes.
pub struct Tree<const D: usize> {
    /// Points in tree order.
    pts: Vec<[f64; D]>,
    /// The same points as f32, leaf by leaf column by column: coordinate `d` of position `p` at
    /// `[(p / LEAF) * D + d][p % LEAF]` (the last leaf padded with zeros). A leaf's
    /// distances are first computed from them in SIMD lanes; only the points that may lie
    /// within the bound get their exact f64 distance.
    cols: Vec<[f32; LEAF]>,
    /// Largest point norm, for the f32 filter's allowance.
    max_norm: f64,
    /// The instruction set the f32 distances are compiled for (chosen at run time).
    arch: pulp::Arch,
    /// Row of each point in the input.
    rows: Vec<u32>,
    /// Each leaf's bounding box over its f32 points, eight leaves at a time column by column:
    /// coordinate `d` of leaf `l`'s lowest corner at `(l / 8) * 8 * D + d * 8 + l % 8` (the
    /// last group padded with empty boxes at +∞).
    leaf_lo: Vec<f32>,
    /// The highest corners, laid out as `leaf_lo`.
    leaf_hi: Vec<f32>,
}

/// (squared distance, row) ordered by distance, then row.
fn cmp_rows(a: &(f64, u32), b: &(f64, u32)) -> Ordering {
    a.0.total_cmp(&b.0).then(a.1.cmp(&b.1))
}

impl<const D: usize> Tree<D> {
    /// A tree over `pts`; items are indices into `pts`.
    pub fn new(pts: &[[f64; D]]) -> Tree<D> {
        let mut perm: Vec<u32> = (0..pts.len() as u32).collect();
        Self::partition(pts, &mut perm);
        let mut cols = vec![[0.0f32; LEAF]; pts.len().div_ceil(LEAF) * D];
        for (pos, &i) in perm.iter().enumerate() {
            for (d, &v) in pts[i as usize].iter().enumerate() {
                cols[(pos / LEAF) * D + d][pos % LEAF] = v as f32;
            }
        }
        let (leaf_lo, leaf_hi) = leaf_boxes::<D>(&cols, pts.len());
        let max_norm = pts
            .iter()
            .map(|p| p.iter().map(|v| v * v).sum::<f64>().sqrt())
            .fold(0.0, f64::max);
        Tree {
            pts: perm.iter().map(|&i| pts[i as usize]).collect(),
            rows: perm,
            leaf_lo,
            leaf_hi,
            cols,
            max_norm,
            arch: pulp::Arch::new(),
        }
    }

    /// Orders `perm` as a kd-tree's leaves: split on the widest dimension at the multiple of
    /// [`LEAF`] points nearest the median, each side recursively, until a part fits in a leaf.
    fn partition(pts: &[[f64; D]], perm: &mut [u32]) {
        if perm.len() <= LEAF {
            return;
        }
        let (mut lo, mut hi) = ([f64::INFINITY; D], [f64::NEG_INFINITY; D]);
        for &i in perm.iter() {
            for ((l, h), v) in lo.iter_mut().zip(hi.iter_mut()).zip(&pts[i as usize]) {
                *l = l.min(*v);
                *h = h.max(*v);
            }
        }
        let mut dim = 0;
        for j in 1..D {
            if hi[j] - lo[j] > hi[dim] - lo[dim] {
                dim = j;
            }
        }
        // The left part a whole number of leaves (at least one, short of all the points), so
        // that every leaf starts at a multiple of LEAF.
        let mid = (perm.len().div_ceil(LEAF) / 2).max(1) * LEAF;
        perm.select_nth_unstable_by(mid, |&x, &y| {
            pts[x as usize][dim]
                .total_cmp(&pts[y as usize][dim])
                .then(x.cmp(&y))
        });
        let (l, r) = perm.split_at_mut(mid);
        Self::partition(pts, l);
        Self::partition(pts, r);
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
        if k == 0 || self.pts.is_empty() {
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
                reach: f32::INFINITY,
                cut_at: if huge { usize::MAX } else { 2 * k },
                buf: cands,
            };
            // The bounds' buffer taken out of its thread-local for the call, so that the whole
            // scan is inlined into the dispatched function (no closure of its own).
            let mut sc = SCAN.take();
            self.arch.dispatch(Scan {
                tree: self,
                q32: &q32,
                best: &mut best,
                sc: &mut sc,
            });
            SCAN.set(sc);
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

    /// Offers every point that may be among the k nearest: first the ⌈2k/16⌉ leaves whose
    /// boxes are nearest `q` (whose k-th f32 distance bounds the search), then every other
    /// leaf whose box lies within the bound. The leaves' lower bounds are
    /// computed eight leaves at a time; each is no more than any of its points' f32 distances
    /// (same operations in the same order on coordinates no nearer `q`, and rounding is
    /// monotone), so a leaf beyond `reach` holds no point the search would keep.
    #[inline(always)]
    fn scan(&self, q32: &[f32; D], best: &mut Best, sc: &mut ScanScratch) {
        let leaves = self.pts.len().div_ceil(LEAF);
        if best.huge {
            (0..leaves).for_each(|l| self.visit(l, q32, best));
            return;
        }
        sc.lb.resize(leaves.div_ceil(8) * 8, 0.0);
        leaf_bounds::<D>(&self.leaf_lo, &self.leaf_hi, q32, &mut sc.lb);
        sc.keys.clear();
        sc.keys.extend(
            sc.lb[..leaves]
                .iter()
                .enumerate()
                .map(|(l, &b)| (u64::from(b.to_bits()) << 32) | l as u64),
        );
        // The leaves nearest by their bounds first (found by selection, not a sort: the rest
        // are only compared with the bound, in any order).
        let first = (2 * best.k).div_ceil(LEAF).min(leaves);
        if first < leaves {
            sc.keys.select_nth_unstable(first - 1);
        }
        for &key in &sc.keys[..first] {
            self.visit(key as u32 as usize, q32, best);
        }
        for &key in &sc.keys[first..] {
            if f32::from_bits((key >> 32) as u32) <= best.reach {
                self.visit(key as u32 as usize, q32, best);
            }
        }
    }

    /// Offers the points of leaf `leaf` whose f32 distance is within `reach` (all when `huge`).
    #[inline(always)]
    fn visit(&self, leaf: usize, q32: &[f32; D], best: &mut Best) {
        let a = leaf * LEAF;
        let b = (a + LEAF).min(self.pts.len());
        let block = self.cols[leaf * D..(leaf + 1) * D]
            .try_into()
            .expect("a leaf is D columns");
        let d32 = block_distances::<D>(block, q32);
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
    }

    /// Memory held by the tree, in bytes (linear in the number of points).
    pub fn bytes(&self) -> usize {
        self.pts.len() * std::mem::size_of::<[f64; D]>()
            + self.cols.len() * LEAF * 4
            + self.rows.len() * 4
            + (self.leaf_lo.len() + self.leaf_hi.len()) * 4
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

/// [`Tree::scan`] as a `pulp` operation: a closure would not be inlined into the dispatched
/// function whole, and what it calls would be compiled for the baseline instruction set.
struct Scan<'a, 'b, const D: usize> {
    tree: &'a Tree<D>,
    q32: &'a [f32; D],
    best: &'a mut Best<'b>,
    sc: &'a mut ScanScratch,
}

/// A thread's buffers for [`Tree::scan`]: the leaves' lower bounds, and the same as keys
/// (bound bits, leaf).
#[derive(Default)]
struct ScanScratch {
    lb: Vec<f32>,
    keys: Vec<u64>,
}

impl<const D: usize> pulp::WithSimd for Scan<'_, '_, D> {
    type Output = ();

    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _: S) {
        self.tree.scan(self.q32, self.best, self.sc);
    }
}

/// Each leaf's box over its f32 points (see [`Tree::leaf_lo`]) from the leaves' columns.
fn leaf_boxes<const D: usize>(cols: &[[f32; LEAF]], n: usize) -> (Vec<f32>, Vec<f32>) {
    let leaves = n.div_ceil(LEAF);
    let mut lo = vec![f32::INFINITY; leaves.div_ceil(8) * 8 * D];
    let mut hi = lo.clone();
    for leaf in 0..leaves {
        let m = LEAF.min(n - leaf * LEAF);
        for d in 0..D {
            let col = &cols[leaf * D + d][..m];
            let at = (leaf / 8) * 8 * D + d * 8 + leaf % 8;
            lo[at] = col.iter().fold(f32::INFINITY, |a, &b| a.min(b));
            hi[at] = col.iter().fold(f32::NEG_INFINITY, |a, &b| a.max(b));
        }
    }
    (lo, hi)
}

/// Lower bounds on the squared f32 distances of each leaf's points to `q`, eight leaves at a
/// time: per coordinate the gap to the box (0 inside it), squared and summed in
/// [`block_distances`]' order. Empty boxes (+∞) give +∞.
#[inline(always)]
fn leaf_bounds<const D: usize>(lo: &[f32], hi: &[f32], q: &[f32; D], out: &mut [f32]) {
    for ((l, h), o) in lo
        .chunks_exact(8 * D)
        .zip(hi.chunks_exact(8 * D))
        .zip(out.chunks_exact_mut(8))
    {
        let mut acc = [0.0f32; 8];
        for ((lc, hc), &qd) in l.chunks_exact(8).zip(h.chunks_exact(8)).zip(q) {
            for ((a, &x), &y) in acc.iter_mut().zip(lc).zip(hc) {
                let (u, v) = (x - qd, qd - y);
                let t = if u > v { u } else { v };
                let t = if t > 0.0 { t } else { 0.0 };
                *a += t * t;
            }
        }
        o.copy_from_slice(&acc);
    }
}

/// Squared f32 distances of one leaf's points (column by column, [`LEAF`] lanes) to `q`.
#[inline(always)]
fn block_distances<const D: usize>(block: &[[f32; LEAF]; D], q: &[f32; D]) -> [f32; LEAF] {
    let mut acc = [0.0f32; LEAF];
    for (col, &qd) in block.iter().zip(q) {
        for j in 0..LEAF {
            let t = col[j] - qd;
            acc[j] += t * t;
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
    /// A point whose f32 distance is beyond this cannot be among the k nearest.
    reach: f32,
    cut_at: usize,
    buf: &'a mut Vec<u64>,
}

thread_local! {
    /// The f32 candidate keys of this thread's queries (no allocation once they hold `2k`).
    static CANDIDATES: std::cell::RefCell<Vec<u64>> = const { std::cell::RefCell::new(Vec::new()) };
    /// The leaves' lower bounds of this thread's queries.
    static SCAN: std::cell::Cell<ScanScratch> = const { std::cell::Cell::new(ScanScratch { lb: Vec::new(), keys: Vec::new() }) };
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
