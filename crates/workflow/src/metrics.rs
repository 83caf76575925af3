//! Disparity scores against ground truth: the numbers of stereo benchmarks.

use dataset::scores::count_errors;
use raster::{Image, Mask, RasterError};
use serde::Serialize;

/// Scores of a predicted disparity over a region. Rates are fractions in [0, 1]. Error statistics
/// are `None` when no pixel of the region was matched (never a division by zero).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DisparityScores {
    /// Pixels of the region with a finite true disparity.
    pub evaluated: usize,
    /// Of those, pixels with a finite prediction.
    pub matched: usize,
    /// `matched / evaluated`.
    pub coverage: Option<f64>,
    /// Mean absolute error over matched pixels, pixels.
    pub mae: Option<f64>,
    /// Root mean square error over matched pixels, pixels.
    pub rmse: Option<f64>,
    /// Share of matched pixels whose error exceeds 1 px.
    pub bad1: Option<f64>,
    /// Share of matched pixels whose error exceeds 2 px.
    pub bad2: Option<f64>,
}

/// Scores `predicted` against `truth` over the pixels of `region`; NaN predictions count as
/// unmatched (they lower the coverage, not the error).
pub fn score_disparity(
    predicted: &Image,
    truth: &Image,
    region: &Mask,
) -> Result<DisparityScores, RasterError> {
    predicted.check_same_size(truth, "predicted and true disparity")?;
    truth.check_mask(region, "true disparity and evaluation mask")?;
    let (px, tx) = (predicted.channels(), truth.channels());
    let c = count_errors(
        region
            .data()
            .iter()
            .enumerate()
            .filter(|(_, &keep)| keep)
            .map(|(i, _)| (predicted.data()[i * px], truth.data()[i * tx])),
    );
    let per = |v: f64| (c.matched > 0).then(|| v / c.matched as f64);
    Ok(DisparityScores {
        evaluated: c.evaluated,
        matched: c.matched,
        coverage: (c.evaluated > 0).then(|| c.matched as f64 / c.evaluated as f64),
        mae: c.mae(),
        rmse: per(c.sq_sum).map(f64::sqrt),
        bad1: per(c.over[0] as f64),
        bad2: per(c.over[1] as f64),
    })
}

/// |predicted − truth| per pixel, NaN where either is not finite.
pub fn error_map(predicted: &Image, truth: &Image) -> Result<Image, RasterError> {
    predicted.check_same_size(truth, "predicted and true disparity")?;
    let data = predicted
        .channel(0)
        .data()
        .iter()
        .zip(truth.channel(0).data())
        .map(|(p, t)| {
            if p.is_finite() && t.is_finite() {
                (p - t).abs()
            } else {
                f32::NAN
            }
        })
        .collect();
    Image::new(truth.width(), truth.height(), 1, data)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn scores_on_a_hand_made_example() {
        let truth = Image::new(4, 1, 1, vec![1.0, 2.0, 3.0, f32::NAN]).unwrap();
        let pred = Image::new(4, 1, 1, vec![1.5, f32::NAN, 6.0, 1.0]).unwrap();
        let s = score_disparity(&pred, &truth, &Mask::filled(4, 1, true)).unwrap();
        assert_eq!((s.evaluated, s.matched), (3, 2));
        assert_eq!(s.mae, Some(1.75));
        assert_eq!(s.bad1, Some(0.5));
        assert_eq!(s.bad2, Some(0.5));
        assert!((s.coverage.unwrap() - 2.0 / 3.0).abs() < 1e-12);
        assert!((s.rmse.unwrap() - (0.25f64 + 9.0).sqrt() / 2f64.sqrt()).abs() < 1e-12);
    }

    #[test]
    fn empty_region_gives_no_numbers_and_no_nan() {
        let truth = Image::filled(3, 3, 1, 1.0);
        let s = score_disparity(&truth, &truth, &Mask::filled(3, 3, false)).unwrap();
        assert_eq!(s.evaluated, 0);
        assert!(s.mae.is_none() && s.coverage.is_none() && s.bad2.is_none());
    }

    #[test]
    fn size_mismatch_is_an_error() {
        let a = Image::filled(3, 3, 1, 1.0);
        let b = Image::filled(3, 2, 1, 1.0);
        assert!(score_disparity(&a, &b, &Mask::filled(3, 3, true)).is_err());
        assert!(score_disparity(&a, &a, &Mask::filled(2, 3, true)).is_err());
        assert!(error_map(&a, &b).is_err());
    }
}
