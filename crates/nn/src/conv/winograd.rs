//! 3×3 stride-1 convolution by Winograd's F(2×2, 3×3): each 2×2 output tile is computed from a
//! 4×4 input patch with 16 multiplications per channel pair instead of 36, as 16 GEMMs
//! (`[co, ci] × [ci, tiles]`, one per element of the transformed patch) between small
//! additions-only transforms. Its transforms only add, subtract and halve, so its rounding stays
//! that of a direct convolution.
//!
//! Work is split into bands of tile rows, one band per rayon task, each band transforming,
//! multiplying and writing its own output rows (single-threaded GEMMs: no synchronisation
//! between the 16 products).

use rayon::prelude::*;

use super::epilogue::Epilogue;
use super::geometry::Nchw;
use super::scratch::{Scratch, PADDED};
use crate::matmul::{gemm_f32, SharedOut, Strided};

/// Tiles per band: the transformed input of a band (`16 · ci · tiles` floats) stays within a
/// few MiB while its GEMMs are wide enough to run at speed.
const BAND_TILES: usize = 256;

thread_local! {
    static INPUT_T: std::cell::Cell<Vec<f32>> = const { std::cell::Cell::new(Vec::new()) };
    static PRODUCT: std::cell::Cell<Vec<f32>> = const { std::cell::Cell::new(Vec::new()) };
}

/// `weight` (`[co, ci, 3, 3]`) → `U = G·g·Gᵀ` per channel pair, stored `[co, 16, ci]`: the GEMM
/// of element `e` reads its `[co, ci]` matrix at row stride `16·ci`.
pub(super) fn transform_weights(weight: &[f32], co: usize, ci: usize) -> Vec<f32> {
    let mut u = vec![0.0f32; 16 * co * ci];
    u.par_chunks_exact_mut(16 * ci)
        .zip(weight.par_chunks_exact(9 * ci))
        .for_each(|(u, per_out)| {
            for (c, g) in per_out.chunks_exact(9).enumerate() {
                // G = [[1, 0, 0], [½, ½, ½], [½, −½, ½], [0, 0, 1]]; rows (G·g), then columns.
                let mut t = [[0.0f32; 3]; 4];
                for j in 0..3 {
                    let (g0, g1, g2) = (g[j], g[3 + j], g[6 + j]);
                    t[0][j] = g0;
                    t[1][j] = 0.5 * (g0 + g1 + g2);
                    t[2][j] = 0.5 * (g0 - g1 + g2);
                    t[3][j] = g2;
                }
                for (i, &[r0, r1, r2]) in t.iter().enumerate() {
                    let v = [r0, 0.5 * (r0 + r1 + r2), 0.5 * (r0 - r1 + r2), r2];
                    for (j, &v) in v.iter().enumerate() {
                        u[(i * 4 + j) * ci + c] = v;
                    }
                }
            }
        });
    u
}

/// 3×3, stride 1, dilation 1 convolution of `input` (`shape`) with the transformed weights `u`
/// ([`transform_weights`] of `[co, ci, 3, 3]`), zero padding `[top, left, bottom, right]`, then
/// `epilogue`, into `out` (`[b, co, oh, ow]`).
pub(super) fn conv3x3(
    input: &[f32],
    shape: Nchw,
    u: &[f32],
    co: usize,
    [top, left, bottom, right]: [usize; 4],
    epilogue: Epilogue<'_>,
    out: &mut [f32],
) {
    let Nchw { b, c: ci, h, w } = shape;
    let (oh, ow) = (h + top + bottom - 2, w + left + right - 2);
    assert_eq!(out.len(), b * co * oh * ow, "winograd: output size");
    let (th, tw) = (oh.div_ceil(2), ow.div_ceil(2));
    // Padded so that every tile's 4×4 patch is inside, odd output sizes included.
    let (hp, wp) = (2 * th + 2, 2 * tw + 2);
    assert_eq!(u.len(), 16 * co * ci, "winograd: transformed weight size");
    let threads = rayon::current_num_threads();
    let rows_per_band = (BAND_TILES / tw).clamp(1, th.div_ceil(2 * threads).max(1));
    let mut padded = Scratch::take(&PADDED, ci * hp * wp);
    for n in 0..b {
        let image = &input[n * ci * h * w..(n + 1) * ci * h * w];
        pad_split(&mut padded, image, [ci, h, w], [top, left], [hp, wp]);
        let padded = &padded[..];
        let dst = SharedOut::new(&mut out[n * co * oh * ow..]);
        let bands: Vec<usize> = (0..th).step_by(rows_per_band).collect();
        bands.into_par_iter().for_each(|ty0| {
            let rows = rows_per_band.min(th - ty0);
            let tiles = rows * tw;
            let mut v = Scratch::take(&INPUT_T, 16 * ci * tiles);
            let mut m = Scratch::take(&PRODUCT, 16 * co * tiles);
            transform_input(padded, [ci, hp, wp], ty0, rows, tw, &mut v);
            for e in 0..16 {
                // SAFETY: dst `[co, tiles]` inside `m` and rhs `[ci, tiles]` inside `v`, both
                // row-major; lhs `[co, ci]` at row stride `16·ci` inside `u`.
                unsafe {
                    gemm_f32(
                        [co, tiles, ci],
                        Strided::rows(m.as_mut_ptr().add(e * co * tiles), tiles),
                        Strided::rows(u.as_ptr().add(e * ci), 16 * ci),
                        Strided::rows(v.as_ptr().add(e * ci * tiles), tiles),
                        false,
                        1.0,
                        gemm::Parallelism::None,
                    );
                }
            }
            // SAFETY: this band writes output rows `2·ty0 .. min(2·(ty0+rows), oh)` of every
            // channel; bands cover disjoint tile rows.
            unsafe { transform_output(&m, co, [oh, ow], ty0, rows, tw, &epilogue, dst) };
            v.give_back(&INPUT_T);
            m.give_back(&PRODUCT);
        });
    }
    padded.give_back(&PADDED);
}

/// Writes `image` (`[c, h, w]`) zero-padded into `split` (`[c, hp, wp]`) with each row's even
/// columns first and its odd columns after them (`wp/2` each): the transforms then read and
/// write only contiguous runs, which the compiler vectorises.
fn pad_split(
    split: &mut [f32],
    image: &[f32],
    [c, h, w]: [usize; 3],
    [top, left]: [usize; 2],
    [hp, wp]: [usize; 2],
) {
    let half = wp / 2;
    split[..c * hp * wp]
        .par_chunks_exact_mut(hp * wp)
        .zip(image.par_chunks_exact(h * w))
        .for_each(|(dst, src)| {
            for (y, row) in dst.chunks_exact_mut(wp).enumerate() {
                row.fill(0.0);
                let Some(iy) = y.checked_sub(top).filter(|&iy| iy < h) else {
                    continue;
                };
                // The source's even-indexed values land in the half of the parity of `left`,
                // from column `left/2`; its odd-indexed ones in the other, from `(left+1)/2`.
                let (even, odd) = row.split_at_mut(half);
                let (first, second) = if left % 2 == 0 {
                    (&mut even[left / 2..], &mut odd[left / 2..])
                } else {
                    (&mut odd[left / 2..], &mut even[left.div_ceil(2)..])
                };
                let src = &src[iy * w..(iy + 1) * w];
                let pairs = src.chunks_exact(2);
                if let [last] = pairs.remainder() {
                    first[w / 2] = *last;
                }
                for ((a, b), pair) in first.iter_mut().zip(second.iter_mut()).zip(pairs) {
                    *a = pair[0];
                    *b = pair[1];
                }
            }
        });
}

/// `V = Bᵀ·d·B` of every 4×4 patch of tile rows `ty0..ty0+rows`, into `v` (`[16, ci, tiles]`),
/// from the even/odd-split padded input. `Bᵀ = [[1, 0, −1, 0], [0, 1, 1, 0], [0, −1, 1, 0],
/// [0, 1, 0, −1]]`: the column step combines the patch's 4 rows (whole rows at once), the row
/// step its columns `2tx..2tx+4` = even `tx`, odd `tx`, even `tx+1`, odd `tx+1`.
fn transform_input(
    split: &[f32],
    [ci, hp, wp]: [usize; 3],
    ty0: usize,
    rows: usize,
    tw: usize,
    v: &mut [f32],
) {
    let tiles = rows * tw;
    let half = wp / 2;
    let stride = ci * tiles;
    let mut t = vec![0.0f32; 4 * wp];
    for c in 0..ci {
        let plane = &split[c * hp * wp..(c + 1) * hp * wp];
        for r in 0..rows {
            let y = 2 * (ty0 + r);
            let d = |i: usize| &plane[(y + i) * wp..(y + i + 1) * wp];
            let (d0, d1, d2, d3) = (d(0), d(1), d(2), d(3));
            let (t0, rest) = t.split_at_mut(wp);
            let (t1, rest) = rest.split_at_mut(wp);
            let (t2, t3) = rest.split_at_mut(wp);
            for x in 0..wp {
                t0[x] = d0[x] - d2[x];
                t1[x] = d1[x] + d2[x];
                t2[x] = d2[x] - d1[x];
                t3[x] = d1[x] - d3[x];
            }
            let at = c * tiles + r * tw;
            for (i, ti) in [&*t0, &*t1, &*t2, &*t3].into_iter().enumerate() {
                let (even, odd) = ti.split_at(half);
                let (e0, e1, o0, o1) = (&even[..tw], &even[1..=tw], &odd[..tw], &odd[1..=tw]);
                let mut out = |k: usize, f: &dyn Fn(usize) -> f32| {
                    let dst = &mut v[(i * 4 + k) * stride + at..][..tw];
                    for (tx, d) in dst.iter_mut().enumerate() {
                        *d = f(tx);
                    }
                };
                out(0, &|x| e0[x] - e1[x]);
                out(1, &|x| o0[x] + e1[x]);
                out(2, &|x| e1[x] - o0[x]);
                out(3, &|x| o0[x] - o1[x]);
            }
        }
    }
}

/// `Y = Aᵀ·M·A` of every tile (`m` is `[16, co, tiles]`), `Aᵀ = [[1, 1, 1, 0], [0, 1, −1, −1]]`,
/// then the epilogue, written into the band's output rows.
///
/// # Safety
/// `dst` points at one image's `[co, oh, ow]` output, of which this band alone writes rows
/// `2·ty0 .. min(2·(ty0+rows), oh)`.
#[allow(clippy::too_many_arguments)] // the band's coordinates, as its caller computes them
unsafe fn transform_output(
    m: &[f32],
    co: usize,
    [oh, ow]: [usize; 2],
    ty0: usize,
    rows: usize,
    tw: usize,
    epilogue: &Epilogue<'_>,
    dst: SharedOut,
) {
    let tiles = rows * tw;
    let mut t = vec![0.0f32; 8 * tw];
    let mut y_even = vec![0.0f32; tw];
    let mut y_odd = vec![0.0f32; tw];
    for o in 0..co {
        let (scale, shift) = epilogue.channel(o);
        let plane = dst.at(o * oh * ow);
        for r in 0..rows {
            let y = 2 * (ty0 + r);
            let e = |k: usize| &m[k * co * tiles + o * tiles + r * tw..][..tw];
            // Column step: rows 0 and 1 of Aᵀ·M, for each of the 4 columns j.
            for j in 0..4 {
                let (m0, m1, m2, m3) = (e(j), e(4 + j), e(8 + j), e(12 + j));
                let (a, b) = t[j * 2 * tw..(j + 1) * 2 * tw].split_at_mut(tw);
                for x in 0..tw {
                    a[x] = m0[x] + m1[x] + m2[x];
                    b[x] = m1[x] - m2[x] - m3[x];
                }
            }
            for i in 0..2 {
                if y + i >= oh {
                    break;
                }
                let col = |j: usize| &t[(j * 2 + i) * tw..][..tw];
                let (c0, c1, c2, c3) = (col(0), col(1), col(2), col(3));
                for x in 0..tw {
                    y_even[x] = c0[x] + c1[x] + c2[x];
                    y_odd[x] = c1[x] - c2[x] - c3[x];
                }
                let row = std::slice::from_raw_parts_mut(plane.add((y + i) * ow), ow);
                for (pair, (&a, &b)) in row.chunks_mut(2).zip(y_even.iter().zip(&y_odd)) {
                    pair[0] = epilogue.act.apply(a * scale + shift);
                    if let Some(second) = pair.get_mut(1) {
                        *second = epilogue.act.apply(b * scale + shift);
                    }
                }
            }
        }
    }
}
