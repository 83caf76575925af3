//! 2-D convolution for inference on the CPU (`flex`) device: one GEMM per kernel tap over the
//! zero-padded NCHW input, read in place through the GEMM's strides (no im2col buffer, no NHWC
//! copy), on the `gemm` crate with every thread.
//!
//! Why: burn's CPU convolution builds im2col tiles of 512 pixels, converts the input to NHWC
//! and re-lays out the weights at every call; on the ConvGRU's 3×3 convolutions that runs at
//! about a third of the GEMM's speed (BENCHMARKS.md, "Where the time goes"). Everything this
//! path does not cover (other devices, autodiff, strides, groups, `Same` padding) keeps burn's
//! convolution, so [`conv2d_forward`] is a drop-in for `Conv2d::forward`.

use std::cell::Cell;

use burn::nn::conv::Conv2d;
use burn::nn::PaddingConfig2d;
use burn::tensor::{Device, Tensor, TensorData};

/// Output pixels per GEMM call: a few rows of the padded image, so that the output tile stays in
/// the cache while the taps accumulate into it.
const TILE_PIXELS: usize = 2048;

/// Input channels below which burn's convolution is kept.
const MIN_CHANNELS: usize = 16;

/// `conv.forward(x)`, through [`conv2d_nchw`] where it applies (see the module docs).
pub fn conv2d_forward(conv: &Conv2d, x: Tensor<4>) -> Tensor<4> {
    let Some(padding) = fast_padding(conv, &x) else {
        return conv.forward(x);
    };
    let device = x.device();
    let [b, ci, h, w] = x.dims();
    let [co, _, kh, kw] = conv.weight.dims();
    let input = f32_vec(x);
    let weight = f32_vec(conv.weight.val());
    let bias = conv.bias.as_ref().map(|b| f32_vec(b.val()));
    let shape = Nchw { b, c: ci, h, w };
    let (out, [oh, ow]) = conv2d_nchw(
        &input,
        shape,
        &weight,
        [co, kh, kw],
        bias.as_deref(),
        padding,
        conv.dilation,
    );
    Tensor::from_data(TensorData::new(out, [b, co, oh, ow]), &device)
}

/// The explicit `[top, left, bottom, right]` padding when the fast path applies to `conv` on `x`.
pub(crate) fn fast_padding(conv: &Conv2d, x: &Tensor<4>) -> Option<[usize; 4]> {
    // Few input channels make thin GEMMs that only stream memory: burn's small-channel
    // kernel does those better.
    let [_, ci, _, _] = conv.weight.dims();
    let plain = conv.stride == [1, 1] && conv.groups == 1 && ci >= MIN_CHANNELS;
    // Device equality ignores the autodiff wrapper: ask for it separately.
    let device = x.device();
    if !plain || device.is_autodiff() || device != Device::flex() {
        return None;
    }
    match conv.padding {
        PaddingConfig2d::Explicit(t, l, b, r) => Some([t, l, b, r]),
        PaddingConfig2d::Valid => Some([0; 4]),
        PaddingConfig2d::Same => None,
    }
}

pub(crate) fn f32_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data()
        .try_into_vec_as::<f32>()
        .expect("a float tensor converts to f32 values")
}

/// Shape of an NCHW tensor.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Nchw {
    pub b: usize,
    pub c: usize,
    pub h: usize,
    pub w: usize,
}

/// Stride-1 convolution of `input` (`shape`, NCHW) with `weight` (`[co, ci, kh, kw]`, row-major)
/// plus `bias`, zero padding `[top, left, bottom, right]`, `dilation` `[dh, dw]`. Returns the
/// output (`[b, co, oh, ow]`) and `[oh, ow]`.
///
/// Each output row is computed over the whole padded width `wp`; for tap `(i, j)` the input it
/// reads is the padded image shifted by `i·dh·wp + j·dw`, a plain strided matrix
/// `[ci, oh·wp]` (row stride `hp·wp`). The `wp − ow` extra columns of each row are discarded.
pub fn conv2d_nchw(
    input: &[f32],
    shape: Nchw,
    weight: &[f32],
    [co, kh, kw]: [usize; 3],
    bias: Option<&[f32]>,
    [top, left, bottom, right]: [usize; 4],
    [dh, dw]: [usize; 2],
) -> (Vec<f32>, [usize; 2]) {
    let Nchw { b, c: ci, h, w } = shape;
    assert_eq!(input.len(), b * ci * h * w, "conv2d_nchw: input size");
    assert_eq!(weight.len(), co * ci * kh * kw, "conv2d_nchw: weight size");
    let (hp, wp) = (h + top + bottom, w + left + right);
    let (span_h, span_w) = (dh * (kh - 1), dw * (kw - 1));
    assert!(
        hp > span_h && wp > span_w,
        "conv2d_nchw: kernel larger than the padded input"
    );
    let (oh, ow) = (hp - span_h, wp - span_w);
    // The taps' shifted views of the last channel read up to `span_w` values past the image
    // (only for the discarded columns): keep them inside the buffer.
    let plane = hp * wp;
    let taps = tap_weights(weight, co, ci, kh * kw);
    let mut out = vec![0.0f32; b * co * oh * ow];
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
                    gemm::gemm(
                        co,
                        rows * wp,
                        ci,
                        wide.as_mut_ptr().add(r0 * wp),
                        1,
                        (oh * wp) as isize,
                        tap > 0,
                        tap_weight.as_ptr(),
                        1,
                        ci as isize,
                        padded.as_ptr().add(offset),
                        1,
                        plane as isize,
                        1.0,
                        1.0,
                        false,
                        false,
                        false,
                        gemm::Parallelism::Rayon(0),
                    );
                }
            }
        }
        let dst = &mut out[n * co * oh * ow..(n + 1) * co * oh * ow];
        for (c, (dst_plane, src_plane)) in dst
            .chunks_exact_mut(oh * ow)
            .zip(wide.chunks_exact(oh * wp))
            .enumerate()
        {
            let shift = bias.map_or(0.0, |b| b[c]);
            for (d, s) in dst_plane
                .chunks_exact_mut(ow)
                .zip(src_plane.chunks_exact(wp))
            {
                for (d, s) in d.iter_mut().zip(&s[..ow]) {
                    *d = s + shift;
                }
            }
        }
    }
    wide.give_back(&WIDE);
    padded.give_back(&PADDED);
    (out, [oh, ow])
}

type Slot = std::thread::LocalKey<Cell<Vec<f32>>>;

thread_local! {
    static WIDE: Cell<Vec<f32>> = const { Cell::new(Vec::new()) };
    static PADDED: Cell<Vec<f32>> = const { Cell::new(Vec::new()) };
}

/// A buffer kept per thread between calls: a fresh allocation of this size costs more in page
/// faults than the work done in it. Taken out of its slot while in use, so a nested call (rayon
/// may run another convolution on this thread while the GEMM waits) gets a buffer of its own.
struct Scratch(Vec<f32>);

impl Scratch {
    fn take(slot: &'static Slot, len: usize) -> Self {
        let mut v = slot.with(Cell::take);
        v.resize(len, 0.0);
        Scratch(v)
    }

    fn give_back(self, slot: &'static Slot) {
        slot.with(|s| s.set(self.0));
    }
}

impl std::ops::Deref for Scratch {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        &self.0
    }
}

impl std::ops::DerefMut for Scratch {
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.0
    }
}

/// `[co, ci, taps]` → `[taps, co, ci]`: one contiguous `co × ci` matrix per tap.
fn tap_weights(weight: &[f32], co: usize, ci: usize, taps: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; weight.len()];
    for (o, per_out) in weight.chunks_exact(ci * taps).enumerate() {
        for (i, per_in) in per_out.chunks_exact(taps).enumerate() {
            for (t, &v) in per_in.iter().enumerate() {
                out[(t * co + o) * ci + i] = v;
            }
        }
    }
    out
}

/// Writes `image` (`[c, h, w]`) into the interior of `padded` (`[c, hp, wp]`) and zeros its
/// borders: each element once (the buffer is reused, its old contents are garbage).
fn pad_into(
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
    for (dst, src) in padded
        .chunks_exact_mut(hp * wp)
        .zip(image.chunks_exact(h * w))
    {
        let (above, rest) = dst.split_at_mut(top * wp);
        let (inner, below) = rest.split_at_mut(h * wp);
        above.fill(0.0);
        below.fill(0.0);
        for (d, s) in inner.chunks_exact_mut(wp).zip(src.chunks_exact(w)) {
            d[..left].fill(0.0);
            d[left..left + w].copy_from_slice(s);
            d[left + w..].fill(0.0);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use burn::nn::conv::Conv2dConfig;
    use burn::tensor::Distribution;

    fn close(a: Tensor<4>, b: Tensor<4>) {
        assert_eq!(a.dims(), b.dims());
        let (a, b) = (f32_vec(a), f32_vec(b));
        let scale = b.iter().fold(0.0f32, |m, v| m.max(v.abs())).max(1.0);
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs())
            .fold(0.0f32, f32::max);
        assert!(
            worst <= 2e-5 * scale,
            "max difference {worst} (scale {scale})"
        );
    }

    type Case = ([usize; 4], [usize; 2], [usize; 2], PaddingConfig2d, bool);

    /// The fast path against burn's convolution on the shapes MonSter++ uses and the edge cases
    /// (1×1, 7×7, asymmetric padding, dilation, no bias, batch 2, a 1-pixel-wide image).
    #[test]
    fn matches_burn_convolution() {
        let device = Device::flex();
        let explicit = PaddingConfig2d::Explicit;
        // (input dims, [out channels, kernel], dilation, padding, bias)
        let cases: [Case; 8] = [
            ([1, 24, 9, 13], [16, 3], [1, 1], explicit(1, 1, 1, 1), true),
            ([2, 17, 7, 6], [4, 1], [1, 1], PaddingConfig2d::Valid, true),
            ([1, 16, 12, 10], [8, 7], [1, 1], explicit(3, 3, 3, 3), true),
            ([1, 16, 8, 9], [3, 3], [2, 2], explicit(2, 2, 2, 2), false),
            ([1, 20, 8, 9], [3, 3], [1, 1], explicit(0, 1, 2, 1), true),
            ([1, 16, 5, 1], [2, 3], [1, 1], explicit(1, 1, 1, 1), true),
            ([1, 18, 6, 6], [5, 3], [1, 1], PaddingConfig2d::Valid, true),
            ([1, 40, 70, 90], [33, 3], [1, 1], explicit(1, 1, 1, 1), true),
        ];
        for (dims, [co, k], dilation, padding, bias) in cases {
            let conv = Conv2dConfig::new([dims[1], co], [k, k])
                .with_dilation(dilation)
                .with_padding(padding.clone())
                .with_bias(bias)
                .init(&device);
            let x = Tensor::<4>::random(dims, Distribution::Normal(0.0, 1.0), &device);
            assert!(
                fast_padding(&conv, &x).is_some(),
                "{padding:?} takes the fast path"
            );
            close(conv2d_forward(&conv, x.clone()), conv.forward(x));
        }
    }

    #[test]
    fn other_convolutions_keep_burn() {
        let device = Device::flex();
        let x = Tensor::<4>::random([1, 16, 8, 8], Distribution::Normal(0.0, 1.0), &device);
        let strided = Conv2dConfig::new([16, 4], [3, 3])
            .with_stride([2, 2])
            .init(&device);
        assert!(fast_padding(&strided, &x).is_none());
        let grouped = Conv2dConfig::new([16, 4], [3, 3])
            .with_groups(2)
            .init(&device);
        assert!(fast_padding(&grouped, &x).is_none());
        let thin = Conv2dConfig::new([3, 4], [3, 3]).init(&device);
        let x3 = Tensor::<4>::random([1, 3, 8, 8], Distribution::Normal(0.0, 1.0), &device);
        assert!(fast_padding(&thin, &x3).is_none());
        let tracked = Tensor::<4>::random(
            [1, 16, 8, 8],
            Distribution::Normal(0.0, 1.0),
            &device.clone().autodiff(),
        );
        let plain = Conv2dConfig::new([16, 4], [3, 3]).init(&device.autodiff());
        assert!(
            fast_padding(&plain, &tracked).is_none(),
            "autodiff keeps burn's"
        );
        close(conv2d_forward(&strided, x.clone()), strided.forward(x));
    }
}
