//! 1-D linear interpolation along the last axis with zeros outside `[0, len − 1]` (upstream's
//! `grid_sample(align_corners=True, padding='zeros')` on height-1 images, which is what the geo
//! encoding lookup does), as a burn backend operation for training on the CPU.
//!
//! Why: on tensors, each lookup is two gathers, their weights and a dozen element-wise ops, and its
//! backward two scatters; burn's CPU gather and scatter compute every index on one thread, a large
//! part of the serial time of a training step (BENCHMARKS.md, "SegFormer and the training step
//! against PyTorch"). [`linear_taps`] does one pass forward and one backward. Positions are
//! constants: the gradient flows to the samples only (upstream detaches the disparity before the
//! lookup).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex, TensorMetadata};
use burn::tensor::Tensor;
use rayon::prelude::*;

use crate::custom_op::{register, step_inputs, RecordOp};
use crate::flex_tensor::{all_f32, dims, tensor, values};

/// `out[n, g, k] = src[n, g, ·]` interpolated at `pos[n, k]` (`src` `[n, g, len]`, `pos`
/// `[n, taps]` → `[n, g, taps]`), differentiable with respect to `src`; `pos` is detached.
/// Only for `f32` tensors on the CPU device (with or without autodiff).
pub fn linear_taps(src: Tensor<3>, pos: Tensor<2>) -> Tensor<3> {
    Tensor::from_dispatch(<Dispatch as InterpKernels>::kernel_linear_taps(
        src.into_dispatch(),
        pos.detach().into_dispatch(),
    ))
}

/// `(i0, w0, i1, w1)`: the two neighbours of `pos` (clamped into range) and their weights (zero
/// for a neighbour outside `[0, len − 1]`).
pub fn linear_tap(pos: f32, len: usize) -> (usize, f32, usize, f32) {
    let f0 = pos.floor();
    let frac = pos - f0;
    let f1 = f0 + 1.0;
    let max = len as f32 - 1.0;
    let inside = |f: f32| if (0.0..=max).contains(&f) { 1.0 } else { 0.0 };
    let w0 = (-frac + 1.0) * inside(f0);
    let w1 = frac * inside(f1);
    (
        f0.clamp(0.0, max) as usize,
        w0,
        f1.clamp(0.0, max) as usize,
        w1,
    )
}

#[backend_extension(Flex, Autodiff)]
pub trait InterpKernels: Backend {
    /// See [`linear_taps`].
    fn kernel_linear_taps(src: FloatTensor<Self>, pos: FloatTensor<Self>) -> FloatTensor<Self>;
}

/// The gradient of [`InterpKernels::kernel_linear_taps`] with respect to `src`.
pub trait InterpGradKernels: InterpKernels {
    fn kernel_linear_taps_grad(
        grad: FloatTensor<Self>,
        pos: &FloatTensor<Self>,
        len: usize,
    ) -> FloatTensor<Self>;
}

impl InterpKernels for Flex {
    fn kernel_linear_taps(src: FlexTensor, pos: FlexTensor) -> FlexTensor {
        assert!(all_f32([&src, &pos]), "linear_taps: f32 tensors only");
        let [n, g, len] = dims(&src);
        let [pn, taps] = dims(&pos);
        assert_eq!(n, pn, "linear_taps: samples and positions disagree");
        let (src, pos) = (values(&src), values(&pos));
        let mut out = vec![0.0f32; n * g * taps];
        out.par_chunks_exact_mut(g * taps)
            .zip(src.par_chunks_exact(g * len))
            .zip(pos.par_chunks_exact(taps))
            .for_each(|((out, src), pos)| {
                for (k, &p) in pos.iter().enumerate() {
                    let (i0, w0, i1, w1) = linear_tap(p, len);
                    for (line, o) in src
                        .chunks_exact(len)
                        .zip(out.iter_mut().skip(k).step_by(taps))
                    {
                        *o = line[i0] * w0 + line[i1] * w1;
                    }
                }
            });
        tensor(out, [n, g, taps])
    }
}

impl InterpGradKernels for Flex {
    fn kernel_linear_taps_grad(grad: FlexTensor, pos: &FlexTensor, len: usize) -> FlexTensor {
        let [n, g, taps] = dims(&grad);
        let (grad, pos) = (values(&grad), values(pos));
        let mut out = vec![0.0f32; n * g * len];
        out.par_chunks_exact_mut(g * len)
            .zip(grad.par_chunks_exact(g * taps))
            .zip(pos.par_chunks_exact(taps))
            .for_each(|((out, grad), pos)| {
                for (k, &p) in pos.iter().enumerate() {
                    let (i0, w0, i1, w1) = linear_tap(p, len);
                    for (line, &d) in out
                        .chunks_exact_mut(len)
                        .zip(grad.iter().skip(k).step_by(taps))
                    {
                        line[i0] += w0 * d;
                        line[i1] += w1 * d;
                    }
                }
            });
        tensor(out, [n, g, len])
    }
}

/// The backward step of [`InterpKernels::kernel_linear_taps`]; state: the positions and `len`.
#[derive(Debug)]
struct LinearTapsBackward;

impl<B: InterpGradKernels> Backward<B, 1> for LinearTapsBackward {
    type State = (FloatTensor<B>, usize);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (grad, (pos, len), [src]) = step_inputs::<B, _, 1>(ops, grads);
        register::<B>(grads, src, || B::kernel_linear_taps_grad(grad, &pos, len));
    }
}

impl<B: InterpGradKernels, C: CheckpointStrategy> InterpKernels for Autodiff<B, C> {
    fn kernel_linear_taps(src: FloatTensor<Self>, pos: FloatTensor<Self>) -> FloatTensor<Self> {
        LinearTapsBackward.record::<C, _>(
            [src],
            pos.into_primitive(),
            |_, [src], pos| (pos.clone(), src.primitive().shape()[2]),
            |[src], pos| B::kernel_linear_taps(src, pos),
        )
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::ops::{GridSampleOptions, GridSamplePaddingMode, InterpolateMode};
    use burn::tensor::{Device, Distribution, TensorData};

    use super::*;

    fn max_difference(a: Tensor<3>, b: Tensor<3>) -> f32 {
        let (a, b) = (a.into_data(), b.into_data());
        let (a, b) = (a.as_slice::<f32>().unwrap(), b.as_slice::<f32>().unwrap());
        a.iter().zip(b).fold(0.0, |m, (x, y)| m.max((x - y).abs()))
    }

    /// Values spread over [lo, hi) by the golden-ratio sequence: the same inputs on every run,
    /// so the comparison's rounding cannot differ from one run to the next.
    fn spread<const D: usize>(shape: [usize; D], lo: f32, hi: f32, device: &Device) -> Tensor<D> {
        let n: usize = shape.iter().product();
        let values: Vec<f32> = (0..n)
            .map(|i| lo + (hi - lo) * (i as f64 * 0.618_033_988_75).fract() as f32)
            .collect();
        Tensor::from_data(TensorData::new(values, shape.to_vec()), device)
    }

    /// Positions inside, on both ends, between the last two samples and outside on both sides.
    fn positions(n: usize, taps: usize, len: usize, device: &Device) -> Tensor<2> {
        let span = len as f32 + 3.0;
        spread([n, taps], 0.0, 1.0, device)
            .mul_scalar(span)
            .sub_scalar(2.0)
            .slice_assign(
                [0..1, 0..2],
                Tensor::from_floats([[0.0, len as f32 - 1.0]], device),
            )
    }

    /// Upstream samples with `grid_sample(align_corners=True, padding='zeros')` on height-1
    /// images: the kernel equals burn's `grid_sample_2d` on that layout, on the CPU device with
    /// and without autodiff.
    #[test]
    fn matches_grid_sample_on_height_one_images() {
        let (n, g, len, taps) = (37, 8, 24, 9);
        for device in [Device::flex(), Device::flex().autodiff()] {
            let src = spread([n, g, len], -2.0, 2.0, &device);
            let pos = positions(n, taps, len, &device);
            let ours = linear_taps(src.clone(), pos.clone());
            // grid x in [-1, 1] over the `len` samples (align_corners), y = 0 on one row.
            let x = pos.mul_scalar(2.0 / (len as f32 - 1.0)).sub_scalar(1.0);
            let grid =
                Tensor::stack::<3>(vec![x.clone(), x.zeros_like()], 2).reshape([n, 1, taps, 2]);
            let options = GridSampleOptions::new(InterpolateMode::Bilinear)
                .with_padding_mode(GridSamplePaddingMode::Zeros)
                .with_align_corners(true);
            let reference = src
                .reshape([n, g, 1, len])
                .grid_sample_2d(grid, options)
                .reshape([n, g, taps]);
            let worst = max_difference(ours, reference);
            assert!(worst < 1e-5, "{device:?}: max difference {worst}");
        }
    }

    /// The operation is linear in `src`, so its gradient is its adjoint:
    /// `⟨taps(src), r⟩ = ⟨src, ∂⟨taps(src), r⟩/∂src⟩` for any `src` and `r`.
    #[test]
    fn gradient_is_the_adjoint() {
        let (n, g, len, taps) = (29, 3, 17, 9);
        let device = Device::flex().autodiff();
        let src = Tensor::<3>::random([n, g, len], Distribution::Normal(0.0, 1.0), &device)
            .require_grad();
        let r = Tensor::<3>::random([n, g, taps], Distribution::Normal(0.0, 1.0), &device);
        let pos = positions(n, taps, len, &device);
        let forward = (linear_taps(src.clone(), pos) * r).sum();
        let grads = forward.clone().backward();
        let grad = src.grad(&grads).expect("gradient of the samples");
        let adjoint: f32 = (src.inner() * grad).sum().into_scalar();
        let forward: f32 = forward.into_scalar();
        assert!(
            (forward - adjoint).abs() <= 1e-4 * forward.abs().max(1.0),
            "⟨taps(src), r⟩ = {forward}, ⟨src, grad⟩ = {adjoint}"
        );
    }
}
