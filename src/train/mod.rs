//! Learning the herd model's parameters (paper §6): the target field (eq. 10–11), the losses
//! (eq. 7–8), the fit loop through unrolled windows, and the gradient check.

pub mod fit;
pub mod gradcheck;
pub mod loss;
pub mod target;
