//! Disparity range estimation when the caller has none.
//!
//! The pair is box-downsampled (NaN-aware) by a factor `f` (4, or more so the coarse image is at
//! most 512 pixels wide and high, or less for small images), matched with SGM over a wide
//! symmetric range `±R` coarse pixels (`R = clamp(coarse_width / 4, 8, 64)`, i.e. up to ±256 px
//! at full resolution for `f = 4`), with the left–right check and a strict uniqueness test.
//! The 1st and 99th percentiles of the valid coarse disparities, times `f`, widened by a margin
//! of `2f + 10 %` of the span, give the range.
//!
//! Limits: disparities beyond `±R · f`, structures narrower than a few coarse pixels (thin
//! towers: below the 1 % tail or invisible at the coarse scale) and nearly textureless pairs are
//! missed; the product will also derive ranges from the cameras. Fails with
//! [`MatchError::RangeEstimation`] when fewer than 1 % of the coarse pixels match.

use crate::error::MatchError;
use crate::sgm::{match_grey, SgmParams};
use raster::Image;

/// An inclusive range `(d_min, d_max)` that should contain the disparities of the pair.
pub fn estimate_range(left: &Image, right: &Image) -> Result<(i32, i32), MatchError> {
    let (w, h) = crate::sgm::check_pair(left, right)?;
    let mut f = 4usize.max(w.max(h).div_ceil(512));
    while f > 1 && w.min(h) / f < 32 {
        f /= 2;
    }
    let (lg, cw, ch) = downsample(left.to_gray().data(), w, h, f);
    if !has_texture(&lg) {
        return Err(MatchError::RangeEstimation(
            "the left image is textureless".into(),
        ));
    }
    let (rg, _, _) = downsample(right.to_gray().data(), w, h, f);
    let r = (cw / 4).clamp(8, 64) as i32;
    let params = SgmParams {
        uniqueness: Some(0.1),
        ..SgmParams::default()
    };
    let (disp, _) = match_grey(&lg, &rg, (cw, ch), (-r, r), &params, None)?;
    let mut valid: Vec<f32> = disp.into_iter().filter(|v| v.is_finite()).collect();
    if valid.len() < (cw * ch / 100).max(16) {
        return Err(MatchError::RangeEstimation(format!(
            "only {} of {} coarse pixels matched",
            valid.len(),
            cw * ch
        )));
    }
    valid.sort_unstable_by(f32::total_cmp);
    let lo = valid[valid.len() / 100] * f as f32;
    let hi = valid[(valid.len() * 99) / 100] * f as f32;
    let margin = 2.0 * f as f32 + 0.1 * (hi - lo);
    Ok(((lo - margin).floor() as i32, (hi + margin).ceil() as i32))
}

/// Whether the 1st and 99th percentiles of the finite values differ.
fn has_texture(grey: &[f32]) -> bool {
    let mut v: Vec<f32> = grey.iter().copied().filter(|v| v.is_finite()).collect();
    if v.len() < 2 {
        return false;
    }
    v.sort_unstable_by(f32::total_cmp);
    v[v.len() / 100] < v[(v.len() * 99) / 100]
}

/// Box average over `f × f` blocks ignoring NaN (NaN when a block has no finite value); the last
/// partial blocks are dropped.
fn downsample(grey: &[f32], w: usize, h: usize, f: usize) -> (Vec<f32>, usize, usize) {
    let (cw, ch) = (w / f, h / f);
    let mut out = Vec::with_capacity(cw * ch);
    for cy in 0..ch {
        for cx in 0..cw {
            let (mut s, mut c) = (0f64, 0u32);
            for y in cy * f..(cy + 1) * f {
                for &v in &grey[y * w + cx * f..y * w + (cx + 1) * f] {
                    if v.is_finite() {
                        s += f64::from(v);
                        c += 1;
                    }
                }
            }
            out.push(if c > 0 {
                (s / f64::from(c)) as f32
            } else {
                f32::NAN
            });
        }
    }
    (out, cw, ch)
}
