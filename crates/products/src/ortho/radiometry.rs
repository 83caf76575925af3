//! A view's digital numbers as 8-bit colours: 8-bit imagery as it is, anything else (11- or
//! 14-bit satellite imagery in uint16, reflectances in float) stretched linearly from its 0.5th
//! to its 99.5th percentile, the same for every channel so the colours keep their balance.
//!
//! 0 is kept for "no colour": real colours take 1–255.

/// Lower and upper percentiles of the stretch.
const STRETCH_PERCENTILES: (f64, f64) = (0.005, 0.995);
/// Samples the percentiles are estimated from, at most (a regular subsample beyond).
const MAX_SAMPLES: usize = 1 << 20;

/// How a view's values become 1–255.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Levels {
    /// 8-bit values, kept (0 raised to 1).
    AsIs,
    /// `lo` → 1, `hi` → 255, linearly, clamped.
    Stretch { lo: f32, hi: f32 },
}

impl Levels {
    /// The levels of a view from its valid values (NaN = invalid): [`Levels::AsIs`] when every
    /// valid value is a whole number within 0–255, the percentile stretch otherwise.
    pub fn of(values: &[f32]) -> Levels {
        let valid = || values.iter().copied().filter(|v| !v.is_nan());
        if valid().all(|v| v.fract() == 0.0 && (0.0..=255.0).contains(&v)) {
            return Levels::AsIs;
        }
        let n = valid().count();
        let stride = n.div_ceil(MAX_SAMPLES).max(1);
        let mut sample: Vec<f32> = valid().step_by(stride).collect();
        let at = |sample: &mut Vec<f32>, q: f64| {
            let i = ((sample.len() - 1) as f64 * q).round() as usize;
            *sample.select_nth_unstable_by(i, f32::total_cmp).1
        };
        let lo = at(&mut sample, STRETCH_PERCENTILES.0);
        let hi = at(&mut sample, STRETCH_PERCENTILES.1);
        if hi > lo {
            Levels::Stretch { lo, hi }
        } else {
            // A flat image: mid-grey.
            Levels::Stretch {
                lo: lo - 1.0,
                hi: lo + 1.0,
            }
        }
    }

    /// The 8-bit level of a valid value: 1–255.
    #[inline]
    pub fn apply(self, v: f32) -> u8 {
        let level = match self {
            Levels::AsIs => v,
            Levels::Stretch { lo, hi } => 1.0 + (v - lo) / (hi - lo) * 254.0,
        };
        level.round().clamp(1.0, 255.0) as u8
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bytes_are_kept_and_black_becomes_one() {
        let levels = Levels::of(&[0.0, 17.0, 255.0, f32::NAN]);
        assert_eq!(levels, Levels::AsIs);
        assert_eq!(levels.apply(0.0), 1);
        assert_eq!(levels.apply(17.0), 17);
        assert_eq!(levels.apply(255.0), 255);
    }

    #[test]
    fn wider_ranges_are_stretched_between_percentiles() {
        // 0..=1999 with one outlier far above: the 99.5th percentile ignores it.
        let mut values: Vec<f32> = (0..2000).map(|v| v as f32).collect();
        values.push(60_000.0);
        let Levels::Stretch { lo, hi } = Levels::of(&values) else {
            panic!("uint16-like values must be stretched");
        };
        assert!((lo - 10.0).abs() <= 1.0, "{lo}");
        assert!((hi - 1990.0).abs() <= 1.0, "{hi}");
        let levels = Levels::Stretch { lo, hi };
        assert_eq!(levels.apply(0.0), 1);
        assert_eq!(levels.apply(60_000.0), 255);
        assert_eq!(levels.apply((lo + hi) / 2.0), 128);
        // Reflectances in [0, 1] are stretched too.
        let reflectance: Vec<f32> = (0..100).map(|v| v as f32 / 100.0).collect();
        assert!(matches!(Levels::of(&reflectance), Levels::Stretch { .. }));
    }
}
