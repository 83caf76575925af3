//! The backward pass of a convolution on plain NCHW `f32` slices, on the forward kernels: the
//! input gradient is itself a convolution (stride 1: of the output gradient with the flipped,
//! transposed weight, so Winograd and the tap GEMMs apply; strided: a transposed convolution),
//! and the weight gradient is one GEMM of the output gradient with the unfolded input per band
//! of output rows.

use rayon::prelude::*;

use super::kernels::{
    conv2d_nchw, conv_transpose2d_nchw, unfold_rows, Epilogue, Geometry, Nchw, TransposeGeometry,
};
use super::prepared::LayerWeights;
use super::scratch::{Scratch, COLUMNS};
use crate::matmul::{gemm_f32, Strided};

/// Floats of unfolded input per weight-gradient GEMM (4 MiB): the GEMM's inner dimension is the
/// band's pixels, so longer bands make fewer, better-shaped products.
const GRAD_COLUMN_FLOATS: usize = 1 << 20;

/// `∂L/∂x` (`[b, ci, h, w]`) of a convolution of an `h × w` input with `weight`
/// (`[co, ci, kh, kw]`), from `grad` (`∂L/∂y`, `[b, co, oh, ow]`).
pub fn conv2d_input_grad(
    grad: &[f32],
    grad_shape: Nchw,
    weight: &[f32],
    ci: usize,
    [h, w]: [usize; 2],
    geometry: Geometry,
) -> Vec<f32> {
    let Nchw { b, c: co, .. } = grad_shape;
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
        let flipped = LayerWeights::new(flip_transpose(weight, co, ci, kh * kw), ci, kh * kw);
        let transposed = Geometry {
            padding: [span_h - top, span_w - left, span_h - bottom, span_w - right],
            ..geometry
        };
        let (out, size) = conv2d_nchw(grad, grad_shape, &flipped, transposed, Epilogue::bias(None));
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
    let k = ci * kh * kw;
    let mut out = vec![0.0f32; co * k];
    let rows_per_band = (GRAD_COLUMN_FLOATS / (k * ow)).clamp(1, oh);
    let mut columns = Scratch::take(&COLUMNS, k * rows_per_band * ow);
    let mut first = true;
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
            // SAFETY: dst is `[co, k]` row-major (`out`); lhs is the band of ȳ, `co × pixels`
            // at row stride `oh·ow` inside image `n`; rhs is the unfolded band read transposed,
            // `pixels × k` (element `(p, j)` at `j·pixels + p`) inside `columns`.
            unsafe {
                gemm_f32(
                    [co, k, pixels],
                    Strided::rows(out.as_mut_ptr(), k),
                    Strided::rows(grad.as_ptr().add(n * co * oh * ow + r0 * ow), oh * ow),
                    Strided::columns(columns.as_ptr(), pixels),
                    !first,
                    1.0,
                    gemm::Parallelism::Rayon(0),
                );
            }
            first = false;
        }
    }
    columns.give_back(&COLUMNS);
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

/// `[co, ci, taps]` → `[ci, co, taps]` with the taps reversed (the kernel rotated by 180°).
fn flip_transpose(weight: &[f32], co: usize, ci: usize, taps: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; weight.len()];
    for o in 0..co {
        for i in 0..ci {
            let src = &weight[(o * ci + i) * taps..][..taps];
            let dst = &mut out[(i * co + o) * taps..][..taps];
            for (d, s) in dst.iter_mut().zip(src.iter().rev()) {
                *d = *s;
            }
        }
    }
    out
}
