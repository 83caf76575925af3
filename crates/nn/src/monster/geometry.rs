//! Combined Geo Encoding Volume (upstream `core/geometry.py`, IGEV): an all-pairs correlation of
//! the matching features plus the 3-D-aggregated geometry volume, both as 2-level pyramids, looked
//! up around the current disparity with radius `r` (2r+1 taps per level).
//!
//! Upstream samples with `grid_sample(align_corners=True, padding='zeros')` on height-1 images,
//! which is exactly 1-D linear interpolation with zeros outside `[0, len-1]`; here it is done with
//! two gathers per level (differentiable w.r.t. the volumes, like upstream; the disparity is
//! detached by the caller upstream anyway).
//!
//! Output channel order (B×162×h×w for r=4, 2 levels, 8 groups): per level `[geo: c·(2r+1)+k,
//! corr: k]`, level 0 then level 1.

use burn::tensor::{Int, Tensor, TensorData};
use rayon::prelude::*;

use crate::cpu_mode::{on_cpu_inference, on_cpu_training};
use crate::flex_tensor::f32_vec;
use crate::interp::{linear_tap, linear_taps};
use crate::matmul::SharedOut;

/// Profile group of the volume's construction and its lookups.
pub const GEO: &str = "geo encoding lookup";

/// The precomputed pyramids of a forward pass (upstream `Combined_Geo_Encoding_Volume`).
#[derive(Debug, Clone)]
pub struct GeoEncodingVolume {
    /// Per level: geometry volume `[B·h·w, C, D/2^i]`.
    geo: Vec<Tensor<3>>,
    /// Per level: all-pairs correlation `[B·h·w, w/2^i]`.
    corr: Vec<Tensor<2>>,
    radius: usize,
    dims: [usize; 3],
    /// The same pyramids as plain values on the CPU inference device, for [`lookup_plain`].
    plain: Option<Vec<(Vec<f32>, Vec<f32>)>>,
}

impl GeoEncodingVolume {
    /// `match_left`, `match_right`: `[B, C, h, w]` matching features (no 1/√C scaling);
    /// `geo_volume`: `[B, G, D, h, w]` (the output of the hourglass, `cost_agg`).
    pub fn new(
        match_left: Tensor<4>,
        match_right: Tensor<4>,
        geo_volume: Tensor<5>,
        radius: usize,
        num_levels: usize,
    ) -> Self {
        let [b, c, h, w1] = match_left.dims();
        let cpu = on_cpu_inference(&match_left);
        let w2 = match_right.dims()[3];
        // corr[b, y, x1, x2] = Σ_c L[b, c, y, x1]·R[b, c, y, x2]
        let l = match_left.permute([0, 2, 3, 1]).reshape([b * h, w1, c]);
        let r = match_right.permute([0, 2, 1, 3]).reshape([b * h, c, w2]);
        let mut corr = l.matmul(r).reshape([b * h * w1, w2]);
        let [gb, g, d, gh, gw] = geo_volume.dims();
        assert_eq!(
            [gb, gh, gw],
            [b, h, w1],
            "geo volume and matching features disagree"
        );
        let mut geo = geo_volume
            .permute([0, 3, 4, 1, 2])
            .reshape([b * h * w1, g, d]);

        let mut geo_pyr = vec![geo.clone()];
        let mut corr_pyr = vec![corr.clone()];
        for _ in 1..num_levels {
            // avg_pool2d([1,2], stride [1,2]) along the last axis (floor for odd lengths).
            let [n, g, d] = geo.dims();
            geo = geo
                .narrow(2, 0, d / 2 * 2)
                .reshape([n, g, d / 2, 2])
                .mean_dim(3)
                .reshape([n, g, d / 2]);
            let [n, l2] = corr.dims();
            corr = corr
                .narrow(1, 0, l2 / 2 * 2)
                .reshape([n, l2 / 2, 2])
                .mean_dim(2)
                .reshape([n, l2 / 2]);
            geo_pyr.push(geo.clone());
            corr_pyr.push(corr.clone());
        }
        let plain = cpu.then(|| {
            geo_pyr
                .iter()
                .zip(&corr_pyr)
                .map(|(g, c)| (f32_vec(g.clone()), f32_vec(c.clone())))
                .collect()
        });
        Self {
            geo: geo_pyr,
            corr: corr_pyr,
            radius,
            dims: [b, h, w1],
            plain,
        }
    }

    /// Number of output channels: `levels · (2r+1) · (G + 1)`.
    pub fn out_channels(&self) -> usize {
        let g = self.geo[0].dims()[1];
        self.geo.len() * (2 * self.radius + 1) * (g + 1)
    }

    /// Upstream `geo_fn(disp, coords)` with `coords = x` (the column index): `disp` `[B, 1, h, w]`
    /// → `[B, levels·(2r+1)·(G+1), h, w]`.
    pub fn lookup(&self, disp: &Tensor<4>) -> Tensor<4> {
        let [b, h, w] = self.dims;
        assert_eq!(disp.dims(), [b, 1, h, w], "disparity shape");
        if self.plain.is_some() && on_cpu_inference(disp) {
            return self.lookup_plain(disp);
        }
        let device = disp.device();
        // Training on the CPU: the interpolation kernel (one pass, no gathers or scatters).
        let kernels = on_cpu_training(disp) && disp.dtype() == burn::tensor::DType::F32;
        let taps = 2 * self.radius + 1;
        let n = b * h * w;
        let disp = disp.clone().reshape([n, 1]);
        let dx = Tensor::<1, Int>::arange(-(self.radius as i64)..self.radius as i64 + 1, &device)
            .float()
            .reshape([1, taps]);
        let xs = Tensor::<1, Int>::arange(0..w as i64, &device)
            .float()
            .reshape([1, 1, w])
            .expand([b * h, 1, w])
            .reshape([n, 1]);
        let mut out = Vec::with_capacity(2 * self.geo.len());
        for (i, (geo, corr)) in self.geo.iter().zip(&self.corr).enumerate() {
            let scale = (1u64 << i) as f32;
            // Upstream: x0 = dx + disp / 2^i (geo); coords / 2^i - disp / 2^i + dx (corr).
            let pos_geo = disp.clone().div_scalar(scale) + dx.clone();
            let pos_corr =
                xs.clone().div_scalar(scale) - disp.clone().div_scalar(scale) + dx.clone();
            let [_, g, d] = geo.dims();
            let l2 = corr.dims()[1];
            if kernels {
                out.push(linear_taps(geo.clone(), pos_geo).reshape([n, g * taps]));
                let corr = corr.clone().reshape([n, 1, l2]);
                out.push(linear_taps(corr, pos_corr).reshape([n, taps]));
                continue;
            }
            let idx = tap_indices(pos_geo, d);
            let sampled_geo = sample_3d(geo.clone(), &idx, g); // [n, g, taps]
            out.push(sampled_geo.reshape([n, g * taps]));
            let idx = tap_indices(pos_corr, l2);
            out.push(sample_2d(corr.clone(), &idx));
        }
        let c = out.iter().map(|t| t.dims()[1]).sum::<usize>();
        Tensor::cat(out, 1)
            .reshape([b, h, w, c])
            .permute([0, 3, 1, 2])
    }
}

impl GeoEncodingVolume {
    /// [`lookup`](Self::lookup) on the plain pyramids: per image row, every tap of every pixel
    /// computed once and written straight into the NCHW output, with the same floating-point
    /// operations as the tensor path (so the same values).
    fn lookup_plain(&self, disp: &Tensor<4>) -> Tensor<4> {
        let [b, h, w] = self.dims;
        let levels = self.plain.as_ref().expect("checked by the caller");
        let disp_values = f32_vec(disp.clone());
        let taps = 2 * self.radius + 1;
        let r = self.radius as f32;
        let c = self.out_channels();
        let plane = h * w;
        // Per level: groups, disparities of the geometry volume, columns of the correlation.
        let shapes: Vec<[usize; 3]> = levels
            .iter()
            .zip(&self.geo)
            .map(|((_, corr), geo)| [geo.dims()[1], geo.dims()[2], corr.len() / (b * plane)])
            .collect();
        let mut out = vec![0.0f32; b * c * plane];
        let dst = SharedOut::new(&mut out);
        // One task per image row: `c` runs of `w` values, written into that row of each channel.
        (0..b * h).into_par_iter().for_each(|row| {
            let mut values = vec![0.0f32; c * w];
            let mut channel = 0;
            for (i, ((geo, corr), &[g, d, l2])) in levels.iter().zip(&shapes).enumerate() {
                let scale = (1u64 << i) as f32;
                for x in 0..w {
                    let p = row * w + x;
                    let disp = disp_values[p];
                    let voxels = &geo[p * g * d..(p + 1) * g * d];
                    for k in 0..taps {
                        let dx = k as f32 - r;
                        let (i0, w0, i1, w1) = linear_tap(disp / scale + dx, d);
                        for gi in 0..g {
                            let v = &voxels[gi * d..(gi + 1) * d];
                            values[(channel + gi * taps + k) * w + x] = v[i0] * w0 + v[i1] * w1;
                        }
                        let pos = x as f32 / scale - disp / scale + dx;
                        let (i0, w0, i1, w1) = linear_tap(pos, l2);
                        let line = &corr[p * l2..(p + 1) * l2];
                        values[(channel + g * taps + k) * w + x] = line[i0] * w0 + line[i1] * w1;
                    }
                }
                channel += (g + 1) * taps;
            }
            let (n, y) = (row / h, row % h);
            for (ch, run) in values.chunks_exact(w).enumerate() {
                // SAFETY: row `y` of channel `ch` of image `n`, inside `out`; only this task
                // writes image row `row`.
                let target = unsafe {
                    std::slice::from_raw_parts_mut(dst.at((n * c + ch) * plane + y * w), w)
                };
                target.copy_from_slice(run);
            }
        });
        Tensor::from_data(TensorData::new(out, [b, c, h, w]), &disp.device())
    }
}

/// Indices and weights of 1-D linear interpolation with zeros outside `[0, len-1]`:
/// `(i0, w0, i1, w1)`, indices clamped into range, weights zeroed for taps outside.
struct Taps {
    i0: Tensor<2, Int>,
    w0: Tensor<2>,
    i1: Tensor<2, Int>,
    w1: Tensor<2>,
}

fn tap_indices(pos: Tensor<2>, len: usize) -> Taps {
    let f0 = pos.clone().floor();
    let frac = pos - f0.clone();
    let f1 = f0.clone().add_scalar(1.0);
    let max = len as f32 - 1.0;
    let inside = |f: &Tensor<2>| {
        f.clone().greater_equal_elem(0.0).float() * f.clone().lower_equal_elem(max).float()
    };
    let w0 = (frac.clone().neg().add_scalar(1.0)) * inside(&f0);
    let w1 = frac * inside(&f1);
    let i0 = f0.clamp(0.0, max).int();
    let i1 = f1.clamp(0.0, max).int();
    Taps { i0, w0, i1, w1 }
}

fn sample_2d(src: Tensor<2>, t: &Taps) -> Tensor<2> {
    let v0 = src.clone().gather(1, t.i0.clone());
    let v1 = src.gather(1, t.i1.clone());
    v0 * t.w0.clone() + v1 * t.w1.clone()
}

fn sample_3d(src: Tensor<3>, t: &Taps, g: usize) -> Tensor<3> {
    let [n, taps] = t.i0.dims();
    let expand_i = |i: &Tensor<2, Int>| i.clone().reshape([n, 1, taps]).expand([n, g, taps]);
    let expand_w = |w: &Tensor<2>| w.clone().reshape([n, 1, taps]);
    let v0 = src.clone().gather(2, expand_i(&t.i0));
    let v1 = src.gather(2, expand_i(&t.i1));
    v0 * expand_w(&t.w0) + v1 * expand_w(&t.w1)
}
