//! Altitude scores of a predicted DSM against the ground-truth DSM on the same grid: mean absolute
//! errors over all cells (`mae`), without water (`mae_no_water`), and without water and foliage
//! (`mae_filtered`, the benchmark's headline number), each after a registration ([`super::align`]).
//!
//! The released evaluator (`utils/misc.py` `align_dsm_with_gt`, called once per score) masks the
//! ground truth FIRST (water, or water and foliage, set to NaN) and registers the prediction on
//! that masked truth: each score has its own shift and offset ([`Registration::PerScore`], the
//! default). [`Registration::Shared`] registers once on the whole truth and masks afterwards.

use raster::{Image, Mask};
use serde::Serialize;

use super::align::{align, apply, AlignParams, Alignment};

/// DFC2019 class of foliage (high vegetation) in `_CLS.tif`.
pub const CLS_FOLIAGE: u8 = 5;
/// DFC2019 class of water in `_CLS.tif`.
pub const CLS_WATER: u8 = 9;

/// Cells excluded from the filtered scores, on the ground-truth grid.
#[derive(Clone, Debug, PartialEq)]
pub struct Exclusions {
    /// Water: class 9 of `_CLS.tif`, or the water of the `_WATER.png` mask.
    pub water: Mask,
    /// Foliage: class 5 of `_CLS.tif`.
    pub foliage: Mask,
}

/// The class of a `_CLS.tif` value as the release reads it: `np.nan_to_num(v, nan=9999)` then
/// `.astype(np.uint8)` (truncation, then wrapping modulo 256).
pub fn class_code(v: f32) -> u8 {
    let c = if v.is_nan() {
        9999
    } else if v.is_infinite() {
        0
    } else {
        v.trunc() as i64
    };
    c.rem_euclid(256) as u8
}

impl Exclusions {
    /// Nothing excluded.
    pub fn none(width: usize, height: usize) -> Self {
        Exclusions {
            water: Mask::filled(width, height, false),
            foliage: Mask::filled(width, height, false),
        }
    }

    /// From a DFC class raster (`_CLS.tif`, read as [`class_code`]) and an optional water mask
    /// (true = water, e.g. [`water_from_png`]).
    pub fn from_classes(classes: &Image, water: Option<&Mask>) -> Self {
        let (w, h) = classes.size();
        let is = |c: u8| Mask::from_fn(w, h, |x, y| class_code(classes.get(x, y, 0)) == c);
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

/// The water of a `_WATER.png` as the release reads it (`misc.py`: `gt[water == 0] = nan`): ZERO
/// is water, any other value land. The first channel is read.
pub fn water_from_png(png: &Image) -> Mask {
    let (w, h) = png.size();
    Mask::from_fn(w, h, |x, y| png.get(x, y, 0) == 0.0)
}

/// Where each score's registration comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Registration {
    /// Each score registers on its own masked truth (the released evaluator).
    #[default]
    PerScore,
    /// One registration on the unmasked truth for all three scores.
    Shared,
}

/// How a DSM is scored.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ScoreParams {
    pub align: AlignParams,
    pub registration: Registration,
}

/// One score: its MAE and the registration it was measured after.
#[derive(Clone, Copy, Debug, PartialEq, Serialize)]
pub struct Score {
    /// Mean |gt − aligned| over the cells finite in both (after masking), metres; `None` when
    /// there is no such cell (never NaN).
    pub mae: Option<f64>,
    /// Shift applied to the prediction (cells, see [`super::align`]) and vertical offset
    /// (metres); `None` when the prediction and the (masked) truth share no cell.
    pub dx: Option<i32>,
    pub dy: Option<i32>,
    pub offset: Option<f64>,
    /// Cells of the MAE.
    pub cells: usize,
}

impl Score {
    fn empty() -> Score {
        Score {
            mae: None,
            dx: None,
            dy: None,
            offset: None,
            cells: 0,
        }
    }
}

/// Scores of one predicted DSM: the three MAEs with the headline's registration (flat fields),
/// and each score with its own registration.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct DsmScores {
    /// [`DsmScores::raw`]'s MAE.
    pub mae_raw: Option<f64>,
    /// [`DsmScores::no_water`]'s MAE.
    pub mae_no_water: Option<f64>,
    /// [`DsmScores::filtered`]'s MAE: the benchmark's number.
    pub mae_filtered: Option<f64>,
    /// Share of the ground truth's finite cells with an aligned prediction, after the raw
    /// score's registration (`None` when the ground truth has no finite cell). The release does
    /// not compute it.
    pub coverage: Option<f64>,
    /// Share of the ground truth's finite cells outside water and foliage whose height after
    /// `mae_filtered`'s registration is within 1 m of the truth; a cell without a prediction
    /// counts as a miss, so the figure rewards coverage and accuracy at once (`None` when no
    /// such truth cell exists). The release does not compute it.
    pub within_1m: Option<f64>,
    /// The same within 2 m.
    pub within_2m: Option<f64>,
    /// The registration of `mae_filtered` (0, 0 and `None` without overlap).
    pub dx: i32,
    pub dy: i32,
    pub offset: Option<f64>,
    /// Cells of `mae_filtered`.
    pub cells: usize,
    /// Every cell (nothing masked).
    pub raw: Score,
    /// Water masked.
    pub no_water: Score,
    /// Water and foliage masked.
    pub filtered: Score,
}

impl DsmScores {
    /// True when the prediction and the ground truth had no finite cell in common.
    pub fn no_overlap(&self) -> bool {
        self.mae_raw.is_none()
    }
}

/// `gt` with the cells of `masks` set to NaN.
fn masked(gt: &Image, masks: &[&Mask]) -> Image {
    let mut out = gt.clone();
    for (i, v) in out.data_mut().iter_mut().enumerate() {
        if masks.iter().any(|m| m.data()[i]) {
            *v = f32::NAN;
        }
    }
    out
}

/// MAE of `aligned` against `gt` over the cells finite in both: (mean, cells). The release
/// differences the float32 rasters; the sum is in float64.
fn mae(gt: &Image, aligned: &Image) -> (Option<f64>, usize) {
    let (mut s, mut n) = (0.0f64, 0usize);
    for (&g, &p) in gt.data().iter().zip(aligned.data()) {
        if g.is_finite() && p.is_finite() {
            s += (g - p).abs() as f64;
            n += 1;
        }
    }
    ((n > 0).then(|| s / n as f64), n)
}

/// Registers `pred` on `truth` (or takes `shared`) and measures the MAE against `truth`.
fn score_one(
    pred: &Image,
    truth: &Image,
    shared: Option<Option<Alignment>>,
    params: &AlignParams,
) -> (Score, Option<Image>) {
    let a = shared.unwrap_or_else(|| align(truth, pred, params));
    let Some(a) = a else {
        return (Score::empty(), None);
    };
    let aligned = apply(pred, a.dx, a.dy, a.offset);
    let (m, cells) = mae(truth, &aligned);
    (
        Score {
            mae: m,
            dx: Some(a.dx),
            dy: Some(a.dy),
            offset: Some(a.offset),
            cells,
        },
        Some(aligned),
    )
}

/// Share of the finite cells of `gt` where `aligned` is within `tolerance` metres (a NaN
/// prediction is a miss); `None` when `gt` has no finite cell.
fn within(gt: &Image, aligned: Option<&Image>, tolerance: f32) -> Option<f64> {
    let total = gt.data().iter().filter(|g| g.is_finite()).count();
    let hits = aligned.map_or(0, |al| {
        gt.data()
            .iter()
            .zip(al.data())
            .filter(|(g, p)| g.is_finite() && (**g - **p).abs() <= tolerance)
            .count()
    });
    (total > 0).then(|| hits as f64 / total as f64)
}

/// Scores `pred` against `gt`. Both are single-channel rasters on the same grid (NaN = no data);
/// `exclusions` are on that grid too.
pub fn score_dsm(
    pred: &Image,
    gt: &Image,
    exclusions: &Exclusions,
    params: &ScoreParams,
) -> Result<DsmScores, raster::RasterError> {
    Ok(score_dsm_registered(pred, gt, exclusions, params)?.scores)
}

/// A DSM scored, with what the filtered score compared: the truth with water and foliage
/// masked, and the prediction after the filtered score's registration (`None` without overlap).
#[derive(Clone, Debug)]
pub struct Registered {
    pub scores: DsmScores,
    pub truth_filtered: Image,
    pub aligned: Option<Image>,
}

/// [`score_dsm`], keeping the registered prediction (for comparisons cell by cell).
pub fn score_dsm_registered(
    pred: &Image,
    gt: &Image,
    exclusions: &Exclusions,
    params: &ScoreParams,
) -> Result<Registered, raster::RasterError> {
    pred.check_same_size(gt, "predicted and ground-truth DSM")?;
    gt.check_mask(&exclusions.water, "ground-truth DSM and water mask")?;
    gt.check_mask(&exclusions.foliage, "ground-truth DSM and foliage mask")?;
    let gt = gt.channel(0);
    let pred = pred.channel(0);
    let gt_cells = gt.data().iter().filter(|v| v.is_finite()).count();
    let no_water = masked(&gt, &[&exclusions.water]);
    let filtered = masked(&gt, &[&exclusions.water, &exclusions.foliage]);
    let a = &params.align;
    let (raw, aligned) = score_one(&pred, &gt, None, a);
    let shared = match params.registration {
        Registration::PerScore => None,
        Registration::Shared => Some(raw.dx.map(|dx| Alignment {
            dx,
            dy: raw.dy.expect("set with dx"),
            offset: raw.offset.expect("set with dx"),
            ncc: None,
            overlap: 0,
        })),
    };
    let (no_water, _) = score_one(&pred, &no_water, shared, a);
    let (filtered_score, filtered_aligned) = score_one(&pred, &filtered, shared, a);
    let covered = aligned.map_or(0, |al| {
        gt.data()
            .iter()
            .zip(al.data())
            .filter(|(g, p)| g.is_finite() && p.is_finite())
            .count()
    });
    let scores = DsmScores {
        mae_raw: raw.mae,
        mae_no_water: no_water.mae,
        mae_filtered: filtered_score.mae,
        coverage: (gt_cells > 0).then(|| covered as f64 / gt_cells as f64),
        within_1m: within(&filtered, filtered_aligned.as_ref(), 1.0),
        within_2m: within(&filtered, filtered_aligned.as_ref(), 2.0),
        dx: filtered_score.dx.unwrap_or(0),
        dy: filtered_score.dy.unwrap_or(0),
        offset: filtered_score.offset,
        cells: filtered_score.cells,
        raw,
        no_water,
        filtered: filtered_score,
    };
    Ok(Registered {
        scores,
        truth_filtered: filtered,
        aligned: filtered_aligned,
    })
}
