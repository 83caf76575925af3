//! Resampling to a new size with the exact filters of the reference pre-processing (PIL, torch antialias).
//!
//! Both reference resizers are separable triangle ("bilinear") filters whose support grows with the
//! down-scale factor, applied width first, then height:
//! - [`resize_pil_bilinear_u8`]: Pillow's `Image.resize(..., BILINEAR)` on 8-bit data (SegFormer
//!   input). Weights in f64, converted to 22-bit fixed point; each pass rounds and clips to 0..255.
//!   Bit-exact with Pillow. [`resize_pil_lanczos_u8`] is the same machinery with Pillow's
//!   `LANCZOS` filter (the release brings a generated season back to the source size with it).
//! - [`resize_antialias_bilinear`]: torch `F.interpolate(mode="bilinear", antialias=True,
//!   align_corners=False)` on f32 (DINOv3 processor). Weights in f32 with torch's mix of f32 and
//!   f64 intermediates; sums in f32 with fused multiply-adds, as torch's AVX2/AVX-512 CPU kernel
//!   is compiled. Bit-exact with torch 2.4 on such a CPU (without the fusion: ≤ 2e-7 off).
//!
//! The weights of all come from one routine, [`filter_weights`], generic over the precision the
//! reference uses, so they cannot drift apart.

use rayon::prelude::*;

use crate::{Image, RasterError, Result};

/// Resizes an 8-bit image (integer values 0..=255 stored in f32, any channel count) exactly as
/// Pillow's `Image.resize((width, height), Image.BILINEAR)`: horizontal pass first, then vertical,
/// each pass in 22-bit fixed point rounded and clipped to 0..255. Returns integers in f32.
///
/// Errors on an empty input or output size and on a sample that is not an integer in 0..=255
/// (convert and clip first: PIL would have had a `uint8` array).
pub fn resize_pil_bilinear_u8(image: &Image, width: usize, height: usize) -> Result<Image> {
    resize_pil_u8(image, width, height, PilFilter::Bilinear)
}

/// [`resize_pil_bilinear_u8`] with Pillow's `Image.LANCZOS` filter (windowed sinc, support 3
/// widened by the down-scale factor; negative lobes, so each pass clips to 0..255). Bit-exact
/// with Pillow ≤ 12, which always resamples width first (Pillow 13 goes height first when it
/// widens and shortens an image; the clipping between passes makes the order matter).
pub fn resize_pil_lanczos_u8(image: &Image, width: usize, height: usize) -> Result<Image> {
    resize_pil_u8(image, width, height, PilFilter::Lanczos)
}

/// The Pillow filters the references resize with.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum PilFilter {
    Bilinear,
    Lanczos,
}

impl PilFilter {
    fn weights(self, in_size: usize, out_size: usize) -> AxisWeights<f64> {
        match self {
            PilFilter::Bilinear => triangle_weights(in_size, out_size),
            PilFilter::Lanczos => filter_weights(in_size, out_size, 3.0, lanczos3),
        }
    }
}

/// Pillow's `lanczos_filter`: `sinc(x) · sinc(x/3)` on [−3, 3).
fn lanczos3(x: f64) -> f64 {
    let sinc = |x: f64| {
        if x == 0.0 {
            1.0
        } else {
            let px = x * std::f64::consts::PI;
            px.sin() / px
        }
    };
    if (-3.0..3.0).contains(&x) {
        sinc(x) * sinc(x / 3.0)
    } else {
        0.0
    }
}

/// Pillow's 8-bit `ImagingResample`: a pass per axis whose size changes (width first), each in
/// fixed point, rounded and clipped to 0..255.
fn resize_pil_u8(image: &Image, width: usize, height: usize, filter: PilFilter) -> Result<Image> {
    let what = match filter {
        PilFilter::Bilinear => "resize_pil_bilinear_u8",
        PilFilter::Lanczos => "resize_pil_lanczos_u8",
    };
    check_sizes(image, width, height, what)?;
    if let Some(bad) = image
        .data()
        .iter()
        .find(|v| !(v.fract() == 0.0 && (0.0..=255.0).contains(*v)))
    {
        return Err(RasterError::Shape(format!(
            "{what}: sample {bad} is not an 8-bit value (integers 0..=255 expected)"
        )));
    }
    let c = image.channels();
    let in_row = image.width() * c;
    let u8_data: Vec<u8> = image.data().iter().map(|&v| v as u8).collect();

    // Width pass: every input row to `width` pixels.
    let tmp = if width == image.width() {
        u8_data
    } else {
        let horizontal = FixedWeights::new(&filter.weights(image.width(), width));
        let mut tmp = vec![0u8; width * image.height() * c];
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
        tmp
    };
    if height == image.height() {
        return Image::new(width, height, c, tmp.into_iter().map(f32::from).collect());
    }

    // Height pass: output row y mixes rows of the width-resized image.
    let vertical = FixedWeights::new(&filter.weights(image.height(), height));
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

/// Normalised triangle-filter weights ([`filter_weights`] with support 1), the bilinear filter of
/// Pillow (T = f64) and of torch's antialiased interpolation (T = f32).
fn triangle_weights<T: FilterFloat>(in_size: usize, out_size: usize) -> AxisWeights<T> {
    filter_weights(in_size, out_size, T::ONE, |arg| {
        let a = if arg < T::ZERO { T::ZERO - arg } else { arg };
        if a < T::ONE {
            T::ONE - a
        } else {
            T::ZERO
        }
    })
}

/// Normalised weights of a separable filter for resizing an axis of `in_size` samples to
/// `out_size` (align_corners=False geometry), as Pillow's `precompute_coeffs` (T = f64) and
/// torch's `_compute_indices_min_size_weights_aa` (T = f32) compute them:
/// scale = in/out, fs = max(scale, 1), support = `filter_support`·fs, centre = (i + 0.5)·scale,
/// taps j ∈ [trunc(centre − support + 0.5), trunc(centre + support + 0.5)) ∩ [0, in),
/// weight = filter((j − centre + 0.5) / fs), divided by the taps' sum.
fn filter_weights<T: FilterFloat>(
    in_size: usize,
    out_size: usize,
    filter_support: T,
    filter: impl Fn(T) -> T,
) -> AxisWeights<T> {
    let scale = T::from_f64(in_size as f64) / T::from_f64(out_size as f64);
    let filter_scale = if scale >= T::ONE { scale } else { T::ONE };
    let support = filter_support * filter_scale;
    let inv_scale = T::from_f64(1.0 / filter_scale.to_f64());
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
            let w = filter(T::from_f64((d.to_f64() + 0.5) * inv_scale.to_f64()));
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

/// `image` (one channel) shrunk by a whole `factor`: each cell the mean of the finite values of
/// its `factor`² block (NaN when none), blocks at the right and bottom edges cut short: a height
/// pyramid that holes do not darken.
pub fn block_mean_finite(image: &Image, factor: usize) -> Image {
    let factor = factor.max(1);
    let (w, h) = image.size();
    Image::from_fn(w.div_ceil(factor), h.div_ceil(factor), |x, y| {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for yy in y * factor..((y + 1) * factor).min(h) {
            for xx in x * factor..((x + 1) * factor).min(w) {
                let v = image.get(xx, yy, 0);
                if v.is_finite() {
                    sum += v as f64;
                    n += 1;
                }
            }
        }
        if n == 0 {
            f32::NAN
        } else {
            (sum / n as f64) as f32
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_means_skip_holes_and_cut_the_edges_short() {
        let image = Image::new(3, 2, 1, vec![1.0, f32::NAN, 5.0, 3.0, f32::NAN, f32::NAN]).unwrap();
        let half = block_mean_finite(&image, 2);
        assert_eq!(half.size(), (2, 1));
        assert_eq!(half.data(), [2.0, 5.0]);
        let all_holes = Image::filled(2, 2, 1, f32::NAN);
        assert!(block_mean_finite(&all_holes, 2).get(0, 0, 0).is_nan());
        assert_eq!(block_mean_finite(&image, 1).data()[..1], [1.0]);
    }

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

    /// Pillow 11.3 and 12.1 `Image.resize(size, Image.LANCZOS)` of a 7×5 RGB image with a sharp
    /// edge (ringing clipped to 0 and 255): up in x and down in y, down in x and up in y, one
    /// axis. (Pillow 13 runs the vertical pass first when it widens and shortens an image, which
    /// changes the first case by up to 12 DN.)
    #[test]
    fn lanczos_matches_pillow() {
        let image = Image::new(
            7,
            5,
            3,
            (0..5)
                .flat_map(|y| {
                    (0..7).flat_map(move |x| {
                        [
                            ((x * 37 + y * 91) % 256) as f32,
                            if x >= 3 { 255.0 } else { 0.0 },
                            ((x * x * 11 + y * 29) % 256) as f32,
                        ]
                    })
                })
                .collect(),
        )
        .unwrap();
        #[rustfmt::skip]
        let cases: [(usize, usize, &[u8]); 3] = [
            (11, 3, &[42, 0, 9, 55, 5, 11, 84, 0, 22, 109, 0, 44, 129, 86, 65, 154, 255, 108, 189,
                255, 197, 167, 247, 160, 108, 255, 34, 118, 255, 81, 148, 255, 162, 122, 0, 58, 155,
                5, 60, 160, 0, 71, 80, 0, 90, 56, 86, 120, 90, 255, 157, 136, 255, 194, 137, 247,
                148, 112, 255, 75, 129, 255, 151, 153, 255, 232, 62, 0, 107, 77, 5, 109, 106, 0,
                120, 126, 0, 132, 165, 86, 191, 176, 255, 206, 98, 255, 68, 70, 247, 19, 109, 255,
                116, 147, 255, 123, 157, 255, 99]),
            (3, 9, &[15, 0, 3, 94, 181, 97, 214, 255, 100, 44, 0, 11, 149, 181, 104, 162, 255, 107,
                102, 0, 30, 204, 181, 123, 87, 255, 126, 166, 0, 47, 133, 181, 151, 64, 255, 150,
                164, 0, 63, 37, 181, 157, 123, 255, 160, 83, 0, 87, 66, 181, 127, 209, 255, 156, 44,
                0, 114, 138, 181, 112, 201, 255, 119, 110, 0, 131, 148, 181, 139, 88, 255, 74, 166,
                0, 136, 143, 181, 162, 8, 255, 50]),
            (7, 2, &[78, 0, 23, 115, 0, 34, 87, 0, 67, 124, 255, 122, 176, 255, 204, 108, 255, 42,
                145, 255, 178, 95, 0, 93, 132, 0, 104, 104, 0, 137, 141, 255, 192, 87, 255, 73, 114,
                255, 112, 151, 255, 142]),
        ];
        for (w, h, want) in cases {
            let got = resize_pil_lanczos_u8(&image, w, h).unwrap();
            let got: Vec<u8> = got.data().iter().map(|&v| v as u8).collect();
            assert_eq!(got, want, "{w}x{h}");
        }
    }
}
