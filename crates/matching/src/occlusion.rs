//! Occlusion and joint visibility from a left disparity map (paper Sec. 3.3, "Valid Pixel
//! Mask"): a z-buffer test along each epipolar row, so the photometric and smoothness losses
//! are not computed where the left pixel has no counterpart in the right image.

use raster::{Image, Mask, RasterError, Result};
use rayon::prelude::*;

/// Result of [`zbuffer_occlusion`]. Every mask is on the LEFT view and TRUE marks a pixel that
/// must be EXCLUDED; the valid-pixel mask is `!occluded` (see [`Occlusion::visible`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Occlusion {
    /// Not jointly visible, for any reason: NaN/infinite disparity, out of view, or hidden.
    /// The union of `out_of_view`, `hidden` and the non-finite disparities.
    pub occluded: Mask,
    /// Lands outside the right image (`round(x − d) ∉ [0, W)`), e.g. the strip near the left
    /// border for positive disparities.
    pub out_of_view: Mask,
    /// Lands on a right column already claimed by a pixel of larger disparity (a closer
    /// surface): the z-buffer losers, mostly on building facades.
    pub hidden: Mask,
}

impl Occlusion {
    /// The jointly visible pixels: `!occluded`.
    pub fn visible(&self) -> Mask {
        let (w, h) = self.occluded.size();
        let data = self.occluded.data().iter().map(|&o| !o).collect();
        Mask::new(w, h, data).expect("same size")
    }
}

/// Z-buffer visibility test (x_R = x_L − d). Each left pixel `x` of a row is sent to the right
/// column `round(x − d)`, rounding halves up (`floor(t + 0.5)`, which commutes with integer
/// shifts, so a constant half-integer disparity maps a row one-to-one); if that column is
/// outside `[0, W)` the pixel is out of view. When several left pixels of a row land on the same
/// right column, only the one with the LARGEST disparity (the closest surface) stays visible and
/// all the others are hidden, whatever their scan order. Pixels with equal disparity can never
/// land on the same column (their targets differ by the same integer as their x), so ties cannot
/// occur; the comparison is strict, so the first pixel in scan order would be kept. Non-finite
/// disparities are occluded (but neither `out_of_view` nor `hidden`). O(W) per row, rows in
/// parallel. The disparity must be single-channel.
pub fn zbuffer_occlusion(disparity: &Image) -> Result<Occlusion> {
    if disparity.channels() != 1 {
        return Err(RasterError::Shape(format!(
            "zbuffer_occlusion: disparity must have 1 channel, got {}",
            disparity.channels()
        )));
    }
    let (w, h) = disparity.size();
    let mut occluded = vec![false; w * h];
    let mut out_of_view = vec![false; w * h];
    let mut hidden = vec![false; w * h];
    if w > 0 {
        occluded
            .par_chunks_mut(w)
            .zip(out_of_view.par_chunks_mut(w))
            .zip(hidden.par_chunks_mut(w))
            .enumerate()
            .for_each_init(
                // Per right column: the left pixel currently owning it (usize::MAX = none).
                || vec![usize::MAX; w],
                |owner, (y, ((occ, oov), hid))| {
                    owner.fill(usize::MAX);
                    let row = disparity.row(y);
                    for (x, &d) in row.iter().enumerate() {
                        if !d.is_finite() {
                            occ[x] = true;
                            continue;
                        }
                        let xr = (x as f64 - d as f64 + 0.5).floor();
                        if !(0.0..w as f64).contains(&xr) {
                            oov[x] = true;
                            occ[x] = true;
                            continue;
                        }
                        let xr = xr as usize;
                        match owner[xr] {
                            usize::MAX => owner[xr] = x,
                            prev if d > row[prev] => {
                                hid[prev] = true;
                                occ[prev] = true;
                                owner[xr] = x;
                            }
                            _ => {
                                hid[x] = true;
                                occ[x] = true;
                            }
                        }
                    }
                },
            );
    }
    Ok(Occlusion {
        occluded: Mask::new(w, h, occluded)?,
        out_of_view: Mask::new(w, h, out_of_view)?,
        hidden: Mask::new(w, h, hidden)?,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn row(d: &[f32]) -> Image {
        Image::new(d.len(), 1, 1, d.to_vec()).unwrap()
    }

    #[test]
    fn foreground_hides_background() {
        // Background d = 1 on x = 0..=7 and 12..=15, a foreground block d = 5 on x = 8..=11.
        // Background lands on x − 1: 0→−1 (out), 1..=7 → 0..=6, 12..=15 → 11..=14.
        // Foreground lands on x − 5: 8..=11 → 3..=6, covering the columns of background 4..=7.
        let mut d = vec![1.0f32; 16];
        d[8..12].fill(5.0);
        let occ = zbuffer_occlusion(&row(&d)).unwrap();
        let hidden: Vec<usize> = (0..16).filter(|&x| occ.hidden.get(x, 0)).collect();
        let oov: Vec<usize> = (0..16).filter(|&x| occ.out_of_view.get(x, 0)).collect();
        let all: Vec<usize> = (0..16).filter(|&x| occ.occluded.get(x, 0)).collect();
        assert_eq!(hidden, vec![4, 5, 6, 7]);
        assert_eq!(oov, vec![0]);
        assert_eq!(all, vec![0, 4, 5, 6, 7]);
        assert_eq!(occ.visible().count(), 11);
    }

    #[test]
    fn closer_surface_wins_regardless_of_order() {
        // W = 7. x = 0, d = 0.4 → round(−0.4) = 0; x = 1 NaN; x = 2, d = 2 → 0 (beats x = 0);
        // x = 3, d = 1.6 → round(1.4) = 1; x = 4, d = 3 → 1 (beats x = 3);
        // x = 5, d = 0.5 → round(4.5) = 5 (half up); x = 6, d = −0.5 → round(6.5) = 7: out.
        let d = [0.4f32, f32::NAN, 2.0, 1.6, 3.0, 0.5, -0.5];
        let occ = zbuffer_occlusion(&row(&d)).unwrap();
        let pick = |m: &Mask| (0..7).filter(|&x| m.get(x, 0)).collect::<Vec<_>>();
        assert_eq!(pick(&occ.hidden), vec![0, 3]);
        assert_eq!(pick(&occ.out_of_view), vec![6]);
        assert_eq!(pick(&occ.occluded), vec![0, 1, 3, 6]);
        assert_eq!(pick(&occ.visible()), vec![2, 4, 5]);
    }

    #[test]
    fn constant_half_pixel_disparity_is_one_to_one() {
        // Half-up rounding: x − 0.5 → x for every x, so nothing is hidden or out of view
        // (half-away-from-zero would send x = 0 to −1).
        let occ = zbuffer_occlusion(&row(&[0.5; 9])).unwrap();
        assert_eq!(occ.occluded.count(), 0);
        // d = 1.5: x − 1.5 → x − 1, so only x = 0 is out of view.
        let occ = zbuffer_occlusion(&row(&[1.5; 9])).unwrap();
        assert_eq!(occ.out_of_view.data()[..2], [true, false]);
        assert_eq!(occ.occluded.count(), 1);
        assert_eq!(occ.hidden.count(), 0);
    }

    #[test]
    fn rows_are_independent() {
        // Row 0: x = 0 out (d = 9); x = 1, d = 1.2 → round(−0.2) = 0; x = 2, d = 1.8 → round(0.2)
        // = 0 and wins; x = 3, d = 2.4 → round(0.6) = 1.
        // Row 1: x = 0 out; x = 1 → 0; x = 2, d = 1.5 → round(0.5) = 1; x = 3 out (d = 9).
        let data = vec![
            9.0, 1.2, 1.8, 2.4, //
            9.0, 1.0, 1.5, 9.0,
        ];
        let img = Image::new(4, 2, 1, data).unwrap();
        let occ = zbuffer_occlusion(&img).unwrap();
        assert_eq!(
            occ.occluded.data(),
            &[true, true, false, false, true, false, false, true]
        );
        assert_eq!(
            occ.hidden.data(),
            &[false, true, false, false, false, false, false, false]
        );
        assert!(zbuffer_occlusion(&Image::filled(3, 3, 2, 0.0)).is_err());
    }
}
