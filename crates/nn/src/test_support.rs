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

/// Asserts `ours` equals `reference` in shape and, element by element, within 1e-4 of the
/// reference's largest magnitude (at least 1): the kernels' tolerance against burn's.
pub(crate) fn assert_close<const D: usize>(what: &str, ours: Tensor<D>, reference: Tensor<D>) {
    assert_eq!(ours.dims(), reference.dims(), "{what}: shape");
    let ours = ours.into_data().try_to_vec::<f32>().unwrap();
    let reference = reference.into_data().try_to_vec::<f32>().unwrap();
    let scale = reference.iter().fold(1.0f32, |m, v| m.max(v.abs()));
    let worst = ours
        .iter()
        .zip(&reference)
        .fold(0.0f32, |m, (a, b)| m.max((a - b).abs()));
    assert!(
        worst <= 1e-4 * scale,
        "{what}: max difference {worst} (scale {scale})"
    );
}
