//! 3-D convolutions and transposed convolutions (the cost-volume hourglass of MonSter++) on the
//! CPU device, as burn operations with their backward. Each batch item's input is unfolded in
//! bands of output depth planes and multiplied by the weight on the `gemm` crate; the input
//! gradient is the transposed product folded back, the weight gradient the output gradient
//! times the unfolded input. A transposed convolution is the input gradient of the convolution
//! with the same weight (and its backward that convolution's forward and weight gradient), so
//! three kernels serve both layers.
//!
//! Why: burn's CPU 3-D convolutions and their gradients were the largest burn kernels left in a
//! MonSter++ training step (BENCHMARKS.md, "SegFormer and the training step against PyTorch").

use std::ops::Range;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::autodiff::NodeId;
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex};
use burn::nn::conv::{Conv3d, ConvTranspose3d};
use burn::nn::PaddingConfig3d;
use burn::tensor::Tensor;
use rayon::prelude::*;

use crate::cpu_mode::on_cpu_training;
use crate::custom_op::{checkpoint_input_and_weight, checkpointed_step_inputs, register, RecordOp};
use crate::flex_tensor::{dims, tensor, values};
use crate::matmul::{gemm_f32, Strided};

/// Floats of unfolded input per GEMM (16 MiB): bounds the scratch of a large volume while
/// keeping each product long.
const BAND_FLOATS: usize = 1 << 22;

/// Fewest pixels per weight-gradient GEMM: shorter pieces spend more on partial sums than they
/// gain in balance.
const MIN_PIECE_PIXELS: usize = 256;

/// The shape of a one-group 3-D convolution (the same padding before and after each axis).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Geometry3 {
    pub kernel: [usize; 3],
    pub stride: [usize; 3],
    pub padding: [usize; 3],
    pub dilation: [usize; 3],
}

impl Geometry3 {
    fn taps(&self) -> usize {
        self.kernel.iter().product()
    }

    /// The output size of an input of `size` (depth, height, width).
    fn output(&self, size: [usize; 3]) -> [usize; 3] {
        std::array::from_fn(|a| {
            let span = self.dilation[a] * (self.kernel[a] - 1) + 1;
            (size[a] + 2 * self.padding[a] - span) / self.stride[a] + 1
        })
    }

    /// The output size of a transposed convolution of an input of `size`.
    fn transposed_output(&self, size: [usize; 3], padding_out: [usize; 3]) -> [usize; 3] {
        std::array::from_fn(|a| {
            (size[a] - 1) * self.stride[a]
                + self.dilation[a] * (self.kernel[a] - 1)
                + 1
                + padding_out[a]
                - 2 * self.padding[a]
        })
    }

    /// A 1×1×1 convolution that reads its input as it is: the input is its own unfolding.
    fn is_pointwise(&self) -> bool {
        self.kernel == [1; 3] && self.stride == [1; 3] && self.padding == [0; 3]
    }
}

/// `[b, c, d, h, w]`.
type Ncdhw = [usize; 5];

/// The output positions `[lo, hi)` along one axis at which kernel offset `k` reads inside an
/// input of `size`, and the input index read at `lo`.
fn valid_span(
    out: usize,
    size: usize,
    k: usize,
    stride: usize,
    pad: usize,
    dil: usize,
) -> (Range<usize>, usize) {
    // Input index at output o: o·stride + k·dil − pad.
    let shift = (k * dil) as isize - pad as isize;
    let lo = if shift >= 0 { 0 } else { (-shift) as usize }.div_ceil(stride);
    let last = size as isize - 1 - shift;
    let hi = if last < 0 {
        0
    } else {
        (last as usize / stride + 1).min(out)
    };
    let lo = lo.min(hi);
    (
        lo..hi,
        (lo as isize * stride as isize + shift).max(0) as usize,
    )
}

/// A band of output depth planes `planes` of a convolution of `geometry` over an input of `size`
/// (output `out`): the unit the input is unfolded (and its gradient folded back) in.
struct Band<'a> {
    geometry: &'a Geometry3,
    size: [usize; 3],
    out: [usize; 3],
    planes: Range<usize>,
}

impl Band<'_> {
    /// Output positions in the band: the length of one unfolded row.
    fn positions(&self) -> usize {
        self.planes.len() * self.out[1] * self.out[2]
    }

    /// For tap `t`: each output line `(oz, oy)` of the band as its offset in a band row, the
    /// offset of the input line it reads (`None` in the padding), the output columns that read
    /// inside the input and the input column of the first of them.
    fn for_each_line(
        &self,
        tap: usize,
        mut line: impl FnMut(usize, Option<usize>, Range<usize>, usize),
    ) {
        let Band {
            geometry,
            size,
            out,
            ..
        } = *self;
        let [kd, kh, kw] = geometry.kernel;
        let offset = [tap / (kh * kw), tap / kw % kh, tap % kw];
        let spans: [_; 3] = std::array::from_fn(|a| {
            valid_span(
                out[a],
                size[a],
                offset[a],
                geometry.stride[a],
                geometry.padding[a],
                geometry.dilation[a],
            )
        });
        debug_assert!(offset[0] < kd);
        let [_, h, w] = size;
        let [_, oh, ow] = out;
        let (columns, first_column) = spans[2].clone();
        for (i, oz) in self.planes.clone().enumerate() {
            for oy in 0..oh {
                let at = (i * oh + oy) * ow;
                let z = spans[0]
                    .0
                    .contains(&oz)
                    .then(|| spans[0].1 + (oz - spans[0].0.start) * geometry.stride[0]);
                let y = spans[1]
                    .0
                    .contains(&oy)
                    .then(|| spans[1].1 + (oy - spans[1].0.start) * geometry.stride[1]);
                let source = z.zip(y).map(|(z, y)| (z * h + y) * w);
                line(at, source, columns.clone(), first_column);
            }
        }
    }

    /// Rows `c·taps + t` of the unfolded input `x` (`[ci, d, h, w]`) over the band: row
    /// `(c, t)`, column `p` holds what tap `t` of channel `c` reads for output position `p` of
    /// the band (zero in the padding).
    fn unfold(&self, x: &[f32], cols: &mut [f32]) {
        let (taps, volume) = (self.geometry.taps(), self.size.iter().product::<usize>());
        let (row_len, stride) = (self.positions(), self.geometry.stride[2]);
        let width = self.out[2];
        cols.par_chunks_exact_mut(row_len)
            .enumerate()
            .for_each(|(row, dst)| {
                let src = &x[row / taps * volume..][..volume];
                self.for_each_line(row % taps, |at, source, columns, first| {
                    let dst = &mut dst[at..][..width];
                    let Some(source) = source else {
                        dst.fill(0.0);
                        return;
                    };
                    dst[..columns.start].fill(0.0);
                    dst[columns.end..].fill(0.0);
                    let src = &src[source + first..];
                    for (k, d) in dst[columns].iter_mut().enumerate() {
                        *d = src[k * stride];
                    }
                });
            });
    }

    /// Adds the unfolded gradient `cols` (rows `c·taps + t` over the band) back onto the input
    /// positions they were read from, into `dx` (`[ci, d, h, w]`); channels in parallel.
    fn fold(&self, cols: &[f32], dx: &mut [f32]) {
        let (taps, volume) = (self.geometry.taps(), self.size.iter().product::<usize>());
        let (row_len, stride) = (self.positions(), self.geometry.stride[2]);
        dx.par_chunks_exact_mut(volume)
            .zip(cols.par_chunks_exact(taps * row_len))
            .for_each(|(dst, rows)| {
                for (tap, row) in rows.chunks_exact(row_len).enumerate() {
                    self.for_each_line(tap, |at, source, columns, first| {
                        let Some(source) = source else { return };
                        let dst = &mut dst[source + first..];
                        for (k, g) in row[at..][columns].iter().enumerate() {
                            dst[k * stride] += g;
                        }
                    });
                }
            });
    }
}

/// The bands of a convolution of `geometry` over an input of `size` whose unfolding has `rows`
/// rows, each near [`BAND_FLOATS`] unfolded, and the scratch one band unfolds into (none for a
/// 1×1×1 convolution: its input is its own unfolding).
fn bands(
    geometry: &Geometry3,
    size: [usize; 3],
    rows: usize,
) -> (impl Iterator<Item = Band<'_>> + Clone, Vec<f32>) {
    let out = geometry.output(size);
    let per_band = (BAND_FLOATS / (rows * out[1] * out[2]).max(1)).clamp(1, out[0]);
    let scratch = if geometry.is_pointwise() {
        0
    } else {
        rows * per_band * out[1] * out[2]
    };
    let bands = (0..out[0]).step_by(per_band).map(move |z| Band {
        geometry,
        size,
        out,
        planes: z..(z + per_band).min(out[0]),
    });
    (bands, vec![0.0f32; scratch])
}

/// Calls `each(n, planes, unfolded, row_stride)` for every batch item `n` of `x` (`shape`) and
/// band of output depth planes: `unfolded` holds the band's `ci·taps` rows of the unfolded input,
/// `row_stride` apart (for a 1×1×1 convolution the input itself from the band's first pixel, rows
/// a whole volume apart, unfolded into nothing).
fn for_each_unfolded_band(
    x: &[f32],
    shape: Ncdhw,
    geometry: &Geometry3,
    mut each: impl FnMut(usize, Range<usize>, &[f32], usize),
) {
    let [b, ci, d, h, w] = shape;
    let volume = d * h * w;
    let k = ci * geometry.taps();
    let (bands, mut cols) = bands(geometry, [d, h, w], k);
    for n in 0..b {
        let x = &x[n * ci * volume..][..ci * volume];
        for band in bands.clone() {
            if geometry.is_pointwise() {
                let plane = band.out[1] * band.out[2];
                each(
                    n,
                    band.planes.clone(),
                    &x[band.planes.start * plane..],
                    volume,
                );
            } else {
                let cols = &mut cols[..k * band.positions()];
                band.unfold(x, cols);
                each(n, band.planes.clone(), cols, band.positions());
            }
        }
    }
}

/// `conv3d(x, weight)` of `x` (`shape`) with `weight` `[co, ci, kd, kh, kw]`: `[b, co, od, oh, ow]`
/// and the output size.
pub fn conv3d_ncdhw(
    x: &[f32],
    shape: Ncdhw,
    weight: &[f32],
    co: usize,
    geometry: &Geometry3,
) -> (Vec<f32>, [usize; 3]) {
    let [b, ci, d, h, w] = shape;
    let out = geometry.output([d, h, w]);
    let (positions, plane) = (out.iter().product::<usize>(), out[1] * out[2]);
    let k = ci * geometry.taps();
    assert_eq!(weight.len(), co * k, "conv3d: weight size");
    let mut y = vec![0.0f32; b * co * positions];
    for_each_unfolded_band(x, shape, geometry, |n, planes, unfolded, stride| {
        let band = planes.len() * plane;
        let dst = &mut y[(n * co * positions + planes.start * plane)..];
        // SAFETY: the views address `co × band` outputs of this item (rows `positions` apart),
        // the `co × k` weight and the `k × band` unfolded input (rows `stride` apart).
        unsafe {
            gemm_f32(
                [co, band, k],
                Strided::rows(dst.as_mut_ptr(), positions),
                Strided::rows(weight.as_ptr(), k),
                Strided::rows(unfolded.as_ptr(), stride),
                false,
                1.0,
                gemm::Parallelism::Rayon(0),
            );
        }
    });
    (y, out)
}

/// `∂L/∂x` (`[b, ci, size]`) of [`conv3d_ncdhw`] from `grad` (`[b, co, od, oh, ow]`).
pub fn conv3d_input_grad(
    grad: &[f32],
    grad_shape: Ncdhw,
    weight: &[f32],
    ci: usize,
    size: [usize; 3],
    geometry: &Geometry3,
) -> Vec<f32> {
    let [b, co, od, oh, ow] = grad_shape;
    let out = [od, oh, ow];
    let (volume, positions, plane) = (size.iter().product::<usize>(), od * oh * ow, oh * ow);
    let k = ci * geometry.taps();
    assert_eq!(weight.len(), co * k, "conv3d_input_grad: weight size");
    assert_eq!(geometry.output(size), out, "conv3d_input_grad: output size");
    let mut dx = vec![0.0f32; b * ci * volume];
    // A 1×1×1 convolution's unfolded gradient is the input gradient: the GEMM writes it in place.
    let (bands, mut cols) = bands(geometry, size, k);
    for n in 0..b {
        let dx = &mut dx[n * ci * volume..][..ci * volume];
        for unfolding in bands.clone() {
            let (planes, band) = (unfolding.planes.clone(), unfolding.positions());
            let (dst, stride) = if geometry.is_pointwise() {
                (&mut dx[planes.start * plane..], volume)
            } else {
                (&mut cols[..k * band], band)
            };
            // SAFETY: `dst` is `k × band`, rows `stride` apart, inside its slice; the weight
            // read transposed is `k × co`; the gradient view addresses `co × band` values of
            // this item.
            unsafe {
                gemm_f32(
                    [k, band, co],
                    Strided::rows(dst.as_mut_ptr(), stride),
                    Strided::columns(weight.as_ptr(), k),
                    Strided::rows(
                        grad[(n * co * positions + planes.start * plane)..].as_ptr(),
                        positions,
                    ),
                    false,
                    1.0,
                    gemm::Parallelism::Rayon(0),
                );
            }
            if !geometry.is_pointwise() {
                unfolding.fold(&cols[..k * band], dx);
            }
        }
    }
    dx
}

/// `∂L/∂W` (`[co, ci, kd, kh, kw]`) of [`conv3d_ncdhw`] of `x` (`shape`) from `grad`
/// (`[b, co, od, oh, ow]`).
pub fn conv3d_weight_grad(
    x: &[f32],
    shape: Ncdhw,
    grad: &[f32],
    co: usize,
    geometry: &Geometry3,
) -> Vec<f32> {
    let [_, ci, d, h, w] = shape;
    let out = geometry.output([d, h, w]);
    let (positions, plane) = (out.iter().product::<usize>(), out[1] * out[2]);
    let k = ci * geometry.taps();
    let mut dw = vec![0.0f32; co * k];
    for_each_unfolded_band(x, shape, geometry, |n, planes, unfolded, stride| {
        let band = planes.len() * plane;
        let grad = &grad[n * co * positions + planes.start * plane..];
        accumulate_weight_grad(
            &mut dw,
            [grad, unfolded],
            [positions, stride],
            [co, k, band],
        );
    });
    dw
}

/// `dw += ȳ · uᵀ` (`[co, k]`) over `pixels` columns of `ȳ` (`co` rows) and of the unfolded
/// input `u` (`k` rows), each row-major with the given row strides. The product is too small for
/// the GEMM to share among threads, so pieces of the pixels run as independent single-threaded
/// GEMMs into partial sums.
fn accumulate_weight_grad(
    dw: &mut [f32],
    [grad, unfolded]: [&[f32]; 2],
    [grad_stride, unfolded_stride]: [usize; 2],
    [co, k, pixels]: [usize; 3],
) {
    let pieces = (2 * rayon::current_num_threads())
        .min(pixels.div_ceil(MIN_PIECE_PIXELS))
        .max(1);
    let piece = pixels.div_ceil(pieces);
    let sum = (0..pieces)
        .into_par_iter()
        .map(|i| {
            let mut part = vec![0.0f32; co * k];
            let columns = i * piece..((i + 1) * piece).min(pixels);
            // SAFETY: `part` is `co × k`; ȳ's view `co × len` values `grad_stride` apart per
            // row; `u` read transposed is `len × k`, rows `unfolded_stride` apart; both inside
            // their slices (the callers pass `co`/`k` rows of at least `pixels` columns).
            unsafe {
                gemm_f32(
                    [co, k, columns.len()],
                    Strided::rows(part.as_mut_ptr(), k),
                    Strided::rows(grad[columns.start..].as_ptr(), grad_stride),
                    Strided::columns(unfolded[columns.start..].as_ptr(), unfolded_stride),
                    false,
                    1.0,
                    gemm::Parallelism::None,
                );
            }
            part
        })
        .reduce_with(|mut a, b| {
            a.iter_mut().zip(&b).for_each(|(a, b)| *a += b);
            a
        });
    if let Some(sum) = sum {
        dw.iter_mut().zip(&sum).for_each(|(d, s)| *d += s);
    }
}

/// `conv.forward(x)` on the kernels where they apply (the CPU device in training, one group, no
/// bias, explicit padding), else burn's layer (whose forward alone, in inference, is as fast).
pub fn conv3d_forward(conv: &Conv3d, x: Tensor<5>) -> Tensor<5> {
    let padding = match conv.padding {
        PaddingConfig3d::Explicit(d, h, w) => [d, h, w],
        PaddingConfig3d::Valid => [0; 3],
        PaddingConfig3d::Same => return conv.forward(x),
    };
    if conv.groups != 1 || conv.bias.is_some() || !on_cpu_training(&x) {
        return conv.forward(x);
    }
    let geometry = Geometry3 {
        kernel: conv.kernel_size,
        stride: conv.stride,
        padding,
        dilation: conv.dilation,
    };
    let (x, weight) = (x.into_dispatch(), conv.weight.val().into_dispatch());
    Tensor::from_dispatch(<Dispatch as VolumeConvKernels>::kernel_conv3d(
        x, weight, geometry,
    ))
}

/// `conv.forward(x)` for a transposed 3-D convolution (see [`conv3d_forward`]).
pub fn conv_transpose3d_forward(conv: &ConvTranspose3d, x: Tensor<5>) -> Tensor<5> {
    if conv.groups != 1 || conv.bias.is_some() || !on_cpu_training(&x) {
        return conv.forward(x);
    }
    let geometry = Geometry3 {
        kernel: conv.kernel_size,
        stride: conv.stride,
        padding: conv.padding,
        dilation: conv.dilation,
    };
    let (x, weight) = (x.into_dispatch(), conv.weight.val().into_dispatch());
    Tensor::from_dispatch(<Dispatch as VolumeConvKernels>::kernel_conv_transpose3d(
        x,
        weight,
        geometry,
        conv.padding_out,
    ))
}

#[backend_extension(Flex, Autodiff)]
pub trait VolumeConvKernels: Backend {
    /// A one-group 3-D convolution without bias; `weight` `[co, ci, kd, kh, kw]`.
    fn kernel_conv3d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        geometry: Geometry3,
    ) -> FloatTensor<Self>;

    /// A one-group transposed 3-D convolution without bias; `weight` `[ci, co, kd, kh, kw]`.
    fn kernel_conv_transpose3d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        geometry: Geometry3,
        padding_out: [usize; 3],
    ) -> FloatTensor<Self>;
}

/// The gradients of [`VolumeConvKernels::kernel_conv3d`].
pub trait VolumeConvGradKernels: VolumeConvKernels {
    /// `∂L/∂x` for an input shaped like `x`.
    fn kernel_conv3d_x_grad(
        x: &FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        geometry: Geometry3,
    ) -> FloatTensor<Self>;
    fn kernel_conv3d_weight_grad(
        x: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        geometry: Geometry3,
    ) -> FloatTensor<Self>;
}

impl VolumeConvKernels for Flex {
    fn kernel_conv3d(x: FlexTensor, weight: FlexTensor, geometry: Geometry3) -> FlexTensor {
        let shape = dims::<5>(&x);
        let co = dims::<5>(&weight)[0];
        let (y, [od, oh, ow]) = conv3d_ncdhw(&values(&x), shape, &values(&weight), co, &geometry);
        tensor(y, [shape[0], co, od, oh, ow])
    }

    fn kernel_conv_transpose3d(
        x: FlexTensor,
        weight: FlexTensor,
        geometry: Geometry3,
        padding_out: [usize; 3],
    ) -> FlexTensor {
        let shape = dims::<5>(&x);
        let co = dims::<5>(&weight)[1];
        let size = geometry.transposed_output([shape[2], shape[3], shape[4]], padding_out);
        let y = conv3d_input_grad(&values(&x), shape, &values(&weight), co, size, &geometry);
        tensor(y, [shape[0], co, size[0], size[1], size[2]])
    }
}

impl VolumeConvGradKernels for Flex {
    fn kernel_conv3d_x_grad(
        x: &FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        geometry: Geometry3,
    ) -> FlexTensor {
        let [b, ci, d, h, w] = dims::<5>(x);
        let dx = conv3d_input_grad(
            &values(&grad),
            dims::<5>(&grad),
            &values(&weight),
            ci,
            [d, h, w],
            &geometry,
        );
        tensor(dx, [b, ci, d, h, w])
    }

    fn kernel_conv3d_weight_grad(
        x: FlexTensor,
        grad: FlexTensor,
        geometry: Geometry3,
    ) -> FlexTensor {
        let shape = dims::<5>(&x);
        let co = dims::<5>(&grad)[1];
        let dw = conv3d_weight_grad(&values(&x), shape, &values(&grad), co, &geometry);
        let [kd, kh, kw] = geometry.kernel;
        tensor(dw, [co, shape[1], kd, kh, kw])
    }
}

/// The backward step of [`VolumeConvKernels::kernel_conv3d`]: parents `[x, weight]`; state: the
/// checkpointed `x` and `weight`, and the geometry.
#[derive(Debug)]
struct Conv3dBackward;

impl<B: VolumeConvGradKernels> Backward<B, 2> for Conv3dBackward {
    type State = ([NodeId; 2], Geometry3);

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, saved: &mut Checkpointer) {
        let (grad, [x, weight], geometry, [dx, dw]) =
            checkpointed_step_inputs::<B, _, 2>(ops, grads, saved);
        register::<B>(grads, dx, || {
            B::kernel_conv3d_x_grad(&x, weight, grad.clone(), geometry)
        });
        register::<B>(grads, dw, || {
            B::kernel_conv3d_weight_grad(x, grad, geometry)
        });
    }
}

/// The backward step of [`VolumeConvKernels::kernel_conv_transpose3d`]: the input gradient is
/// the convolution of the output gradient, the weight gradient that convolution's weight
/// gradient with the roles of input and output gradient swapped.
#[derive(Debug)]
struct ConvTranspose3dBackward;

impl<B: VolumeConvGradKernels> Backward<B, 2> for ConvTranspose3dBackward {
    type State = ([NodeId; 2], Geometry3);

    fn backward(self, ops: Ops<Self::State, 2>, grads: &mut Gradients, saved: &mut Checkpointer) {
        let (grad, [x, weight], geometry, [dx, dw]) =
            checkpointed_step_inputs::<B, _, 2>(ops, grads, saved);
        register::<B>(grads, dx, || {
            B::kernel_conv3d(grad.clone(), weight, geometry)
        });
        register::<B>(grads, dw, || {
            B::kernel_conv3d_weight_grad(grad, x, geometry)
        });
    }
}

impl<B: VolumeConvGradKernels, C: CheckpointStrategy> VolumeConvKernels for Autodiff<B, C> {
    fn kernel_conv3d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        geometry: Geometry3,
    ) -> FloatTensor<Self> {
        Conv3dBackward.record::<C, _>(
            [x, weight],
            geometry,
            checkpoint_input_and_weight,
            |[x, weight], geometry| B::kernel_conv3d(x, weight, geometry),
        )
    }

    fn kernel_conv_transpose3d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        geometry: Geometry3,
        padding_out: [usize; 3],
    ) -> FloatTensor<Self> {
        ConvTranspose3dBackward.record::<C, _>(
            [x, weight],
            geometry,
            checkpoint_input_and_weight,
            |[x, weight], geometry| B::kernel_conv_transpose3d(x, weight, geometry, padding_out),
        )
    }
}

#[cfg(test)]
mod tests {
    use burn::module::Module;
    use burn::nn::conv::{Conv3dConfig, ConvTranspose3dConfig};
    use burn::tensor::{Device, Distribution};

    use crate::test_support::{assert_close, position_weighted_grads};

    use super::*;

    /// Runs `forward` with ours or burn's layer under autodiff; the output and the gradients of
    /// the input and the weight.
    fn outcome<M: Module>(
        x: &Tensor<5>,
        layer: &M,
        weight: impl Fn(&M) -> Tensor<5>,
        forward: impl Fn(&M, Tensor<5>) -> Tensor<5>,
    ) -> [Tensor<5>; 3] {
        let x = x.clone().require_grad();
        let y = forward(layer, x.clone());
        let grads = position_weighted_grads(&y);
        [
            y.inner(),
            x.grad(&grads).expect("x gradient"),
            weight(layer).grad(&grads).expect("weight gradient"),
        ]
    }

    /// Forward values and both gradients equal burn's layers: the hourglass's shapes (3³
    /// stride 1 and 2, 1³, the 4³ stride-2 transposed convolution), dilation, batch 2, sizes
    /// that strides do not divide, a band split over depth.
    #[test]
    fn convolutions_match_burn() {
        let device = Device::flex().autodiff();
        // (x dims, co, kernel, stride, padding, dilation)
        let cases: [([usize; 5], usize, usize, usize, usize, usize); 5] = [
            ([1, 8, 12, 9, 10], 8, 3, 1, 1, 1),
            ([2, 6, 7, 10, 9], 12, 3, 2, 1, 1),
            ([1, 5, 6, 7, 8], 7, 1, 1, 0, 1),
            ([1, 4, 9, 8, 7], 6, 3, 1, 2, 2),
            ([1, 3, 160, 40, 40], 4, 3, 1, 1, 1),
        ];
        for (dims, co, k, stride, pad, dil) in cases {
            let x = Tensor::random(dims, Distribution::Normal(0.0, 1.0), &device);
            let conv = Conv3dConfig::new([dims[1], co], [k; 3])
                .with_stride([stride; 3])
                .with_padding(PaddingConfig3d::Explicit(pad, pad, pad))
                .with_dilation([dil; 3])
                .with_bias(false)
                .init(&device);
            let weight = |c: &Conv3d| c.weight.val();
            let ours = outcome(&x, &conv, weight, conv3d_forward);
            let burn = outcome(&x, &conv, weight, |c, x| c.forward(x));
            let what = format!("conv3d {dims:?} co{co} k{k} s{stride} p{pad} d{dil}");
            for (name, (a, b)) in ["output", "∂x", "∂w"]
                .iter()
                .zip(ours.into_iter().zip(burn))
            {
                assert_close(&format!("{what} {name}"), a, b);
            }
        }
        // (x dims, co, kernel, stride, padding, padding_out)
        let cases: [([usize; 5], usize, usize, usize, usize, usize); 3] = [
            ([1, 16, 6, 4, 5], 8, 4, 2, 1, 0),
            ([2, 6, 3, 5, 4], 5, 3, 2, 1, 1),
            ([1, 4, 5, 6, 7], 3, 3, 1, 1, 0),
        ];
        for (dims, co, k, stride, pad, pad_out) in cases {
            let x = Tensor::random(dims, Distribution::Normal(0.0, 1.0), &device);
            let conv = ConvTranspose3dConfig::new([dims[1], co], [k; 3])
                .with_stride([stride; 3])
                .with_padding([pad; 3])
                .with_padding_out([pad_out; 3])
                .with_bias(false)
                .init(&device);
            let weight = |c: &ConvTranspose3d| c.weight.val();
            let ours = outcome(&x, &conv, weight, conv_transpose3d_forward);
            let burn = outcome(&x, &conv, weight, |c, x| c.forward(x));
            let what = format!("conv_transpose3d {dims:?} co{co} k{k} s{stride} p{pad} o{pad_out}");
            for (name, (a, b)) in ["output", "∂x", "∂w"]
                .iter()
                .zip(ours.into_iter().zip(burn))
            {
                assert_close(&format!("{what} {name}"), a, b);
            }
        }
    }
}
