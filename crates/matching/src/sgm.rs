//! The public matcher: parameters, memory accounting and the pipeline
//! grey → census → cost volume → aggregation → selection → median.

use crate::aggregate::{aggregate, Dims, Penalties, Progress};
use crate::census::{census_transform, CensusWindow};
use crate::cost::build_cost_volume;
use crate::error::MatchError;
use crate::mgm::aggregate_mgm;
use crate::select::{median3x3, select, Selection, Subpixel};
use crate::speckle::{remove_speckles, Speckle};
use raster::Image;
use rayon::prelude::*;
use std::collections::TryReserveError;

/// Which aggregation paths SGM uses.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Paths {
    /// Horizontal and vertical, both senses: faster, more streaking.
    Four,
    /// Horizontal, vertical and both diagonals, both senses (Hirschmüller's default).
    #[default]
    Eight,
}

impl Paths {
    fn count(self) -> usize {
        match self {
            Paths::Four => 4,
            Paths::Eight => 8,
        }
    }
}

/// How the cost volume is aggregated.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Aggregation {
    /// Semi-Global Matching: straight paths ([`SgmParams::paths`]).
    Sgm,
    /// More Global Matching (Facciolo et al. 2015): 8 directions, each averaging two
    /// predecessors; smoother and with fewer wrong islands on real satellite pairs, about twice
    /// SGM's time (half of it single-threaded). [`SgmParams::paths`] is ignored.
    #[default]
    Mgm,
}

/// The disparities tested, `(d_min, d_max)` **inclusive** (`d_max − d_min + 1` of them; `d_min`
/// may be negative). It belongs to the pair (its cameras and altitudes), not to the matcher, so it
/// is an argument of [`match_pair`] beside the parameters.
pub type DisparityRange = (i32, i32);

/// Number of disparities of `range`, `None` when it is empty.
pub fn disparity_count((d_min, d_max): DisparityRange) -> Option<usize> {
    let n = i64::from(d_max) - i64::from(d_min) + 1;
    (n > 0).then_some(n as usize)
}

/// Parameters of [`match_pair`] (the range is not one of them: see [`DisparityRange`]).
#[derive(Clone, Debug, PartialEq)]
pub struct SgmParams {
    /// Penalty of a ±1 disparity change between neighbours, in census bits.
    pub p1: u16,
    /// Penalty of a larger jump, in census bits (`P1 < P2 ≤ 4000`).
    pub p2: u16,
    /// Gradient adaptation of `P2`: `Some(k)` uses `P2' = max(P1 + 1, P2 / (1 + |ΔI| / k))` where
    /// `ΔI` is the grey difference between the pixel and its predecessor on the path, in units of
    /// the left image's robust range (1st–99th percentile), so it does not depend on the value
    /// range of the input. Disparity jumps become cheap across intensity edges (building
    /// outlines). `None`: constant `P2`.
    pub p2_adaptive: Option<f32>,
    /// Census window.
    pub census: CensusWindow,
    /// SGM or MGM aggregation.
    pub aggregation: Aggregation,
    /// Aggregation paths of SGM.
    pub paths: Paths,
    /// Left–right consistency: a disparity is kept when the right view's winner at `x − d`
    /// agrees within this many pixels. `None`: no check.
    pub lr_tolerance: Option<f32>,
    /// Uniqueness ratio `u`: the best aggregated cost must be below `(1 − u)` times the best cost
    /// more than one disparity away. `None`: no test.
    pub uniqueness: Option<f32>,
    /// Sub-pixel refinement: equiangular (symmetric V) fit on the aggregated costs of the
    /// winner and its two neighbours; it suits census costs (V-shaped, not quadratic) and is
    /// less biased towards integers than a parabola.
    pub subpixel: bool,
    /// NaN-aware 3×3 median of the result.
    pub median: bool,
    /// Speckle removal after the median: connected regions of disparity smaller than
    /// `min_area` pixels are cleared. `None`: keep them.
    pub speckle: Option<Speckle>,
    /// Refuse to match (with [`MatchError::TooLarge`]) when [`memory_bytes`] exceeds this.
    pub max_memory: Option<usize>,
}

impl Default for SgmParams {
    /// Chosen on real WorldView-3 pairs (the DFC2019 JAX_068 development set, near-synchronic and
    /// winter↔summer; ablation in BENCHMARKS.md) while keeping the procedural world's accuracy:
    /// MGM, 5×5 census, `P1 = 16`, `P2 = 300` adapted to the gradient (`k = 0.02`: a jump costs
    /// `P2 / 3` across an edge of 4 % of the image's range, `P1 + 1` across strong edges),
    /// left–right tolerance 1 px, uniqueness 0.02, equiangular sub-pixel fit, median, speckle
    /// regions under 200 px removed (1 px tolerance).
    fn default() -> Self {
        Self {
            p1: 16,
            p2: 300,
            p2_adaptive: Some(0.02),
            census: CensusWindow::default(),
            aggregation: Aggregation::Mgm,
            paths: Paths::Eight,
            lr_tolerance: Some(1.0),
            uniqueness: Some(0.02),
            subpixel: true,
            median: true,
            speckle: Some(Speckle {
                min_area: 200,
                max_diff: 1.0,
            }),
            max_memory: None,
        }
    }
}

impl SgmParams {
    /// The parameters in words, for reports and records.
    pub fn describe(&self) -> String {
        let p = self;
        let aggregation = match p.aggregation {
            Aggregation::Mgm => "MGM (8 directions, two predecessors each)".to_string(),
            Aggregation::Sgm => format!(
                "SGM ({} paths)",
                match p.paths {
                    Paths::Four => 4,
                    Paths::Eight => 8,
                }
            ),
        };
        let p2 = match p.p2_adaptive {
            Some(k) => format!("P2 {} adapted to the image gradient (k = {k})", p.p2),
            None => format!("P2 {} (constant)", p.p2),
        };
        let lr = match p.lr_tolerance {
            Some(t) => format!("left–right check within {t} px"),
            None => "no left–right check".into(),
        };
        let uniqueness = match p.uniqueness {
            Some(u) => format!("uniqueness ratio {u}"),
            None => "no uniqueness test".into(),
        };
        let speckle = match &p.speckle {
            Some(s) => format!(
                "regions under {} px removed (tolerance {} px)",
                s.min_area, s.max_diff
            ),
            None => "no speckle filter".into(),
        };
        let on_off = |b: bool| if b { "on" } else { "off" };
        format!(
            "census {}×{} + {aggregation}; P1 {}, {p2}; {lr}; {uniqueness}; equiangular sub-pixel fit {}; \
             3×3 median {}; {speckle}.",
            p.census.width,
            p.census.height,
            p.p1,
            on_off(p.subpixel),
            on_off(p.median),
        )
    }

    /// Checks the parameters and `range`; returns the number of disparities.
    fn validate(&self, range: DisparityRange) -> Result<usize, MatchError> {
        let n = disparity_count(range).ok_or(MatchError::EmptyRange {
            d_min: range.0,
            d_max: range.1,
        })?;
        if n > usize::from(u16::MAX) {
            return Err(MatchError::InvalidParams(format!(
                "at most 65535 disparities, got {n}"
            )));
        }
        self.check()?;
        Ok(n)
    }

    /// Checks the parameters (what [`match_pair`] would refuse, the range aside), so a bad
    /// setting fails before any pair is read.
    pub fn check(&self) -> Result<(), MatchError> {
        if !self.census.is_valid() {
            return Err(MatchError::InvalidParams(format!(
                "census window {}x{} must have odd sides and at most 64 bits",
                self.census.width, self.census.height
            )));
        }
        if self.p1 == 0 || self.p2 <= self.p1 || self.p2 > 4000 {
            return Err(MatchError::InvalidParams(format!(
                "penalties need 0 < P1 < P2 <= 4000 (got P1 = {}, P2 = {})",
                self.p1, self.p2
            )));
        }
        if let Some(k) = self.p2_adaptive {
            if !(k > 0.0 && k.is_finite()) {
                return Err(MatchError::InvalidParams(format!(
                    "P2 adaptation constant must be positive, got {k}"
                )));
            }
        }
        if let Some(t) = self.lr_tolerance {
            if t.is_nan() || t < 0.0 {
                return Err(MatchError::InvalidParams(format!(
                    "left-right tolerance must be >= 0, got {t}"
                )));
            }
        }
        if let Some(sp) = &self.speckle {
            sp.validate().map_err(MatchError::InvalidParams)?;
        }
        if let Some(u) = self.uniqueness {
            if !(0.0..1.0).contains(&u) {
                return Err(MatchError::InvalidParams(format!(
                    "uniqueness ratio must be in [0, 1), got {u}"
                )));
            }
        }
        Ok(())
    }
}

/// Peak bytes [`match_pair`] allocates for a `width × height` pair and `n_disp` disparities: the
/// cost volume (`u8`) and the aggregated volume (`u16`), i.e. **3 bytes per pixel per
/// disparity**, plus 32 bytes per pixel (grey images, census codes and validity, the normalised
/// grey of the adaptive `P2`) and the two vertical-sweep line buffers (`2 · 3 · width ·
/// (n_disp + 2)` `u16`). The input images and the returned map are not counted.
pub fn memory_bytes(width: usize, height: usize, n_disp: usize) -> usize {
    let px = width.saturating_mul(height);
    let volume = px.saturating_mul(n_disp).saturating_mul(3);
    let per_pixel = px.saturating_mul(32);
    let lines = width.saturating_mul(n_disp + 2).saturating_mul(2 * 3 * 2);
    volume.saturating_add(per_pixel).saturating_add(lines)
}

/// Disparity map of the left view of a rectified pair (single channel, NaN where invalid).
///
/// Images of any channel count are converted to grey ([`Image::to_gray`]); they must have the same
/// size. NaN input pixels are invalid: the output is NaN there (and where the match lands on a NaN
/// right pixel).
pub fn match_pair(
    left: &Image,
    right: &Image,
    range: DisparityRange,
    params: &SgmParams,
) -> Result<Image, MatchError> {
    match_pair_with_progress(left, right, range, params, None)
}

/// [`match_pair`] with a progress callback, called as `(done, total)` from any thread (about
/// `5 · height` steps in all).
pub fn match_pair_with_progress(
    left: &Image,
    right: &Image,
    range: DisparityRange,
    params: &SgmParams,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<Image, MatchError> {
    Ok(match_pair_with_confidence(left, right, range, params, progress)?.0)
}

/// [`match_pair_with_progress`] and the confidence of each disparity: `1 − S₁ / S₂`, the margin
/// of the winner's aggregated cost `S₁` over the best cost `S₂` more than one disparity away
/// (in `[0, 1]`; NaN where the disparity is NaN; after the median, the confidence of the
/// pixel's own winner). Low at occlusions, in weak or repetitive texture and where the
/// aggregation smoothed a disparity edge.
pub fn match_pair_with_confidence(
    left: &Image,
    right: &Image,
    range: DisparityRange,
    params: &SgmParams,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<(Image, Image), MatchError> {
    let (w, h) = check_pair(left, right)?;
    let lg = left.to_gray();
    let rg = right.to_gray();
    let (disp, conf) = match_grey(lg.data(), rg.data(), (w, h), range, params, progress)?;
    Ok((
        Image::new(w, h, 1, disp).expect("sizes match"),
        Image::new(w, h, 1, conf).expect("sizes match"),
    ))
}

/// The common size of a pair, or the error saying why it cannot be matched.
pub(crate) fn check_pair(left: &Image, right: &Image) -> Result<(usize, usize), MatchError> {
    if left.size() != right.size() {
        return Err(MatchError::SizeMismatch {
            left: left.size(),
            right: right.size(),
        });
    }
    let (w, h) = left.size();
    if w == 0 || h == 0 {
        return Err(MatchError::EmptyImage(w, h));
    }
    Ok((w, h))
}

/// The whole pipeline on grey, row-major buffers of `w × h`: the disparities and their
/// confidences.
pub(crate) fn match_grey(
    lg: &[f32],
    rg: &[f32],
    (w, h): (usize, usize),
    range: DisparityRange,
    params: &SgmParams,
    progress: Option<&(dyn Fn(usize, usize) + Sync)>,
) -> Result<(Vec<f32>, Vec<f32>), MatchError> {
    let n = params.validate(range)?;
    let (mut cost, mut sum) = allocate_volumes(w, h, n, params)?;
    let steps = 4 * h + if params.median { h } else { 0 };
    let progress = Progress::new(steps, progress);
    let tick = || progress.tick();
    let dims = Dims {
        width: w,
        height: h,
        n_disp: n,
    };

    let (left_valid, right_valid) = census_costs(lg, rg, dims, range, params, &mut cost);
    let adaptation = params.p2_adaptive.map(|k| (normalised(lg), k));
    let pen = Penalties {
        p1: params.p1,
        p2: params.p2,
        adapt: adaptation.as_ref().map(|(grey, k)| (&grey[..], *k)),
    };
    aggregate_costs(&cost, &mut sum, dims, &pen, params, &tick);
    drop(cost);

    let (mut disp, mut conf) = select(
        &sum,
        dims,
        &left_valid,
        &right_valid,
        &selection(range, params),
        &tick,
    );
    drop(sum);
    if params.median {
        disp = median3x3(&disp, w, h);
        for _ in 0..h {
            tick();
        }
    }
    if let Some(sp) = &params.speckle {
        remove_speckles(&mut disp, w, h, sp);
    }
    clear_off_image(&mut disp, w, &right_valid);
    for (c, d) in conf.iter_mut().zip(&disp) {
        if d.is_nan() {
            *c = f32::NAN;
        }
    }
    Ok((disp, conf))
}

/// Both volumes (census costs and aggregated costs) up front, so that an impossible request fails
/// before any work: over `max_memory`, over the address space, or refused by the allocator.
fn allocate_volumes(
    w: usize,
    h: usize,
    n: usize,
    params: &SgmParams,
) -> Result<(Vec<u8>, Vec<u16>), MatchError> {
    let needed = memory_bytes(w, h, n);
    if let Some(limit) = params.max_memory {
        if needed > limit {
            return Err(MatchError::TooLarge { needed, limit });
        }
    }
    let vol_len = w
        .checked_mul(h)
        .and_then(|v| v.checked_mul(n))
        .ok_or(MatchError::TooLarge {
            needed,
            limit: isize::MAX as usize,
        })?;
    let too_large = |_| MatchError::OutOfMemory { needed };
    let cost: Vec<u8> = zeroed(vol_len).map_err(too_large)?;
    let sum: Vec<u16> = zeroed(vol_len).map_err(too_large)?;
    Ok((cost, sum))
}

/// Census transforms of both views and their Hamming distances into `cost`; returns the
/// validity of the left and right pixels (the census codes are dropped at once: they are the
/// largest buffers after the volumes).
fn census_costs(
    lg: &[f32],
    rg: &[f32],
    dims: Dims,
    range: DisparityRange,
    params: &SgmParams,
    cost: &mut [u8],
) -> (Vec<bool>, Vec<bool>) {
    let (w, h) = (dims.width, dims.height);
    let lc = census_transform(lg, w, h, params.census);
    let rc = census_transform(rg, w, h, params.census);
    let invalid_cost = (params.census.bits() / 2) as u8;
    build_cost_volume(&lc, &rc, range.0, dims.n_disp, invalid_cost, cost);
    (lc.valid, rc.valid)
}

/// Aggregates `cost` into `sum` with the configured method (MGM, or SGM over 4 or 8 paths).
fn aggregate_costs(
    cost: &[u8],
    sum: &mut [u16],
    dims: Dims,
    pen: &Penalties,
    params: &SgmParams,
    tick: &(dyn Fn() + Sync),
) {
    match params.aggregation {
        Aggregation::Sgm => aggregate(cost, sum, dims, pen, params.paths == Paths::Eight, tick),
        Aggregation::Mgm => aggregate_mgm(cost, sum, dims, pen, tick),
    }
    debug_assert!(params.paths.count() * (64 + params.p2 as usize) < 65536);
}

/// The selection rules of `params` for disparities from `range.0` up.
fn selection(range: DisparityRange, params: &SgmParams) -> Selection {
    Selection {
        d_min: range.0,
        lr_tolerance: params.lr_tolerance,
        uniqueness: params.uniqueness,
        subpixel: if params.subpixel {
            Subpixel::Equiangular
        } else {
            Subpixel::None
        },
    }
}

/// The sub-pixel fit and the median may move a match by a pixel: clears the disparities that no
/// longer land inside the right image, on a valid pixel.
fn clear_off_image(disp: &mut [f32], w: usize, right_valid: &[bool]) {
    disp.par_chunks_mut(w).enumerate().for_each(|(y, row)| {
        for (x, d) in row.iter_mut().enumerate() {
            let xr = (x as f32 - *d).round();
            if !(xr >= 0.0 && xr < w as f32 && right_valid[y * w + xr as usize]) {
                *d = f32::NAN;
            }
        }
    });
}

/// A zeroed vector of `len` elements, or an error when it cannot be allocated. The zeroing (and
/// so the first touch of the pages) is spread over the threads.
fn zeroed<T: Copy + Default + Send>(len: usize) -> Result<Vec<T>, TryReserveError> {
    let mut v: Vec<T> = Vec::new();
    v.try_reserve_exact(len)?;
    v.spare_capacity_mut()[..len]
        .par_chunks_mut(1 << 16)
        .for_each(|c| {
            for e in c {
                e.write(T::default());
            }
        });
    // SAFETY: the capacity is at least `len` and the first `len` elements were initialised above.
    unsafe { v.set_len(len) };
    Ok(v)
}

/// `grey` divided by its robust range (1st to 99th percentile of the finite values, from a
/// sample), so gradient thresholds do not depend on the input's value range.
fn normalised(grey: &[f32]) -> Vec<f32> {
    let step = (grey.len() / 65536).max(1);
    let mut sample: Vec<f32> = grey
        .iter()
        .step_by(step)
        .copied()
        .filter(|v| v.is_finite())
        .collect();
    let scale = if sample.len() < 2 {
        1.0
    } else {
        sample.sort_unstable_by(f32::total_cmp);
        let lo = sample[sample.len() / 100];
        let hi = sample[(sample.len() * 99) / 100];
        let r = hi - lo;
        if r > 0.0 && r.is_finite() {
            r
        } else {
            1.0
        }
    };
    grey.iter().map(|v| v / scale).collect()
}
