//! Leaky ReLU in one pass, forward and backward, for the CPU device in training.
//!
//! Why: burn composes it from a comparison, a scaled copy and a select, and the select's
//! backward makes two zero tensors and two more selects; on the 3-D cost volumes of the
//! hourglass that cost more than the convolutions around them in a training step. Here the
//! forward is one pass and the backward one pass over the saved output (its sign is the
//! input's for a positive slope).

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind};
use burn::backend::flex::FlexTensor;
use burn::backend::ops::ActivationOps;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex, TensorMetadata};
use burn::tensor::{activation, DType, Tensor};
use rayon::prelude::*;

use crate::conv::on_cpu_training;
use crate::flex_tensor::{tensor, values};

/// Elements per parallel task of the element-wise passes.
const CHUNK: usize = 1 << 14;

/// `x` where `x ≥ 0`, `slope · x` elsewhere (torch's `leaky_relu`); `slope` must be positive
/// for the one-pass backward, which reads the sign off the output.
pub fn leaky_relu<const D: usize>(x: Tensor<D>, slope: f32) -> Tensor<D> {
    if slope > 0.0 && on_cpu_training(&x) && x.dtype() == DType::F32 {
        return Tensor::from_dispatch(<Dispatch as ActivationKernels>::kernel_leaky_relu(
            x.into_dispatch(),
            slope,
        ));
    }
    activation::leaky_relu(x, slope as f64)
}

#[backend_extension(Flex, Autodiff)]
pub trait ActivationKernels: Backend {
    /// [`leaky_relu`] with a positive `slope`.
    fn kernel_leaky_relu(x: FloatTensor<Self>, slope: f32) -> FloatTensor<Self>;
}

/// The gradient of [`ActivationKernels::kernel_leaky_relu`] from its output.
pub trait ActivationGradKernels: Backend {
    fn kernel_leaky_relu_grad(
        output: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        slope: f32,
    ) -> FloatTensor<Self>;
}

impl ActivationKernels for Flex {
    fn kernel_leaky_relu(x: FlexTensor, slope: f32) -> FlexTensor {
        if x.dtype() != DType::F32 {
            return <Flex as ActivationOps<Flex>>::leaky_relu(x, (slope as f64).into());
        }
        let shape = x.shape();
        let mut out = values(&x).into_owned();
        out.par_chunks_mut(CHUNK).for_each(|chunk| {
            for v in chunk {
                if *v < 0.0 {
                    *v *= slope;
                }
            }
        });
        tensor(out, shape)
    }
}

impl ActivationGradKernels for Flex {
    fn kernel_leaky_relu_grad(output: FlexTensor, grad: FlexTensor, slope: f32) -> FlexTensor {
        let shape = grad.shape();
        let output = values(&output);
        let mut out = values(&grad).into_owned();
        out.par_chunks_mut(CHUNK)
            .zip(output.par_chunks(CHUNK))
            .for_each(|(g, y)| {
                for (g, y) in g.iter_mut().zip(y) {
                    if *y < 0.0 {
                        *g *= slope;
                    }
                }
            });
        tensor(out, shape)
    }
}

/// The backward step of [`ActivationKernels::kernel_leaky_relu`]; state: the output, the slope.
#[derive(Debug)]
struct LeakyReluBackward;

impl<B: ActivationGradKernels> Backward<B, 1> for LeakyReluBackward {
    type State = (FloatTensor<B>, f32);

    fn backward(self, ops: Ops<Self::State, 1>, grads: &mut Gradients, _: &mut Checkpointer) {
        let grad = grads.consume::<B>(&ops.node);
        let (output, slope) = ops.state;
        if let Some(node) = &ops.parents[0] {
            grads.register::<B>(node.id, B::kernel_leaky_relu_grad(output, grad, slope));
        }
    }
}

impl<B, C> ActivationKernels for Autodiff<B, C>
where
    B: ActivationKernels + ActivationGradKernels,
    C: CheckpointStrategy,
{
    fn kernel_leaky_relu(x: FloatTensor<Self>, slope: f32) -> FloatTensor<Self> {
        match LeakyReluBackward
            .prepare::<C>([x.node()])
            .compute_bound()
            .stateful()
        {
            OpsKind::Tracked(prep) => {
                let out = B::kernel_leaky_relu(x.into_primitive(), slope);
                prep.finish((out.clone(), slope), out)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(B::kernel_leaky_relu(x.into_primitive(), slope))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution, Int};

    use super::*;

    /// Values and input gradient against burn's composition, on both CPU devices, for a 4-D
    /// map and a 5-D volume.
    #[test]
    fn matches_burn() {
        for device in [Device::flex(), Device::flex().autodiff()] {
            let x = Tensor::<5>::random([2, 3, 4, 5, 6], Distribution::Normal(0.0, 1.0), &device);
            let run = |ours: bool| {
                let tracked = device.is_autodiff();
                let x = if tracked {
                    x.clone().require_grad()
                } else {
                    x.clone()
                };
                let y = if ours {
                    leaky_relu(x.clone(), 0.2)
                } else {
                    activation::leaky_relu(x.clone(), 0.2)
                };
                let grad = tracked.then(|| {
                    let count = y.dims().iter().product::<usize>() as i64;
                    let r = Tensor::<1, Int>::arange(0..count, &device)
                        .float()
                        .sin()
                        .reshape(y.dims());
                    let grads = (y.clone() * r).sum().backward();
                    x.grad(&grads).expect("input gradient")
                });
                (y.detach(), grad)
            };
            let (ours, theirs) = (run(true), run(false));
            let d: f32 = (ours.0 - theirs.0).abs().max().into_scalar();
            assert!(d < 1e-7, "{device:?}: values differ by {d}");
            if let (Some(a), Some(b)) = (ours.1, theirs.1) {
                let d: f32 = (a - b).abs().max().into_scalar();
                assert!(d < 1e-7, "{device:?}: gradients differ by {d}");
            }
        }
    }
}
