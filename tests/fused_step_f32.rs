//! The plain simulation step (`sim::plain_step`) against the tensor-op step around the fused
//! forces, in f32: the same bytes (the f64 case is in `tests/fused.rs`).

#[path = "fused_step/body.rs"]
mod body;

#[test]
fn plain_step_has_the_bytes_of_the_tensor_ops_in_f32() {
    body::plain_step_has_the_bytes_of_the_tensor_ops(herdfit::backend::Precision::F32);
}
