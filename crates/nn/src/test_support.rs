//! Helpers shared by the kernels' unit tests.

use burn::tensor::{Device, Gradients, Int, Tensor};

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

/// The gradients of `sum(y · position_weights)`: `y`'s backward under the fixed upstream
/// gradient of [`position_weights`].
pub(crate) fn position_weighted_grads<const D: usize>(y: &Tensor<D>) -> Gradients {
    (y.clone() * position_weights(y.dims(), &y.device()))
        .sum()
        .backward()
}

/// `layer(inputs)` detached and, where the inputs live on an autodiff device, their gradients
/// under [`position_weighted_grads`]: one side of a comparison with burn's operation.
pub(crate) fn output_and_grads<const D: usize, const E: usize, const N: usize>(
    inputs: [&Tensor<D>; N],
    layer: impl FnOnce([Tensor<D>; N]) -> Tensor<E>,
) -> (Tensor<E>, Option<[Tensor<D>; N]>) {
    let tracked = inputs[0].device().is_autodiff();
    let inputs = inputs.map(|x| {
        if tracked {
            x.clone().require_grad()
        } else {
            x.clone()
        }
    });
    let y = layer(inputs.clone());
    let grads = tracked.then(|| {
        let grads = position_weighted_grads(&y);
        inputs.map(|x| x.grad(&grads).expect("input gradient"))
    });
    (y.detach(), grads)
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
