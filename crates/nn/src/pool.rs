//! Average pooling of feature maps on plain buffers, for the CPU inference device.
//!
//! Why: burn's CPU backend pools a 2-D map through its 3-D pooling kernel and a strided index
//! iterator; the ConvGRU pools two hidden states at every iteration, which took 2 % of a
//! MonSter++ pass (BENCHMARKS.md).

use burn::tensor::module::avg_pool2d;
use burn::tensor::ops::AvgPoolOptions;
use burn::tensor::{Tensor, TensorData};
use rayon::prelude::*;

use crate::conv::{f32_vec, on_cpu_inference};

/// PyTorch's `avg_pool2d(x, k, stride, padding, count_include_pad=True)` with a square window:
/// the plain kernel on the CPU inference device, burn's elsewhere.
pub fn avg_pool2d_padded(x: Tensor<4>, k: usize, stride: usize, padding: usize) -> Tensor<4> {
    if !on_cpu_inference(&x) {
        return avg_pool2d(
            x,
            AvgPoolOptions::new([k, k])
                .with_stride([stride, stride])
                .with_padding([padding, padding])
                .with_count_include_pad(true),
        );
    }
    let (device, [b, c, h, w]) = (x.device(), x.dims());
    let (out, [oh, ow]) = avg_pool_planes(&f32_vec(x), [h, w], k, stride, padding);
    Tensor::from_data(TensorData::new(out, [b, c, oh, ow]), &device)
}

/// [`avg_pool2d_padded`] of every `h × w` plane of `planes`: the window's sum (rows, then
/// columns, as PyTorch adds them) divided by `k²`, padding counted. Returns the output and its
/// size `[oh, ow]`, `(n + 2·padding − k) / stride + 1` per axis.
pub fn avg_pool_planes(
    planes: &[f32],
    [h, w]: [usize; 2],
    k: usize,
    stride: usize,
    padding: usize,
) -> (Vec<f32>, [usize; 2]) {
    assert!(
        h + 2 * padding >= k && w + 2 * padding >= k,
        "avg_pool: window larger than the padded input"
    );
    let (oh, ow) = (
        (h + 2 * padding - k) / stride + 1,
        (w + 2 * padding - k) / stride + 1,
    );
    let divisor = (k * k) as f32;
    // The window's first index along an axis and the in-bounds part of it.
    let span = |o: usize, n: usize| {
        let start = (o * stride) as isize - padding as isize;
        let lo = start.max(0) as usize;
        let hi = ((start + k as isize) as usize).min(n);
        lo..hi
    };
    let mut out = vec![0.0f32; planes.len() / (h * w) * oh * ow];
    out.par_chunks_exact_mut(oh * ow)
        .zip(planes.par_chunks_exact(h * w))
        .for_each(|(dst, src)| {
            for (oy, row) in dst.chunks_exact_mut(ow).enumerate() {
                let rows = span(oy, h);
                for (ox, v) in row.iter_mut().enumerate() {
                    let cols = span(ox, w);
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

    /// The plain kernel against burn's on the ConvGRU's pooling (3×3, stride 2, padding 1) of
    /// even and odd sizes, and a 2×2 window without padding.
    #[test]
    fn matches_burn() {
        let device = Device::flex();
        for (dims, k, stride, padding) in [
            ([1, 3, 16, 32], 3, 2, 1),
            ([2, 4, 7, 9], 3, 2, 1),
            ([1, 2, 1, 1], 3, 2, 1),
            ([1, 2, 6, 5], 2, 2, 0),
        ] {
            let x = Tensor::<4>::random(dims, Distribution::Normal(0.0, 1.0), &device);
            let ours = avg_pool2d_padded(x.clone(), k, stride, padding);
            let theirs = avg_pool2d(
                x,
                AvgPoolOptions::new([k, k])
                    .with_stride([stride, stride])
                    .with_padding([padding, padding])
                    .with_count_include_pad(true),
            );
            assert_eq!(ours.dims(), theirs.dims());
            let d: f32 = (ours - theirs).abs().max().into_scalar();
            assert!(d < 1e-6, "{dims:?} k{k} s{stride} p{padding}: {d}");
        }
    }
}
