//! Resampling to a new size with the exact filters of the reference pre-processing (PIL, torch antialias).
//!
//! Both reference resizers are separable triangle ("bilinear") filters whose support grows with the
//! down-scale factor, applied width first, then height:
//! - [`resize_pil_bilinear_u8`]: Pillow's `Image.resize(..., BILINEAR)` on 8-bit data (SegFormer
//!   input). Weights in f64, converted to 22-bit fixed point; each pass rounds and clips to 0..255.
//!   Bit-exact with Pillow.
//! - [`resize_antialias_bilinear`]: torch `F.interpolate(mode="bilinear", antialias=True,
//!   align_corners=False)` on f32 (DINOv3 processor). Weights in f32 with torch's mix of f32 and
//!   f64 intermediates; sums in f32 with fused multiply-adds, as torch's AVX2/AVX-512 CPU kernel
//!   is compiled. Bit-exact with torch 2.4 on such a CPU (without the fusion: ≤ 2e-7 off).
//!
//! The weights of both come from one routine, [`triangle_weights`], generic over the precision the
//! reference uses, so the two cannot drift apart.

use rayon::prelude::*;

use crate::{Image, RasterError, Result};

/// Resizes an 8-bit image (integer values 0..=255 stored in f32, any channel count) exactly as
/// Pillow's `Image.resize((width, height), Image.BILINEAR)`: horizontal pass first, then vertical,
/// each pass in 22-bit fixed point rounded and clipped to 0..255. Returns integers in f32.
///
/// Errors on an empty input or output size and on a sample that is not an integer in 0..=255
/// (convert and clip first: PIL would have had a `uint8` array).
pub fn resize_pil_bilinear_u8(image: &Image, width: usize, height: usize) -> Result<Image> {
    check_sizes(image, width, height, "resize_pil_bilinear_u8")?;
    if let Some(bad) = image
        .data()
        .iter()
        .find(|v| !(v.fract() == 0.0 && (0.0..=255.0).contains(*v)))
    {
        return Err(RasterError::Shape(format!(
            "resize_pil_bilinear_u8: sample {bad} is not an 8-bit value (integers 0..=255 expected)"
        )));
    }
    let c = image.channels();
    let u8_data: Vec<u8> = image.data().iter().map(|&v| v as u8).collect();
    let horizontal = FixedWeights::new(&triangle_weights::<f64>(image.width(), width));
    let vertical = FixedWeights::new(&triangle_weights::<f64>(image.height(), height));

    // Width pass: every input row to `width` pixels.
    let mut tmp = vec![0u8; width * image.height() * c];
    let in_row = image.width() * c;
    tmp.par_chunks_mut(width * c)
        .zip(u8_data.par_chunks(in_row))
        .for_each(|(out, src)| {
            for (x, px) in out.chunks_exact_mut(c).enumerate() {
                let (start, taps) = horizontal.taps(x);
                for (ch, o) in px.iter_mut().enumerate() {
                    let acc = taps.iter().enumerate().fold(FIXED_HALF, |acc, (j, &k)| {
                        acc + src[(start + j) * c + ch] as i32 * k
                    });
                    *o = clip8(acc);
                }
            }
        });

    // Height pass: output row y mixes rows of the width-resized image.
    let row = width * c;
    let mut out = vec![0f32; row * height];
    out.par_chunks_mut(row).enumerate().for_each(|(y, dst)| {
        let (start, taps) = vertical.taps(y);
        for (i, o) in dst.iter_mut().enumerate() {
            let acc = taps.iter().enumerate().fold(FIXED_HALF, |acc, (j, &k)| {
                acc + tmp[(start + j) * row + i] as i32 * k
            });
            *o = clip8(acc) as f32;
        }
    });
    Image::new(width, height, c, out)
}

/// Resizes an f32 image (any channel count) exactly as torch
/// `F.interpolate(x, size=(height, width), mode="bilinear", antialias=True, align_corners=False)`
/// on CPU: the width pass, then the height pass, f32 weights, f32 sums with no rounding in between
/// (bit-exact with torch's fused-multiply-add CPU kernel).
/// A pass whose size does not change is skipped, as torch skips it. NaN samples spread to every
/// output pixel whose filter touches them (even with a zero weight, as in torch).
pub fn resize_antialias_bilinear(image: &Image, width: usize, height: usize) -> Result<Image> {
    check_sizes(image, width, height, "resize_antialias_bilinear")?;
    let c = image.channels();

    let tmp = if width == image.width() {
        image.data().to_vec()
    } else {
        let horizontal = triangle_weights::<f32>(image.width(), width);
        let in_row = image.width() * c;
        let mut tmp = vec![0f32; width * image.height() * c];
        tmp.par_chunks_mut(width * c)
            .zip(image.data().par_chunks(in_row))
            .for_each(|(out, src)| {
                for (x, px) in out.chunks_exact_mut(c).enumerate() {
                    let (start, taps) = horizontal.taps(x);
                    for (ch, o) in px.iter_mut().enumerate() {
                        *o = weighted_sum(taps, |j| src[(start + j) * c + ch]);
                    }
                }
            });
        tmp
    };
    if height == image.height() {
        return Image::new(width, height, c, tmp);
    }

    let vertical = triangle_weights::<f32>(image.height(), height);
    let row = width * c;
    let mut out = vec![0f32; row * height];
    out.par_chunks_mut(row).enumerate().for_each(|(y, dst)| {
        let (start, taps) = vertical.taps(y);
        for (i, o) in dst.iter_mut().enumerate() {
            *o = weighted_sum(taps, |j| tmp[(start + j) * row + i]);
        }
    });
    Image::new(width, height, c, out)
}

fn check_sizes(image: &Image, width: usize, height: usize, what: &str) -> Result<()> {
    if image.width() == 0 || image.height() == 0 || width == 0 || height == 0 {
        return Err(RasterError::Shape(format!(
            "{what}: cannot resize {}x{} to {width}x{height} (empty size)",
            image.width(),
            image.height()
        )));
    }
    Ok(())
}

/// torch's order: `t0·w0`, then `+= tj·wj` in f32. The compiler contracts torch's `+=` into a
/// fused multiply-add on AVX2 builds; `mul_add` reproduces that bit for bit.
#[inline]
fn weighted_sum(taps: &[f32], sample: impl Fn(usize) -> f32) -> f32 {
    let mut acc = sample(0) * taps[0];
    for (j, &w) in taps.iter().enumerate().skip(1) {
        acc = sample(j).mul_add(w, acc);
    }
    acc
}

/// Fractional bits of Pillow's 8-bit resampling (`PRECISION_BITS = 32 − 8 − 2`).
const PRECISION_BITS: u32 = 22;
/// Rounding offset every fixed-point accumulation starts from.
const FIXED_HALF: i32 = 1 << (PRECISION_BITS - 1);

/// Pillow's `clip8`: drops the fraction and clamps to 0..255.
#[inline]
fn clip8(acc: i32) -> u8 {
    if acc >= 1 << (PRECISION_BITS + 8) {
        255
    } else if acc <= 0 {
        0
    } else {
        (acc >> PRECISION_BITS) as u8
    }
}

/// Per-output-index filter taps along one axis: output `i` reads inputs
/// `start[i] .. start[i] + len(taps of i)`.
#[derive(Debug, Clone)]
struct AxisWeights<T> {
    start: Vec<usize>,
    /// Taps of output `i` are `weights[offset[i]..offset[i + 1]]`.
    offset: Vec<usize>,
    weights: Vec<T>,
}

impl<T> AxisWeights<T> {
    fn taps(&self, i: usize) -> (usize, &[T]) {
        (
            self.start[i],
            &self.weights[self.offset[i]..self.offset[i + 1]],
        )
    }
}

/// Pillow's 8-bit weights: each f64 weight rounded half away from zero to 22-bit fixed point.
type FixedWeights = AxisWeights<i32>;

impl FixedWeights {
    fn new(weights: &AxisWeights<f64>) -> Self {
        let scale = (1u32 << PRECISION_BITS) as f64;
        AxisWeights {
            start: weights.start.clone(),
            offset: weights.offset.clone(),
            weights: weights
                .weights
                .iter()
                .map(|&w| {
                    if w < 0.0 {
                        (-0.5 + w * scale) as i32
                    } else {
                        (0.5 + w * scale) as i32
                    }
                })
                .collect(),
        }
    }
}

/// The float type a reference computes its filter weights in. The bound and filter-argument
/// computations promote to f64 at the same places as the C/C++ references (torch mixes f32 values
/// with f64 literals), so each precision reproduces its reference's rounding.
trait FilterFloat:
    Copy
    + PartialOrd
    + std::ops::Add<Output = Self>
    + std::ops::Sub<Output = Self>
    + std::ops::Mul<Output = Self>
    + std::ops::Div<Output = Self>
{
    const ZERO: Self;
    const ONE: Self;
    fn from_f64(v: f64) -> Self;
    fn to_f64(self) -> f64;
}

impl FilterFloat for f32 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn from_f64(v: f64) -> Self {
        v as f32
    }
    fn to_f64(self) -> f64 {
        self as f64
    }
}

impl FilterFloat for f64 {
    const ZERO: Self = 0.0;
    const ONE: Self = 1.0;
    fn from_f64(v: f64) -> Self {
        v
    }
    fn to_f64(self) -> f64 {
        self
    }
}

/// Normalised triangle-filter weights for resizing an axis of `in_size` samples to `out_size`
/// (align_corners=False geometry), shared by Pillow (`precompute_coeffs`, T = f64) and torch
/// (`_compute_indices_min_size_weights_aa`, T = f32):
/// scale = in/out, support = max(scale, 1), centre = (i + 0.5)·scale,
/// taps j ∈ [trunc(centre − support + 0.5), trunc(centre + support + 0.5)) ∩ [0, in),
/// weight = max(0, 1 − |(j − centre + 0.5) / max(scale, 1)|), divided by the taps' sum.
fn triangle_weights<T: FilterFloat>(in_size: usize, out_size: usize) -> AxisWeights<T> {
    let scale = T::from_f64(in_size as f64) / T::from_f64(out_size as f64);
    let support = if scale >= T::ONE { scale } else { T::ONE };
    let inv_scale = T::from_f64(1.0 / support.to_f64());
    let mut start = Vec::with_capacity(out_size);
    let mut offset = Vec::with_capacity(out_size + 1);
    let mut weights = Vec::new();
    offset.push(0);
    for i in 0..out_size {
        let centre = T::from_f64(i as f64 + 0.5) * scale;
        // Truncation toward zero as C's `(int)`; a negative bound clamps to 0 anyway.
        let lo = ((centre - support).to_f64() + 0.5).max(0.0) as usize;
        let hi = (((centre + support).to_f64() + 0.5) as usize).min(in_size);
        let first = weights.len();
        let mut total = T::ZERO;
        for j in lo..hi {
            let d = T::from_f64(j as f64) - centre;
            let arg = T::from_f64((d.to_f64() + 0.5) * inv_scale.to_f64());
            let a = if arg < T::ZERO { T::ZERO - arg } else { arg };
            let w = if a < T::ONE { T::ONE - a } else { T::ZERO };
            weights.push(w);
            total = total + w;
        }
        if total != T::ZERO {
            for w in &mut weights[first..] {
                *w = *w / total;
            }
        }
        start.push(lo);
        offset.push(weights.len());
    }
    AxisWeights {
        start,
        offset,
        weights,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn ramp(width: usize, height: usize, channels: usize) -> Image {
        let data = (0..width * height * channels)
            .map(|i| ((i * 37) % 256) as f32)
            .collect();
        Image::new(width, height, channels, data).unwrap()
    }

    #[test]
    fn weights_sum_to_one_and_stay_inside() {
        for (n_in, n_out) in [(10, 3), (3, 10), (1024, 1000), (7, 7), (1, 5), (5, 1)] {
            let w = triangle_weights::<f64>(n_in, n_out);
            for i in 0..n_out {
                let (start, taps) = w.taps(i);
                assert!(!taps.is_empty() && start + taps.len() <= n_in);
                let sum: f64 = taps.iter().sum();
                assert!((sum - 1.0).abs() < 1e-12, "{n_in}->{n_out} at {i}: {sum}");
            }
        }
    }

    #[test]
    fn same_size_is_identity() {
        let img = ramp(9, 6, 3);
        assert_eq!(resize_pil_bilinear_u8(&img, 9, 6).unwrap(), img);
        assert_eq!(resize_antialias_bilinear(&img, 9, 6).unwrap(), img);
    }

    #[test]
    fn halving_averages_pairs_with_triangle_weights() {
        // 4 -> 2: scale 2, support 2, centre 1, taps 0..3; by hand, arg = (j − 1 + 0.5)/2 gives
        // weights 0.75, 0.75, 0.25 (sum 1.75) for inputs 0, 1, 2.
        let img = Image::new(4, 1, 1, vec![0.0, 70.0, 140.0, 210.0]).unwrap();
        let out = resize_antialias_bilinear(&img, 2, 1).unwrap();
        let want0: f64 = (0.0 * 0.75 + 70.0 * 0.75 + 140.0 * 0.25) / 1.75;
        assert!(
            (out.data()[0] as f64 - want0).abs() < 1e-4,
            "{:?}",
            out.data()
        );
        let pil = resize_pil_bilinear_u8(&img, 2, 1).unwrap();
        assert_eq!(pil.data()[0], (want0 + 0.5).floor() as f32);
    }

    #[test]
    fn constant_images_stay_constant() {
        let img = Image::filled(13, 7, 2, 200.0);
        for (w, h) in [(5, 3), (30, 20), (13, 20)] {
            let p = resize_pil_bilinear_u8(&img, w, h).unwrap();
            assert!(p.data().iter().all(|&v| v == 200.0));
            let t = resize_antialias_bilinear(&img, w, h).unwrap();
            assert!(t.data().iter().all(|&v| (v - 200.0).abs() < 1e-3));
        }
    }

    #[test]
    fn unchanged_axis_is_not_resampled() {
        // Only the width changes: a NaN in row 1 must not reach row 0 (torch skips the pass).
        let mut img = ramp(6, 3, 1);
        img.set(2, 1, 0, f32::NAN);
        let out = resize_antialias_bilinear(&img, 3, 3).unwrap();
        assert!(out.row(0).iter().all(|v| v.is_finite()));
        assert!(out.row(1).iter().any(|v| v.is_nan()));
    }

    #[test]
    fn bad_input_is_an_error() {
        let img = Image::new(2, 1, 1, vec![0.5, 3.0]).unwrap();
        assert!(resize_pil_bilinear_u8(&img, 1, 1).is_err());
        let img = Image::new(2, 1, 1, vec![256.0, 3.0]).unwrap();
        assert!(resize_pil_bilinear_u8(&img, 1, 1).is_err());
        let img = ramp(3, 3, 1);
        assert!(resize_antialias_bilinear(&img, 0, 3).is_err());
        assert!(resize_pil_bilinear_u8(&img, 3, 0).is_err());
    }
}
