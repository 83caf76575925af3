//! Average pooling of feature maps on plain buffers, for the CPU device: directly in inference,
//! as a burn backend operation with its backward in training.
//!
//! Why: burn's CPU backend pools a 2-D map through its 3-D pooling kernel and a strided index
//! iterator, forward and backward; the ConvGRU pools two hidden states at every iteration, which
//! made it a visible share of a MonSter++ pass and of a training step (BENCHMARKS.md, "MonSter++
//! against PyTorch, and where the time goes" and "SegFormer and the training step against
//! PyTorch").

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex, TensorMetadata};
use burn::tensor::module::avg_pool2d;
use burn::tensor::ops::AvgPoolOptions;
use burn::tensor::{DType, Tensor, TensorData};
use rayon::prelude::*;

use crate::cpu_mode::{on_cpu_inference, on_cpu_training};
use crate::custom_op::{register, step_inputs, RecordOp};
use crate::flex_tensor::f32_vec;
use crate::flex_tensor::{dims, tensor, values};

/// PyTorch's `avg_pool2d(x, k, stride, padding, count_include_pad=True)` with a square window.
pub fn avg_pool2d_padded(x: Tensor<4>, k: usize, stride: usize, padding: usize) -> Tensor<4> {
    avg_pool2d_box(x, [k, k], [stride, stride], [padding, padding])
}

/// PyTorch's `avg_pool2d(x, kernel, stride, padding, count_include_pad=True)`: the plain kernel
/// on the CPU device (with or without autodiff), burn's elsewhere.
pub fn avg_pool2d_box(
    x: Tensor<4>,
    kernel: [usize; 2],
    stride: [usize; 2],
    padding: [usize; 2],
) -> Tensor<4> {
    let window = [0, 1].map(|a| Axis {
        k: kernel[a],
        stride: stride[a],
        padding: padding[a],
    });
    if on_cpu_inference(&x) {
        let (device, [b, c, h, w]) = (x.device(), x.dims());
        let (out, [oh, ow]) = avg_pool_planes(&f32_vec(x), [h, w], window);
        return Tensor::from_data(TensorData::new(out, [b, c, oh, ow]), &device);
    }
    if on_cpu_training(&x) && x.dtype() == DType::F32 {
        return Tensor::from_dispatch(<Dispatch as PoolKernels>::kernel_avg_pool2d(
            x.into_dispatch(),
            encode(window),
        ));
    }
    avg_pool2d(
        x,
        AvgPoolOptions::new(kernel)
            .with_stride(stride)
            .with_padding(padding)
            .with_count_include_pad(true),
    )
}

/// A pooling window along one axis: size, stride and zero padding (counted in the average).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Axis {
    pub k: usize,
    pub stride: usize,
    pub padding: usize,
}

impl Axis {
    /// Output size along an axis of `n`.
    fn output(self, n: usize) -> usize {
        assert!(
            n + 2 * self.padding >= self.k,
            "avg_pool: window larger than the padded input"
        );
        (n + 2 * self.padding - self.k) / self.stride + 1
    }

    /// The in-bounds input indices of output `o`'s window along an axis of `n`.
    fn span(self, o: usize, n: usize) -> std::ops::Range<usize> {
        let start = (o * self.stride) as isize - self.padding as isize;
        let lo = start.max(0) as usize;
        let hi = ((start + self.k as isize) as usize).min(n);
        lo..hi
    }
}

/// The window as the extension operation carries it: `[kh, sh, ph, kw, sw, pw]`.
fn encode([y, x]: [Axis; 2]) -> [usize; 6] {
    [y.k, y.stride, y.padding, x.k, x.stride, x.padding]
}

fn decode([kh, sh, ph, kw, sw, pw]: [usize; 6]) -> [Axis; 2] {
    [
        Axis {
            k: kh,
            stride: sh,
            padding: ph,
        },
        Axis {
            k: kw,
            stride: sw,
            padding: pw,
        },
    ]
}

#[backend_extension(Flex, Autodiff)]
pub trait PoolKernels: Backend {
    /// [`avg_pool2d_box`] with `window` = `[kh, sh, ph, kw, sw, pw]`.
    fn kernel_avg_pool2d(x: FloatTensor<Self>, window: [usize; 6]) -> FloatTensor<Self>;
}

/// The gradient of [`PoolKernels::kernel_avg_pool2d`].
pub trait PoolGradKernels: PoolKernels {
    fn kernel_avg_pool2d_grad(
        grad: FloatTensor<Self>,
        input: [usize; 2],
        window: [usize; 6],
    ) -> FloatTensor<Self>;
}

impl PoolKernels for Flex {
    fn kernel_avg_pool2d(x: FlexTensor, window: [usize; 6]) -> FlexTensor {
        let [b, c, h, w] = dims(&x);
        let (out, [oh, ow]) = avg_pool_planes(&values(&x), [h, w], decode(window));
        tensor(out, [b, c, oh, ow])
    }
}

impl PoolGradKernels for Flex {
    fn kernel_avg_pool2d_grad(
        grad: FlexTensor,
        [h, w]: [usize; 2],
        window: [usize; 6],
    ) -> FlexTensor {
        let [b, c, oh, ow] = dims(&grad);
        let [ay, ax] = decode(window);
        let share = 1.0 / (ay.k * ax.k) as f32;
        let grad = values(&grad);
        let mut out = vec![0.0f32; b * c * h * w];
        out.par_chunks_exact_mut(h * w)
            .zip(grad.par_chunks_exact(oh * ow))
            .for_each(|(dst, src)| {
                for (oy, row) in src.chunks_exact(ow).enumerate() {
                    for y in ay.span(oy, h) {
                        let dst = &mut dst[y * w..(y + 1) * w];
                        for (ox, &g) in row.iter().enumerate() {
                            for d in &mut dst[ax.span(ox, w)] {
                                *d += g * share;
                            }
                        }
                    }
                }
            });
        tensor(out, [b, c, h, w])
    }
}

/// The backward step of [`PoolKernels::kernel_avg_pool2d`]; state: the input's size, the window.
#[derive(Debug)]
struct AvgPoolBackward;

impl<B: PoolGradKernels> Backward<B, 1> for AvgPoolBackward {
    type State = ([usize; 2], [usize; 6]);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (grad, (input, window), [x]) = step_inputs::<B, _, 1>(ops, grads);
        register::<B>(grads, x, || B::kernel_avg_pool2d_grad(grad, input, window));
    }
}

impl<B: PoolGradKernels, C: CheckpointStrategy> PoolKernels for Autodiff<B, C> {
    fn kernel_avg_pool2d(x: FloatTensor<Self>, window: [usize; 6]) -> FloatTensor<Self> {
        AvgPoolBackward.record::<C, _>(
            [x],
            (),
            |_, [x], ()| {
                let shape = x.primitive().shape();
                ([shape[2], shape[3]], window)
            },
            |[x], ()| B::kernel_avg_pool2d(x, window),
        )
    }
}

/// [`avg_pool2d_box`] of every `h × w` plane of `planes`: the window's sum (rows, then
/// columns, as PyTorch adds them) divided by `kh·kw`, padding counted. Returns the output and
/// its size `[oh, ow]`, `(n + 2·padding − k) / stride + 1` per axis.
pub fn avg_pool_planes(
    planes: &[f32],
    [h, w]: [usize; 2],
    [ay, ax]: [Axis; 2],
) -> (Vec<f32>, [usize; 2]) {
    let (oh, ow) = (ay.output(h), ax.output(w));
    let divisor = (ay.k * ax.k) as f32;
    let mut out = vec![0.0f32; planes.len() / (h * w) * oh * ow];
    out.par_chunks_exact_mut(oh * ow)
        .zip(planes.par_chunks_exact(h * w))
        .for_each(|(dst, src)| {
            for (oy, row) in dst.chunks_exact_mut(ow).enumerate() {
                let rows = ay.span(oy, h);
                for (ox, v) in row.iter_mut().enumerate() {
                    let cols = ax.span(ox, w);
                    let mut sum = 0.0f32;
                    for y in rows.clone() {
                        for &s in &src[y * w + cols.start..y * w + cols.end] {
                            sum += s;
                        }
                    }
                    *v = sum / divisor;
                }
            }
        });
    (out, [oh, ow])
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, Distribution};

    use crate::test_support::output_and_grads;

    /// The plain kernel against burn's on the ConvGRU's pooling (3×3, stride 2, padding 1) of
    /// even and odd sizes, a 2×2 window without padding and the SSIM's 1-D box windows.
    ///
    /// Under autodiff the operation's values and its input gradient match burn's too.
    #[test]
    fn matches_burn() {
        let max_difference = |a: Tensor<4>, b: Tensor<4>| -> f32 {
            assert_eq!(a.dims(), b.dims());
            (a - b).abs().max().into_scalar()
        };
        for device in [Device::flex(), Device::flex().autodiff()] {
            for (dims, k, stride, padding) in [
                ([1, 3, 16, 32], [3, 3], [2, 2], [1, 1]),
                ([2, 4, 7, 9], [3, 3], [2, 2], [1, 1]),
                ([1, 2, 1, 1], [3, 3], [2, 2], [1, 1]),
                ([1, 2, 6, 5], [2, 2], [2, 2], [0, 0]),
                ([1, 3, 12, 13], [1, 11], [1, 1], [0, 5]),
                ([1, 3, 12, 13], [11, 1], [1, 1], [5, 0]),
            ] {
                let x = Tensor::<4>::random(dims, Distribution::Normal(0.0, 1.0), &device);
                let ours = output_and_grads([&x], |[x]| avg_pool2d_box(x, k, stride, padding));
                let theirs = output_and_grads([&x], |[x]| {
                    let options = AvgPoolOptions::new(k)
                        .with_stride(stride)
                        .with_padding(padding)
                        .with_count_include_pad(true);
                    avg_pool2d(x, options)
                });
                let what = format!("{device:?} {dims:?} k{k:?} s{stride:?} p{padding:?}");
                let d = max_difference(ours.0, theirs.0);
                assert!(d < 1e-6, "{what}: {d}");
                if let (Some([a]), Some([b])) = (ours.1, theirs.1) {
                    let d = max_difference(a, b);
                    assert!(d < 1e-6, "{what} gradient: {d}");
                }
            }
        }
    }
}
