//! Disparity errors against a ground truth, counted in one place for every report (the demo's
//! and `eval`'s tables, training validation). Each report then says how it treats unmatched
//! (non-finite) predictions: as missing coverage, or as errors above every threshold.

/// Error counts over the evaluated pixels: those with a finite true disparity.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct ErrorCounts {
    /// Pixels with a finite true disparity.
    pub evaluated: usize,
    /// Of those, pixels with a finite prediction.
    pub matched: usize,
    /// Sum of |prediction − truth| over the matched pixels, pixels.
    pub abs_sum: f64,
    /// Sum of the squared errors over the matched pixels.
    pub sq_sum: f64,
    /// Matched pixels whose error exceeds 1, 2 and 3 px.
    pub over: [usize; 3],
}

impl ErrorCounts {
    /// Mean absolute error of the matched pixels (the EPE), `None` when none is matched.
    pub fn mae(&self) -> Option<f64> {
        (self.matched > 0).then(|| self.abs_sum / self.matched as f64)
    }

    /// Pixels not matched.
    pub fn unmatched(&self) -> usize {
        self.evaluated - self.matched
    }
}

/// Counts the errors of `(prediction, truth)` pairs; pairs with a non-finite truth are skipped.
pub fn count_errors(pairs: impl IntoIterator<Item = (f32, f32)>) -> ErrorCounts {
    let mut c = ErrorCounts::default();
    for (p, t) in pairs {
        if !t.is_finite() {
            continue;
        }
        c.evaluated += 1;
        if !p.is_finite() {
            continue;
        }
        c.matched += 1;
        let e = (p - t).abs() as f64;
        c.abs_sum += e;
        c.sq_sum += e * e;
        for (k, n) in c.over.iter_mut().enumerate() {
            *n += (e > (k + 1) as f64) as usize;
        }
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn counts_skip_unknown_truth_and_keep_unmatched_apart() {
        let c = count_errors([(1.0, 1.5), (f32::NAN, 2.0), (5.0, f32::NAN), (0.0, 2.5)]);
        assert_eq!((c.evaluated, c.matched, c.unmatched()), (3, 2, 1));
        assert_eq!(c.over, [1, 1, 0]);
        assert_eq!(c.mae(), Some(1.5));
        assert_eq!(count_errors([(f32::NAN, 1.0)]).mae(), None);
    }
}
