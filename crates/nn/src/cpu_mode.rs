//! Where the crate's CPU kernels run: on burn's CPU device (`flex`), as plain values in
//! inference and as burn operations with their backward under autodiff.

use burn::tensor::{Device, Tensor};

/// How the kernels run on a CPU tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum CpuMode {
    /// Plain values: fused epilogues, weights prepared once per pass.
    Inference,
    /// Under autodiff: the kernels as a burn operation with their backward.
    Training,
}

/// Whether `x` is on the CPU device, and with or without autodiff.
pub(crate) fn cpu_mode<const D: usize>(x: &Tensor<D>) -> Option<CpuMode> {
    let device = x.device();
    (device == Device::flex()).then(|| {
        if device.is_autodiff() {
            CpuMode::Training
        } else {
            CpuMode::Inference
        }
    })
}

/// The plain CPU device without autodiff (device equality ignores the autodiff wrapper: it is
/// asked separately).
pub fn on_cpu_inference<const D: usize>(x: &Tensor<D>) -> bool {
    cpu_mode(x) == Some(CpuMode::Inference)
}

/// The CPU device with autodiff: where the kernels run as burn operations with their backward.
pub fn on_cpu_training<const D: usize>(x: &Tensor<D>) -> bool {
    cpu_mode(x) == Some(CpuMode::Training)
}
