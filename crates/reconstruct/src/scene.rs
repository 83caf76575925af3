//! What every tile of a scene shares, and which of a tile's pixels are its own: the two views'
//! tiles (`tile`, `both_views`) read both.

use std::path::Path;

use anyhow::{Context, Result};
use camera::rectify::{Rectification, Shear};
use camera::{DsmGrid, Gridding, RpcModel};
use raster::{Image, Mask};

use super::plan::Tile;
use super::raw::RawImage;
use crate::dsm::valid_pixels;
use workflow::matcher::Matcher;

/// What every tile shares.
pub struct Scene<'a> {
    pub left: &'a RawImage,
    pub right: &'a RawImage,
    pub rpc_left: &'a RpcModel,
    pub rpc_right: &'a RpcModel,
    /// The JSON cameras, when the images' tags are not used (for the rectify records).
    pub rpc_files: [Option<&'a Path>; 2],
    pub alt_range: (f64, f64),
    /// Where the altitude range came from.
    pub alt_source: &'a str,
    pub matcher: &'a Matcher,
    pub grid: &'a DsmGrid,
    pub gridding: Gridding,
    /// Pixels of each rectified disparity ignored at its borders.
    pub border: usize,
    /// Keep each tile's rectified pair and disparity under this folder, in the layout `eval`
    /// reads.
    pub keep: Option<&'a Path>,
    /// Pair name: the files of a single-tile scene are `<stem>`, those of a tile
    /// `<stem>_<tile id>`.
    pub stem: &'a str,
    pub single_tile: bool,
    /// Whether very narrow baselines are measured from both views ([`super::both_views`]).
    pub both_views: bool,
    /// Whether the right image is sheared to level the ground ([`Shear`]).
    pub shear: Shear,
}

/// The valid pixels of a rectified `disparity` (see [`valid_pixels`]) whose left-view pixel —
/// the rectified column `left_column(x, d)` of pixel `x` with disparity `d`, on its row — lies in
/// the tile's core, so that no two tiles claim the same left pixels.
pub(crate) fn core_mask(
    scene: &Scene,
    tile: &Tile,
    rect: &Rectification,
    disparity: &Image,
    left_column: impl Fn(usize, f32) -> f64,
) -> Result<Mask> {
    let h_left_inv = rect
        .h_left
        .inverse()
        .context("the left rectifying homography is singular")?;
    let core = tile.core;
    let (cx0, cy0) = (core.x as f64, core.y as f64);
    let (cx1, cy1) = (cx0 + core.width as f64, cy0 + core.height as f64);
    let valid = valid_pixels(disparity, scene.border);
    let (w, h) = disparity.size();
    Ok(Mask::from_fn(w, h, |x, y| {
        if !valid.get(x, y) {
            return false;
        }
        let xl = left_column(x, disparity.get(x, y, 0));
        let (u, v) = h_left_inv.apply(xl + 0.5, y as f64 + 0.5);
        (cx0..cx1).contains(&u) && (cy0..cy1).contains(&v)
    }))
}
