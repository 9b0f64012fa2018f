//! k nearest samples in the PCA state space (§5.1), with `kiddo`'s immutable kd-tree (the paper
//! keeps its samples in kd-trees, §8) and an exact brute-force search to check it against.
//!
//! kiddo's trees take their dimension as a const generic; [`StateTree`] picks one of the
//! dimensions 1–12 at run time (the paper's PCA keeps 8–12).

use crate::error::{Error, Result};
use kiddo::immutable::float::kdtree::ImmutableKdTree;
use kiddo::SquaredEuclidean;
use std::num::NonZeroUsize;

/// Largest PCA dimension a tree supports.
pub const MAX_DIMS: usize = 12;

/// Leaf size of the trees.
const BUCKET: usize = 32;

macro_rules! state_tree {
    ($($v:ident => $k:literal),*) => {
        /// A kd-tree over points of one of the supported dimensions.
        #[allow(clippy::large_enum_variant)]
        pub enum StateTree {
            $($v(ImmutableKdTree<f64, u32, $k, BUCKET>),)*
        }

        impl StateTree {
            /// A tree over `points` (row-major, `dims` columns); items are row indices.
            pub fn build(points: &[f64], dims: usize) -> Result<StateTree> {
                if points.len() / dims.max(1) > u32::MAX as usize {
                    return Err(Error::invalid("too many samples for one tree"));
                }
                match dims {
                    $($k => {
                        let rows: Vec<[f64; $k]> = points
                            .chunks_exact($k)
                            .map(|c| c.try_into().expect("chunk of the tree's dimension"))
                            .collect();
                        Ok(StateTree::$v(ImmutableKdTree::new_from_slice(&rows)))
                    })*
                    d => Err(Error::invalid(format!(
                        "pca_dims = {d} must be in 1..={MAX_DIMS}"
                    ))),
                }
            }

            /// The `k` nearest rows to `q` as (squared distance, row), nearest first; ties in
            /// distance are ordered by row.
            pub fn nearest(&self, q: &[f64], k: usize, out: &mut Vec<(f64, u32)>) {
                out.clear();
                let Some(k) = NonZeroUsize::new(k) else { return };
                match self {
                    $(StateTree::$v(t) => {
                        let q: &[f64; $k] = q.try_into().expect("query of the tree's dimension");
                        out.extend(
                            t.nearest_n::<SquaredEuclidean>(q, k)
                                .into_iter()
                                .map(|n| (n.distance, n.item)),
                        );
                    })*
                }
                out.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            }
        }
    };
}

state_tree!(D1 => 1, D2 => 2, D3 => 3, D4 => 4, D5 => 5, D6 => 6, D7 => 7, D8 => 8, D9 => 9,
    D10 => 10, D11 => 11, D12 => 12);

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
    all.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    all.truncate(k);
    all
}
