//! The backward pass of a convolution on plain NCHW `f32` slices, on the forward kernels: the
//! input gradient is itself a convolution (stride 1: of the output gradient with the flipped,
//! transposed weight, so Winograd and the tap GEMMs apply; strided: a transposed convolution),
//! and the weight gradient is one GEMM of the output gradient with the unfolded input per band
//! of output rows.

use rayon::prelude::*;

use super::epilogue::Epilogue;
use super::geometry::{Geometry, Nchw, TransposeGeometry};
use super::kernels::{conv2d_nchw, conv_transpose2d_nchw, MIN_TAP_CHANNELS};
use super::prepared::LayerWeights;
use super::scratch::{Scratch, COLUMNS};
use crate::matmul::{gemm_f32, Strided};

/// Floats of unfolded input per weight-gradient GEMM (4 MiB): the GEMM's inner dimension is the
/// band's pixels, so longer bands make fewer, better-shaped products.
const GRAD_COLUMN_FLOATS: usize = 1 << 20;

/// Largest `ci·co` whose stride-1 weight gradient runs as tap GEMMs ([`weight_grad_by_taps`]);
/// wider layers make one large unfolded GEMM pay better (measured on the MonSter++ layers).
const MAX_TAP_GRAD_CHANNEL_PAIRS: usize = 128 * 128;

/// Fewest pixels per weight-gradient GEMM of [`weight_grad_by_taps`]: shorter bands spend more
/// on the partial sums than they gain in balance.
const MIN_BAND_PIXELS: usize = 256;

/// `∂L/∂x` (`[b, ci, h, w]`) of a convolution of an `h × w` input with `weights`
/// (`[co, ci, kh, kw]`), from `grad` (`∂L/∂y`, `[b, co, oh, ow]`).
pub fn conv2d_input_grad(
    grad: &[f32],
    grad_shape: Nchw,
    weights: &LayerWeights,
    [h, w]: [usize; 2],
    geometry: Geometry,
) -> Vec<f32> {
    let Nchw { b, c: co, .. } = grad_shape;
    let (weight, ci) = (weights.raw(), weights.ci());
    let [kh, kw] = geometry.kernel;
    let [dh, dw] = geometry.dilation;
    let [top, left, bottom, right] = geometry.padding;
    let (span_h, span_w) = (dh * (kh - 1), dw * (kw - 1));
    assert_eq!(
        weight.len(),
        co * ci * kh * kw,
        "conv2d_input_grad: weight size"
    );
    if geometry.stride == [1, 1] && top.max(bottom) <= span_h && left.max(right) <= span_w {
        // x̄ = ȳ ⋆ flip(W)ᵀ, padded by the kernel's span less the forward padding.
        let transposed = Geometry {
            padding: [span_h - top, span_w - left, span_h - bottom, span_w - right],
            ..geometry
        };
        let (out, size) = conv2d_nchw(
            grad,
            grad_shape,
            weights.flipped(),
            transposed,
            Epilogue::bias(None),
        );
        assert_eq!(size, [h, w], "conv2d_input_grad: output size");
        return out;
    }
    // Strided (or padded beyond the kernel): the transposed convolution over the whole padded
    // input, `weight` read as its `[in = co, out = ci]` kernel, then the padding cut off.
    let full_geometry = TransposeGeometry {
        kernel: geometry.kernel,
        stride: geometry.stride,
        padding: [0, 0],
        dilation: geometry.dilation,
        padding_out: [0, 0],
    };
    let (full, [fh, fw]) = conv_transpose2d_nchw(
        grad,
        grad_shape,
        weight,
        ci,
        full_geometry,
        None,
        Epilogue::bias(None),
    );
    let mut out = vec![0.0f32; b * ci * h * w];
    out.par_chunks_exact_mut(h * w)
        .zip(full.par_chunks_exact(fh * fw))
        .for_each(|(dst, src)| {
            // Input rows and columns past the last one the kernel reached get no gradient.
            let rows = fh.saturating_sub(top).min(h);
            let cols = fw.saturating_sub(left).min(w);
            for (y, d) in dst.chunks_exact_mut(w).take(rows).enumerate() {
                d[..cols].copy_from_slice(&src[(y + top) * fw + left..][..cols]);
            }
        });
    out
}

/// `∂L/∂W` (`[co, ci, kh, kw]`) of a convolution of `input` (`shape`), from `grad`
/// (`[b, co, oh, ow]`): `Σ_pixels ȳ[co, p] · unfold(x)[ci·kh·kw, p]`.
pub fn conv2d_weight_grad(
    input: &[f32],
    shape: Nchw,
    grad: &[f32],
    co: usize,
    geometry: Geometry,
) -> Vec<f32> {
    let Nchw { b, c: ci, h, w } = shape;
    let [kh, kw] = geometry.kernel;
    let [oh, ow] = geometry.output([h, w]);
    assert_eq!(
        input.len(),
        b * ci * h * w,
        "conv2d_weight_grad: input size"
    );
    assert_eq!(
        grad.len(),
        b * co * oh * ow,
        "conv2d_weight_grad: gradient size"
    );
    let thin = ci * co <= MAX_TAP_GRAD_CHANNEL_PAIRS || kh * kw == 1;
    if geometry.stride == [1, 1] && ci >= MIN_TAP_CHANNELS && thin {
        return weight_grad_by_taps(input, shape, grad, co, geometry);
    }
    weight_grad_unfolded(input, shape, grad, co, geometry)
}

/// The weight gradient as one GEMM per band of output rows with the input unfolded
/// pixel-major (`[pixels, taps·ci]`, a row of every tap's channels per output pixel): the
/// unfolded band is then the GEMM's column-major left operand, which it reads in place
/// instead of repacking it on one thread.
fn weight_grad_unfolded(
    input: &[f32],
    shape: Nchw,
    grad: &[f32],
    co: usize,
    geometry: Geometry,
) -> Vec<f32> {
    let Nchw { b, c: ci, h, w } = shape;
    let [kh, kw] = geometry.kernel;
    let [sh, sw] = geometry.stride;
    let [dh, dw] = geometry.dilation;
    let [hp, wp] = geometry.padded([h, w]);
    let [oh, ow] = geometry.output([h, w]);
    let taps = kh * kw;
    let k = taps * ci;
    let x_hwc = padded_pixel_major(input, shape, geometry);
    // `[co, taps, ci]`: the unfolded rows' order.
    let mut by_tap = vec![0.0f32; co * k];
    let rows_per_band = (GRAD_COLUMN_FLOATS / (k * ow)).clamp(1, oh);
    let mut columns = Scratch::take(&COLUMNS, k * rows_per_band * ow);
    let mut first = true;
    for n in 0..b {
        let image = &x_hwc[n * hp * wp * ci..][..hp * wp * ci];
        for r0 in (0..oh).step_by(rows_per_band) {
            let rows = rows_per_band.min(oh - r0);
            let pixels = rows * ow;
            columns[..k * pixels]
                .par_chunks_exact_mut(k)
                .enumerate()
                .for_each(|(p, dst)| {
                    let (y, x) = ((r0 + p / ow) * sh, (p % ow) * sw);
                    for (tap, d) in dst.chunks_exact_mut(ci).enumerate() {
                        let (i, j) = (tap / kw, tap % kw);
                        let at = ((y + i * dh) * wp + x + j * dw) * ci;
                        d.copy_from_slice(&image[at..at + ci]);
                    }
                });
            // SAFETY: dst is `[co, k]` row-major (`by_tap`) read as `k × co` column-major; lhs
            // is the unfolded band, `k × pixels` column-major inside `columns`; rhs is the band
            // of ȳ read transposed, `pixels × co` with columns `oh·ow` apart inside image `n`.
            unsafe {
                gemm_f32(
                    [k, co, pixels],
                    Strided::columns(by_tap.as_mut_ptr(), k),
                    Strided::columns(columns.as_ptr(), k),
                    Strided::columns(grad.as_ptr().add(n * co * oh * ow + r0 * ow), oh * ow),
                    !first,
                    1.0,
                    gemm::Parallelism::Rayon(0),
                );
            }
            first = false;
        }
    }
    columns.give_back(&COLUMNS);
    let mut out = vec![0.0f32; co * k];
    out.par_chunks_exact_mut(k)
        .zip(by_tap.par_chunks_exact(k))
        .for_each(|(dst, src)| {
            for (tap, channels) in src.chunks_exact(ci).enumerate() {
                for (c, v) in channels.iter().enumerate() {
                    dst[c * taps + tap] = *v;
                }
            }
        });
    out
}

/// The input zero-padded by the geometry's padding and stored pixel-major: `[b, hp, wp, ci]`.
fn padded_pixel_major(input: &[f32], shape: Nchw, geometry: Geometry) -> Vec<f32> {
    let Nchw { b, c: ci, h, w } = shape;
    let [top, left, _, _] = geometry.padding;
    let [hp, wp] = geometry.padded([h, w]);
    let mut x_hwc = vec![0.0f32; b * hp * wp * ci];
    x_hwc
        .par_chunks_exact_mut(wp * ci)
        .enumerate()
        .for_each(|(row, dst)| {
            let (n, y) = (row / hp, row % hp);
            if y < top || y >= top + h {
                return;
            }
            let image = &input[n * ci * h * w..][..ci * h * w];
            let row = |c: usize| &image[c * h * w + (y - top) * w..][..w];
            // Eight channels at a time: eight read streams, eight consecutive writes per pixel.
            for c0 in (0..ci).step_by(8) {
                let lanes = (ci - c0).min(8);
                let block: [&[f32]; 8] = std::array::from_fn(|k| row((c0 + k).min(ci - 1)));
                let block = &block[..lanes];
                for x in 0..w {
                    let d = &mut dst[(left + x) * ci + c0..][..lanes];
                    for (d, src) in d.iter_mut().zip(block) {
                        *d = src[x];
                    }
                }
            }
        });
    x_hwc
}

/// The stride-1 weight gradient without an unfolded input: with the input padded and stored
/// pixel-major (`[hp·wp, ci]`) and `ȳ` widened to the padded width (zeros past `ow`), tap
/// `(i, j)` reads the input as one strided matrix starting `i·dh` rows and `j·dw` columns in,
/// so `∂L/∂W[:, :, i, j]ᵀ = x_tapᵀ · ȳᵀ` is a single GEMM over the pixels whose operands both
/// have unit stride along their outer dimension (the GEMM packs nothing). Taps and bands of
/// pixels run as independent single-threaded GEMMs into partial sums, added at the end.
fn weight_grad_by_taps(
    input: &[f32],
    shape: Nchw,
    grad: &[f32],
    co: usize,
    geometry: Geometry,
) -> Vec<f32> {
    let Nchw { b, c: ci, h, w } = shape;
    let [kh, kw] = geometry.kernel;
    let [dh, dw] = geometry.dilation;
    let [hp, wp] = geometry.padded([h, w]);
    let [oh, ow] = geometry.output([h, w]);
    // Pixels of the widened output: the last row stops at `ow`, so that every tap's view ends
    // inside the padded image.
    let pixels = (oh - 1) * wp + ow;
    let x_hwc = padded_pixel_major(input, shape, geometry);
    let mut grad_wide = vec![0.0f32; b * co * pixels];
    grad_wide
        .par_chunks_exact_mut(pixels)
        .zip(grad.par_chunks_exact(oh * ow))
        .for_each(|(dst, src)| {
            for (d, s) in dst.chunks_mut(wp).zip(src.chunks_exact(ow)) {
                d[..ow].copy_from_slice(s);
            }
        });
    let taps = kh * kw;
    let bands = (4 * rayon::current_num_threads())
        .div_ceil(taps)
        .min(pixels.div_ceil(MIN_BAND_PIXELS))
        .max(1);
    let band = pixels.div_ceil(bands);
    let partial: Vec<Vec<f32>> = (0..taps * bands)
        .into_par_iter()
        .map(|task| {
            let (tap, p0) = (task / bands, (task % bands) * band);
            let len = band.min(pixels - p0);
            let shift = (tap / kw) * dh * wp + (tap % kw) * dw;
            let mut sum = vec![0.0f32; co * ci];
            for n in 0..b {
                let x = &x_hwc[(n * hp * wp + shift + p0) * ci..][..len * ci];
                let g = &grad_wide[n * co * pixels + p0..];
                // SAFETY: dst is `[co, ci]` row-major read as `ci × co` column-major (`sum`);
                // lhs is `ci × len` with columns `ci` apart inside `x`; rhs is `len × co` with
                // columns `pixels` apart inside `g` (the last column ends at `(co − 1)·pixels +
                // p0 + len ≤ co·pixels`).
                unsafe {
                    gemm_f32(
                        [ci, co, len],
                        Strided::columns(sum.as_mut_ptr(), ci),
                        Strided::columns(x.as_ptr(), ci),
                        Strided::columns(g.as_ptr(), pixels),
                        n > 0,
                        1.0,
                        gemm::Parallelism::None,
                    );
                }
            }
            sum
        })
        .collect();
    let mut out = vec![0.0f32; co * ci * taps];
    out.par_chunks_exact_mut(ci * taps)
        .enumerate()
        .for_each(|(o, dst)| {
            for (tap, bands_of_tap) in partial.chunks_exact(bands).enumerate() {
                for c in 0..ci {
                    dst[c * taps + tap] = bands_of_tap.iter().map(|s| s[o * ci + c]).sum();
                }
            }
        });
    out
}

/// `∂L/∂bias` (`[c]`): the gradient summed over the batch and the plane.
pub fn bias_grad(grad: &[f32], shape: Nchw) -> Vec<f32> {
    let Nchw { b, c, h, w } = shape;
    let plane = h * w;
    (0..c)
        .into_par_iter()
        .map(|ch| {
            (0..b)
                .map(|n| grad[(n * c + ch) * plane..][..plane].iter().sum::<f32>())
                .sum()
        })
        .collect()
}
