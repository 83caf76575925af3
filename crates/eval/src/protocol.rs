//! Which scoring rules `seasonstereo eval` follows.
//!
//! [`Protocol::Release`] (the default) reproduces the benchmark's released evaluator
//! (`multimedia-eurecat/SeasonStereo`, `season_stereo/eval_test.py::_save_pair_outputs_and_row`
//! → `utils/misc.py` → `utils/dsmr.py`) number for number:
//!
//! - the disparity mask is applied twice: on the (cropped) prediction, then again in the
//!   coordinates of the 32-px-trimmed prediction, so a kept pixel has finite d > 0, lies 32 px
//!   or more inside every border, and its match x − d falls in [32, W − 32) ([`evaluation_mask`]);
//! - each score registers on its own masked truth ([`super::metrics::Registration::PerScore`])
//!   with the release's multiscale NCC ([`super::align::Scheme::Release`]);
//! - `_WATER.png` marks water with ZERO, and is read only when `_CLS.tif` exists; without a
//!   `_CLS.tif` nothing is masked (the three scores coincide);
//! - the ground truth's nodata value is NOT mapped to NaN (the release reads the raw values);
//! - a class raster of another size is resized to the DSM's (nearest neighbour, as
//!   `skimage.transform.resize(order=0)`).
//!
//! SeasonStereo applies the disparity mask; the diachronic benchmark's own `evaluate_all.py`
//! applies none. seasonstereo follows SeasonStereo, whose evaluator produced the paper's Table 1.
//!
//! [`Protocol::Robust`] keeps seasonstereo's earlier, deliberate variants where they are better
//! founded, for studies beyond the paper: the truth's nodata value becomes NaN; one registration
//! on the unmasked truth serves the three scores (so they differ only by the cells they count);
//! the NCC pyramid uses aligned 2×2 blocks down to 32 cells, needs 25 % overlap and breaks ties
//! towards the centre; a class raster of another size is refused. The disparity mask and the
//! water polarity are the release's in both (they are the benchmark's data conventions).
//!
//! Coverage (share of the truth's cells with an aligned prediction), which the release does not
//! compute, is reported beside the scores under both protocols.

use raster::{Image, Mask};

use super::align::AlignParams;
use super::metrics::{Registration, ScoreParams};

/// The border trimmed by the release before triangulating, pixels (`--border-trim`).
pub const BORDER_TRIM: usize = 32;

/// The scoring rules.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Protocol {
    /// The released evaluator, exactly.
    #[default]
    Release,
    /// seasonstereo's robust variant (see the module doc).
    Robust,
}

impl Protocol {
    /// Parses `release` or `robust`.
    pub fn parse(s: &str) -> Result<Protocol, String> {
        match s.trim().to_ascii_lowercase().as_str() {
            "release" => Ok(Protocol::Release),
            "robust" => Ok(Protocol::Robust),
            _ => Err(format!("unknown protocol {s:?}: release or robust")),
        }
    }

    /// Its name on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            Protocol::Release => "release",
            Protocol::Robust => "robust",
        }
    }

    /// How DSMs are registered and scored.
    pub fn score_params(&self) -> ScoreParams {
        match self {
            Protocol::Release => ScoreParams {
                align: AlignParams::release(),
                registration: Registration::PerScore,
            },
            Protocol::Robust => ScoreParams {
                align: AlignParams::robust(),
                registration: Registration::Shared,
            },
        }
    }

    /// Whether the truth's nodata value becomes NaN.
    pub fn nodata_to_nan(&self) -> bool {
        matches!(self, Protocol::Robust)
    }

    /// Whether a class raster of another size is resized (else refused).
    pub fn resize_classes(&self) -> bool {
        matches!(self, Protocol::Release)
    }
}

/// The pixels of a (cropped) rectified disparity that the release triangulates: finite d > 0,
/// at least `BORDER_TRIM` px inside every border, and the match x − d in
/// [`BORDER_TRIM`, W − `BORDER_TRIM`) — the release's `compute_disparity_mask` applied to the
/// full prediction (0 ≤ x − d < W) and again after the trim, in the trimmed coordinates.
pub fn evaluation_mask(disparity: &Image) -> Mask {
    let (w, h) = disparity.size();
    let b = BORDER_TRIM;
    Mask::from_fn(w, h, |x, y| {
        if x < b || y < b || x + b >= w || y + b >= h {
            return false;
        }
        let d = disparity.get(x, y, 0) as f64;
        // In the trimmed frame: x' = x − b, W' = W − 2b, 0 ≤ x' − d < W'.
        let xr = (x - b) as f64 - d;
        d.is_finite() && d > 0.0 && xr >= 0.0 && xr < (w - 2 * b) as f64
    })
}

/// `skimage.transform.resize(image, (h, w), order=0, preserve_range=True,
/// anti_aliasing=False)`: output cell (x, y) takes the input cell nearest to
/// ((x + ½)·W/w − ½, (y + ½)·H/h − ½), halves rounded up (scipy's order-0 `zoom` with
/// `grid_mode=True`), clamped to the raster.
pub fn resize_nearest(image: &Image, w: usize, h: usize) -> Image {
    let (iw, ih) = image.size();
    let src = |o: usize, n_in: usize, n_out: usize| -> usize {
        let c = (o as f64 + 0.5) * n_in as f64 / n_out as f64 - 0.5;
        ((c + 0.5).floor().max(0.0) as usize).min(n_in - 1)
    };
    Image::from_fn(w, h, |x, y| image.get(src(x, iw, w), src(y, ih, h), 0))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_match_must_fall_inside_the_trimmed_right_image() {
        // W = 100: x − d must lie in [32, 68).
        let d = Image::from_fn(100, 70, |x, _| if x < 50 { 10.0 } else { 20.0 });
        let m = evaluation_mask(&d);
        assert!(!m.get(41, 35)); // 41 − 10 = 31 < 32
        assert!(m.get(42, 35)); // 32
        assert!(m.get(67, 35)); // 67 − 20 = 47
        assert!(!m.get(68, 35)); // outside the trimmed left image
        let d = Image::filled(100, 70, 1, -1.0);
        assert_eq!(evaluation_mask(&d).count(), 0);
        // x − d ≥ 32 drops the first column of the trimmed frame, which [0, W) kept.
        let d = Image::filled(100, 70, 1, 0.5);
        assert_eq!(evaluation_mask(&d).count(), 35 * 6);
    }

    #[test]
    fn nearest_resize_picks_the_nearest_source_cell() {
        let img = Image::from_fn(4, 2, |x, y| (10 * y + x) as f32);
        let up = resize_nearest(&img, 8, 4);
        // Output column 1 → source (1.5)/2 − 0.5 = 0.25 → 0; column 2 → 0.75 → 1.
        assert_eq!(up.get(1, 0, 0), 0.0);
        assert_eq!(up.get(2, 0, 0), 1.0);
        assert_eq!(up.get(7, 3, 0), 13.0);
        let down = resize_nearest(&img, 2, 1);
        // Column 0 → 2·0.5 − 0.5 = 0.5 → rounds up to 1; row 0 → 0.5 → 1.
        assert_eq!(down.get(0, 0, 0), 11.0);
        // Checked against scikit-image 0.26: (2, 4) → (3, 5) gives rows [0 1 2 2 3],
        // [10 11 12 12 13] twice.
        let odd = resize_nearest(&img, 5, 3);
        let rows: Vec<Vec<f32>> = (0..3)
            .map(|y| (0..5).map(|x| odd.get(x, y, 0)).collect())
            .collect();
        assert_eq!(rows[0], [0.0, 1.0, 2.0, 2.0, 3.0]);
        assert_eq!(rows[1], [10.0, 11.0, 12.0, 12.0, 13.0]);
        assert_eq!(rows[2], rows[1]);
    }
}
