//! Learning the herd model's parameters (paper §6). For now: the gradient check of the unrolled
//! model; the fit loop, target field and losses follow.

pub mod gradcheck;
