//! The CPU kernels on plain NCHW `f32` slices: convolution by tap GEMMs (stride 1) or by an
//! unfolded input (strides, thin inputs), transposed convolution by one GEMM plus a scatter,
//! each ending in a per-channel affine map and an activation applied while the output is
//! written (bias, a folded BatchNorm, ReLU/LeakyReLU).

use rayon::prelude::*;

use super::epilogue::Epilogue;
use super::geometry::{Geometry, Nchw, TransposeGeometry};
use super::prepared::LayerWeights;
use super::scratch::{Scratch, COLUMNS, PADDED, WIDE};
use crate::matmul::{gemm_f32, Strided};

/// Output pixels per tap-GEMM call: a few rows of the padded image, so that the output tile
/// stays in the cache while the taps accumulate into it.
const TILE_PIXELS: usize = 2048;

/// Floats of unfolded input per GEMM call (1 MiB): a tile that stays in the L2 cache.
const COLUMN_FLOATS: usize = 1 << 18;

/// Input channels from which a stride-1 convolution runs as tap GEMMs; thinner inputs make
/// GEMMs too thin to pay, so they are unfolded (`k = c·kh·kw` instead of `c`).
pub(super) const MIN_TAP_CHANNELS: usize = 16;

/// Fewest 2×2 output tiles for which a 3×3 convolution runs as Winograd: on smaller maps its
/// bands are too short for its GEMMs (MonSter++'s 1/16 ConvGRU at 8×8 runs faster as tap GEMMs;
/// at 16×16 Winograd is ahead: BENCHMARKS.md, "SegFormer and the training step against
/// PyTorch", the seventh session).
const MIN_WINOGRAD_TILES: usize = 32;

/// Convolution of `input` (`shape`, NCHW) with `weights` (`[co, ci, kh, kw]`), then
/// `epilogue`. Returns the output (`[b, co, oh, ow]`) and `[oh, ow]`.
pub fn conv2d_nchw(
    input: &[f32],
    shape: Nchw,
    weights: &LayerWeights,
    geometry: Geometry,
    epilogue: Epilogue<'_>,
) -> (Vec<f32>, [usize; 2]) {
    let Nchw { b, c: ci, h, w } = shape;
    let [kh, kw] = geometry.kernel;
    let (weight, co) = (weights.raw(), weights.co());
    assert_eq!(input.len(), b * ci * h * w, "conv2d_nchw: input size");
    assert_eq!(weight.len(), co * ci * kh * kw, "conv2d_nchw: weight size");
    let [oh, ow] = geometry.output([h, w]);
    let mut out = vec![0.0f32; b * co * oh * ow];
    let plain_3x3 = geometry.kernel == [3, 3] && geometry.dilation == [1, 1];
    let tiles = oh.div_ceil(2) * ow.div_ceil(2);
    if plain_3x3
        && geometry.stride == [1, 1]
        && ci >= MIN_TAP_CHANNELS
        && co >= MIN_TAP_CHANNELS
        && tiles >= MIN_WINOGRAD_TILES
    {
        super::winograd::conv3x3(
            input,
            shape,
            weights.winograd(),
            co,
            geometry.padding,
            epilogue,
            &mut out,
        );
    } else if geometry.stride == [1, 1] && co < MIN_TAP_CHANNELS && ci >= MIN_TAP_CHANNELS {
        conv_thin_output(input, shape, weight, co, geometry, epilogue, &mut out);
    } else if geometry.stride == [1, 1] && ci >= MIN_TAP_CHANNELS {
        conv_taps(
            input,
            shape,
            weights.tap_major(),
            co,
            geometry,
            epilogue,
            &mut out,
        );
    } else {
        conv_unfolded(input, shape, weight, co, geometry, &mut out);
        for image in out.chunks_exact_mut(co * oh * ow) {
            epilogue.apply(image, oh * ow);
        }
    }
    (out, [oh, ow])
}

/// Stride 1: one GEMM per kernel tap. Each output row is computed over the whole padded width
/// `wp`; for tap `(i, j)` the input it reads is the padded image shifted by `i·dh·wp + j·dw`,
/// a plain strided matrix `[ci, oh·wp]` (row stride `hp·wp`). The `wp − ow` extra columns of
/// each row are discarded when the epilogue writes `out`. `taps` is the weight tap-major
/// ([`LayerWeights::tap_major`]).
fn conv_taps(
    input: &[f32],
    shape: Nchw,
    taps: &[f32],
    co: usize,
    geometry: Geometry,
    epilogue: Epilogue<'_>,
    out: &mut [f32],
) {
    let Nchw { b, c: ci, h, w } = shape;
    let [kh, kw] = geometry.kernel;
    let [top, left, _, _] = geometry.padding;
    let [dh, dw] = geometry.dilation;
    let [hp, wp] = geometry.padded([h, w]);
    let [oh, ow] = geometry.output([h, w]);
    let span_w = dw * (kw - 1);
    // The taps' shifted views of the last channel read up to `span_w` values past the image
    // (only for the discarded columns): keep them inside the buffer.
    let plane = hp * wp;
    assert_eq!(taps.len(), kh * kw * co * ci, "conv_taps: weight size");
    let mut wide = Scratch::take(&WIDE, co * oh * wp);
    let mut padded = Scratch::take(&PADDED, ci * plane + span_w);
    padded[ci * plane..].fill(0.0);
    let rows_per_tile = (TILE_PIXELS / wp).max(1);
    for n in 0..b {
        let image = &input[n * ci * h * w..(n + 1) * ci * h * w];
        pad_into(&mut padded, image, [ci, h, w], [top, left], [hp, wp]);
        for r0 in (0..oh).step_by(rows_per_tile) {
            let rows = rows_per_tile.min(oh - r0);
            for (tap, tap_weight) in taps.chunks_exact(co * ci).enumerate() {
                let offset = (tap / kw) * dh * wp + (tap % kw) * dw + r0 * wp;
                // SAFETY: dst is `co × rows·wp` at row stride `oh·wp` inside `wide`; lhs is the
                // `co × ci` tap matrix; rhs is `ci × rows·wp` at row stride `plane`, whose last
                // element, `(ci−1)·plane + offset + rows·wp − 1 ≤ ci·plane + span_w − 1`, is
                // inside `padded`.
                unsafe {
                    gemm_f32(
                        [co, rows * wp, ci],
                        Strided::rows(wide.as_mut_ptr().add(r0 * wp), oh * wp),
                        Strided::rows(tap_weight.as_ptr(), ci),
                        Strided::rows(padded.as_ptr().add(offset), plane),
                        tap > 0,
                        1.0,
                        gemm::Parallelism::Rayon(0),
                    );
                }
            }
        }
        let dst = &mut out[n * co * oh * ow..(n + 1) * co * oh * ow];
        dst.par_chunks_exact_mut(oh * ow)
            .zip(wide.par_chunks_exact(oh * wp))
            .enumerate()
            .for_each(|(c, (dst_plane, src_plane))| {
                let (scale, shift) = epilogue.channel(c);
                for (d, s) in dst_plane
                    .chunks_exact_mut(ow)
                    .zip(src_plane.chunks_exact(wp))
                {
                    for (d, s) in d.iter_mut().zip(&s[..ow]) {
                        *d = epilogue.act.apply(s * scale + shift);
                    }
                }
            });
    }
    wide.give_back(&WIDE);
    padded.give_back(&PADDED);
}

/// Stride 1 with few output channels (a disparity head's 256 → 1): a GEMM with so few rows only
/// streams its input once per tap, so each output row is accumulated directly instead, one
/// multiply-add of a whole input row per channel and tap (one pass over the input).
fn conv_thin_output(
    input: &[f32],
    shape: Nchw,
    weight: &[f32],
    co: usize,
    geometry: Geometry,
    epilogue: Epilogue<'_>,
    out: &mut [f32],
) {
    let Nchw { b, c: ci, h, w } = shape;
    let [kh, kw] = geometry.kernel;
    let [top, left, _, _] = geometry.padding;
    let [dh, dw] = geometry.dilation;
    let [hp, wp] = geometry.padded([h, w]);
    let [oh, ow] = geometry.output([h, w]);
    let mut padded = Scratch::take(&PADDED, ci * hp * wp);
    for n in 0..b {
        let image = &input[n * ci * h * w..(n + 1) * ci * h * w];
        pad_into(&mut padded, image, [ci, h, w], [top, left], [hp, wp]);
        let padded = &padded[..];
        let dst = &mut out[n * co * oh * ow..(n + 1) * co * oh * ow];
        // One task per (output channel, output row).
        dst.par_chunks_exact_mut(ow)
            .enumerate()
            .for_each(|(row, acc)| {
                let (o, y) = (row / oh, row % oh);
                acc.fill(0.0);
                let kernel = &weight[o * ci * kh * kw..(o + 1) * ci * kh * kw];
                for (c, taps) in kernel.chunks_exact(kh * kw).enumerate() {
                    let plane = &padded[c * hp * wp..(c + 1) * hp * wp];
                    for (tap, &k) in taps.iter().enumerate() {
                        let (i, j) = (tap / kw, tap % kw);
                        let src = &plane[(y + i * dh) * wp + j * dw..][..ow];
                        for (a, &v) in acc.iter_mut().zip(src) {
                            *a += k * v;
                        }
                    }
                }
                let (scale, shift) = epilogue.channel(o);
                for a in acc.iter_mut() {
                    *a = epilogue.act.apply(*a * scale + shift);
                }
            });
    }
    padded.give_back(&PADDED);
}

/// Any stride: the input is unfolded a band of output rows at a time into `[ci·kh·kw, pixels]`
/// (im2col), then one GEMM with the weight as it is stored (`[co, ci·kh·kw]`) writes the band.
fn conv_unfolded(
    input: &[f32],
    shape: Nchw,
    weight: &[f32],
    co: usize,
    geometry: Geometry,
    out: &mut [f32],
) {
    let Nchw { b, c: ci, h, w } = shape;
    let [kh, kw] = geometry.kernel;
    let [oh, ow] = geometry.output([h, w]);
    let k = ci * kh * kw;
    let rows_per_band = (COLUMN_FLOATS / (k * ow)).clamp(1, oh);
    let mut columns = Scratch::take(&COLUMNS, k * rows_per_band * ow);
    for n in 0..b {
        let image = &input[n * ci * h * w..(n + 1) * ci * h * w];
        for r0 in (0..oh).step_by(rows_per_band) {
            let rows = rows_per_band.min(oh - r0);
            let pixels = rows * ow;
            unfold_rows(
                image,
                [ci, h, w],
                geometry,
                r0,
                rows,
                &mut columns[..k * pixels],
            );
            // SAFETY: dst is `co × pixels` at row stride `oh·ow` inside this image's output;
            // lhs is `[co, k]` row-major; rhs is `[k, pixels]` row-major inside `columns`.
            unsafe {
                gemm_f32(
                    [co, pixels, k],
                    Strided::rows(out.as_mut_ptr().add(n * co * oh * ow + r0 * ow), oh * ow),
                    Strided::rows(weight.as_ptr(), k),
                    Strided::rows(columns.as_ptr(), pixels),
                    false,
                    1.0,
                    gemm::Parallelism::Rayon(0),
                );
            }
        }
    }
    columns.give_back(&COLUMNS);
}

/// The im2col of output rows `r0..r0 + rows` of one image (`[c, h, w]`) into `dst`
/// (`[c·kh·kw, rows·ow]`): row `(c, i, j)` holds, for each of those output pixels, the input
/// value that tap `(i, j)` of channel `c` reads (zero in the padding).
pub(super) fn unfold_rows(
    image: &[f32],
    [c, h, w]: [usize; 3],
    geometry: Geometry,
    r0: usize,
    rows: usize,
    dst: &mut [f32],
) {
    let [kh, kw] = geometry.kernel;
    let [top, left, _, _] = geometry.padding;
    let [sh, sw] = geometry.stride;
    let [dh, dw] = geometry.dilation;
    let ow = geometry.output([h, w])[1];
    let pixels = rows * ow;
    assert_eq!(dst.len(), c * kh * kw * pixels, "unfold_rows: buffer size");
    dst.par_chunks_exact_mut(pixels)
        .enumerate()
        .for_each(|(row, dst)| {
            let (c, i, j) = (row / (kh * kw), (row / kw) % kh, row % kw);
            let plane = &image[c * h * w..(c + 1) * h * w];
            // Output columns whose input column `ox·sw + j·dw − left` is inside the image.
            let x0 = (left.saturating_sub(j * dw)).div_ceil(sw).min(ow);
            let x1 = ((w + left).saturating_sub(j * dw))
                .div_ceil(sw)
                .clamp(x0, ow);
            for (r, d) in dst.chunks_exact_mut(ow).enumerate() {
                let y = ((r0 + r) * sh + i * dh) as isize - top as isize;
                if y < 0 || y >= h as isize {
                    d.fill(0.0);
                    continue;
                }
                let src = &plane[y as usize * w..][..w];
                d[..x0].fill(0.0);
                d[x1..].fill(0.0);
                for (ox, d) in (x0..x1).zip(&mut d[x0..x1]) {
                    *d = src[ox * sw + j * dw - left];
                }
            }
        });
}

/// Transposed convolution of `input` (`shape`) with `weight` (`[ci, co, kh, kw]`, PyTorch's
/// layout, one group), plus `bias`, then `epilogue`. Each band of input rows is multiplied by
/// the weight in one GEMM (`[co·kh·kw, pixels]`: what every input pixel adds to each tap), then
/// scattered into the output, one output channel per task.
pub fn conv_transpose2d_nchw(
    input: &[f32],
    shape: Nchw,
    weight: &[f32],
    co: usize,
    geometry: TransposeGeometry,
    bias: Option<&[f32]>,
    epilogue: Epilogue<'_>,
) -> (Vec<f32>, [usize; 2]) {
    let Nchw { b, c: ci, h, w } = shape;
    let [kh, kw] = geometry.kernel;
    let [sh, sw] = geometry.stride;
    let [ph, pw] = geometry.padding;
    let [dh, dw] = geometry.dilation;
    assert_eq!(
        input.len(),
        b * ci * h * w,
        "conv_transpose2d_nchw: input size"
    );
    assert_eq!(
        weight.len(),
        ci * co * kh * kw,
        "conv_transpose2d_nchw: weight size"
    );
    let [oh, ow] = geometry.output([h, w]);
    let m = co * kh * kw;
    let rows_per_band = (COLUMN_FLOATS / (m * w)).clamp(1, h);
    let mut out = vec![0.0f32; b * co * oh * ow];
    let mut columns = Scratch::take(&COLUMNS, m * rows_per_band * w);
    for n in 0..b {
        let image = &input[n * ci * h * w..(n + 1) * ci * h * w];
        let dst = &mut out[n * co * oh * ow..(n + 1) * co * oh * ow];
        if let Some(bias) = bias {
            dst.par_chunks_exact_mut(oh * ow)
                .zip(bias)
                .for_each(|(plane, &v)| plane.fill(v));
        }
        for r0 in (0..h).step_by(rows_per_band) {
            let rows = rows_per_band.min(h - r0);
            let pixels = rows * w;
            // SAFETY: dst is `[m, pixels]` row-major inside `columns`; lhs is the weight read as
            // `[m, ci]` (element `(t, c)` at `c·m + t`); rhs is `[ci, pixels]` at row stride
            // `h·w`, rows `r0..r0+rows` of this image.
            unsafe {
                gemm_f32(
                    [m, pixels, ci],
                    Strided::rows(columns.as_mut_ptr(), pixels),
                    Strided::columns(weight.as_ptr(), m),
                    Strided::rows(image.as_ptr().add(r0 * w), h * w),
                    false,
                    1.0,
                    gemm::Parallelism::Rayon(0),
                );
            }
            let columns = &columns[..m * pixels];
            dst.par_chunks_exact_mut(oh * ow)
                .enumerate()
                .for_each(|(o, plane)| {
                    for tap in 0..kh * kw {
                        let (i, j) = (tap / kw, tap % kw);
                        let src = &columns[(o * kh * kw + tap) * pixels..][..pixels];
                        for (r, src) in src.chunks_exact(w).enumerate() {
                            let y = ((r0 + r) * sh + i * dh) as isize - ph as isize;
                            if y < 0 || y >= oh as isize {
                                continue;
                            }
                            let row = &mut plane[y as usize * ow..][..ow];
                            // Input columns whose output column `x·sw + j·dw − pw` is inside.
                            let x0 = pw.saturating_sub(j * dw).div_ceil(sw).min(w);
                            let x1 = (ow + pw).saturating_sub(j * dw).div_ceil(sw).clamp(x0, w);
                            for (x, &v) in (x0..x1).zip(&src[x0..x1]) {
                                row[x * sw + j * dw - pw] += v;
                            }
                        }
                    }
                });
        }
        epilogue.apply(dst, oh * ow);
    }
    columns.give_back(&COLUMNS);
    (out, [oh, ow])
}

/// Writes `image` (`[c, h, w]`) into the interior of `padded` (`[c, hp, wp]`) and zeros its
/// borders: each element once (the buffer is reused, its old contents are garbage).
pub(super) fn pad_into(
    padded: &mut [f32],
    image: &[f32],
    [c, h, w]: [usize; 3],
    [top, left]: [usize; 2],
    [hp, wp]: [usize; 2],
) {
    if hp == h && wp == w {
        padded[..c * h * w].copy_from_slice(image);
        return;
    }
    padded[..c * hp * wp]
        .par_chunks_exact_mut(hp * wp)
        .zip(image.par_chunks_exact(h * w))
        .for_each(|(dst, src)| {
            let (above, rest) = dst.split_at_mut(top * wp);
            let (inner, below) = rest.split_at_mut(h * wp);
            above.fill(0.0);
            below.fill(0.0);
            for (d, s) in inner.chunks_exact_mut(wp).zip(src.chunks_exact(w)) {
                d[..left].fill(0.0);
                d[left..left + w].copy_from_slice(s);
                d[left + w..].fill(0.0);
            }
        });
}
