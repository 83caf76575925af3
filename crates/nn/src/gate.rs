//! The ConvGRU's state update `(1 − z)·h + z·q` as one burn operation on the CPU in training.
//!
//! Why: as tensors it is five operations forward and, backward, two multiplications per
//! product plus the sums of the gradients that meet at `h` and `z`, each a single-threaded pass
//! of burn's CPU kernels, for three GRUs at every refinement iteration. Here the forward is one
//! pass and the backward one pass that writes all three gradients.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops};
use burn::backend::flex::FlexTensor;
use burn::backend::tensor::FloatTensor;
use burn::backend::{backend_extension, Autodiff, Backend, Dispatch, Flex, TensorMetadata};
use burn::tensor::{DType, Tensor};
use rayon::prelude::*;

use crate::cpu_mode::on_cpu_training;
use crate::custom_op::{register, step_inputs, RecordOp};
use crate::flex_tensor::{tensor, values, ELEMENTWISE_CHUNK};

/// `(1 − z)·h + z·q` of three tensors of one shape.
pub fn gru_blend(h: Tensor<4>, z: Tensor<4>, q: Tensor<4>) -> Tensor<4> {
    let fused = on_cpu_training(&h)
        && [&h, &z, &q].iter().all(|t| t.dtype() == DType::F32)
        && h.dims() == z.dims()
        && h.dims() == q.dims();
    if !fused {
        return z.clone().neg().add_scalar(1.0) * h + z * q;
    }
    Tensor::from_dispatch(<Dispatch as GateKernels>::kernel_gru_blend(
        h.into_dispatch(),
        z.into_dispatch(),
        q.into_dispatch(),
    ))
}

#[backend_extension(Flex, Autodiff)]
pub trait GateKernels: Backend {
    /// See [`gru_blend`].
    fn kernel_gru_blend(
        h: FloatTensor<Self>,
        z: FloatTensor<Self>,
        q: FloatTensor<Self>,
    ) -> FloatTensor<Self>;
}

/// The gradients of [`GateKernels::kernel_gru_blend`]: `(∂h, ∂z, ∂q)`.
pub trait GateGradKernels: GateKernels {
    fn kernel_gru_blend_grad(
        h: FloatTensor<Self>,
        z: FloatTensor<Self>,
        q: FloatTensor<Self>,
        grad: FloatTensor<Self>,
    ) -> [FloatTensor<Self>; 3];
}

impl GateKernels for Flex {
    fn kernel_gru_blend(h: FlexTensor, z: FlexTensor, q: FlexTensor) -> FlexTensor {
        let shape = h.shape();
        let (h, z, q) = (values(&h), values(&z), values(&q));
        let mut out = vec![0.0f32; h.len()];
        out.par_chunks_mut(ELEMENTWISE_CHUNK)
            .enumerate()
            .for_each(|(i, dst)| {
                let at = i * ELEMENTWISE_CHUNK;
                for (k, d) in dst.iter_mut().enumerate() {
                    let (h, z, q) = (h[at + k], z[at + k], q[at + k]);
                    *d = (1.0 - z) * h + z * q;
                }
            });
        tensor(out, shape)
    }
}

impl GateGradKernels for Flex {
    fn kernel_gru_blend_grad(
        h: FlexTensor,
        z: FlexTensor,
        q: FlexTensor,
        grad: FlexTensor,
    ) -> [FlexTensor; 3] {
        let shape = h.shape();
        let (h, z, q, g) = (values(&h), values(&z), values(&q), values(&grad));
        let (mut dh, mut dz, mut dq) = (
            vec![0.0f32; h.len()],
            vec![0.0f32; h.len()],
            vec![0.0f32; h.len()],
        );
        dh.par_chunks_mut(ELEMENTWISE_CHUNK)
            .zip(dz.par_chunks_mut(ELEMENTWISE_CHUNK))
            .zip(dq.par_chunks_mut(ELEMENTWISE_CHUNK))
            .enumerate()
            .for_each(|(i, ((dh, dz), dq))| {
                let at = i * ELEMENTWISE_CHUNK;
                for k in 0..dh.len() {
                    let (h, z, q, g) = (h[at + k], z[at + k], q[at + k], g[at + k]);
                    dh[k] = g * (1.0 - z);
                    dz[k] = g * (q - h);
                    dq[k] = g * z;
                }
            });
        [dh, dz, dq].map(|d| tensor(d, shape.clone()))
    }
}

/// The backward step of [`GateKernels::kernel_gru_blend`]; state: `h`, `z` and `q`.
#[derive(Debug)]
struct GruBlendBackward;

impl<B: GateGradKernels> Backward<B, 3> for GruBlendBackward {
    type State = [FloatTensor<B>; 3];

    fn backward(self, ops: Ops<Self::State, 3>, grads: &mut Gradients, _: &mut Checkpointer) {
        let (grad, [h, z, q], parents) = step_inputs::<B, _, 3>(ops, grads);
        let partials = B::kernel_gru_blend_grad(h, z, q, grad);
        for (parent, d) in parents.into_iter().zip(partials) {
            register::<B>(grads, parent, || d);
        }
    }
}

impl<B: GateGradKernels, C: CheckpointStrategy> GateKernels for Autodiff<B, C> {
    fn kernel_gru_blend(
        h: FloatTensor<Self>,
        z: FloatTensor<Self>,
        q: FloatTensor<Self>,
    ) -> FloatTensor<Self> {
        GruBlendBackward.record::<C, _>(
            [h, z, q],
            (),
            |_, inputs, ()| inputs.each_ref().map(|t| t.primitive().clone()),
            |[h, z, q], ()| B::kernel_gru_blend(h, z, q),
        )
    }
}

#[cfg(test)]
mod tests {
    use burn::tensor::{Device, Distribution};

    use crate::test_support::output_and_grads;

    use super::*;

    /// Values and the three gradients equal the tensor composition's.
    #[test]
    fn matches_the_composition() {
        let device = Device::flex().autodiff();
        let random = |d: Distribution| Tensor::<4>::random([2, 5, 7, 9], d, &device);
        let h = random(Distribution::Normal(0.0, 1.0));
        let z = random(Distribution::Uniform(0.0, 1.0));
        let q = random(Distribution::Normal(0.0, 1.0));
        let run = |fused: bool| {
            let (y, grads) = output_and_grads([&h, &z, &q], |[h, z, q]| {
                if fused {
                    gru_blend(h, z, q)
                } else {
                    z.clone().neg().add_scalar(1.0) * h + z * q
                }
            });
            let [dh, dz, dq] = grads.expect("an autodiff device");
            [y, dh, dz, dq]
        };
        for (name, (a, b)) in ["value", "∂h", "∂z", "∂q"]
            .iter()
            .zip(run(true).into_iter().zip(run(false)))
        {
            let d: f32 = (a - b).abs().max().into_scalar();
            assert!(d < 1e-5, "{name}: differs by {d}");
        }
    }
}
