//! Bilinear resizing of feature maps (PyTorch `F.interpolate(mode='bilinear')`) that every
//! backend can differentiate.
//!
//! burn's `interpolate` has no bilinear backward on the CubeCL backends (wgpu and CUDA panic
//! with "Bilinear interpolation backward is not supported by JIT backend"), so training on a GPU
//! needs another route: a tensor that takes part in an autodiff graph is resized axis by axis as
//! `x[i0]·(1 − λ) + x[i1]·λ` with two `select`s, whose backward (a scatter-add) every backend
//! has. On the CPU device a plain-buffer kernel ([`resize_bilinear_planes`]) runs instead: burn's
//! was a visible share of a MonSter++ pass (the ConvGRU resizes its hidden states at every
//! iteration), and in training it is a burn operation whose backward is its adjoint
//! ([`resize_bilinear_planes_grad`]), where burn's backward ran on one thread (BENCHMARKS.md,
//! "MonSter++ against PyTorch, and where the time goes" and "SegFormer and the training step
//! against PyTorch"). Other tensors keep burn's kernel. All follow PyTorch's source-index rules,
//! so they agree to float rounding (`tests/resize.rs`).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex, TensorMetadata};
use burn::tensor::module::interpolate;
use burn::tensor::ops::{InterpolateMode, InterpolateOptions};
use burn::tensor::{DType, Device, Int, Tensor, TensorData};
use rayon::prelude::*;

use crate::cpu_mode::{on_cpu_inference, on_cpu_training};
use crate::custom_op::{register, step_inputs, RecordOp};
use crate::flex_tensor::f32_vec;
use crate::flex_tensor::{dims, tensor, values};

/// Bilinear resize of `B×C×H×W` to `size = [H', W']` with PyTorch's `align_corners` semantics.
pub fn resize_bilinear(x: Tensor<4>, size: [usize; 2], align_corners: bool) -> Tensor<4> {
    if x.dims()[2..] == size {
        // PyTorch copies in both modes when the size does not change.
        return x;
    }
    if on_cpu_inference(&x) {
        let (device, [b, c, h, w]) = (x.device(), x.dims());
        let out = resize_bilinear_planes(&f32_vec(x), [h, w], size, align_corners);
        Tensor::from_data(TensorData::new(out, [b, c, size[0], size[1]]), &device)
    } else if on_cpu_training(&x) && x.dtype() == DType::F32 {
        Tensor::from_dispatch(<Dispatch as ResizeKernels>::kernel_resize_bilinear(
            x.into_dispatch(),
            size,
            align_corners,
        ))
    } else if x.is_tracked() && x.device().inner() != Device::flex() {
        resize_bilinear_separable(x, size, align_corners)
    } else {
        interpolate(
            x,
            InterpolateOptions::new(InterpolateMode::Bilinear)
                .with_output_size(size)
                .with_align_corners(align_corners),
        )
    }
}

/// The differentiable-everywhere path of [`resize_bilinear`]: height, then width, each as two
/// `select`s and a blend.
pub fn resize_bilinear_separable(x: Tensor<4>, size: [usize; 2], align_corners: bool) -> Tensor<4> {
    let x = resize_axis(x, 2, size[0], align_corners);
    resize_axis(x, 3, size[1], align_corners)
}

/// Bilinear resize of every `h × w` plane of `planes` (NCHW, any number of planes) to `size`,
/// as PyTorch's `upsample_bilinear2d` computes it:
/// `λ0ʸ·(λ0ˣ·x00 + λ1ˣ·x01) + λ1ʸ·(λ0ˣ·x10 + λ1ˣ·x11)`. One rayon task per plane.
pub fn resize_bilinear_planes(
    planes: &[f32],
    [h, w]: [usize; 2],
    size: [usize; 2],
    align_corners: bool,
) -> Vec<f32> {
    let [oh, ow] = size;
    let rows = linear_taps(h, oh, align_corners);
    let cols = linear_taps(w, ow, align_corners);
    let mut out = vec![0.0f32; planes.len() / (h * w) * oh * ow];
    if out.is_empty() {
        return out;
    }
    out.par_chunks_exact_mut(oh * ow)
        .zip(planes.par_chunks_exact(h * w))
        .for_each(|(dst, src)| {
            // A source row blended along x, kept while consecutive output rows reuse it.
            let blend = |y: usize, row: &mut [f32]| {
                let s = &src[y * w..(y + 1) * w];
                for (x, v) in row.iter_mut().enumerate() {
                    *v = cols.w0[x] * s[cols.i0[x] as usize] + cols.w1[x] * s[cols.i1[x] as usize];
                }
            };
            let (mut top, mut bottom) = (vec![0.0f32; ow], vec![0.0f32; ow]);
            let mut loaded = [usize::MAX; 2];
            for (y, out_row) in dst.chunks_exact_mut(ow).enumerate() {
                let (y0, y1) = (rows.i0[y] as usize, rows.i1[y] as usize);
                if loaded[0] != y0 {
                    if loaded[1] == y0 {
                        std::mem::swap(&mut top, &mut bottom);
                        loaded[1] = usize::MAX;
                    } else {
                        blend(y0, &mut top);
                    }
                    loaded[0] = y0;
                }
                if loaded[1] != y1 {
                    blend(y1, &mut bottom);
                    loaded[1] = y1;
                }
                let (a, b) = (rows.w0[y], rows.w1[y]);
                for ((o, &t), &u) in out_row.iter_mut().zip(&top).zip(&bottom) {
                    *o = a * t + b * u;
                }
            }
        });
    out
}

/// The adjoint of [`resize_bilinear_planes`]: `∂L/∂x` (planes of `size`) from `grad` (planes of
/// `[oh, ow]`). Each output row's gradient is first gathered along x into one source-width row,
/// then added to its two source rows.
pub fn resize_bilinear_planes_grad(
    grad: &[f32],
    [oh, ow]: [usize; 2],
    size: [usize; 2],
    align_corners: bool,
) -> Vec<f32> {
    let [h, w] = size;
    let rows = linear_taps(h, oh, align_corners);
    let cols = linear_taps(w, ow, align_corners);
    let mut dx = vec![0.0f32; grad.len() / (oh * ow).max(1) * h * w];
    if dx.is_empty() {
        return dx;
    }
    dx.par_chunks_exact_mut(h * w)
        .zip(grad.par_chunks_exact(oh * ow))
        .for_each(|(dst, src)| {
            let mut row = vec![0.0f32; w];
            for (y, g) in src.chunks_exact(ow).enumerate() {
                row.fill(0.0);
                for (x, &g) in g.iter().enumerate() {
                    row[cols.i0[x] as usize] += cols.w0[x] * g;
                    row[cols.i1[x] as usize] += cols.w1[x] * g;
                }
                for (i, weight) in [(rows.i0[y], rows.w0[y]), (rows.i1[y], rows.w1[y])] {
                    let target = &mut dst[i as usize * w..][..w];
                    for (d, &v) in target.iter_mut().zip(&row) {
                        *d += weight * v;
                    }
                }
            }
        });
    dx
}

#[backend_extension(Flex, Autodiff)]
pub trait ResizeKernels: Backend {
    /// [`resize_bilinear`] of an `f32` tensor on the CPU device.
    fn kernel_resize_bilinear(
        x: FloatTensor<Self>,
        size: [usize; 2],
        align_corners: bool,
    ) -> FloatTensor<Self>;
}

/// The gradient of [`ResizeKernels::kernel_resize_bilinear`] for an input of `size`.
pub trait ResizeGradKernels: ResizeKernels {
    fn kernel_resize_bilinear_grad(
        grad: FloatTensor<Self>,
        size: [usize; 2],
        align_corners: bool,
    ) -> FloatTensor<Self>;
}

impl ResizeKernels for Flex {
    fn kernel_resize_bilinear(x: FlexTensor, size: [usize; 2], align_corners: bool) -> FlexTensor {
        let [b, c, h, w] = dims(&x);
        let out = resize_bilinear_planes(&values(&x), [h, w], size, align_corners);
        tensor(out, [b, c, size[0], size[1]])
    }
}

impl ResizeGradKernels for Flex {
    fn kernel_resize_bilinear_grad(
        grad: FlexTensor,
        size: [usize; 2],
        align_corners: bool,
    ) -> FlexTensor {
        let [b, c, oh, ow] = dims(&grad);
        let dx = resize_bilinear_planes_grad(&values(&grad), [oh, ow], size, align_corners);
        tensor(dx, [b, c, size[0], size[1]])
    }
}

/// The backward step of [`ResizeKernels::kernel_resize_bilinear`]; state: the input size and
/// the convention (the operation is linear: no tensor is kept).
#[derive(Debug)]
struct ResizeBackward;

impl<B: ResizeGradKernels> Backward<B, 1> for ResizeBackward {
    type State = ([usize; 2], bool);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (grad, (size, align_corners), [x]) = step_inputs::<B, _, 1>(ops, grads);
        register::<B>(grads, x, || {
            B::kernel_resize_bilinear_grad(grad, size, align_corners)
        });
    }
}

impl<B: ResizeGradKernels, C: CheckpointStrategy> ResizeKernels for Autodiff<B, C> {
    fn kernel_resize_bilinear(
        x: FloatTensor<Self>,
        size: [usize; 2],
        align_corners: bool,
    ) -> FloatTensor<Self> {
        ResizeBackward.record::<C, _>(
            [x],
            (),
            |_, [x], ()| {
                let shape = x.primitive().shape();
                ([shape[2], shape[3]], align_corners)
            },
            |[x], ()| B::kernel_resize_bilinear(x, size, align_corners),
        )
    }
}

/// Resizes dimension `dim` (2 or 3) of `x` to `len` samples.
fn resize_axis(x: Tensor<4>, dim: usize, len: usize, align_corners: bool) -> Tensor<4> {
    let n = x.dims()[dim];
    if n == len {
        return x;
    }
    let device = x.device();
    let taps = linear_taps(n, len, align_corners);
    let index = |v: Vec<i64>| Tensor::<1, Int>::from_data(TensorData::new(v, [len]), &device);
    let mut shape = [1usize; 4];
    shape[dim] = len;
    let weight =
        |v: Vec<f32>| Tensor::<1>::from_data(TensorData::new(v, [len]), &device).reshape(shape);
    let lo = x.clone().select(dim, index(taps.i0));
    let hi = x.select(dim, index(taps.i1));
    lo * weight(taps.w0) + hi * weight(taps.w1)
}

/// Per output sample: the two source samples and their weights.
struct LinearTaps {
    i0: Vec<i64>,
    i1: Vec<i64>,
    w0: Vec<f32>,
    w1: Vec<f32>,
}

/// PyTorch's `upsample_bilinear2d` indices along one axis of `n` samples resized to `len`:
/// source `s = i·(n−1)/(len−1)` with align_corners (0 when `len = 1`), else
/// `s = max((i + ½)·n/len − ½, 0)`; taps `⌊s⌋` and `min(⌊s⌋ + 1, n − 1)`, weights `1 − λ`, `λ`.
fn linear_taps(n: usize, len: usize, align_corners: bool) -> LinearTaps {
    let scale = if align_corners {
        if len > 1 {
            (n as f32 - 1.0) / (len as f32 - 1.0)
        } else {
            0.0
        }
    } else {
        n as f32 / len as f32
    };
    let mut taps = LinearTaps {
        i0: Vec::with_capacity(len),
        i1: Vec::with_capacity(len),
        w0: Vec::with_capacity(len),
        w1: Vec::with_capacity(len),
    };
    for i in 0..len {
        let s = if align_corners {
            scale * i as f32
        } else {
            (scale * (i as f32 + 0.5) - 0.5).max(0.0)
        };
        let i0 = (s as usize).min(n - 1);
        let i1 = (i0 + 1).min(n - 1);
        let lambda = s - i0 as f32;
        taps.i0.push(i0 as i64);
        taps.i1.push(i1 as i64);
        taps.w0.push(1.0 - lambda);
        taps.w1.push(lambda);
    }
    taps
}
