//! Very narrow baselines measured from both views: the tile is matched a second time with the
//! right image as the reference, and a cell keeps a height only where both views measured it
//! and agree ([`agreeing_cells`]); the others are left to the hole filling.
//!
//! Why: under [`BOTH_VIEWS_PIXELS_PER_METRE`] a pixel of disparity is more than 1.6 m of
//! height. The two views' matches have their own census windows, aggregation grid and
//! sub-pixel errors, so their mean halves the noise, and a cell only one view measured is more
//! often a mismatch than the ground-first fill is wrong (BENCHMARKS.md, "Both views on very
//! narrow baselines").

use anyhow::{Context, Result};
use camera::{rasterize_window, rasterize_window_with, triangulate_disparity, GridWindow, Points};
use raster::Image;

use super::plan::Tile;
use super::scene::{core_mask, Scene};
use camera::rectify::Rectification;
use matching::DisparityRange;
use workflow::matcher::{Matcher, RangeSource};
use workflow::Silent;

/// Below this disparity per metre of altitude (raw pixels) the classical matcher measures a tile
/// from both views. On the dev pairs every pair under the line gains in MAE and within 1 m; the
/// next ones up gain within 1 m on average but half of them lose MAE, where more of the cells one
/// view alone measured are real (wider occlusions). The procedural world's standard pair, just
/// above the line, loses too (exact cameras, synthetic texture: its single-view cells are right
/// more often), so the line sits just under it (BENCHMARKS.md, "Both views on very narrow
/// baselines").
pub const BOTH_VIEWS_PIXELS_PER_METRE: f64 = 0.63;

/// Two views' heights of a cell further apart than this are a mismatch in one of them (1 m and
/// 2 m are alike on the dev pairs; 2 m keeps more of the procedural world's sharp edges).
pub const AGREEMENT_METRES: f32 = 2.0;

/// Whether a tile of this baseline (raw pixels per metre) is measured from both views.
pub fn wants_both_views(matcher: &Matcher, pixels_per_metre: f64) -> bool {
    matches!(matcher, Matcher::Classical(_)) && pixels_per_metre < BOTH_VIEWS_PIXELS_PER_METRE
}

/// `image` mirrored left–right.
fn mirrored(image: &Image) -> Image {
    let (w, h) = image.size();
    let c = image.channels();
    let mut data = Vec::with_capacity(image.data().len());
    for y in 0..h {
        let row = image.row(y);
        for x in (0..w).rev() {
            data.extend_from_slice(&row[x * c..(x + 1) * c]);
        }
    }
    Image::new(w, h, c, data).expect("same size")
}

/// The disparity of the right view of a rectified pair, in the convention `x_other = x − d`,
/// and its confidence when the matcher gives one.
///
/// Mirrored, the right image becomes a left one with the same disparity range: a right pixel
/// `x_r` matches the left `x_r + d`, i.e. `(w − 1 − x_r) − d` in the mirrored left. Mirrored
/// back and negated, that disparity gives the left match of each right pixel as `x_r − (−d)`.
pub fn right_view_disparity(
    matcher: &Matcher,
    (left, right): (&Image, &Image),
    range: DisparityRange,
) -> Result<(Image, Option<Image>)> {
    let matched = matcher.disparity(
        &mirrored(right),
        &mirrored(left),
        RangeSource::Given(range),
        &Silent,
    )?;
    let mut disparity = mirrored(&matched.disparity);
    for d in disparity.data_mut() {
        *d = -*d;
    }
    Ok((disparity, matched.confidence.as_ref().map(mirrored)))
}

/// The right view's points from its disparity ([`right_view_disparity`]), triangulated with
/// the roles of the cameras swapped. Only the right pixels whose left match lands in the tile's
/// core are kept, as for the left view.
fn right_view_points(
    scene: &Scene,
    tile: &Tile,
    rect: &Rectification,
    disparity: &Image,
) -> Result<Option<Points>> {
    let mask = core_mask(scene, tile, rect, disparity, |x, d| x as f64 - f64::from(d))?;
    if mask.count() == 0 {
        return Ok(None);
    }
    let points = triangulate_disparity(
        disparity,
        &rect.h_right,
        &rect.h_left,
        scene.rpc_right,
        scene.rpc_left,
        &mask,
    )
    .context("triangulating the right view")?;
    Ok(Some(points))
}

/// The cells both windows measured with heights within [`AGREEMENT_METRES`], at their mean
/// height and mean confidence (the points of both counted); `None` when there are none.
pub fn agreeing_cells(a: &GridWindow, b: &GridWindow) -> Option<GridWindow> {
    let col = a.col.max(b.col);
    let row = a.row.max(b.row);
    let col_end = (a.col + a.width).min(b.col + b.width);
    let row_end = (a.row + a.height).min(b.row + b.height);
    if col >= col_end || row >= row_end {
        return None;
    }
    let (width, height) = (col_end - col, row_end - row);
    let at = |g: &GridWindow, c: usize, r: usize| (r - g.row) * g.width + (c - g.col);
    let mut heights = vec![f32::NAN; width * height];
    let mut counts = vec![0u16; width * height];
    let mut confidence = a
        .confidence
        .as_ref()
        .zip(b.confidence.as_ref())
        .map(|_| vec![f32::NAN; width * height]);
    let mut any = false;
    for r in row..row_end {
        for c in col..col_end {
            let (i, j) = (at(a, c, r), at(b, c, r));
            let (za, zb) = (a.heights[i], b.heights[j]);
            if (za - zb).abs() <= AGREEMENT_METRES {
                let k = (r - row) * width + (c - col);
                heights[k] = 0.5 * (za + zb);
                counts[k] = a.counts[i].saturating_add(b.counts[j]);
                if let (Some(c), Some(ca), Some(cb)) =
                    (&mut confidence, &a.confidence, &b.confidence)
                {
                    c[k] = 0.5 * (ca[i] + cb[j]);
                }
                any = true;
            }
        }
    }
    any.then_some(GridWindow {
        col,
        row,
        width,
        height,
        heights,
        counts,
        confidence,
    })
}

/// One view's points gridded on the scene's grid, with their confidence when there is one.
pub fn view_cells(
    scene: &Scene,
    points: &Points,
    confidence: Option<&Image>,
) -> Option<GridWindow> {
    match confidence {
        Some(c) => rasterize_window_with(points, c.data(), scene.grid, scene.gridding),
        None => rasterize_window(points, scene.grid, scene.gridding),
    }
}

/// Both views' cells of a tile from the left view's points and the right view's disparity: the
/// right view triangulated, both gridded, and only their agreeing cells kept.
pub fn both_views_cells(
    scene: &Scene,
    tile: &Tile,
    rect: &Rectification,
    (right_disparity, right_confidence): (&Image, Option<&Image>),
    (left_points, left_confidence): (&Points, Option<&Image>),
) -> Result<Option<GridWindow>> {
    let Some(left) = view_cells(scene, left_points, left_confidence) else {
        return Ok(None);
    };
    let Some(points) = right_view_points(scene, tile, rect, right_disparity)? else {
        return Ok(None);
    };
    let Some(right) = view_cells(scene, &points, right_confidence) else {
        return Ok(None);
    };
    Ok(agreeing_cells(&left, &right))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn window(col: usize, row: usize, width: usize, heights: Vec<f32>) -> GridWindow {
        let height = heights.len() / width;
        GridWindow {
            col,
            row,
            width,
            height,
            counts: vec![1; heights.len()],
            heights,
            confidence: None,
        }
    }

    #[test]
    fn only_cells_both_views_measured_alike_are_kept_at_their_mean() {
        let nan = f32::NAN;
        // a covers columns 0..3, b columns 1..4 of one row.
        let a = window(0, 0, 3, vec![5.0, 10.0, 20.0]);
        let b = window(1, 0, 3, vec![10.5, 23.0, 7.0]);
        let both = agreeing_cells(&a, &b).expect("one cell agrees");
        assert_eq!((both.col, both.row, both.width, both.height), (1, 0, 2, 1));
        assert_eq!(both.heights[0], 10.25);
        assert!(both.heights[1].is_nan(), "3 m apart: a mismatch");
        assert_eq!(both.counts, vec![2, 0]);
        assert_eq!(both.confidence, None, "neither view has a confidence");
        let a = GridWindow {
            confidence: Some(vec![0.9, 0.4, 0.5]),
            ..a
        };
        let b = GridWindow {
            confidence: Some(vec![0.2, 0.7, 0.1]),
            ..b
        };
        let c = agreeing_cells(&a, &b).unwrap().confidence.unwrap();
        assert!((c[0] - 0.3).abs() < 1e-6 && c[1].is_nan(), "{c:?}");
        let holes = window(1, 0, 2, vec![nan, 20.0]);
        let far = window(1, 0, 2, vec![10.0, 30.0]);
        assert!(agreeing_cells(&holes, &far).is_none());
        assert!(agreeing_cells(&window(0, 0, 1, vec![1.0]), &window(1, 0, 1, vec![1.0])).is_none());
    }

    #[test]
    fn mirroring_twice_is_the_identity_and_keeps_pixels_whole() {
        let image = Image::new(3, 1, 2, vec![1.0, 2.0, 3.0, 4.0, 5.0, 6.0]).unwrap();
        let m = mirrored(&image);
        assert_eq!(m.data(), &[5.0, 6.0, 3.0, 4.0, 1.0, 2.0]);
        assert_eq!(mirrored(&m).data(), image.data());
    }
}
