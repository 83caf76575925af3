//! ReLU, leaky ReLU, the logistic sigmoid and `tanh` in one parallel pass each, forward and
//! backward, for the CPU device in training.
//!
//! Why: burn composes leaky ReLU from a comparison, a scaled copy and a select, whose backward
//! makes two zero tensors and two more selects (on the hourglass's 3-D volumes that cost more than
//! the convolutions around them), and runs ReLU, sigmoid and `tanh` on one thread (ReLU alone was a
//! large part of the main thread's serial time in a training step: BENCHMARKS.md, "SegFormer and
//! the training step against PyTorch"), forward and again in the backward (the ConvGRU's gates,
//! every iteration). Here the forward is one pass over the input and the backward one pass over the
//! saved output: each derivative is a function of the output (`σ' = σ(1 − σ)`, `tanh' = 1 − tanh²`,
//! (leaky) ReLU: the output's sign).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex, TensorMetadata};
use burn::tensor::{activation, DType, Tensor};
use rayon::prelude::*;

use crate::cpu_mode::on_cpu_training;
use crate::custom_op::{register, step_inputs, RecordOp};
use crate::fastmath;
use crate::flex_tensor::{tensor, updated, values, ELEMENTWISE_CHUNK};

/// `max(x, 0)` (NaN stays NaN, as torch's `relu`).
pub fn relu<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    if kernels_apply(&x) {
        return pointwise(x, Pointwise::Relu);
    }
    activation::relu(x)
}

/// `x` where `x ≥ 0`, `slope · x` elsewhere (torch's `leaky_relu`).
pub fn leaky_relu<const D: usize>(x: Tensor<D>, slope: f32) -> Tensor<D> {
    // The one-pass backward reads the sign off the output: a positive slope keeps it.
    if slope > 0.0 && kernels_apply(&x) {
        return pointwise(x, Pointwise::LeakyRelu(slope));
    }
    activation::leaky_relu(x, slope as f64)
}

/// The logistic sigmoid `1 / (1 + e⁻ˣ)`.
pub fn sigmoid<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    if kernels_apply(&x) {
        return pointwise(x, Pointwise::Sigmoid);
    }
    activation::sigmoid(x)
}

/// `tanh x`.
pub fn tanh<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    if kernels_apply(&x) {
        return pointwise(x, Pointwise::Tanh);
    }
    activation::tanh(x)
}

fn kernels_apply<const D: usize>(x: &Tensor<D>) -> bool {
    on_cpu_training(x) && x.dtype() == DType::F32
}

fn pointwise<const D: usize>(x: Tensor<D>, op: Pointwise) -> Tensor<D> {
    Tensor::from_dispatch(<Dispatch as ActivationKernels>::kernel_pointwise(
        x.into_dispatch(),
        op,
    ))
}

/// An element-wise activation whose derivative is a function of its output.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Pointwise {
    Relu,
    /// Leaky ReLU with a positive slope.
    LeakyRelu(f32),
    Sigmoid,
    Tanh,
}

impl Pointwise {
    #[inline(always)]
    fn apply(self, x: f32) -> f32 {
        match self {
            Pointwise::Relu => {
                if x < 0.0 {
                    0.0
                } else {
                    x
                }
            }
            Pointwise::LeakyRelu(slope) => {
                if x < 0.0 {
                    x * slope
                } else {
                    x
                }
            }
            Pointwise::Sigmoid => fastmath::sigmoid(x),
            Pointwise::Tanh => fastmath::tanh(x),
        }
    }

    /// `∂y/∂x` at the input whose output is `y`.
    #[inline(always)]
    fn derivative(self, y: f32) -> f32 {
        match self {
            Pointwise::Relu => {
                if y > 0.0 {
                    1.0
                } else {
                    0.0
                }
            }
            Pointwise::LeakyRelu(slope) => {
                if y < 0.0 {
                    slope
                } else {
                    1.0
                }
            }
            Pointwise::Sigmoid => y * (1.0 - y),
            Pointwise::Tanh => 1.0 - y * y,
        }
    }
}

#[backend_extension(Flex, Autodiff)]
pub trait ActivationKernels: Backend {
    /// `op` applied to every element of `x`.
    fn kernel_pointwise(x: FloatTensor<Self>, op: Pointwise) -> FloatTensor<Self>;
}

/// The gradient of [`ActivationKernels::kernel_pointwise`] from its output.
pub trait ActivationGradKernels: ActivationKernels {
    fn kernel_pointwise_grad(
        output: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        op: Pointwise,
    ) -> FloatTensor<Self>;
}

impl Pointwise {
    /// `out[i] = op(x[i])`: the variant is matched once, outside the loop, so that each loop
    /// vectorises.
    fn apply_slice(self, x: &[f32], out: &mut [f32]) {
        match self {
            Pointwise::Relu => map_into(x, out, |v| Pointwise::Relu.apply(v)),
            Pointwise::LeakyRelu(s) => map_into(x, out, |v| Pointwise::LeakyRelu(s).apply(v)),
            Pointwise::Sigmoid => map_into(x, out, fastmath::sigmoid),
            Pointwise::Tanh => map_into(x, out, fastmath::tanh),
        }
    }

    /// `grad[i] *= op'(y[i])` for the outputs `y`, one loop per variant as
    /// [`Pointwise::apply_slice`].
    fn scale_by_derivative(self, y: &[f32], grad: &mut [f32]) {
        match self {
            Pointwise::Relu => scale_into(y, grad, |v| Pointwise::Relu.derivative(v)),
            Pointwise::LeakyRelu(s) => {
                scale_into(y, grad, |v| Pointwise::LeakyRelu(s).derivative(v))
            }
            Pointwise::Sigmoid => scale_into(y, grad, |v| Pointwise::Sigmoid.derivative(v)),
            Pointwise::Tanh => scale_into(y, grad, |v| Pointwise::Tanh.derivative(v)),
        }
    }
}

#[inline(always)]
fn map_into(x: &[f32], out: &mut [f32], f: impl Fn(f32) -> f32) {
    out.iter_mut().zip(x).for_each(|(o, &v)| *o = f(v));
}

#[inline(always)]
fn scale_into(y: &[f32], grad: &mut [f32], d: impl Fn(f32) -> f32) {
    grad.iter_mut().zip(y).for_each(|(g, &y)| *g *= d(y));
}

/// `pass(input piece, output piece)` over matching pieces of `input` and `out`: in parallel
/// pieces of [`ELEMENTWISE_CHUNK`], or here for small tensors (handing them to the pool costs
/// more than the pass).
fn by_pieces(input: &[f32], out: &mut [f32], pass: impl Fn(&[f32], &mut [f32]) + Sync) {
    if input.len() < 2 * ELEMENTWISE_CHUNK {
        pass(input, out);
    } else {
        out.par_chunks_mut(ELEMENTWISE_CHUNK)
            .zip(input.par_chunks(ELEMENTWISE_CHUNK))
            .for_each(|(o, i)| pass(i, o));
    }
}

impl ActivationKernels for Flex {
    fn kernel_pointwise(x: FlexTensor, op: Pointwise) -> FlexTensor {
        let shape = x.shape();
        let x = values(&x);
        let mut out = vec![0.0f32; x.len()];
        by_pieces(&x, &mut out, |x, out| op.apply_slice(x, out));
        tensor(out, shape)
    }
}

impl ActivationGradKernels for Flex {
    fn kernel_pointwise_grad(output: FlexTensor, grad: FlexTensor, op: Pointwise) -> FlexTensor {
        let output = values(&output);
        updated(grad, |grad| {
            by_pieces(&output, grad, |y, g| op.scale_by_derivative(y, g))
        })
    }
}

/// The backward step of [`ActivationKernels::kernel_pointwise`]; state: the output, the op.
#[derive(Debug)]
struct PointwiseBackward;

impl<B: ActivationGradKernels> Backward<B, 1> for PointwiseBackward {
    type State = (FloatTensor<B>, Pointwise);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (grad, (output, op), [x]) = step_inputs::<B, _, 1>(ops, grads);
        register::<B>(grads, x, || B::kernel_pointwise_grad(output, grad, op));
    }
}

impl<B: ActivationGradKernels, C: CheckpointStrategy> ActivationKernels for Autodiff<B, C> {
    fn kernel_pointwise(x: FloatTensor<Self>, op: Pointwise) -> FloatTensor<Self> {
        PointwiseBackward.record_from_output::<C>(
            [x],
            |[x]| B::kernel_pointwise(x, op),
            |output| (output, op),
        )
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};

    use crate::test_support::output_and_grads;

    use super::*;

    type Activation = fn(Tensor<5>) -> Tensor<5>;

    /// Values and input gradients against burn's, on both CPU devices, on a 5-D volume small
    /// enough for one piece and on one split into parallel pieces (the last one short).
    #[test]
    fn matches_burn() {
        let cases: [(&str, Activation, Activation); 4] = [
            ("relu", relu, activation::relu),
            (
                "leaky_relu",
                |x| leaky_relu(x, 0.2),
                |x| activation::leaky_relu(x, 0.2),
            ),
            ("sigmoid", sigmoid, activation::sigmoid),
            ("tanh", tanh, activation::tanh),
        ];
        let shapes = [[2, 3, 4, 5, 6], [1, 4, 8, 64, 41]];
        assert!(shapes[1].iter().product::<usize>() > 2 * ELEMENTWISE_CHUNK);
        for (device, shape) in [Device::flex(), Device::flex().autodiff()]
            .into_iter()
            .flat_map(|d| shapes.map(|s| (d.clone(), s)))
        {
            for (name, ours_fn, theirs_fn) in cases {
                let x = Tensor::<5>::random(shape, Distribution::Normal(0.0, 1.0), &device);
                let ours = output_and_grads([&x], |[x]| ours_fn(x));
                let theirs = output_and_grads([&x], |[x]| theirs_fn(x));
                let d: f32 = (ours.0 - theirs.0).abs().max().into_scalar();
                assert!(d < 1e-6, "{name} {device:?}: values differ by {d}");
                if let (Some([a]), Some([b])) = (ours.1, theirs.1) {
                    let d: f32 = (a - b).abs().max().into_scalar();
                    assert!(d < 1e-6, "{name} {device:?}: gradients differ by {d}");
                }
            }
        }
    }
}
