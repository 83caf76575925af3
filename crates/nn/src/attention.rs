//! Transformer pieces for inference on the CPU (`flex`) device: multi-head self-attention read
//! in place from the fused `qkv` projection, and the erf GELU; elsewhere burn's operations.
//!
//! Why: burn computes `q·kᵀ` on a transposed view by first copying it (far below the GEMM's
//! speed on DINOv2's 513 tokens), and its erf GELU runs on one thread through a scalar `erff`;
//! together these were a large part of DINOv2's time (BENCHMARKS.md, "MonSter++ against
//! PyTorch, and where the time goes").

use burn::tensor::activation::{gelu, softmax};
use burn::tensor::{Tensor, TensorData};
use rayon::prelude::*;

use crate::cpu_mode::on_cpu_inference;
use crate::fastmath;
use crate::flex_tensor::f32_vec;
use crate::matmul::{gemm_f32, SharedOut, Strided};

/// Self-attention of `qkv` (`[b, n, 3e]`: q, k, v, each `heads × e/heads`, as PyTorch's
/// `qkv.reshape(b, n, 3, heads, e/heads)`) with scores scaled by `scale`: `[b, n, e]`, heads
/// concatenated (the input of the output projection).
pub fn attention_qkv(qkv: Tensor<3>, heads: usize, scale: f32) -> Tensor<3> {
    let [b, n, e3] = qkv.dims();
    let (e, hd) = (e3 / 3, e3 / 3 / heads);
    if !on_cpu_inference(&qkv) {
        let split = qkv.reshape([b, n, 3, heads, hd]).permute([2, 0, 3, 1, 4]);
        let part = |i| split.clone().narrow(0, i, 1).reshape([b, heads, n, hd]);
        let (q, k, v) = (part(0).mul_scalar(scale), part(1), part(2));
        let attn = softmax(q.matmul(k.swap_dims(2, 3)), 3);
        return attn.matmul(v).swap_dims(1, 2).reshape([b, n, e]);
    }
    let device = qkv.device();
    let qkv = f32_vec(qkv);
    let mut out = vec![0.0f32; b * n * e];
    let dst = SharedOut::new(&mut out);
    (0..b * heads).into_par_iter().for_each(|task| {
        let (image, head) = (task / heads, task % heads);
        let base = image * n * e3 + head * hd;
        let (q, k, v) = (&qkv[base..], &qkv[base + e..], &qkv[base + 2 * e..]);
        let mut scores = vec![0.0f32; n * n];
        // SAFETY: scores `[n, n]` row-major; q `[n, hd]` at row stride 3e; kᵀ `[hd, n]` read as
        // element (d, j) = k[j·3e + d]; all inside `qkv`.
        unsafe {
            gemm_f32(
                [n, n, hd],
                Strided::rows(scores.as_mut_ptr(), n),
                Strided::rows(q.as_ptr(), e3),
                Strided::columns(k.as_ptr(), e3),
                false,
                scale,
                gemm::Parallelism::None,
            );
        }
        for row in scores.chunks_exact_mut(n) {
            let max = row.iter().copied().fold(f32::NEG_INFINITY, f32::max);
            let mut sum = 0.0f32;
            for s in row.iter_mut() {
                *s = fastmath::exp(*s - max);
                sum += *s;
            }
            for s in row.iter_mut() {
                *s /= sum;
            }
        }
        // SAFETY: this task alone writes columns `head·hd .. (head+1)·hd` of image `image`'s
        // `[n, e]` output; v `[n, hd]` at row stride 3e inside `qkv`.
        unsafe {
            gemm_f32(
                [n, hd, n],
                Strided::rows(dst.at(image * n * e + head * hd), e),
                Strided::rows(scores.as_ptr(), n),
                Strided::rows(v.as_ptr(), e3),
                false,
                1.0,
                gemm::Parallelism::None,
            );
        }
    });
    Tensor::from_data(TensorData::new(out, [b, n, e]), &device)
}

/// GELU with the exact erf, `x·½·(1 + erf(x/√2))` (PyTorch's default), in parallel on the CPU
/// inference device; burn's `gelu` elsewhere.
pub fn gelu_erf<const D: usize>(x: Tensor<D>) -> Tensor<D> {
    if !on_cpu_inference(&x) {
        return gelu(x);
    }
    let (device, dims) = (x.device(), x.dims());
    let mut values = f32_vec(x);
    values
        .par_chunks_mut(4096)
        .for_each(|chunk| chunk.iter_mut().for_each(|v| *v = gelu_scalar(*v)));
    Tensor::from_data(TensorData::new(values, dims), &device)
}

fn gelu_scalar(x: f32) -> f32 {
    x * 0.5 * (1.0 + erf(x * std::f32::consts::FRAC_1_SQRT_2))
}

/// erf by Abramowitz & Stegun 7.1.26 (absolute error ≤ 1.5·10⁻⁷, below f32's spacing near 1).
fn erf(x: f32) -> f32 {
    let a = x.abs();
    let t = 1.0 / (1.0 + 0.327_591_1 * a);
    let poly = t
        * (0.254_829_6
            + t * (-0.284_496_74 + t * (1.421_413_8 + t * (-1.453_152_1 + t * 1.061_405_4))));
    let y = 1.0 - poly * fastmath::exp(-a * a);
    y.copysign(x)
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::tensor::{Device, Distribution};

    fn worst(a: Tensor<3>, b: Tensor<3>) -> f32 {
        let (a, b) = (f32_vec(a), f32_vec(b));
        a.iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0, f32::max)
    }

    /// The in-place attention equals burn's (the generic path) on two images, 3 heads.
    #[test]
    fn attention_matches_burn() {
        let device = Device::flex();
        let qkv = Tensor::<3>::random([2, 37, 3 * 48], Distribution::Normal(0.0, 1.0), &device);
        let fast = attention_qkv(qkv.clone(), 3, 0.25);
        let reference = attention_qkv(
            Tensor::from_data(qkv.into_data(), &device.clone().autodiff()),
            3,
            0.25,
        );
        let reference = Tensor::from_data(reference.into_data(), &device);
        let err = worst(fast, reference);
        assert!(err < 1e-5, "max difference {err}");
    }

    /// The erf approximation against burn's GELU over [−8, 8].
    #[test]
    fn gelu_matches_burn() {
        let device = Device::flex();
        let values: Vec<f32> = (0..4001).map(|i| -8.0 + i as f32 * 0.004).collect();
        let x = Tensor::<3>::from_data(TensorData::new(values, [1, 1, 4001]), &device);
        let err = worst(gelu_erf(x.clone()), gelu(x));
        assert!(err < 5e-7, "max difference {err}");
    }
}
