//! Speckle removal: small connected regions of disparity are cleared.
//!
//! Why: on real (and especially multi-date) satellite pairs, the matcher leaves small islands of
//! wrong disparity that agree with themselves and survive the left–right check. A DSM keeps the
//! highest point per cell, so a few such islands above the roofs dominate its error. Like s2p's
//! and OpenCV's `filterSpeckles`, a region is the set of pixels connected (4-neighbourhood)
//! through neighbours whose disparities differ by at most `max_diff`; regions smaller than
//! `min_area` pixels are set to NaN.

/// Parameters of the speckle filter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Speckle {
    /// Regions with fewer pixels than this are removed.
    pub min_area: usize,
    /// Largest disparity difference between 4-neighbours of one region, pixels.
    pub max_diff: f32,
}

impl Speckle {
    pub(crate) fn validate(&self) -> Result<(), String> {
        if self.max_diff.is_nan() || self.max_diff < 0.0 {
            return Err(format!(
                "speckle tolerance must be >= 0, got {}",
                self.max_diff
            ));
        }
        Ok(())
    }
}

/// Clears (sets to NaN) the regions of `disp` (`w × h`, row-major) smaller than
/// `params.min_area`. NaN pixels belong to no region. Returns the number of pixels cleared.
pub fn remove_speckles(disp: &mut [f32], w: usize, h: usize, params: &Speckle) -> usize {
    assert_eq!(disp.len(), w * h);
    if params.min_area <= 1 {
        return 0;
    }
    let mut seen = vec![false; w * h];
    let mut stack: Vec<usize> = Vec::new();
    let mut region: Vec<usize> = Vec::new();
    let mut cleared = 0;
    for start in 0..w * h {
        if seen[start] || disp[start].is_nan() {
            continue;
        }
        region.clear();
        stack.push(start);
        seen[start] = true;
        while let Some(p) = stack.pop() {
            region.push(p);
            let (x, y) = (p % w, p / w);
            let d = disp[p];
            let mut visit = |q: usize| {
                if !seen[q] && (disp[q] - d).abs() <= params.max_diff {
                    seen[q] = true;
                    stack.push(q);
                }
            };
            if x > 0 {
                visit(p - 1);
            }
            if x + 1 < w {
                visit(p + 1);
            }
            if y > 0 {
                visit(p - w);
            }
            if y + 1 < h {
                visit(p + w);
            }
        }
        if region.len() < params.min_area {
            for &p in &region {
                disp[p] = f32::NAN;
            }
            cleared += region.len();
        }
    }
    cleared
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn small_islands_go_large_regions_and_slopes_stay() {
        let (w, h) = (20, 10);
        // A slope (1 px per column is within tolerance 1), a 2×2 island of 50 on it, and a
        // lone NaN.
        let mut d: Vec<f32> = (0..w * h).map(|i| (i % w) as f32).collect();
        for (x, y) in [(5, 5), (6, 5), (5, 6), (6, 6)] {
            d[y * w + x] = 50.0;
        }
        d[3] = f32::NAN;
        let p = Speckle {
            min_area: 5,
            max_diff: 1.0,
        };
        let cleared = remove_speckles(&mut d, w, h, &p);
        assert_eq!(cleared, 4);
        assert!(d[5 * w + 5].is_nan() && d[6 * w + 6].is_nan());
        assert_eq!(d[0], 0.0);
        assert_eq!(d[9 * w + 19], 19.0);
        assert_eq!(d.iter().filter(|v| v.is_nan()).count(), 5);
        // The island survives when the area threshold is at its size.
        let mut e: Vec<f32> = (0..w * h).map(|i| (i % w) as f32).collect();
        for (x, y) in [(5, 5), (6, 5), (5, 6), (6, 6)] {
            e[y * w + x] = 50.0;
        }
        let p4 = Speckle { min_area: 4, ..p };
        assert_eq!(remove_speckles(&mut e, w, h, &p4), 0);
    }

    #[test]
    fn a_steep_slope_breaks_into_columns() {
        // 2 px per column exceeds the tolerance: each column (height 3) is its own region.
        let (w, h) = (6, 3);
        let mut d: Vec<f32> = (0..w * h).map(|i| 2.0 * (i % w) as f32).collect();
        let p = Speckle {
            min_area: 4,
            max_diff: 1.0,
        };
        assert_eq!(remove_speckles(&mut d, w, h, &p), w * h);
    }
}
