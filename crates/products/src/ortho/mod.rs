//! The true orthoimage: the views' colours on the DSM's grid, each cell coloured from a view that
//! sees it. Every cell's top (its centre at its height) is projected into every view through the
//! view's RPC; a view whose line of sight to the cell passes below the DSM sees an occluder
//! there, not the cell ([`visibility`]). Unlike a classic orthophoto, draped on bare terrain,
//! roofs stand on their footprints and the ground behind buildings keeps its own colour where
//! another view sees it.
//!
//! Cost: per cell and view, one RPC projection, a bilinear sample and a line-of-sight walk of a
//! few steps (block maxima); [`OrthoBlend::MostNadir`] stops at the first view, most nadir first,
//! that sees the cell, so it usually pays for one view. The images are read once, only over the
//! DSM's footprint, and held as 8-bit RGB (3 bytes per pixel of each view's window) while the
//! cells are coloured.

mod blend;
mod directions;
mod lonlat;
mod radiometry;
mod source;
mod view;
mod visibility;

use std::path::Path;

use camera::{DsmGrid, RpcModel};
use raster::formats::{write_tiled_u8, GeoTiffMeta};
use raster::Image;
use rayon::prelude::*;

use self::blend::{Sample, Scratch};
use self::directions::{BlockHeights, NadirOrder, ViewDirections};
use self::source::ViewImage;
use self::visibility::MaxPyramid;
use crate::{ProductsError, Result};

pub use self::view::{OrthoBlend, OrthoView};
pub use self::visibility::{visibility, TOLERANCE_M};

/// The true orthoimage of `dsm` (heights on `grid`, NaN where unknown) from `views`: RGB, values
/// 0–255, `(0, 0, 0)` where the cell has no height or no view images it (and only there: real
/// black is 1). A cell that no view sees (hidden in all of them) takes the colour of the most
/// nadir view (or of all, for [`OrthoBlend::Median`]) all the same.
pub fn orthoimage(
    dsm: &Image,
    grid: &DsmGrid,
    views: &[OrthoView],
    blend: OrthoBlend,
) -> Result<Image> {
    grid.check_heights(dsm, "orthoimage")?;
    let (w, h) = dsm.size();
    let mut out = vec![0.0f32; w * h * 3];
    let (Some(heights), Some(range)) = (BlockHeights::new(dsm), dsm.finite_range()) else {
        return Ok(Image::new(w, h, 3, out).expect("three samples per cell"));
    };
    let mut prepared = Vec::with_capacity(views.len());
    for view in views {
        if let Some(image) = ViewImage::read(view, grid, range)? {
            let directions = ViewDirections::new(&view.rpc, grid, &heights);
            prepared.push(PreparedView {
                image,
                rpc: &view.rpc,
                directions,
            });
        }
    }
    let order = NadirOrder::new(&prepared.iter().map(|v| &v.directions).collect::<Vec<_>>());
    let pyramid = MaxPyramid::new(dsm);
    out.par_chunks_mut(w * 3).enumerate().for_each_init(
        || (Scratch::default(), Vec::with_capacity(w)),
        |(scratch, lonlat), (row, line)| {
            lonlat::row_lonlat(grid, row, lonlat);
            for (col, rgb) in line.chunks_exact_mut(3).enumerate() {
                let z = dsm.get(col, row, 0);
                if !z.is_finite() {
                    continue;
                }
                let (lon, lat) = lonlat[col];
                let samples = order
                    .at(col, row)
                    .iter()
                    .filter_map(|&v| prepared[v].sample(&pyramid, (col, row), (lon, lat, z)));
                if let Some(colour) = blend.pick(samples, scratch) {
                    for (o, c) in rgb.iter_mut().zip(colour) {
                        *o = c as f32;
                    }
                }
            }
        },
    );
    Ok(Image::new(w, h, 3, out).expect("three samples per cell"))
}

/// Writes an orthoimage on `grid` as a tiled, Deflate-compressed RGB uint8 GeoTIFF with the DSM's
/// georeference and nodata 0, atomically.
pub fn write_ortho(path: &Path, ortho: &Image, grid: &DsmGrid) -> Result<()> {
    if ortho.size() != (grid.width, grid.height) || ortho.channels() != 3 {
        return Err(ProductsError::Input(format!(
            "{}: the orthoimage is {}x{}x{} but its grid is {}x{} (RGB expected)",
            path.display(),
            ortho.width(),
            ortho.height(),
            ortho.channels(),
            grid.width,
            grid.height
        )));
    }
    let meta = GeoTiffMeta {
        georef: Some(grid.georeference()),
        nodata: Some(0.0),
        ..GeoTiffMeta::default()
    };
    Ok(write_tiled_u8(path, ortho, &meta)?)
}

/// A view ready to colour cells: its image window, camera and directions.
struct PreparedView<'a> {
    image: ViewImage,
    rpc: &'a RpcModel,
    directions: ViewDirections,
}

impl PreparedView<'_> {
    /// The view's colour of cell (col, row) whose top is at (lon, lat, z); `None` when the cell
    /// projects outside the image or next to a pixel without data.
    #[inline]
    fn sample(
        &self,
        pyramid: &MaxPyramid,
        (col, row): (usize, usize),
        (lon, lat, z): (f64, f64, f32),
    ) -> Option<Sample> {
        let (c, r) = self.rpc.projection(lon, lat, z as f64);
        let rgb = self.image.sample(c, r)?;
        let seen = !pyramid.occluded(col, row, z, self.directions.at(col, row));
        Some(Sample { rgb, seen })
    }
}
