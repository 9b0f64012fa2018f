//! `herdfit-kernels`: the non-differentiable hot loops of herdfit — a uniform bucket grid,
//! padded neighbour lists with capsule occlusion, obstacle-cell traversal and (later) splatting.
//! Plain Rust (rayon for parallel loops), no burn: the differentiable model consumes their output
//! as constant data.

pub mod geometry;
pub mod grid;
pub mod obstacles;
pub mod perception;

pub use geometry::{Capsule, P2};
pub use obstacles::ObstacleMap;
pub use perception::{
    branch_of, perceive, Perception, PerceptionConfig, BRANCH_BEHIND, BRANCH_RIGHT,
};
