//! Altitude scores of a predicted DSM against the ground-truth DSM on the same grid: registration
//! ([`super::align`]), then mean absolute errors over all cells, without water, and without water
//! and foliage (`mae_filtered`, the benchmark's headline number).

use raster::{Image, Mask};
use serde::Serialize;

use super::align::{align, apply, AlignParams};

/// DFC2019 class of foliage (high vegetation) in `_CLS.tif`.
pub const CLS_FOLIAGE: u8 = 5;
/// DFC2019 class of water in `_CLS.tif`.
pub const CLS_WATER: u8 = 9;

/// Cells excluded from the filtered scores, on the ground-truth grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Exclusions {
    /// Water: class 9 of `_CLS.tif`, or the `_WATER.png` mask.
    pub water: Mask,
    /// Foliage: class 5 of `_CLS.tif`.
    pub foliage: Mask,
}

impl Exclusions {
    /// Nothing excluded.
    pub fn none(width: usize, height: usize) -> Self {
        Exclusions {
            water: Mask::filled(width, height, false),
            foliage: Mask::filled(width, height, false),
        }
    }

    /// From a DFC class raster (`_CLS.tif`) and an optional water mask (true = water).
    pub fn from_classes(classes: &Image, water: Option<&Mask>) -> Self {
        let (w, h) = classes.size();
        let is = |c: u8| {
            Mask::from_fn(w, h, |x, y| {
                let v = classes.get(x, y, 0);
                v.is_finite() && v.round() == c as f32
            })
        };
        let mut water_mask = is(CLS_WATER);
        if let Some(m) = water {
            assert_eq!(m.size(), (w, h), "water mask on another grid");
            for (a, &b) in water_mask.data_mut().iter_mut().zip(m.data()) {
                *a |= b;
            }
        }
        Exclusions {
            water: water_mask,
            foliage: is(CLS_FOLIAGE),
        }
    }
}

/// Scores of one predicted DSM. MAEs are `None` when no cell was scored (never NaN).
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DsmScores {
    /// Mean |gt − aligned| over every cell finite in both, metres.
    pub mae_raw: Option<f64>,
    /// The same without water cells.
    pub mae_no_water: Option<f64>,
    /// The same without water and foliage cells: the benchmark's number.
    pub mae_filtered: Option<f64>,
    /// Share of the ground truth's finite cells with an aligned prediction (`None` when the ground
    /// truth has no finite cell).
    pub coverage: Option<f64>,
    /// Registration: shift applied to the prediction (cells) and vertical offset (metres).
    pub dx: i32,
    pub dy: i32,
    pub offset: Option<f64>,
    /// Cells of the filtered MAE.
    pub cells: usize,
}

impl DsmScores {
    /// True when the prediction and the ground truth had no finite cell in common.
    pub fn no_overlap(&self) -> bool {
        self.mae_raw.is_none()
    }
}

/// Aligns `pred` to `gt` and scores it. Both are single-channel rasters on the same grid (NaN =
/// no data); `exclusions` are on that grid too.
pub fn score_dsm(
    pred: &Image,
    gt: &Image,
    exclusions: &Exclusions,
    params: &AlignParams,
) -> Result<DsmScores, raster::RasterError> {
    pred.check_same_size(gt, "predicted and ground-truth DSM")?;
    gt.check_mask(&exclusions.water, "ground-truth DSM and water mask")?;
    gt.check_mask(&exclusions.foliage, "ground-truth DSM and foliage mask")?;
    let gt = gt.channel(0);
    let gt_cells = gt.data().iter().filter(|v| v.is_finite()).count();
    let Some(a) = align(&gt, pred, params) else {
        return Ok(DsmScores {
            mae_raw: None,
            mae_no_water: None,
            mae_filtered: None,
            coverage: (gt_cells > 0).then_some(0.0),
            dx: 0,
            dy: 0,
            offset: None,
            cells: 0,
        });
    };
    let aligned = apply(pred, a.dx, a.dy, a.offset);
    let mut sums = [(0.0f64, 0usize); 3];
    let mut covered = 0usize;
    for (i, (&g, &p)) in gt.data().iter().zip(aligned.data()).enumerate() {
        if !g.is_finite() || !p.is_finite() {
            continue;
        }
        covered += 1;
        let e = (g as f64 - p as f64).abs();
        let water = exclusions.water.data()[i];
        let foliage = exclusions.foliage.data()[i];
        sums[0].0 += e;
        sums[0].1 += 1;
        if !water {
            sums[1].0 += e;
            sums[1].1 += 1;
            if !foliage {
                sums[2].0 += e;
                sums[2].1 += 1;
            }
        }
    }
    let mean = |(s, n): (f64, usize)| (n > 0).then(|| s / n as f64);
    Ok(DsmScores {
        mae_raw: mean(sums[0]),
        mae_no_water: mean(sums[1]),
        mae_filtered: mean(sums[2]),
        coverage: (gt_cells > 0).then(|| covered as f64 / gt_cells as f64),
        dx: a.dx,
        dy: a.dy,
        offset: Some(a.offset),
        cells: sums[2].1,
    })
}
