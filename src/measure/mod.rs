//! Model-agnostic measures on agents and fields: the emergent measures of paper §7.1.2
//! (polarization eq. 12, angular momentum eq. 13, aspect ratio), rasterising agents into clip
//! fields and the speed–density table (§6.2), and field comparisons (density and velocity errors).

pub mod dir_variance;
pub mod distribution;
pub mod emergent;
pub mod fields;
pub mod info;
pub mod raster;
pub mod reference;

pub use emergent::{angular_momentum, aspect_ratio, centroid, polarization};
pub use raster::{rasterise, speed_density_table, DENSITY_BINS};
