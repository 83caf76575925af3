//! Validity masks of the SeasonStereo loss (paper Sec. 3.3, "Valid Pixel Mask"), built exactly as
//! the public release builds them (`losses/self_supervised.py`, `utils/utils.py`,
//! `datasets/dataset_stereo.py`).
//!
//! Two masks per batch element, both on the LEFT view:
//! - the **supervision mask** `V` ([`supervision_mask`]): the sample's validity mask (rectification
//!   border ∧ ¬water ∧ ¬tree), a finite and positive target disparity, `|target| < max_disp`, and
//!   an `ignore_border`-pixel frame removed on every side. The release applies it to the disparity
//!   term. It does not depend on the prediction.
//! - the **photometric mask** ([`photometric_mask`]): `V` ∧ the prediction warps inside the right
//!   image ∧ the prediction survives the z-buffer test ([`zbuffer_visible`]) ∧ the building mask
//!   `V_B` (when the photometric term is restricted to buildings). It depends on the (detached)
//!   prediction, so it is rebuilt for every prediction of the sequence.
//!
//! Everything here is plain CPU code on `f32`/`bool` slices: masks are not differentiated.

use raster::{Image, Mask};

/// How close (in pixels) a disparity must be to the z-buffer winner of its right-image column to
/// count as visible: the release's `(d − zbuf).abs() < 0.5`. Pixels of a slanted surface that land
/// on the same column with nearly equal disparities therefore all stay visible.
pub const ZBUFFER_TOLERANCE_PX: f32 = 0.5;

/// Parameters of the supervision mask (release `build_valid_mask`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SupervisionParams {
    /// Targets with `|d| ≥ max_disp` are excluded (release: 576).
    pub max_disp: f32,
    /// Width of the frame removed on each side (release: 32 px), where crops and padding make
    /// predictions unreliable.
    pub ignore_border: usize,
}

/// Errors of the mask builders: mismatched inputs, named so the caller can fix them.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum MaskError {
    #[error("{what}: size {got:?} does not match the target disparity {expected:?}")]
    Size {
        what: &'static str,
        got: (usize, usize),
        expected: (usize, usize),
    },
    #[error("{what}: expected a single-channel disparity, got {channels} channels")]
    Channels { what: &'static str, channels: usize },
    #[error("{what}: expected {expected} values ({width} per row), got {got}")]
    Length {
        what: &'static str,
        expected: usize,
        got: usize,
        width: usize,
    },
}

/// The supervision mask `V` of one sample: `valid_left` ∧ `target` finite ∧ `target > 0` ∧
/// `|target| < max_disp` ∧ outside the `ignore_border` frame.
///
/// `valid_left` is the sample's rectification ∧ ¬water ∧ ¬tree mask; `target` the teacher (or, in
/// configuration (a), LiDAR) disparity with NaN where unknown. The release folds "finite and
/// positive" into its dataset's `valid` before augmentation; here it is tested after, on the
/// augmented target (the augmentation keeps NaN where the target is unknown).
pub fn supervision_mask(
    valid_left: &Mask,
    target: &Image,
    params: &SupervisionParams,
) -> Result<Mask, MaskError> {
    if target.channels() != 1 {
        return Err(MaskError::Channels {
            what: "supervision_mask: target",
            channels: target.channels(),
        });
    }
    if valid_left.size() != target.size() {
        return Err(MaskError::Size {
            what: "supervision_mask: valid_left",
            got: valid_left.size(),
            expected: target.size(),
        });
    }
    let (w, h) = target.size();
    let b = params.ignore_border;
    Ok(Mask::from_fn(w, h, |x, y| {
        let d = target.get(x, y, 0);
        let inside = x >= b && y >= b && x + b < w && y + b < h;
        inside && valid_left.get(x, y) && d.is_finite() && d > 0.0 && d.abs() < params.max_disp
    }))
}

/// The release's z-buffer visibility test (`zbuffer_occlusion_mask`) on a left disparity map of
/// `width` columns (row-major, any number of rows): pixel `x` of a row is sent to the right column
/// `round(x − d)` (rounding half to even, as `torch.round`); it is visible iff that column lies in
/// `[0, W)` and `d` is within [`ZBUFFER_TOLERANCE_PX`] of the largest disparity sent to the same
/// column (the closest surface wins). Non-finite disparities are not visible and take no part in
/// the z-buffer.
///
/// Unlike a strict z-buffer (one winner per column, half-up rounding), the release keeps every near-tie visible, which matters on
/// slanted roofs where neighbouring pixels compress onto one column.
pub fn zbuffer_visible(disparity: &[f32], width: usize) -> Result<Vec<bool>, MaskError> {
    check_rows("zbuffer_visible", disparity.len(), width)?;
    let mut visible = vec![false; disparity.len()];
    if width == 0 {
        return Ok(visible);
    }
    let mut zbuf = vec![f32::NEG_INFINITY; width];
    let mut target = vec![usize::MAX; width];
    for (row, vis) in disparity
        .chunks_exact(width)
        .zip(visible.chunks_exact_mut(width))
    {
        zbuf.fill(f32::NEG_INFINITY);
        for (x, &d) in row.iter().enumerate() {
            target[x] = right_column(x, d, width).unwrap_or(usize::MAX);
            if target[x] != usize::MAX && d > zbuf[target[x]] {
                zbuf[target[x]] = d;
            }
        }
        for (x, &d) in row.iter().enumerate() {
            vis[x] = target[x] != usize::MAX && (d - zbuf[target[x]]).abs() < ZBUFFER_TOLERANCE_PX;
        }
    }
    Ok(visible)
}

/// `round(x − d)` as the release computes it (f32, half to even) when it falls in `[0, width)`.
fn right_column(x: usize, d: f32, width: usize) -> Option<usize> {
    if !d.is_finite() {
        return None;
    }
    let xr = (x as f32 - d).round_ties_even();
    (xr >= 0.0 && xr < width as f32).then_some(xr as usize)
}

/// The release's warp validity (`warp_image`'s `valid`): the sampling position `x − d` lies in
/// `[0, W − 1]` and is finite, so the bilinear warp reads only real right-image pixels.
pub fn warp_in_bounds(disparity: &[f32], width: usize) -> Result<Vec<bool>, MaskError> {
    check_rows("warp_in_bounds", disparity.len(), width)?;
    let last = width.saturating_sub(1) as f32;
    Ok(disparity
        .iter()
        .enumerate()
        .map(|(i, &d)| {
            let xr = (i % width.max(1)) as f32 - d;
            xr.is_finite() && xr >= 0.0 && xr <= last
        })
        .collect())
}

/// The photometric mask of one sample (release `photometric_map`, `occlusion_mode: zbuffer`):
/// `supervision` ∧ [`warp_in_bounds`] ∧ [`zbuffer_visible`] (on the PREDICTED disparity) ∧
/// `building` when given (`photometric_on_buildings_only`). All slices are row-major with
/// `width` columns.
pub fn photometric_mask(
    supervision: &[bool],
    prediction: &[f32],
    width: usize,
    building: Option<&[bool]>,
) -> Result<Vec<bool>, MaskError> {
    let n = prediction.len();
    let same = |what: &'static str, got: usize| {
        if got == n {
            Ok(())
        } else {
            Err(MaskError::Length {
                what,
                expected: n,
                got,
                width,
            })
        }
    };
    same("photometric_mask: supervision", supervision.len())?;
    if let Some(b) = building {
        same("photometric_mask: building", b.len())?;
    }
    let in_bounds = warp_in_bounds(prediction, width)?;
    let visible = zbuffer_visible(prediction, width)?;
    Ok((0..n)
        .map(|i| supervision[i] && in_bounds[i] && visible[i] && building.is_none_or(|b| b[i]))
        .collect())
}

fn check_rows(what: &'static str, len: usize, width: usize) -> Result<(), MaskError> {
    if (width == 0 && len != 0) || (width != 0 && !len.is_multiple_of(width)) {
        return Err(MaskError::Length {
            what,
            expected: len.next_multiple_of(width.max(1)),
            got: len,
            width,
        });
    }
    Ok(())
}
