//! `herdfit-kernels`: the non-differentiable hot loops of herdfit — a uniform bucket grid,
//! padded neighbour lists with capsule occlusion, obstacle-cell traversal, the fused force kernel
//! of eq. 3–5 (forward and backward), the whole-sequence lifting energy with its gradient, and
//! (later) splatting.
//! Plain Rust (rayon for parallel loops), no burn: the differentiable model consumes their output
//! as constant data, and wraps the force kernel's forward/backward pair as one autodiff operation.

mod fastmath;
pub mod forces;
pub mod geometry;
pub mod grid;
pub mod lift;
pub mod obstacles;
pub mod pairs;
pub mod perception;

pub use forces::{
    forces_backward, forces_forward, forces_forward_keep, AgentsRef, Coefficients, ForceGrads,
    PairLists, PairTerms, N_COEF,
};
pub use geometry::{Capsule, P2};
pub use obstacles::ObstacleMap;
pub use perception::{
    branch_of, perceive, perceive_among, NeighbourLists, Perception, PerceptionConfig, Scene,
    BRANCH_BEHIND, BRANCH_RIGHT,
};

/// `f` run on a rayon pool of `threads` threads (tests that the output does not depend on it).
#[cfg(test)]
pub(crate) fn on_threads<T: Send>(threads: usize, f: impl FnOnce() -> T + Send) -> T {
    rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .unwrap()
        .install(f)
}
