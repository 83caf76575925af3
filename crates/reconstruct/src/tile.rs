//! One tile of a scene: rectified on its own from the RPCs (an affine rectification holds only
//! over a small area), matched, triangulated, and gridded on the scene's grid. Only the points
//! seen from the tile's core are kept, so the collar gives the matcher context without two tiles
//! claiming the same pixels.

use std::path::Path;
use std::time::Instant;

use anyhow::{bail, Context, Result};
use camera::rectify::{rectification_with, warp_nan, Rectification};
use camera::{triangulate_disparity, GridWindow};
use raster::formats::{write_homographies, write_npy};
use raster::{Homography, Image};
use serde::{Deserialize, Serialize};

use super::both_views::{both_views_cells, right_view_disparity, view_cells, wants_both_views};
use super::plan::Tile;
use super::raw::RawImage;
use super::scene::{core_mask, Scene};
use crate::rectify::{right_coverage, RawInputs};
use workflow::matcher::{Matcher, RangeSource};
use workflow::pairs::PairFolder;
use workflow::stage::write_json;
use workflow::Silent;

/// How a tile ended.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum TileStatus {
    /// Points gridded.
    Done,
    /// Nothing to grid (no texture, clouds, water, outside the right image): not an error.
    Empty,
    /// An error; the message is in the record, and a rerun tries the tile again.
    Failed,
}

/// The record of one tile (`tiles/<id>.json`), written when it ends.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TileRecord {
    pub tile: Tile,
    pub status: TileStatus,
    pub error: Option<String>,
    pub seconds: f64,
    /// Disparity search range of its rectification, pixels.
    pub disparity_range: Option<(i32, i32)>,
    /// `(width, height)` of its rectified pair.
    pub rectified_size: Option<(usize, usize)>,
    /// Disparity per metre of altitude in raw pixels: the pair's baseline (B/H over the GSD).
    #[serde(default)]
    pub pixels_per_metre: Option<f64>,
    /// How many times the rectified frame is stretched along the rows (2 on very narrow
    /// baselines, [`NARROW_PIXELS_PER_METRE`]): the disparity range and size are in stretched
    /// pixels.
    #[serde(default)]
    pub stretch: Option<f64>,
    /// The classical matcher's `P2` on this tile, after [`workflow::matcher::baseline_p2`].
    #[serde(default)]
    pub p2: Option<u16>,
    /// Measured from both views, only the cells they agree on kept (very narrow baselines,
    /// [`super::both_views`]).
    #[serde(default)]
    pub both_views: Option<bool>,
    /// Its cells carry the matcher's confidence (a third band of `tiles/<id>.tif`); absent in
    /// the records of earlier versions, whose cells have none.
    #[serde(default)]
    pub confidence: Option<bool>,
    /// Share of the rectified left pixels with a disparity.
    pub matched: Option<f64>,
    /// Median row offset of the right view's matches of textured left patches, pixels
    /// ([`matching::vertical_parallax`]): under a pixel when each RPC belongs to its image.
    #[serde(default)]
    pub vertical_parallax: Option<f32>,
    /// Points triangulated from its core.
    pub points: usize,
    /// Estimated peak memory, bytes.
    pub memory_bytes: u64,
    /// Its cells on the scene grid: column, row, width, height (`tiles/<id>.tif` holds them).
    pub cells: Option<(usize, usize, usize, usize)>,
}

impl TileRecord {
    /// A tile that has not run yet: `Done` until something says otherwise.
    pub(super) fn new(tile: &Tile, memory_bytes: u64) -> Self {
        TileRecord {
            tile: tile.clone(),
            status: TileStatus::Done,
            error: None,
            seconds: 0.0,
            disparity_range: None,
            rectified_size: None,
            pixels_per_metre: None,
            stretch: None,
            p2: None,
            both_views: None,
            confidence: None,
            matched: None,
            vertical_parallax: None,
            points: 0,
            memory_bytes,
            cells: None,
        }
    }

    /// The record of a tile that could not even be rectified.
    pub fn failed(tile: &Tile, e: &anyhow::Error) -> Self {
        TileRecord {
            status: TileStatus::Failed,
            error: Some(format!("{e:#}")),
            ..TileRecord::new(tile, 0)
        }
    }
}

/// The local rectification of a tile, stretched along the rows on very narrow baselines for the
/// classical matcher (see [`NARROW_PIXELS_PER_METRE`]).
pub fn tile_rectification(scene: &Scene, tile: &Tile) -> Result<Rectification> {
    let rect = rectification_with(
        scene.rpc_left,
        scene.rpc_right,
        tile.extended,
        scene.alt_range,
        scene.shear,
    )
    .with_context(|| format!("rectifying tile {} ({:?})", tile.id, tile.extended))?;
    let narrow = matches!(scene.matcher, Matcher::Classical(_))
        && rect.pixels_per_metre < NARROW_PIXELS_PER_METRE;
    Ok(if narrow {
        rect.stretched(NARROW_STRETCH)
    } else {
        rect
    })
}

/// Below this disparity per metre of altitude (one pixel is more than 2.5 m of height) the
/// classical matcher works on a frame stretched [`NARROW_STRETCH`] times along the rows, so that
/// its integer winners and sub-pixel fit come in half-pixel steps. On the dev pairs it lowered
/// the filled DSM's MAE on the two narrowest and did not help the next ones up, where the
/// costlier search buys nothing; the line sits between them (BENCHMARKS.md, "Rows stretched 2×
/// before matching on very narrow baselines").
pub const NARROW_PIXELS_PER_METRE: f64 = 0.4;

/// How many times a very narrow baseline's frame is stretched along the rows.
pub const NARROW_STRETCH: f64 = 2.0;

/// Peak memory of a tile, bytes: the matcher's volumes ([`matching::memory_bytes`]; MonSter++
/// is bounded by its own budget), both rectified images, the raw windows, the disparity, the
/// points and the mask; measured from both views, the two matches run at once and the right
/// view adds its mirrored images, disparity and points.
pub fn tile_memory(rect: &Rectification, tile: &Tile, bands: usize, scene: &Scene) -> u64 {
    let (w, h) = rect.size;
    let matching = scene.matcher.memory_bytes(rect.size, rect.disparity_range);
    let px = (w * h) as u64;
    let raw = (tile.extended.width * tile.extended.height) as u64 * bands as u64 * 4 * 3;
    let one_view = matching + px * (2 * 4 * bands as u64 + 4 + 24 + 1);
    let views = if measures_both_views(scene, rect) {
        2
    } else {
        1
    };
    views * one_view + raw
}

/// Whether the scene measures this tile from both views ([`super::both_views`]).
fn measures_both_views(scene: &Scene, rect: &Rectification) -> bool {
    scene.both_views && wants_both_views(scene.matcher, raw_pixels_per_metre(rect))
}

/// Runs one tile: its record, and its cells when it has any.
pub fn run_tile(
    scene: &Scene,
    tile: &Tile,
    rect: &Rectification,
    memory_bytes: u64,
) -> (TileRecord, Option<GridWindow>) {
    let t = Instant::now();
    let mut record = TileRecord {
        disparity_range: Some(rect.disparity_range),
        rectified_size: Some(rect.size),
        pixels_per_metre: Some(raw_pixels_per_metre(rect)),
        stretch: Some(rect.stretch),
        ..TileRecord::new(tile, memory_bytes)
    };
    let cells = match match_and_grid(scene, tile, rect, &mut record) {
        Ok(Some(cells)) => {
            record.cells = Some((cells.col, cells.row, cells.width, cells.height));
            record.confidence = Some(cells.confidence.is_some());
            Some(cells)
        }
        Ok(None) => {
            record.status = TileStatus::Empty;
            None
        }
        Err(e) => {
            record.status = TileStatus::Failed;
            record.error = Some(format!("{e:#}"));
            None
        }
    };
    record.seconds = t.elapsed().as_secs_f64();
    (record, cells)
}

/// Reads the windows, warps, matches, triangulates the core's pixels and grids them.
fn match_and_grid(
    scene: &Scene,
    tile: &Tile,
    rect: &Rectification,
    record: &mut TileRecord,
) -> Result<Option<GridWindow>> {
    let size = rect.size;
    let e = tile.extended;
    let left = warp_window(
        scene.left,
        &rect.h_left,
        (
            e.x as f64,
            e.y as f64,
            (e.x + e.width) as f64,
            (e.y + e.height) as f64,
        ),
        size,
    )?;
    let Some(left) = left else {
        bail!("tile {} lies outside the left image", tile.id);
    };
    let h_right_inv = rect
        .h_right
        .inverse()
        .context("the right rectifying homography is singular")?;
    let (w, h) = (size.0 as f64, size.1 as f64);
    let corners = [(0.0, 0.0), (w, 0.0), (0.0, h), (w, h)].map(|(x, y)| h_right_inv.apply(x, y));
    let bounds = corners.iter().fold(
        (
            f64::INFINITY,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NEG_INFINITY,
        ),
        |b, &(x, y)| (b.0.min(x), b.1.min(y), b.2.max(x), b.3.max(y)),
    );
    let Some(right) = warp_window(scene.right, &rect.h_right, bounds, size)? else {
        return Ok(None);
    };
    record.vertical_parallax =
        matching::vertical_parallax(&left, &right, rect.disparity_range).map(|p| p.median_rows);

    let for_baseline = scene.matcher.for_baseline(rect.pixels_per_metre);
    let matcher = for_baseline.as_ref().unwrap_or(scene.matcher);
    record.p2 = matcher.p2();
    let both_views = measures_both_views(scene, rect);
    // Both views at once: half of MGM's time is single-threaded, so two matches share the cores.
    let (disparity, right_disparity) = rayon::join(
        || {
            matcher.disparity(
                &left,
                &right,
                RangeSource::Given(rect.disparity_range),
                &Silent,
            )
        },
        || both_views.then(|| right_view_disparity(matcher, (&left, &right), rect.disparity_range)),
    );
    let matched = disparity?;
    let (disparity, confidence) = (matched.disparity, matched.confidence);
    let right_disparity = right_disparity.transpose()?;
    let finite = disparity.data().iter().filter(|v| v.is_finite()).count();
    record.matched = Some(finite as f64 / disparity.data().len().max(1) as f64);
    if let Some(dir) = scene.keep {
        let name = if scene.single_tile {
            scene.stem.to_string()
        } else {
            format!("{}_{}", scene.stem, tile.id)
        };
        keep_files(scene, dir, &name, tile, &left, &right, &disparity, rect)?;
    }
    drop((left, right));

    let mask = core_mask(scene, tile, rect, &disparity, |x, _| x as f64)?;
    if mask.count() == 0 {
        return Ok(None);
    }
    let left_points = triangulate_disparity(
        &disparity,
        &rect.h_left,
        &rect.h_right,
        scene.rpc_left,
        scene.rpc_right,
        &mask,
    )
    .context("triangulating")?;
    record.points = left_points.valid_count();
    let Some((right_disparity, right_confidence)) = right_disparity else {
        return Ok(view_cells(scene, &left_points, confidence.as_ref()));
    };
    record.both_views = Some(true);
    both_views_cells(
        scene,
        tile,
        rect,
        (&right_disparity, right_confidence.as_ref()),
        (&left_points, confidence.as_ref()),
    )
}

/// A tile's disparity per metre of altitude in raw pixels (before any stretch).
fn raw_pixels_per_metre(rect: &Rectification) -> f64 {
    rect.pixels_per_metre / rect.stretch
}

/// The raw window covering `bounds` (raw pixels, with a 2-pixel margin for the interpolation,
/// clipped to the image) warped into the rectified frame; `None` when the window is empty.
fn warp_window(
    raw: &RawImage,
    h: &Homography,
    bounds: (f64, f64, f64, f64),
    size: (usize, usize),
) -> Result<Option<Image>> {
    let (w, h_img) = raw.size();
    let x0 = (bounds.0.floor() - 2.0).max(0.0);
    let y0 = (bounds.1.floor() - 2.0).max(0.0);
    let x1 = (bounds.2.ceil() + 2.0).min(w as f64);
    let y1 = (bounds.3.ceil() + 2.0).min(h_img as f64);
    if !(x1 > x0 && y1 > y0) {
        return Ok(None);
    }
    let (x0, y0) = (x0 as usize, y0 as usize);
    let window = raw.window(x0, y0, x1 as usize - x0, y1 as usize - y0)?;
    let h_window = h.compose(&Homography::translation(x0 as f64, y0 as f64));
    Ok(Some(warp_nan(&window, &h_window, size)?))
}

/// Writes a tile's rectified pair, homographies, rectify record and disparity in the layout
/// `eval` and `masks --pairs` read.
#[allow(clippy::too_many_arguments)]
fn keep_files(
    scene: &Scene,
    dir: &Path,
    name: &str,
    tile: &Tile,
    left: &Image,
    right: &Image,
    disparity: &Image,
    rect: &Rectification,
) -> Result<()> {
    let folder = PairFolder::new(dir);
    let files = folder.paths(name);
    write_npy(&files.left, left)?;
    write_npy(&files.right, right)?;
    write_npy(&files.disparity, disparity)?;
    write_homographies(&files.homography, &rect.h_left, &rect.h_right)?;
    let raw = RawInputs {
        stem: name,
        left: scene.left.path(),
        right: scene.right.path(),
        rpc_left: scene.rpc_files[0],
        rpc_right: scene.rpc_files[1],
        roi: tile.extended,
        alt_range: scene.alt_range,
        alt_source: scene.alt_source,
    };
    let record = crate::rectify::rectify_record(&raw, rect, right_coverage(right, rect), &files);
    write_json(&folder.rectify_record_path(name), &record)?;
    Ok(())
}
