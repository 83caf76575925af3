//! BatchNorm in training (batch statistics) as one burn operation on the CPU device: the
//! statistics in one pass (shared by the running statistics, the output and the backward), the
//! output in another, the backward two passes, channels in parallel.
//!
//! Why: burn builds the training BatchNorm from about ten tensor operations (a transposed copy,
//! reductions, broadcasts) and its backward from twenty, each a single-threaded pass over the
//! volume; on the hourglass's 3-D volumes they were a large part of the main thread's serial
//! time in a MonSter++ training step (BENCHMARKS.md, "SegFormer and the training step against
//! PyTorch").

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex, TensorMetadata};
use burn::nn::BatchNorm;
use burn::tensor::{DType, Tensor, TensorData};
use rayon::prelude::*;

use crate::cpu_mode::on_cpu_training;
use crate::custom_op::{register, step_inputs, RecordOp};
use crate::flex_tensor::f32_vec;
use crate::flex_tensor::{tensor, values};

/// `bn.forward(x)`: in training on the CPU device the fused operation (and the running statistics
/// updated as burn's layer does), elsewhere burn's layer.
pub fn batch_norm<const D: usize>(bn: &BatchNorm, x: Tensor<D>) -> Tensor<D> {
    let training = bn.training.is_enabled() && on_cpu_training(&x);
    if !training || x.dtype() != DType::F32 || D < 2 {
        return bn.forward(x);
    }
    let device = x.device();
    let dims = x.dims();
    // The batch's statistics, computed once: for the running statistics, the normalisation and
    // its backward.
    let (mean, variance) = channel_statistics(&f32_vec(x.clone().inner()), dims[0], dims[1]);
    let channels = dims[1];
    let statistics = Tensor::<2>::from_data(
        TensorData::new([mean, variance].concat(), [2, channels]),
        &device,
    );
    let momentum = bn.momentum;
    let blend = |running: Tensor<1>, row: usize| {
        let batch = statistics
            .clone()
            .slice([row..row + 1, 0..channels])
            .reshape([channels]);
        running
            .to_device(&device)
            .mul_scalar(1.0 - momentum)
            .add(batch.mul_scalar(momentum))
            .detach()
    };
    bn.running_mean
        .update(blend(bn.running_mean.value_sync(), 0));
    bn.running_var.update(blend(bn.running_var.value_sync(), 1));
    Tensor::from_dispatch(<Dispatch as BatchNormKernels>::kernel_batch_norm_train(
        x.into_dispatch(),
        bn.gamma.val().into_dispatch(),
        bn.beta.val().into_dispatch(),
        statistics.into_dispatch(),
        bn.epsilon as f32,
    ))
}

/// Per-channel mean and biased variance of `x` (`[b, c, …]` row-major).
fn channel_statistics(x: &[f32], b: usize, c: usize) -> (Vec<f32>, Vec<f32>) {
    let n = x.len() / (b * c);
    (0..c)
        .into_par_iter()
        .map(|ch| {
            let planes = || (0..b).map(move |i| &x[(i * c + ch) * n..][..n]);
            let count = (b * n) as f64;
            let mean = planes().flatten().map(|&v| v as f64).sum::<f64>() / count;
            let var = planes()
                .flatten()
                .map(|&v| (v as f64 - mean).powi(2))
                .sum::<f64>()
                / count;
            (mean as f32, var as f32)
        })
        .unzip()
}

#[backend_extension(Flex, Autodiff)]
pub trait BatchNormKernels: Backend {
    /// `γ·(x − μ)/√(σ² + ε) + β` with the batch's per-channel `μ` and biased `σ²`, given as the
    /// rows of `statistics` (`[2, c]`, constants: the gradient through them is in the backward).
    fn kernel_batch_norm_train(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        statistics: FloatTensor<Self>,
        epsilon: f32,
    ) -> FloatTensor<Self>;
}

/// The gradients of [`BatchNormKernels::kernel_batch_norm_train`]: `(∂x, ∂γ, ∂β)`.
pub trait BatchNormGradKernels: BatchNormKernels {
    fn kernel_batch_norm_train_grad(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        statistics: FloatTensor<Self>,
        grad: FloatTensor<Self>,
        epsilon: f32,
    ) -> (FloatTensor<Self>, FloatTensor<Self>, FloatTensor<Self>);
}

/// `[b, c, n]` of a `[b, c, …]` tensor.
fn layout(x: &FlexTensor) -> [usize; 3] {
    let shape = x.shape();
    let (b, c) = (shape[0], shape[1]);
    [b, c, shape.num_elements() / (b * c).max(1)]
}

impl BatchNormKernels for Flex {
    fn kernel_batch_norm_train(
        x: FlexTensor,
        gamma: FlexTensor,
        beta: FlexTensor,
        statistics: FlexTensor,
        epsilon: f32,
    ) -> FlexTensor {
        let shape = x.shape();
        let [_, c, n] = layout(&x);
        let (x, gamma, beta) = (values(&x), values(&gamma), values(&beta));
        let statistics = values(&statistics);
        let (mean, var) = statistics.split_at(c);
        let mut out = vec![0.0f32; x.len()];
        out.par_chunks_exact_mut(n)
            .zip(x.par_chunks_exact(n))
            .enumerate()
            .for_each(|(plane, (dst, src))| {
                let ch = plane % c;
                let scale = gamma[ch] / (var[ch] + epsilon).sqrt();
                let shift = beta[ch] - mean[ch] * scale;
                for (d, &v) in dst.iter_mut().zip(src) {
                    *d = v * scale + shift;
                }
            });
        tensor(out, shape)
    }
}

impl BatchNormGradKernels for Flex {
    fn kernel_batch_norm_train_grad(
        x: FlexTensor,
        gamma: FlexTensor,
        statistics: FlexTensor,
        grad: FlexTensor,
        epsilon: f32,
    ) -> (FlexTensor, FlexTensor, FlexTensor) {
        let shape = x.shape();
        let [b, c, n] = layout(&x);
        let (x, gamma, grad) = (values(&x), values(&gamma), values(&grad));
        let statistics = values(&statistics);
        let (mean, var) = statistics.split_at(c);
        let count = (b * n) as f32;
        let plane = |i: usize, ch: usize| (i * c + ch) * n..(i * c + ch + 1) * n;
        // Per channel: ∂β = Σ ḡ, ∂γ = Σ ḡ·x̂.
        let (d_beta, d_gamma): (Vec<f32>, Vec<f32>) = (0..c)
            .into_par_iter()
            .map(|ch| {
                let inv_std = 1.0 / (var[ch] + epsilon).sqrt();
                let (mut sum, mut dot) = (0.0f64, 0.0f64);
                for i in 0..b {
                    let range = plane(i, ch);
                    for (&g, &v) in grad[range.clone()].iter().zip(&x[range]) {
                        sum += g as f64;
                        dot += (g * (v - mean[ch]) * inv_std) as f64;
                    }
                }
                (sum as f32, dot as f32)
            })
            .unzip();
        // ∂x = γ/σ · (ḡ − ∂β/N − x̂·∂γ/N).
        let mut d_x = vec![0.0f32; x.len()];
        d_x.par_chunks_exact_mut(n)
            .enumerate()
            .for_each(|(p, dst)| {
                let ch = p % c;
                let inv_std = 1.0 / (var[ch] + epsilon).sqrt();
                let scale = gamma[ch] * inv_std;
                let (mean_g, mean_gx) = (d_beta[ch] / count, d_gamma[ch] / count);
                let (src, g) = (&x[p * n..][..n], &grad[p * n..][..n]);
                for ((d, &v), &g) in dst.iter_mut().zip(src).zip(g) {
                    let normalised = (v - mean[ch]) * inv_std;
                    *d = scale * (g - mean_g - normalised * mean_gx);
                }
            });
        (
            tensor(d_x, shape),
            tensor(d_gamma, [c]),
            tensor(d_beta, [c]),
        )
    }
}

/// The backward step of [`BatchNormKernels::kernel_batch_norm_train`]: parents
/// `[x, gamma, beta]`; state: `x`, `gamma`, the statistics and `ε`.
#[derive(Debug)]
struct BatchNormBackward;

impl<B: BatchNormGradKernels> Backward<B, 3> for BatchNormBackward {
    type State = (FloatTensor<B>, FloatTensor<B>, FloatTensor<B>, f32);

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (grad, (x, gamma, statistics, epsilon), parents) = step_inputs::<B, _, 3>(ops, grads);
        let (d_x, d_gamma, d_beta) =
            B::kernel_batch_norm_train_grad(x, gamma, statistics, grad, epsilon);
        for (parent, d) in parents.into_iter().zip([d_x, d_gamma, d_beta]) {
            register::<B>(grads, parent, || d);
        }
    }
}

impl<B: BatchNormGradKernels, C: CheckpointStrategy> BatchNormKernels for Autodiff<B, C> {
    fn kernel_batch_norm_train(
        x: FloatTensor<Self>,
        gamma: FloatTensor<Self>,
        beta: FloatTensor<Self>,
        statistics: FloatTensor<Self>,
        epsilon: f32,
    ) -> FloatTensor<Self> {
        BatchNormBackward.record::<C, _>(
            [x, gamma, beta],
            statistics.into_primitive(),
            |_, [x, gamma, _], statistics| {
                let [x, gamma] = [x, gamma].map(|t| t.primitive().clone());
                (x, gamma, statistics.clone(), epsilon)
            },
            |[x, gamma, beta], statistics| {
                B::kernel_batch_norm_train(x, gamma, beta, statistics, epsilon)
            },
        )
    }
}

#[cfg(test)]
mod tests {
    use burn::nn::BatchNormConfig;
    use burn::tensor::{Device, Distribution};

    use crate::test_support::{assert_close, position_weighted_grads};

    use super::*;

    /// Output, running statistics and the gradients of the input, γ and β equal burn's
    /// training BatchNorm on a batch-2 volume, after two steps (the running statistics blend).
    #[test]
    fn matches_burn_in_training() {
        let device = Device::flex().autodiff();
        let x = Tensor::<5>::random([2, 6, 3, 5, 4], Distribution::Normal(0.5, 2.0), &device);
        // Two layers (γ = 1, β = 0, running 0 and 1 at init), not clones sharing their state.
        let (ours_bn, burn_bn) = (
            BatchNormConfig::new(6).init(&device),
            BatchNormConfig::new(6).init(&device),
        );
        let run = |layer: &BatchNorm, ours: bool| {
            let mut last = None;
            for step in 0..2 {
                let x = x.clone().mul_scalar(1.0 + step as f32).require_grad();
                let y = if ours {
                    batch_norm(layer, x.clone())
                } else {
                    layer.forward(x.clone())
                };
                let grads = position_weighted_grads(&y);
                last = Some((
                    y.inner(),
                    x.grad(&grads).expect("x gradient"),
                    layer.gamma.grad(&grads).expect("γ gradient"),
                    layer.beta.grad(&grads).expect("β gradient"),
                ));
            }
            last.expect("two steps")
        };
        let ours = run(&ours_bn, true);
        let theirs = run(&burn_bn, false);
        assert_close("output", ours.0, theirs.0);
        assert_close("∂x", ours.1, theirs.1);
        assert_close("∂γ", ours.2, theirs.2);
        assert_close("∂β", ours.3, theirs.3);
        assert_close(
            "running mean",
            ours_bn.running_mean.value(),
            burn_bn.running_mean.value(),
        );
        assert_close(
            "running var",
            ours_bn.running_var.value(),
            burn_bn.running_var.value(),
        );
    }
}
