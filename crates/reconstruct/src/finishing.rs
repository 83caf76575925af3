//! How gridded cells become a DSM: the gridding of a cell's points, the filling of the holes
//! enclosed by data and the median filter. One type for every command that writes a DSM
//! (`dsm`, `reconstruct`, `reconstruct-many` and its pairs, the tiles' merge), so that each
//! option is declared, defaulted and recorded once.

use anyhow::{bail, Result};
use camera::{Gridding, HoleFill};
use raster::Image;
use serde_json::{json, Value};

/// `reconstruct`'s hole filling distance, cells; the masks' heights fill their DSMs alike.
pub const DEFAULT_FILL_CELLS: usize = 40;
/// How far from a measured cell `reconstruct` invents heights, cells (8 m at 0.5 m): on the 45
/// dev pairs the cells beyond were mostly far off, and leaving them empty lowered the MAE in
/// nearly every bin of date gap and baseline at no loss of cells within 1 m (BENCHMARKS.md, "The
/// filling stops 16 cells from the data").
pub const DEFAULT_FILL_REACH: usize = 16;
/// `reconstruct`'s median window after filling, cells (odd; 7.5 m at 0.5 m): one pair's DSM
/// carries matching noise of a pixel of disparity and more, and on the 45 dev pairs a 15-cell
/// window beat 7 and 11 in every bin of date gap and baseline (BENCHMARKS.md, "The DSM's median
/// window: 15 cells, not 7").
pub const DEFAULT_MEDIAN_CELLS: usize = 15;
/// The median window of DSMs made from several pairs at once (`reconstruct-many`'s fused DSM,
/// the masks' heights), cells: the pairs already average the matching noise, and a wider window
/// only erodes structures (the fused dev DSM is worse with 15 cells than with 7: BENCHMARKS.md,
/// "The DSM's median window: 15 cells, not 7").
pub const FUSED_MEDIAN_CELLS: usize = 7;

/// The post-processing of a gridded DSM: hole filling ([`camera::fill_holes`]), then a
/// NaN-aware median filter over an odd `median_filter` window.
pub fn finish_dsm(
    mut dsm: Image,
    fill: Option<HoleFill>,
    median_filter: Option<usize>,
) -> Result<Image> {
    if let Some(fill) = fill {
        dsm = camera::fill_holes(&dsm, fill).0;
    }
    if let Some(window) = median_filter {
        if window % 2 == 0 {
            bail!("the DSM median filter needs an odd window, got {window} cells");
        }
        dsm = camera::median_filter(&dsm, window);
    }
    Ok(dsm)
}

/// The finishing of a DSM.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Finishing {
    /// Height of a cell from its points: the median (robust), or the highest (the benchmark's
    /// protocol).
    pub gridding: Gridding,
    /// Fill the holes enclosed by data ([`camera::fill_holes`]); `None`: leave them empty.
    pub fill_holes: Option<HoleFill>,
    /// NaN-aware median filter over this odd window of cells, after the filling; `None`: none.
    pub median_filter: Option<usize>,
}

impl Default for Finishing {
    /// What a single pair's DSM gets by default: median gridding, filling along rays of
    /// [`DEFAULT_FILL_CELLS`] up to [`DEFAULT_FILL_REACH`] cells from the data, a
    /// [`DEFAULT_MEDIAN_CELLS`] median.
    fn default() -> Self {
        Finishing::new(
            Gridding::Median,
            Some(DEFAULT_FILL_CELLS),
            Some(DEFAULT_FILL_REACH),
            Some(DEFAULT_MEDIAN_CELLS),
        )
    }
}

impl Finishing {
    /// Filling along rays of `fill_holes` cells (`None`: no filling) up to `fill_reach` cells
    /// from the data (capped at the rays' length; `None`: as far as the rays reach), then a
    /// `median_filter`.
    pub fn new(
        gridding: Gridding,
        fill_holes: Option<usize>,
        fill_reach: Option<usize>,
        median_filter: Option<usize>,
    ) -> Self {
        let fill_holes = fill_holes.map(|span| match fill_reach {
            Some(reach) => HoleFill {
                span,
                reach: reach.min(span),
            },
            None => HoleFill::spanning(span),
        });
        Finishing {
            gridding,
            fill_holes,
            median_filter,
        }
    }

    /// The filling and the median filter applied to a gridded DSM.
    pub fn finish(&self, dsm: Image) -> Result<Image> {
        finish_dsm(dsm, self.fill_holes, self.median_filter)
    }

    /// Rows above and below a cell that its finished height depends on: the filling's rays walk
    /// `span` cells (the diagonals as many rows), and the median reads `window / 2` rows of
    /// filled cells.
    pub fn halo(&self) -> usize {
        let fill = self.fill_holes.map_or(0, |f| f.span);
        fill.saturating_add(self.median_filter.map_or(0, |w| w / 2))
    }

    /// The filling and the median as a run record keeps them (a resumed run with other values
    /// rewrites the DSM only with `--overwrite`).
    pub fn record(&self) -> Value {
        json!({
            "fill_holes": self.fill_holes.map(|f| f.span),
            "fill_reach": self.fill_holes.map(|f| f.reach),
            "median_filter": self.median_filter,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The rays and the reach become the filling's, the reach never past the rays (a cell's
    /// nearest ray end is within them anyway), and no filling stays none.
    #[test]
    fn the_filling_stays_within_its_reach() {
        let fill = |reach| Finishing::new(Gridding::Median, Some(40), reach, None).fill_holes;
        assert_eq!(
            Finishing::default().fill_holes,
            Some(HoleFill {
                span: DEFAULT_FILL_CELLS,
                reach: DEFAULT_FILL_REACH
            })
        );
        assert_eq!(
            fill(Some(16)),
            Some(HoleFill {
                span: 40,
                reach: 16
            })
        );
        assert_eq!(fill(Some(1000)), Some(HoleFill::spanning(40)));
        assert_eq!(fill(None), Some(HoleFill::spanning(40)));
        assert_eq!(
            Finishing::new(Gridding::Max, None, Some(16), None).fill_holes,
            None
        );
        assert_eq!(
            Finishing::default().halo(),
            DEFAULT_FILL_CELLS + DEFAULT_MEDIAN_CELLS / 2
        );
    }
}
