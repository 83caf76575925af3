//! The residual vertical parallax of a rectified pair: how many rows the right view's matches of
//! textured left patches sit above or below them. With each image's own cameras it is well under
//! a pixel (what s2p's pointing correction measures and removes); with an RPC that is not its
//! image's (swapped, another scene's) it is many pixels, and matching along rows finds little.
//! Measured on a few dozen patches by normalised cross-correlation at half resolution: a patch
//! of 15 × 15 half-pixels holds enough texture to be matched unambiguously over a 2-D search of
//! hundreds of disparities and ±24 rows (at full resolution an 11 × 11 patch found no clear
//! match on the dev pairs, and unclear ones put cross-season pairs many pixels off). On the
//! JAX_068 dev pairs (BA cameras) it tells the pairs with their own cameras from swapped cameras
//! wherever enough patches match (BENCHMARKS.md, "Images as delivered", "Swapped cameras"); so it
//! costs milliseconds and only speaks with evidence.

use raster::Image;

/// The images are compared at 1/`SCALE` of their resolution.
const SCALE: usize = 2;
/// Half the side of a compared patch (15 × 15 pixels at 1/`SCALE`).
const HALF: usize = 7;
/// Rows searched above and below each left patch, full-resolution pixels.
pub const MAX_ROWS: usize = 24;
/// Rows searched at 1/`SCALE`.
const COARSE_ROWS: usize = MAX_ROWS / SCALE;
/// Candidate patches per side of the sampling grid.
const GRID: usize = 12;
/// When a patch's best match counts: its correlation reaches `ncc` and beats every row more
/// than `peak_rows` away by `margin`.
struct Acceptance {
    ncc: f32,
    margin: f32,
    peak_rows: usize,
}

const ACCEPT: Acceptance = Acceptance {
    ncc: 0.8,
    margin: 0.1,
    peak_rows: 2,
};
/// Too few matched patches measure nothing.
const MIN_POINTS: usize = 3;

/// The measure of one rectified pair.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Parallax {
    /// Median absolute row offset of the matched patches, full-resolution pixels (a multiple of
    /// 2: the search is at half resolution).
    pub median_rows: f32,
    /// Patches matched (correlation ≥ 0.8, inside the row search) of those tried.
    pub matched: usize,
    /// Textured patches tried.
    pub tried: usize,
}

/// The vertical parallax of the rectified `left`/`right` pair whose matches lie at
/// `x_R = x_L − d`, `d` in `range` (inclusive); `None` when too few textured patches match to
/// tell (featureless, or the rows are off by more than [`MAX_ROWS`]).
pub fn vertical_parallax(left: &Image, right: &Image, range: (i32, i32)) -> Option<Parallax> {
    let (l, r) = (reduced(&left.to_gray()), reduced(&right.to_gray()));
    let range = (
        range.0.div_euclid(SCALE as i32),
        -(-range.1).div_euclid(SCALE as i32),
    );
    let (lw, lh) = l.size();
    let (rw, rh) = r.size();
    let margin = HALF + COARSE_ROWS;
    if lw <= 2 * margin || lh <= 2 * margin || rh <= 2 * margin {
        return None;
    }
    let patches = textured_patches(&l, margin);
    let mut offsets: Vec<f32> = patches
        .iter()
        .filter_map(|&(x, y)| best_row_offset(&l, &r, (x, y), range, (rw, rh)))
        .map(|dy| (dy.unsigned_abs() as usize * SCALE) as f32)
        .collect();
    if offsets.len() < MIN_POINTS {
        return None;
    }
    offsets.sort_by(f32::total_cmp);
    Some(Parallax {
        median_rows: offsets[offsets.len() / 2],
        matched: offsets.len(),
        tried: patches.len(),
    })
}

/// `grey` at 1/[`SCALE`] of its size, each pixel the mean of a block (NaN if one of its pixels is).
fn reduced(grey: &Image) -> Image {
    let (w, h) = grey.size();
    let n = (SCALE * SCALE) as f32;
    Image::from_fn(w / SCALE, h / SCALE, |x, y| {
        let block = (0..SCALE).flat_map(|dy| (0..SCALE).map(move |dx| (dx, dy)));
        block
            .map(|(dx, dy)| grey.get(x * SCALE + dx, y * SCALE + dy, 0))
            .sum::<f32>()
            / n
    })
}

/// The centres of the more textured half of a regular grid of patches, all finite.
fn textured_patches(grey: &Image, margin: usize) -> Vec<(usize, usize)> {
    let (w, h) = grey.size();
    let mut scored: Vec<(f32, (usize, usize))> = Vec::new();
    for gy in 0..GRID {
        for gx in 0..GRID {
            let x = margin + (w - 2 * margin) * (2 * gx + 1) / (2 * GRID);
            let y = margin + (h - 2 * margin) * (2 * gy + 1) / (2 * GRID);
            if let Some((_, spread)) = patch_stats(grey, x, y) {
                scored.push((spread, (x, y)));
            }
        }
    }
    scored.sort_by(|a, b| b.0.total_cmp(&a.0));
    scored.truncate(scored.len().div_ceil(2));
    scored
        .into_iter()
        .filter(|(spread, _)| *spread > 1e-3)
        .map(|(_, p)| p)
        .collect()
}

/// Mean and standard deviation of the patch centred at `(x, y)`; `None` if a value is not finite.
fn patch_stats(grey: &Image, x: usize, y: usize) -> Option<(f32, f32)> {
    let (mut sum, mut sq) = (0.0f32, 0.0f32);
    for v in patch(grey, x, y) {
        if !v.is_finite() {
            return None;
        }
        sum += v;
        sq += v * v;
    }
    let n = ((2 * HALF + 1) * (2 * HALF + 1)) as f32;
    let mean = sum / n;
    Some((mean, (sq / n - mean * mean).max(0.0).sqrt()))
}

fn patch(grey: &Image, x: usize, y: usize) -> impl Iterator<Item = f32> + '_ {
    (y - HALF..=y + HALF)
        .flat_map(move |yy| (x - HALF..=x + HALF).map(move |xx| grey.get(xx, yy, 0)))
}

/// The row offset of the right patch that best correlates with the left one at `(x, y)`, over
/// the disparity range and ±[`COARSE_ROWS`]; `None` when the best is weak, on the search's edge, or
/// not clearly above the best of the rows further away ([`ACCEPT`]) (a repeated or changed
/// texture: cross-season pairs have many of those).
fn best_row_offset(
    l: &Image,
    r: &Image,
    (x, y): (usize, usize),
    range: (i32, i32),
    (rw, rh): (usize, usize),
) -> Option<i32> {
    let (lm, ls) = patch_stats(l, x, y)?;
    let left: Vec<f32> = patch(l, x, y).map(|v| (v - lm) / ls).collect();
    let rows = -(COARSE_ROWS as i32)..=COARSE_ROWS as i32;
    // The best correlation of each row offset over the disparities.
    let by_row: Vec<f32> = rows
        .clone()
        .map(|dy| {
            let ry = y as i32 + dy;
            if ry < HALF as i32 || ry + HALF as i32 >= rh as i32 {
                return f32::NEG_INFINITY;
            }
            (range.0..=range.1)
                .filter_map(|d| {
                    let rx = x as i32 - d;
                    if rx < HALF as i32 || rx + HALF as i32 >= rw as i32 {
                        return None;
                    }
                    let (rx, ry) = (rx as usize, ry as usize);
                    let (rm, rs) = patch_stats(r, rx, ry)?;
                    (rs > 1e-6).then(|| {
                        let dot: f32 = left
                            .iter()
                            .zip(patch(r, rx, ry))
                            .map(|(a, b)| a * (b - rm))
                            .sum();
                        dot / (rs * left.len() as f32)
                    })
                })
                .fold(f32::NEG_INFINITY, f32::max)
        })
        .collect();
    let (k, &best) = by_row
        .iter()
        .enumerate()
        .max_by(|a, b| a.1.total_cmp(b.1))?;
    let elsewhere = by_row
        .iter()
        .enumerate()
        .filter(|(i, _)| i.abs_diff(k) > ACCEPT.peak_rows)
        .map(|(_, &v)| v)
        .fold(f32::NEG_INFINITY, f32::max);
    let dy = k as i32 - COARSE_ROWS as i32;
    let clear = best >= ACCEPT.ncc && best - elsewhere >= ACCEPT.margin;
    (clear && dy.unsigned_abs() < COARSE_ROWS as u32).then_some(dy)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Random values on a 3-pixel lattice, interpolated: texture without repeats.
    fn texture(w: usize, h: usize, shift: (usize, usize)) -> Image {
        let noise = |ix: usize, iy: usize| {
            let mut v = (ix as u64).wrapping_mul(0x9E37_79B9_7F4A_7C15)
                ^ (iy as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
            v ^= v >> 29;
            v = v.wrapping_mul(0xBF58_476D_1CE4_E5B9);
            v ^= v >> 32;
            (v & 0xFFFF) as f32 / 65535.0
        };
        Image::from_fn(w, h, |x, y| {
            let (x, y) = ((x + shift.0) as f32 / 3.0, (y + shift.1) as f32 / 3.0);
            let (ix, iy) = (x.floor() as usize, y.floor() as usize);
            let (fx, fy) = (x - x.floor(), y - y.floor());
            let top = noise(ix, iy) * (1.0 - fx) + noise(ix + 1, iy) * fx;
            let bottom = noise(ix, iy + 1) * (1.0 - fx) + noise(ix + 1, iy + 1) * fx;
            top * (1.0 - fy) + bottom * fy
        })
    }

    #[test]
    fn measures_the_rows_between_the_views() {
        let left = texture(200, 160, (50, 50));
        // The right view: its pixel (x − 8, y − dy) shows the left's (x, y): disparity 8, and
        // the matches `dy` rows off.
        for dy in [0i32, 4, -6, 16] {
            let right = texture(200, 160, (58, (50 + dy) as usize));
            let p = vertical_parallax(&left, &right, (0, 10)).expect("textured");
            assert_eq!(p.median_rows, dy.unsigned_abs() as f32, "{p:?}");
            assert!(p.matched >= MIN_POINTS, "{p:?}");
        }
    }

    #[test]
    fn featureless_or_far_off_views_measure_nothing() {
        let flat = Image::filled(200, 160, 1, 0.5);
        assert_eq!(vertical_parallax(&flat, &flat, (-4, 4)), None);
        let left = texture(200, 160, (50, 50));
        let far = texture(200, 160, (50, 90));
        assert_eq!(vertical_parallax(&left, &far, (-4, 4)), None);
    }
}
