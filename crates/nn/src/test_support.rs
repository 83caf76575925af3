//! Helpers shared by the kernels' unit tests.

use burn::tensor::{Device, Int, Tensor};

/// A fixed, varied upstream gradient of shape `dims`: `sin(0.37·i)` of the flat index `i`, so
/// that a gradient comparison feeds both sides the same values, no two neighbours alike.
pub(crate) fn position_weights<const D: usize>(dims: [usize; D], device: &Device) -> Tensor<D> {
    let count = dims.iter().product::<usize>() as i64;
    Tensor::<1, Int>::arange(0..count, device)
        .float()
        .mul_scalar(0.37)
        .sin()
        .reshape(dims)
}
