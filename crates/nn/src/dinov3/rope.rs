//! DINOv3's 2-D rotary position embedding (HF `DINOv3ViTRopePositionEmbedding`, eval mode).
//!
//! Patch (i, j) of an n_h × n_w grid sits at y = 2·(i + 0.5)/n_h − 1, x = 2·(j + 0.5)/n_w − 1
//! (each axis normalised by its own count, so any grid covers [−1, 1]). With
//! inv_freq_k = 1/θ^(4k/head_dim), k < head_dim/4, the angles of a patch are
//! [2π·y·inv_freq, 2π·x·inv_freq] tiled twice to head_dim. Only patch tokens are rotated; the
//! CLS and register tokens pass through unchanged. Every step is rounded to f32 where torch
//! rounds, so the tables match torch to an ulp.

use burn::tensor::{Device, Tensor, TensorData};

/// cos and sin tables, `[n_h·n_w, head_dim]` (row-major patches), shared by all layers and heads.
#[derive(Debug, Clone)]
pub struct Rope {
    /// cos of the angles.
    pub cos: Tensor<2>,
    /// sin of the angles.
    pub sin: Tensor<2>,
}

/// The raw angle table `[n_h·n_w · head_dim]` in f32, as torch computes it.
pub fn rope_angles(n_h: usize, n_w: usize, head_dim: usize, theta: f64) -> Vec<f32> {
    let quarter = head_dim / 4;
    // `1 / theta ** arange(0, 1, 4/head_dim)`: pow in f32 precision, then an f32 reciprocal.
    let inv_freq: Vec<f32> = (0..quarter)
        .map(|k| {
            let exponent = (k as f64 * (4.0 / head_dim as f64)) as f32 as f64;
            1.0f32 / (theta.powf(exponent) as f32)
        })
        .collect();
    // `2.0 * (arange(0.5, n) / n) - 1.0` in f32.
    let coord = |i: usize, n: usize| 2.0f32 * ((i as f32 + 0.5) / n as f32) - 1.0;
    let two_pi = (2.0 * std::f64::consts::PI) as f32;
    let mut out = Vec::with_capacity(n_h * n_w * head_dim);
    for i in 0..n_h {
        let y = two_pi * coord(i, n_h);
        for j in 0..n_w {
            let x = two_pi * coord(j, n_w);
            for _tile in 0..2 {
                out.extend(inv_freq.iter().map(|&f| y * f));
                out.extend(inv_freq.iter().map(|&f| x * f));
            }
        }
    }
    out
}

impl Rope {
    /// Tables for an `n_h × n_w` patch grid.
    pub fn new(n_h: usize, n_w: usize, head_dim: usize, theta: f64, device: &Device) -> Self {
        let angles = rope_angles(n_h, n_w, head_dim, theta);
        let table = |f: fn(f64) -> f64| {
            let v: Vec<f32> = angles.iter().map(|&a| f(a as f64) as f32).collect();
            Tensor::<2>::from_data(TensorData::new(v, [n_h * n_w, head_dim]), device)
        };
        Self {
            cos: table(f64::cos),
            sin: table(f64::sin),
        }
    }

    /// Rotates the patch tokens of `x` (`[B, heads, prefix + patches, head_dim]`):
    /// `x·cos + rotate_half(x)·sin` with `rotate_half(x) = [−x₂, x₁]` (halves of head_dim).
    /// The first `prefix` tokens (CLS, registers) are returned unchanged.
    pub fn apply(&self, x: Tensor<4>, prefix: usize) -> Tensor<4> {
        let [b, h, n, d] = x.dims();
        let patches = n - prefix;
        let head = x.clone().narrow(2, 0, prefix);
        let p = x.narrow(2, prefix, patches);
        let half = d / 2;
        let rotated = Tensor::cat(
            vec![
                p.clone().narrow(3, half, half).neg(),
                p.clone().narrow(3, 0, half),
            ],
            3,
        );
        let cos = self
            .cos
            .clone()
            .reshape([1, 1, patches, d])
            .expand([b, h, patches, d]);
        let sin = self
            .sin
            .clone()
            .reshape([1, 1, patches, d])
            .expand([b, h, patches, d]);
        Tensor::cat(vec![head, p * cos + rotated * sin], 2)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_follow_the_formula() {
        // 2×3 grid, head_dim 8 → inv_freq = [1, 1/θ^0.5] = [1, 0.1] for θ = 100.
        let a = rope_angles(2, 3, 8, 100.0);
        assert_eq!(a.len(), 6 * 8);
        let two_pi = 2.0 * std::f32::consts::PI;
        // patch (1, 2): y = 2·1.5/2 − 1 = 0.5, x = 2·2.5/3 − 1 = 2/3.
        let p = &a[5 * 8..6 * 8];
        let want = [0.5, 0.05, 2.0 / 3.0, 2.0 / 30.0];
        for (k, w) in want.iter().enumerate() {
            assert!(
                (p[k] - two_pi * w).abs() < 1e-5,
                "{k}: {} vs {}",
                p[k],
                two_pi * w
            );
            assert_eq!(p[k], p[k + 4], "tiled twice");
        }
    }
}
