//! Disparity selection from the aggregated volume `S`: winner-take-all, uniqueness test,
//! sub-pixel fit, left–right consistency, and a NaN-aware 3×3 median.

use crate::aggregate::Dims;
use rayon::prelude::*;

/// How the sub-pixel offset is fitted on `S(d − 1), S(d), S(d + 1)`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Subpixel {
    None,
    /// `δ = (c₋ − c₊) / (2 (c₋ − 2c₀ + c₊))`. Kept for comparison: on census costs it is
    /// biased towards integers (a larger mean error than the V fit on the synthetic test:
    /// BENCHMARKS.md, "Census + MGM / SGM").
    #[allow(dead_code)]
    Parabola,
    /// Symmetric V fit (Shimizu–Okutomi): `δ = (c₋ − c₊) / (2 (max(c₋, c₊) − c₀))`.
    Equiangular,
}

pub(crate) struct Selection {
    pub d_min: i32,
    pub lr_tolerance: Option<f32>,
    pub uniqueness: Option<f32>,
    pub subpixel: Subpixel,
}

/// Left-view disparities (`height · width`, NaN where invalid) from `sum`, and the confidence
/// of each ([`confidence`], NaN where the disparity is).
pub(crate) fn select(
    sum: &[u16],
    dims: Dims,
    left_valid: &[bool],
    right_valid: &[bool],
    sel: &Selection,
    tick: &(dyn Fn() + Sync),
) -> (Vec<f32>, Vec<f32>) {
    let (w, h, n) = dims.sizes();
    let mut out = vec![f32::NAN; w * h];
    let mut conf = vec![f32::NAN; w * h];
    if w == 0 || n == 0 {
        return (out, conf);
    }
    #[cfg(target_arch = "x86_64")]
    let avx2 = is_x86_feature_detected!("avx2");
    out.par_chunks_mut(w)
        .zip(conf.par_chunks_mut(w))
        .zip(sum.par_chunks(w * n))
        .enumerate()
        .for_each_init(
            || (vec![0usize; w], vec![u32::MAX; w]),
            |(best_k, best_r), (y, ((orow, crow), srow))| {
                let valid = (
                    &left_valid[y * w..(y + 1) * w],
                    &right_valid[y * w..(y + 1) * w],
                );
                let row = Row {
                    disparity: orow,
                    confidence: crow,
                };
                #[cfg(target_arch = "x86_64")]
                if avx2 {
                    // SAFETY: AVX2 support was checked at run time.
                    unsafe { select_row_avx2(srow, n, valid, sel, row, best_k, best_r) };
                    tick();
                    return;
                }
                select_row(srow, n, valid, sel, row, best_k, best_r);
                tick();
            },
        );
    (out, conf)
}

/// One output row of [`select`].
struct Row<'a> {
    disparity: &'a mut [f32],
    confidence: &'a mut [f32],
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
unsafe fn select_row_avx2(
    srow: &[u16],
    n: usize,
    valid: (&[bool], &[bool]),
    sel: &Selection,
    row: Row,
    best_k: &mut [usize],
    best_r: &mut [u32],
) {
    select_row(srow, n, valid, sel, row, best_k, best_r)
}

/// Marks a pixel without a selected disparity in `best_k`.
const NONE: usize = usize::MAX;

/// One row: `srow` is `width · n`, `valid` the left and right validity of the row.
#[inline(always)]
fn select_row(
    srow: &[u16],
    n: usize,
    (lvalid, rvalid): (&[bool], &[bool]),
    sel: &Selection,
    row: Row,
    best_k: &mut [usize],
    best_r: &mut [u32],
) {
    let Row {
        disparity: orow,
        confidence: crow,
    } = row;
    let w = orow.len();
    best_r.fill(u32::MAX);
    for (x, sx) in srow.chunks_exact(n).enumerate() {
        if sel.lr_tolerance.is_some() {
            fold_right_winners(sx, x, sel.d_min, best_r);
        }
        best_k[x] = NONE;
        orow[x] = f32::NAN;
        crow[x] = f32::NAN;
        if !lvalid[x] {
            continue;
        }
        let (m, k) = winner(sx);
        // The match must land inside the right image, on a valid pixel.
        let xr = x as i64 - (sel.d_min as i64 + k as i64);
        if xr < 0 || xr >= w as i64 || !rvalid[xr as usize] {
            continue;
        }
        let second = second_best(sx, k);
        if sel.uniqueness.is_some_and(|u| is_ambiguous(m, second, u)) {
            continue;
        }
        let mut d = (sel.d_min as i64 + k as i64) as f32;
        if k > 0 && k + 1 < n {
            let (cm, c0, cp) = (f32::from(sx[k - 1]), f32::from(m), f32::from(sx[k + 1]));
            d += subpixel_offset(sel.subpixel, cm, c0, cp);
        }
        orow[x] = d;
        crow[x] = confidence(m, second);
        best_k[x] = k;
    }
    if let Some(tol) = sel.lr_tolerance {
        check_left_right(orow, best_k, best_r, sel.d_min, tol);
        for (c, d) in crow.iter_mut().zip(orow.iter()) {
            if d.is_nan() {
                *c = f32::NAN;
            }
        }
    }
}

/// Folds the costs `sx` of left pixel `x` into the right view's winners:
/// `d_R(x_R) = argmin_d S(x_R + d, d)`, packed (cost, k) so `min` is an argmin that prefers the
/// smallest disparity on ties. `best_r` is stored mirrored (index `w − 1 − x_R`) so that k and
/// the index grow together and the loop vectorises.
#[inline(always)]
fn fold_right_winners(sx: &[u16], x: usize, d_min: i32, best_r: &mut [u32]) {
    let (n, w) = (sx.len(), best_r.len());
    let base = x as i64 - d_min as i64;
    let k_hi = base.min(n as i64 - 1);
    let k_lo = (base - w as i64 + 1).max(0);
    if k_lo > k_hi {
        return;
    }
    let j_lo = (w as i64 - 1 - base + k_lo) as usize;
    let (k_lo, k_hi) = (k_lo as usize, k_hi as usize);
    let len = k_hi - k_lo + 1;
    for ((b, &s), k) in best_r[j_lo..j_lo + len]
        .iter_mut()
        .zip(&sx[k_lo..=k_hi])
        .zip(k_lo as u32..)
    {
        *b = (*b).min((u32::from(s) << 16) | k);
    }
}

/// The lowest cost of `sx` and its index, the smallest index on ties (packed (cost, k): the
/// minimum is the argmin).
#[inline(always)]
fn winner(sx: &[u16]) -> (u16, usize) {
    let packed = sx
        .iter()
        .zip(0u32..)
        .map(|(&s, k)| (u32::from(s) << 16) | k)
        .min()
        .unwrap_or(0);
    ((packed >> 16) as u16, (packed & 0xFFFF) as usize)
}

/// The best cost of `sx` more than one disparity away from the winner at `k`, `None` when the
/// range has no such disparity.
#[inline(always)]
fn second_best(sx: &[u16], k: usize) -> Option<u16> {
    let left = sx[..k.saturating_sub(1)].iter().copied().min();
    let right = sx.get(k + 2..).and_then(|s| s.iter().copied().min());
    left.into_iter().chain(right).min()
}

/// Whether the winner's cost `m` fails the uniqueness test of ratio `u`: it is not below
/// `(1 − u)` times its rival `second`.
#[inline(always)]
fn is_ambiguous(m: u16, second: Option<u16>, u: f32) -> bool {
    second.is_some_and(|second| f32::from(m) >= (1.0 - u) * f32::from(second))
}

/// How clearly the winner's cost `m` beats the best cost `second` more than one disparity away:
/// `1 − m / second` (the peak ratio of Hu & Mordohai, 2012, in `[0, 1]`), 1 without a rival
/// and 0 when both are zero. A winner that passes the uniqueness test of ratio `u` has a
/// confidence above `u`. Low at occlusions, in repetitive or weak texture and along the
/// disparity edges the aggregation smoothed: what a fusion of several pairs should trust less.
#[inline(always)]
fn confidence(m: u16, second: Option<u16>) -> f32 {
    match second {
        None => 1.0,
        Some(0) => 0.0,
        Some(s) => (1.0 - f32::from(m) / f32::from(s)).max(0.0),
    }
}

/// Sub-pixel offset of the winner from its cost `c0` and its neighbours' `cm`, `cp`.
#[inline(always)]
fn subpixel_offset(fit: Subpixel, cm: f32, c0: f32, cp: f32) -> f32 {
    let den = match fit {
        Subpixel::None => return 0.0,
        Subpixel::Parabola => cm - 2.0 * c0 + cp,
        Subpixel::Equiangular => cm.max(cp) - c0,
    };
    if den > 0.0 {
        (cm - cp) / (2.0 * den)
    } else {
        0.0
    }
}

/// Left–right consistency: clears the disparities whose right-view winner disagrees by more
/// than `tol` disparities.
#[inline(always)]
fn check_left_right(orow: &mut [f32], best_k: &[usize], best_r: &[u32], d_min: i32, tol: f32) {
    let w = orow.len();
    for x in 0..w {
        let k = best_k[x];
        if k == NONE {
            continue;
        }
        let xr = (x as i64 - (d_min as i64 + k as i64)) as usize;
        let kr = (best_r[w - 1 - xr] & 0xFFFF) as f32;
        if (k as f32 - kr).abs() > tol {
            orow[x] = f32::NAN;
        }
    }
}

/// 3×3 median of the finite values around each finite pixel (NaN pixels stay NaN; the window is
/// clipped at the borders; an even count takes the mean of the two middle values).
pub(crate) fn median3x3(disp: &[f32], w: usize, h: usize) -> Vec<f32> {
    let mut out = vec![f32::NAN; w * h];
    if w == 0 {
        return out;
    }
    out.par_chunks_mut(w).enumerate().for_each(|(y, orow)| {
        let mut vals = [0f32; 9];
        for (x, o) in orow.iter_mut().enumerate() {
            let c = disp[y * w + x];
            if c.is_nan() {
                continue;
            }
            let mut cnt = 0;
            for yy in y.saturating_sub(1)..(y + 2).min(h) {
                for xx in x.saturating_sub(1)..(x + 2).min(w) {
                    let v = disp[yy * w + xx];
                    if !v.is_nan() {
                        vals[cnt] = v;
                        cnt += 1;
                    }
                }
            }
            if cnt == 9 {
                *o = median9(vals);
                continue;
            }
            let v = &mut vals[..cnt];
            v.sort_unstable_by(f32::total_cmp);
            *o = if cnt % 2 == 1 {
                v[cnt / 2]
            } else {
                0.5 * (v[cnt / 2 - 1] + v[cnt / 2])
            };
        }
    });
    out
}

/// Median of 9 finite values with the 19-exchange network of Paeth / Devillard's `opt_med9`.
#[inline]
fn median9(mut p: [f32; 9]) -> f32 {
    let mut s = |a: usize, b: usize| {
        let (x, y) = (p[a], p[b]);
        p[a] = x.min(y);
        p[b] = x.max(y);
    };
    s(1, 2);
    s(4, 5);
    s(7, 8);
    s(0, 1);
    s(3, 4);
    s(6, 7);
    s(1, 2);
    s(4, 5);
    s(7, 8);
    s(0, 3);
    s(5, 8);
    s(4, 7);
    s(3, 6);
    s(1, 4);
    s(2, 5);
    s(4, 7);
    s(4, 2);
    s(6, 4);
    s(4, 2);
    p[4]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median9_network() {
        let mut seed = 7u64;
        for _ in 0..2000 {
            let mut v = [0f32; 9];
            for e in &mut v {
                seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1);
                *e = ((seed >> 40) % 17) as f32;
            }
            let mut sorted = v;
            sorted.sort_by(f32::total_cmp);
            assert_eq!(median9(v), sorted[4], "{v:?}");
        }
    }

    #[test]
    fn median_ignores_nan() {
        let nan = f32::NAN;
        #[rustfmt::skip]
        let d = vec![
            1.0, 2.0, nan,
            9.0, 3.0, 4.0,
            nan, 5.0, 100.0,
        ];
        let m = median3x3(&d, 3, 3);
        assert_eq!(m[4], 4.0); // {1,2,9,3,4,5,100} → 4
        assert!(m[2].is_nan() && m[6].is_nan());
        assert_eq!(m[0], 2.5); // {1,2,9,3}
    }

    /// [`select`] with every pixel of both views valid.
    fn select_all_valid(s: &[u16], dims: Dims, sel: &Selection) -> (Vec<f32>, Vec<f32>) {
        let valid = vec![true; dims.width * dims.height];
        select(s, dims, &valid, &valid, sel, &|| {})
    }

    #[test]
    fn subpixel_fits_and_lr_check() {
        // One row, 4 pixels, 5 disparities, d_min = 0.
        let (w, n) = (4, 5);
        let mut s = vec![100u16; w * n];
        // Pixel 2: minimum at k = 1 with a symmetric-ish neighbourhood, true offset +0.25.
        s[2 * n..3 * n].copy_from_slice(&[40, 10, 20, 60, 80]);
        // Pixel 1: minimum at k = 0 (border, no fit).
        s[n..2 * n].copy_from_slice(&[5, 50, 60, 70, 80]);
        let dims = Dims {
            width: w,
            height: 1,
            n_disp: n,
        };
        let run = |subpixel, lr| {
            let sel = Selection {
                d_min: 0,
                lr_tolerance: lr,
                uniqueness: None,
                subpixel,
            };
            select_all_valid(&s, dims, &sel).0
        };
        let p = run(Subpixel::Parabola, None);
        assert!((p[2] - (1.0 + 20.0 / 80.0)).abs() < 1e-6, "{}", p[2]);
        assert_eq!(p[1], 0.0);
        let e = run(Subpixel::Equiangular, None);
        assert!((e[2] - (1.0 + 20.0 / 60.0)).abs() < 1e-6, "{}", e[2]);
        // Pixel 0 all 100: argmin k = 0, x_R = 0, fine. Pixel 3 all 100 → k = 0.
        // The right pixel x_R = 1 is claimed by left x = 2 (k = 1, cost 10) and left x = 1
        // (k = 0, cost 5): d_R(1) = 0, so pixel 2 fails the check at tolerance 0.5.
        let l = run(Subpixel::None, Some(0.5));
        assert!(l[2].is_nan());
        assert_eq!(l[1], 0.0);
        let l = run(Subpixel::None, Some(1.0));
        assert_eq!(l[2], 1.0);
    }

    #[test]
    fn confidence_is_the_winners_margin_over_its_rival_and_follows_the_disparity() {
        // One row, 3 pixels, 6 disparities: a clear winner, an ambiguous one, a flat one.
        let n = 6;
        let s: Vec<u16> = [
            [90, 80, 20, 70, 80, 90],   // rival 80 (k = 4 or 0): 1 − 20/80
            [50, 40, 100, 100, 42, 60], // winner k = 1 (40), rival 42 at k = 4
            [40, 40, 30, 30, 30, 30],   // a tie with a far disparity: no confidence
        ]
        .concat();
        let dims = Dims {
            width: 3,
            height: 1,
            n_disp: n,
        };
        let run = |uniqueness| {
            let sel = Selection {
                d_min: -2,
                lr_tolerance: None,
                uniqueness,
                subpixel: Subpixel::None,
            };
            select_all_valid(&s, dims, &sel)
        };
        let (d, c) = run(None);
        assert_eq!(d[0], 0.0);
        assert!((c[0] - 0.75).abs() < 1e-6, "{}", c[0]);
        assert!((c[1] - (1.0 - 40.0 / 42.0)).abs() < 1e-6, "{}", c[1]);
        assert_eq!(c[2], 0.0);
        // The uniqueness test drops exactly the winners whose confidence is at most its ratio,
        // and their confidence with them.
        let (d, c) = run(Some(0.1));
        assert!(d[0].is_finite() && c[0] > 0.1);
        assert!(d[1].is_nan() && c[1].is_nan());
        assert!(d[2].is_nan() && c[2].is_nan());
        assert_eq!(confidence(5, None), 1.0);
        assert_eq!(confidence(0, Some(0)), 0.0);
    }
}
