//! The convolution kernels as a burn backend operation, so that training on the CPU runs them
//! too, forward and backward.
//!
//! Why: under autodiff the layers fell back to burn's CPU convolution, whose forward (im2col tiles,
//! NHWC conversions, fresh buffers) and backward (a transposed convolution for the input, another
//! im2col pass for the weight) made most of a MonSter++ training step (BENCHMARKS.md, "SegFormer
//! and the training step against PyTorch"). [`conv2d`] is a burn extension operation (`Flex`, and
//! `Autodiff<Flex>` with a hand-written backward on [`super::gradients`]); other dtypes fall back
//! to burn's own convolution and its gradients.

use std::borrow::Cow;
use std::sync::Arc;

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::autodiff::NodeId;
use burn::backend::flex::FlexTensor;
use burn::backend::ops::{ConvOptions, ConvTransposeOptions, ModuleOps};
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex};
use burn::tensor::Tensor;

use super::epilogue::Epilogue;
use super::geometry::{Geometry, Nchw, TransposeGeometry};
use super::gradients::{bias_grad, conv2d_input_grad, conv2d_weight_grad};
use super::kernels::{conv2d_nchw, conv_transpose2d_nchw};
use super::prepared::{prepared_for_buffer, LayerWeights};
use crate::custom_op::{checkpoint_input_and_weight, checkpointed_step_inputs, register, RecordOp};
use crate::flex_tensor::{all_f32, dims, tensor, values};

/// `conv2d(x, weight, bias)` (one group, explicit padding) on the kernels, differentiable where
/// `x` tracks gradients. Only for the CPU device (`Flex`, with or without autodiff).
pub fn conv2d(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    geometry: Geometry,
) -> Tensor<4> {
    let [top, left, bottom, right] = geometry.padding;
    let options = ConvOptions::new_with_padding(
        geometry.stride,
        [(top, bottom), (left, right)],
        geometry.dilation,
        1,
    );
    let (x, weight) = (x.into_dispatch(), weight.into_dispatch());
    Tensor::from_dispatch(match bias {
        Some(bias) => {
            <Dispatch as ConvKernels>::kernel_conv2d_bias(x, weight, bias.into_dispatch(), options)
        }
        None => <Dispatch as ConvKernels>::kernel_conv2d(x, weight, options),
    })
}

/// `conv_transpose2d(x, weight, bias)` (`weight` `[ci, co, kh, kw]`, one group) on the kernels,
/// differentiable where `x` tracks gradients; its backward is the convolution of the output
/// gradient with the same weight and that convolution's weight gradient with the roles of input
/// and output gradient swapped. Only for the CPU device.
pub fn conv_transpose2d(
    x: Tensor<4>,
    weight: Tensor<4>,
    bias: Option<Tensor<1>>,
    geometry: TransposeGeometry,
) -> Tensor<4> {
    let (x, weight) = (x.into_dispatch(), weight.into_dispatch());
    Tensor::from_dispatch(match bias {
        Some(bias) => <Dispatch as ConvKernels>::kernel_conv_transpose2d_bias(
            x,
            weight,
            bias.into_dispatch(),
            geometry,
        ),
        None => <Dispatch as ConvKernels>::kernel_conv_transpose2d(x, weight, geometry),
    })
}

#[backend_extension(Flex, Autodiff)]
pub trait ConvKernels: Backend {
    /// A one-group 2-D convolution on the kernels.
    fn kernel_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self>;

    /// [`kernel_conv2d`](Self::kernel_conv2d) plus a bias (the extension macro of burn 0.22.1
    /// does not route an `Option` of a tensor).
    fn kernel_conv2d_bias(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self>;

    /// A one-group transposed 2-D convolution on the kernels; `weight` `[ci, co, kh, kw]`.
    fn kernel_conv_transpose2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        geometry: TransposeGeometry,
    ) -> FloatTensor<Self>;

    /// [`kernel_conv_transpose2d`](Self::kernel_conv_transpose2d) plus a bias.
    fn kernel_conv_transpose2d_bias(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        geometry: TransposeGeometry,
    ) -> FloatTensor<Self>;
}

/// The gradients of [`ConvKernels::kernel_conv2d`] on a backend that has the kernels.
pub trait ConvGradKernels: ConvKernels {
    fn kernel_conv2d_x_grad(
        x: &FloatTensor<Self>,
        weight: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self>;
    fn kernel_conv2d_weight_grad(
        x: FloatTensor<Self>,
        weight: &FloatTensor<Self>,
        grad: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self>;
    fn kernel_conv2d_bias_grad(grad: FloatTensor<Self>) -> FloatTensor<Self>;
}

fn geometry_of(options: &ConvOptions<2>, weight: &FlexTensor) -> Geometry {
    let dims = weight.layout().shape();
    let [(top, bottom), (left, right)] = options.padding;
    Geometry {
        kernel: [dims[2], dims[3]],
        stride: options.stride,
        padding: [top, left, bottom, right],
        dilation: options.dilation,
    }
}

impl ConvKernels for Flex {
    fn kernel_conv2d(x: FlexTensor, weight: FlexTensor, options: ConvOptions<2>) -> FlexTensor {
        flex_conv2d(x, weight, None, options)
    }

    fn kernel_conv2d_bias(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        options: ConvOptions<2>,
    ) -> FlexTensor {
        flex_conv2d(x, weight, Some(bias), options)
    }

    fn kernel_conv_transpose2d(
        x: FlexTensor,
        weight: FlexTensor,
        geometry: TransposeGeometry,
    ) -> FlexTensor {
        flex_conv_transpose2d(x, weight, None, geometry)
    }

    fn kernel_conv_transpose2d_bias(
        x: FlexTensor,
        weight: FlexTensor,
        bias: FlexTensor,
        geometry: TransposeGeometry,
    ) -> FlexTensor {
        flex_conv_transpose2d(x, weight, Some(bias), geometry)
    }
}

/// [`ConvKernels::kernel_conv_transpose2d`] on `Flex`: burn's for other dtypes.
fn flex_conv_transpose2d(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    geometry: TransposeGeometry,
) -> FlexTensor {
    if !all_f32([&x, &weight].into_iter().chain(&bias)) {
        let options = ConvTransposeOptions::new(
            geometry.stride,
            geometry.padding,
            geometry.padding_out,
            geometry.dilation,
            1,
        );
        return <Flex as ModuleOps<Flex>>::conv_transpose2d(x, weight, bias, options);
    }
    let [b, c, h, w] = dims::<4>(&x);
    let co = dims::<4>(&weight)[1];
    let bias = bias.as_ref().map(values);
    let (out, [oh, ow]) = conv_transpose2d_nchw(
        &values(&x),
        Nchw { b, c, h, w },
        &values(&weight),
        co,
        geometry,
        bias.as_deref(),
        Epilogue::bias(None),
    );
    tensor(out, [b, co, oh, ow])
}

/// The convolution whose input gradient a transposed convolution of `geometry` is.
fn forward_options(geometry: &TransposeGeometry) -> ConvOptions<2> {
    ConvOptions::new(geometry.stride, geometry.padding, geometry.dilation, 1)
}

/// The kernels' view of a weight tensor `[co, ci, kh, kw]`, made once per
/// [`with_prepared_weights`](super::with_prepared_weights) scope for the forward and the input
/// gradient alike (keyed by the tensor's buffer where its values are contiguous).
fn layer_weights(weight: &FlexTensor) -> Arc<LayerWeights> {
    let [co, _, kh, kw] = dims::<4>(weight);
    match values(weight) {
        Cow::Borrowed(contiguous) => prepared_for_buffer(contiguous, weight.clone(), || {
            LayerWeights::new(contiguous.to_vec(), co, kh * kw)
        }),
        Cow::Owned(copied) => Arc::new(LayerWeights::new(copied, co, kh * kw)),
    }
}

/// [`ConvKernels::kernel_conv2d`] on `Flex`: burn's convolution for other dtypes.
fn flex_conv2d(
    x: FlexTensor,
    weight: FlexTensor,
    bias: Option<FlexTensor>,
    options: ConvOptions<2>,
) -> FlexTensor {
    if !all_f32([&x, &weight].into_iter().chain(&bias)) {
        return <Flex as ModuleOps<Flex>>::conv2d(x, weight, bias, options);
    }
    let [b, c, h, w] = dims::<4>(&x);
    let co = dims::<4>(&weight)[0];
    let geometry = geometry_of(&options, &weight);
    let weights = layer_weights(&weight);
    let bias = bias.as_ref().map(values);
    let (out, [oh, ow]) = conv2d_nchw(
        &values(&x),
        Nchw { b, c, h, w },
        &weights,
        geometry,
        Epilogue::bias(bias.as_deref()),
    );
    tensor(out, [b, co, oh, ow])
}

impl ConvGradKernels for Flex {
    fn kernel_conv2d_x_grad(
        x: &FlexTensor,
        weight: FlexTensor,
        grad: FlexTensor,
        options: ConvOptions<2>,
    ) -> FlexTensor {
        if !all_f32([x, &weight, &grad]) {
            return <Flex as ModuleOps<Flex>>::conv2d_x_backward(x.clone(), weight, grad, options);
        }
        let [b, ci, h, w] = dims::<4>(x);
        let [_, co, oh, ow] = dims::<4>(&grad);
        let geometry = geometry_of(&options, &weight);
        let shape = Nchw {
            b,
            c: co,
            h: oh,
            w: ow,
        };
        let out = conv2d_input_grad(
            &values(&grad),
            shape,
            &layer_weights(&weight),
            [h, w],
            geometry,
        );
        tensor(out, [b, ci, h, w])
    }

    fn kernel_conv2d_weight_grad(
        x: FlexTensor,
        weight: &FlexTensor,
        grad: FlexTensor,
        options: ConvOptions<2>,
    ) -> FlexTensor {
        if !all_f32([&x, weight, &grad]) {
            return <Flex as ModuleOps<Flex>>::conv2d_weight_backward(
                x,
                weight.clone(),
                grad,
                options,
            );
        }
        let [b, c, h, w] = dims::<4>(&x);
        let dims = dims::<4>(weight);
        let geometry = geometry_of(&options, weight);
        let out = conv2d_weight_grad(
            &values(&x),
            Nchw { b, c, h, w },
            &values(&grad),
            dims[0],
            geometry,
        );
        tensor(out, dims)
    }

    fn kernel_conv2d_bias_grad(grad: FlexTensor) -> FlexTensor {
        if !all_f32([&grad]) {
            return <Flex as burn::backend::ops::FloatTensorOps<Flex>>::float_sum_dims(
                grad,
                &[0, 2, 3],
            );
        }
        let [b, c, h, w] = dims::<4>(&grad);
        tensor(bias_grad(&values(&grad), Nchw { b, c, h, w }), [c])
    }
}

/// The backward step of [`ConvKernels::kernel_conv2d`]: parents `[x, weight]` or
/// `[x, weight, bias]`; state: the checkpointed `x` and `weight`, and the options.
#[derive(Debug)]
struct Conv2dBackward<const N: usize>;

impl<B: ConvGradKernels, const N: usize> Backward<B, N> for Conv2dBackward<N> {
    type State = ([NodeId; 2], ConvOptions<2>);

    fn backward(self, ops: Ops<Self::State, N>, grads: &mut Gradients, saved: &mut Checkpointer) {
        let (grad, [x, weight], options, parents) =
            checkpointed_step_inputs::<B, _, N>(ops, grads, saved);
        register::<B>(grads, parents[0], || {
            B::kernel_conv2d_x_grad(&x, weight.clone(), grad.clone(), options.clone())
        });
        register::<B>(grads, parents[1], || {
            B::kernel_conv2d_weight_grad(x, &weight, grad.clone(), options)
        });
        register::<B>(grads, bias_parent(&parents), || {
            B::kernel_conv2d_bias_grad(grad)
        });
    }
}

/// The backward step of [`ConvKernels::kernel_conv_transpose2d`]: parents `[x, weight]` or
/// `[x, weight, bias]`; state: the checkpointed `x` and `weight`, and the geometry.
#[derive(Debug)]
struct ConvTranspose2dBackward<const N: usize>;

impl<B: ConvGradKernels, const N: usize> Backward<B, N> for ConvTranspose2dBackward<N> {
    type State = ([NodeId; 2], TransposeGeometry);

    fn backward(self, ops: Ops<Self::State, N>, grads: &mut Gradients, saved: &mut Checkpointer) {
        let (grad, [x, weight], geometry, parents) =
            checkpointed_step_inputs::<B, _, N>(ops, grads, saved);
        let options = forward_options(&geometry);
        register::<B>(grads, parents[0], || {
            B::kernel_conv2d(grad.clone(), weight.clone(), options.clone())
        });
        register::<B>(grads, parents[1], || {
            B::kernel_conv2d_weight_grad(grad.clone(), &weight, x, options)
        });
        register::<B>(grads, bias_parent(&parents), || {
            B::kernel_conv2d_bias_grad(grad)
        });
    }
}

/// The bias's parent of a convolution step: the third where there is one.
fn bias_parent<const N: usize>(parents: &[Option<NodeId>; N]) -> Option<NodeId> {
    parents.get(2).copied().flatten()
}

impl<B: ConvGradKernels, C: CheckpointStrategy> ConvKernels for Autodiff<B, C> {
    fn kernel_conv2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        Conv2dBackward::<2>.record::<C, _>(
            [x, weight],
            options,
            checkpoint_input_and_weight,
            |[x, weight], options| B::kernel_conv2d(x, weight, options),
        )
    }

    fn kernel_conv2d_bias(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        options: ConvOptions<2>,
    ) -> FloatTensor<Self> {
        Conv2dBackward::<3>.record::<C, _>(
            [x, weight, bias],
            options,
            checkpoint_input_and_weight,
            |[x, weight, bias], options| B::kernel_conv2d_bias(x, weight, bias, options),
        )
    }

    fn kernel_conv_transpose2d(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        geometry: TransposeGeometry,
    ) -> FloatTensor<Self> {
        ConvTranspose2dBackward::<2>.record::<C, _>(
            [x, weight],
            geometry,
            checkpoint_input_and_weight,
            |[x, weight], geometry| B::kernel_conv_transpose2d(x, weight, geometry),
        )
    }

    fn kernel_conv_transpose2d_bias(
        x: FloatTensor<Self>,
        weight: FloatTensor<Self>,
        bias: FloatTensor<Self>,
        geometry: TransposeGeometry,
    ) -> FloatTensor<Self> {
        ConvTranspose2dBackward::<3>.record::<C, _>(
            [x, weight, bias],
            geometry,
            checkpoint_input_and_weight,
            |[x, weight, bias], geometry| {
                B::kernel_conv_transpose2d_bias(x, weight, bias, geometry)
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::module::{conv2d as burn_conv2d, conv_transpose2d as burn_conv_transpose2d};
    use burn::tensor::{Device, Distribution};

    use crate::test_support::{assert_close, position_weighted_grads};

    use super::*;

    fn random<const D: usize>(dims: [usize; D], device: &Device) -> Tensor<D> {
        Tensor::random(dims, Distribution::Normal(0.0, 1.0), device)
    }

    /// The output of `layer(x, weight, bias)` under autodiff and the gradients of `x`, the
    /// weight and the bias.
    type Outcome = (Tensor<4>, Tensor<4>, Tensor<4>, Option<Tensor<1>>);

    fn outcome(
        [x, weight]: [&Tensor<4>; 2],
        bias: &Option<Tensor<1>>,
        layer: impl FnOnce(Tensor<4>, Tensor<4>, Option<Tensor<1>>) -> Tensor<4>,
    ) -> Outcome {
        let x = x.clone().require_grad();
        let weight = weight.clone().require_grad();
        let bias = bias.clone().map(Tensor::require_grad);
        let y = layer(x.clone(), weight.clone(), bias.clone());
        let grads = position_weighted_grads(&y);
        (
            y.inner(),
            x.grad(&grads).expect("x gradient"),
            weight.grad(&grads).expect("weight gradient"),
            bias.map(|b| b.grad(&grads).expect("bias gradient")),
        )
    }

    /// Asserts our outcome equals burn's, part by part.
    fn assert_outcomes_close(what: &str, ours: Outcome, theirs: Outcome) {
        assert_close(&format!("{what} output"), ours.0, theirs.0);
        assert_close(&format!("{what} ∂x"), ours.1, theirs.1);
        assert_close(&format!("{what} ∂w"), ours.2, theirs.2);
        if let (Some(a), Some(b)) = (ours.3, theirs.3) {
            assert_close(&format!("{what} ∂b"), a, b);
        }
    }

    /// Forward values and the gradients of `x`, the weight and the bias equal burn's
    /// convolution under autodiff: Winograd and tap GEMMs (stride 1, 3×3 on a small map), the
    /// transposed path (strides 2 and 3, padding beyond the kernel), dilation, asymmetric
    /// padding, 1×1, batch 2, thin layers and no bias.
    #[test]
    fn gradients_match_burn_convolution() {
        // (x dims, [co, kh, kw], stride, dilation, [top, left, bottom, right], bias)
        type Case = ([usize; 4], [usize; 3], usize, usize, [usize; 4], bool);
        let cases: [Case; 10] = [
            ([1, 24, 13, 11], [32, 3, 3], 1, 1, [1, 1, 1, 1], true),
            ([2, 20, 12, 13], [16, 3, 3], 1, 1, [0, 1, 2, 1], false),
            ([1, 24, 9, 11], [32, 3, 3], 1, 1, [1, 1, 1, 1], true),
            ([1, 18, 6, 9], [20, 1, 1], 1, 1, [0, 0, 0, 0], true),
            ([1, 16, 12, 10], [8, 7, 7], 1, 1, [3, 3, 3, 3], true),
            ([1, 17, 10, 10], [16, 3, 3], 1, 2, [2, 2, 2, 2], true),
            ([1, 3, 17, 22], [32, 3, 3], 2, 1, [1, 1, 1, 1], false),
            ([2, 24, 16, 20], [48, 3, 3], 2, 2, [2, 2, 2, 2], true),
            ([1, 16, 15, 9], [6, 4, 4], 3, 1, [0, 2, 1, 0], true),
            ([1, 16, 7, 8], [4, 1, 5], 1, 1, [0, 3, 0, 2], true),
        ];
        let device = Device::flex().autodiff();
        for (dims, [co, kh, kw], stride, dilation, padding, with_bias) in cases {
            let x = random(dims, &device);
            let weight = random([co, dims[1], kh, kw], &device);
            let bias = with_bias.then(|| random([co], &device));
            let geometry = Geometry {
                kernel: [kh, kw],
                stride: [stride; 2],
                padding,
                dilation: [dilation; 2],
            };
            let [top, left, bottom, right] = padding;
            let options = ConvOptions::new_with_padding(
                [stride; 2],
                [(top, bottom), (left, right)],
                [dilation; 2],
                1,
            );
            let ours = outcome([&x, &weight], &bias, |x, w, b| conv2d(x, w, b, geometry));
            let theirs = outcome([&x, &weight], &bias, |x, w, b| {
                burn_conv2d(x, w, b, options)
            });
            let what = format!("{dims:?} k{kh}×{kw} s{stride} d{dilation} p{padding:?}");
            assert_outcomes_close(&what, ours, theirs);
        }
    }

    /// The transposed convolution's values and gradients equal burn's: MonSter++'s 4×4
    /// stride-2 upsampling, 3×3 stride 2 with output padding, stride 1, dilation, batch 2, with
    /// and without bias.
    #[test]
    fn transposed_gradients_match_burn() {
        // (x dims, [co, k], stride, padding, padding_out, dilation, bias)
        type Case = ([usize; 4], [usize; 2], usize, usize, usize, usize, bool);
        let cases: [Case; 5] = [
            ([1, 24, 8, 9], [16, 4], 2, 1, 0, 1, false),
            ([2, 12, 7, 6], [10, 3], 2, 1, 1, 1, true),
            ([1, 16, 9, 11], [12, 3], 1, 1, 0, 1, true),
            ([1, 8, 6, 7], [6, 3], 1, 2, 0, 2, false),
            ([1, 96, 10, 12], [48, 4], 2, 1, 0, 1, true),
        ];
        let device = Device::flex().autodiff();
        for (dims, [co, k], stride, padding, padding_out, dilation, with_bias) in cases {
            let x = random(dims, &device);
            let weight = random([dims[1], co, k, k], &device);
            let bias = with_bias.then(|| random([co], &device));
            let geometry = TransposeGeometry {
                kernel: [k; 2],
                stride: [stride; 2],
                padding: [padding; 2],
                dilation: [dilation; 2],
                padding_out: [padding_out; 2],
            };
            let options = ConvTransposeOptions::new(
                [stride; 2],
                [padding; 2],
                [padding_out; 2],
                [dilation; 2],
                1,
            );
            let ours = outcome([&x, &weight], &bias, |x, w, b| {
                conv_transpose2d(x, w, b, geometry)
            });
            let theirs = outcome([&x, &weight], &bias, |x, w, b| {
                burn_conv_transpose2d(x, w, b, options)
            });
            let what = format!("{dims:?} k{k} s{stride} p{padding} o{padding_out} d{dilation}");
            assert_outcomes_close(&what, ours, theirs);
        }
    }
}
