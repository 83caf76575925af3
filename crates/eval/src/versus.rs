//! Two DSMs of one scene compared on the cells they share: each is registered on the truth on
//! its own by the benchmark's protocol (NCC shift, vertical offset, water and foliage masked,
//! [`super::metrics`]), then the truth cells outside water and foliage are split by who covers
//! them after registration: both, only ours, only the other, neither.
//!
//! Why: a DSM with more holes has a lower MAE when its holes are where matching is hard
//! (shadows, occlusions, facades), so two MAEs over different cells do not rank two methods. The
//! MAE of each on the cells both cover does, and the MAE of the cells only one covers says what
//! its extra coverage costs.

use raster::Image;
use serde::Serialize;

use super::metrics::{score_dsm_registered, DsmScores, Exclusions, Registered, ScoreParams};

/// The MAE of one DSM over a set of cells.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct CellsMae {
    /// Cells of the set.
    pub cells: usize,
    /// Mean |truth − registered DSM| over them, metres; `None` when the set is empty.
    pub mae: Option<f64>,
}

/// Two DSMs ("ours" and "other") against one truth, cell by cell.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct Versus {
    /// Ours scored on its own (its coverage, within 1 m / 2 m, registration).
    pub ours: DsmScores,
    /// The other scored on its own.
    pub other: DsmScores,
    /// Ours on the cells both cover.
    pub common_ours: CellsMae,
    /// The other on the cells both cover.
    pub common_other: CellsMae,
    /// Ours on the cells only ours covers.
    pub only_ours: CellsMae,
    /// The other on the cells only it covers.
    pub only_other: CellsMae,
    /// Truth cells (outside water and foliage) that neither covers.
    pub neither: usize,
}

/// Scores `ours` and `other` (single-channel rasters on the truth's grid, NaN = no data) against
/// `gt` and splits the filtered truth's cells by who covers them after registration.
pub fn score_versus(
    ours: &Image,
    other: &Image,
    gt: &Image,
    exclusions: &Exclusions,
    params: &ScoreParams,
) -> Result<Versus, raster::RasterError> {
    let a = score_dsm_registered(ours, gt, exclusions, params)?;
    let b = score_dsm_registered(other, gt, exclusions, params)?;
    Ok(split(a, b))
}

/// Sums of |truth − DSM| over a set of cells.
#[derive(Default)]
struct Sum {
    n: usize,
    s: f64,
}

impl Sum {
    fn add(&mut self, truth: f32, dsm: f32) {
        self.n += 1;
        self.s += (truth - dsm).abs() as f64;
    }

    fn mae(&self) -> CellsMae {
        CellsMae {
            cells: self.n,
            mae: (self.n > 0).then(|| self.s / self.n as f64),
        }
    }
}

/// The cell-by-cell split of two registered DSMs (both registered on the same filtered truth).
fn split(a: Registered, b: Registered) -> Versus {
    let nan = || {
        Image::filled(
            a.truth_filtered.width(),
            a.truth_filtered.height(),
            1,
            f32::NAN,
        )
    };
    let (pa, pb) = (a.aligned.unwrap_or_else(nan), b.aligned.unwrap_or_else(nan));
    let (mut both_a, mut both_b, mut only_a, mut only_b) = Default::default();
    let mut neither = 0;
    for ((&g, &x), &y) in a.truth_filtered.data().iter().zip(pa.data()).zip(pb.data()) {
        if !g.is_finite() {
            continue;
        }
        match (x.is_finite(), y.is_finite()) {
            (true, true) => {
                Sum::add(&mut both_a, g, x);
                Sum::add(&mut both_b, g, y);
            }
            (true, false) => Sum::add(&mut only_a, g, x),
            (false, true) => Sum::add(&mut only_b, g, y),
            (false, false) => neither += 1,
        }
    }
    Versus {
        ours: a.scores,
        other: b.scores,
        common_ours: Sum::mae(&both_a),
        common_other: Sum::mae(&both_b),
        only_ours: Sum::mae(&only_a),
        only_other: Sum::mae(&only_b),
        neither,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 24×24 truth: ground at 0 m, a 8×8 roof at 10 m.
    fn truth() -> Image {
        Image::from_fn(24, 24, |x, y| {
            if (8..16).contains(&x) && (8..16).contains(&y) {
                10.0
            } else {
                0.0
            }
        })
    }

    #[test]
    fn cells_split_by_who_covers_them_and_each_mae_is_over_its_own_cells() {
        let gt = truth();
        let ex = Exclusions::none(24, 24);
        // Ours: truth + 0.5 m on the left 16 columns, nothing on the right.
        let ours = Image::from_fn(24, 24, |x, y| {
            if x < 16 {
                gt.get(x, y, 0) + 0.5
            } else {
                f32::NAN
            }
        });
        // Other: alternating ±2 m (mean offset 0) on the right 16 columns only.
        let other = Image::from_fn(24, 24, |x, y| {
            if x >= 8 {
                gt.get(x, y, 0) + if (x + y) % 2 == 0 { 2.0 } else { -2.0 }
            } else {
                f32::NAN
            }
        });
        let v = score_versus(&ours, &other, &gt, &ex, &ScoreParams::default()).unwrap();
        // Registration removes ours' constant 0.5 m; the other's mean error is 0 already.
        assert_eq!(v.ours.dx, 0);
        assert_eq!(v.ours.dy, 0);
        assert!((v.ours.offset.unwrap() + 0.5).abs() < 1e-6);
        assert_eq!(v.common_ours.cells, 8 * 24);
        assert_eq!(v.common_other.cells, 8 * 24);
        assert!(v.common_ours.mae.unwrap() < 1e-6);
        assert!((v.common_other.mae.unwrap() - 2.0).abs() < 1e-6);
        assert_eq!(v.only_ours.cells, 8 * 24);
        assert_eq!(v.only_other.cells, 8 * 24);
        assert!((v.only_other.mae.unwrap() - 2.0).abs() < 1e-6);
        assert_eq!(v.neither, 0);
        // Within 1 m: ours on its 2/3 of the grid, the other nowhere; within 2 m both.
        assert!((v.ours.within_1m.unwrap() - 2.0 / 3.0).abs() < 1e-9);
        assert_eq!(v.other.within_1m, Some(0.0));
        assert!((v.other.within_2m.unwrap() - 2.0 / 3.0).abs() < 1e-9);
    }

    #[test]
    fn masked_cells_count_nowhere_and_a_dsm_against_itself_has_nothing_of_its_own() {
        let gt = truth();
        let mut ex = Exclusions::none(24, 24);
        for y in 0..4 {
            for x in 0..24 {
                ex.foliage.set(x, y, true);
            }
        }
        let ours = Image::from_fn(24, 24, |x, y| {
            if y < 20 {
                gt.get(x, y, 0) + 0.3 * ((x * 7 + y * 3) % 5) as f32
            } else {
                f32::NAN
            }
        });
        let v = score_versus(&ours, &ours, &gt, &ex, &ScoreParams::default()).unwrap();
        assert_eq!(v.common_ours, v.common_other);
        assert_eq!(v.common_ours.mae, v.ours.mae_filtered);
        assert_eq!(v.common_ours.cells, 16 * 24);
        assert_eq!(v.only_ours.cells, 0);
        assert_eq!(v.only_ours.mae, None);
        assert_eq!(v.only_other.cells, 0);
        assert_eq!(v.neither, 4 * 24);
    }

    #[test]
    fn an_empty_dsm_covers_nothing_and_misses_every_cell() {
        let gt = truth();
        let ex = Exclusions::none(24, 24);
        let empty = Image::filled(24, 24, 1, f32::NAN);
        let v = score_versus(&empty, &gt, &gt, &ex, &ScoreParams::default()).unwrap();
        assert_eq!(v.ours.within_1m, Some(0.0));
        assert_eq!(v.other.within_1m, Some(1.0));
        assert_eq!(v.common_ours.cells, 0);
        assert_eq!(v.only_other.cells, 24 * 24);
        assert_eq!(v.only_other.mae, Some(0.0));
    }
}
