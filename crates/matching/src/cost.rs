//! Matching cost volume: Hamming distance of census codes, `u8`, laid out `C[y][x][d − d_min]`
//! (disparity contiguous innermost).
//!
//! A disparity whose right pixel `x − d` falls outside the right image, or where either pixel is
//! NaN, gets the *neutral* cost `bits / 2`: the expected Hamming distance of two unrelated codes.
//! It neither attracts nor repels the winner, so aggregation fills such pixels from their
//! neighbours (and the left–right check usually invalidates them).

use crate::census::Census;
use rayon::prelude::*;

/// Fills `out` (`height · width · n_disp` bytes) with the cost volume of `left` against `right`
/// for disparities `d_min .. d_min + n_disp`.
pub(crate) fn build_cost_volume(
    left: &Census,
    right: &Census,
    d_min: i32,
    n_disp: usize,
    neutral: u8,
    out: &mut [u8],
) {
    let (w, h) = (left.width, left.height);
    assert_eq!(out.len(), w * h * n_disp);
    if w == 0 || n_disp == 0 {
        return;
    }
    #[cfg(target_arch = "x86_64")]
    let fast = is_x86_feature_detected!("avx2") && is_x86_feature_detected!("popcnt");
    #[cfg(not(target_arch = "x86_64"))]
    let fast = false;
    out.par_chunks_mut(w * n_disp)
        .enumerate()
        .for_each(|(y, crow)| {
            let r = y * w..(y + 1) * w;
            let args = (
                &left.codes[r.clone()],
                &left.valid[r.clone()],
                &right.codes[r.clone()],
                &right.valid[r],
            );
            #[cfg(target_arch = "x86_64")]
            if fast {
                // SAFETY: AVX2 and POPCNT support were checked at run time.
                unsafe { cost_row_avx2(args, d_min, n_disp, neutral, crow) };
                return;
            }
            let _ = fast;
            cost_row(args, d_min, n_disp, neutral, crow);
        });
}

type RowArgs<'a> = (&'a [u64], &'a [bool], &'a [u64], &'a [bool]);

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2,popcnt")]
unsafe fn cost_row_avx2(args: RowArgs, d_min: i32, n_disp: usize, neutral: u8, crow: &mut [u8]) {
    cost_row(args, d_min, n_disp, neutral, crow)
}

/// One row of the volume: `crow` is `width · n_disp`.
#[inline(always)]
fn cost_row(
    (lrow, lval, rrow, rval): RowArgs,
    d_min: i32,
    n_disp: usize,
    neutral: u8,
    crow: &mut [u8],
) {
    let w = lrow.len();
    for (x, cx) in crow.chunks_exact_mut(n_disp).enumerate() {
        // k = d − d_min; x_R = x − d_min − k must be in [0, w).
        let base = x as i64 - d_min as i64;
        let k_hi = base.min(n_disp as i64 - 1); // x_R >= 0
        let k_lo = (base - w as i64 + 1).max(0); // x_R <= w − 1
        if !lval[x] || k_lo > k_hi {
            cx.fill(neutral);
            continue;
        }
        let (k_lo, k_hi) = (k_lo as usize, k_hi as usize);
        cx[..k_lo].fill(neutral);
        cx[k_hi + 1..].fill(neutral);
        let xr_hi = (base - k_lo as i64) as usize;
        let xr_lo = (base - k_hi as i64) as usize;
        let code = lrow[x];
        let rc = rrow[xr_lo..=xr_hi].iter().rev();
        let rv = rval[xr_lo..=xr_hi].iter().rev();
        for ((c, &r), &v) in cx[k_lo..=k_hi].iter_mut().zip(rc).zip(rv) {
            let ham = (code ^ r).count_ones() as u8;
            *c = if v { ham } else { neutral };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn costs_follow_definition() {
        let (w, h) = (9, 2);
        let codes: Vec<u64> = (0..w * h)
            .map(|i| (i as u64 * 0x9E37_79B9) & 0xFFFF)
            .collect();
        let mut rcodes: Vec<u64> = codes.iter().map(|c| c.rotate_left(3) & 0xFFFF).collect();
        rcodes[3] = 0;
        let mut rvalid = vec![true; w * h];
        rvalid[4] = false;
        let l = Census {
            width: w,
            height: h,
            codes: codes.clone(),
            valid: vec![true; w * h],
        };
        let r = Census {
            width: w,
            height: h,
            codes: rcodes.clone(),
            valid: rvalid.clone(),
        };
        let (d_min, n) = (-2, 6);
        let mut vol = vec![0u8; w * h * n];
        build_cost_volume(&l, &r, d_min, n, 8, &mut vol);
        for y in 0..h {
            for x in 0..w {
                for k in 0..n {
                    let xr = x as i32 - (d_min + k as i32);
                    let expect = if xr < 0 || xr >= w as i32 || !rvalid[y * w + xr as usize] {
                        8
                    } else {
                        (codes[y * w + x] ^ rcodes[y * w + xr as usize]).count_ones() as u8
                    };
                    assert_eq!(vol[(y * w + x) * n + k], expect, "x {x} y {y} k {k}");
                }
            }
        }
    }
}
