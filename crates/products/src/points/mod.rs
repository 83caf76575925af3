//! The coloured point cloud of a DSM: one point per cell with a height (and, when the caller says
//! so, only the cells that were measured rather than filled), at the cell's centre in the grid's
//! CRS, coloured by the orthoimage. LAS/LAZ for GIS and lidar tools, PLY for mesh tools (s2p's
//! layout).

mod cells;
mod las_file;
mod ply_file;

use std::path::Path;

use camera::DsmGrid;
use raster::Image;

use self::cells::Cells;
use crate::{ProductsError, Result};

/// The extensions [`write_point_cloud`] understands.
pub const POINT_CLOUD_EXTENSIONS: &[&str] = &["las", "laz", "ply"];

/// Writes the point cloud of `dsm` (lying on `grid`) at `path`, atomically; returns the number of
/// points. One point per cell with a finite height and `keep[cell]` true (when given, row-major,
/// one flag per cell): x, y the cell's centre in the grid's CRS, z its height; RGB from `colours`
/// (a 3-channel image on the grid, 0–255) when given. The extension picks the format: `.las`
/// (LAS 1.2, point format 2 with colours, 0 without), `.laz` (the same, compressed) or `.ply`
/// (binary little-endian, x y z double, red green blue uchar). LAS files carry the grid's EPSG
/// code as GeoTIFF keys.
pub fn write_point_cloud(
    path: &Path,
    dsm: &Image,
    grid: &DsmGrid,
    colours: Option<&Image>,
    keep: Option<&[bool]>,
) -> Result<usize> {
    check_inputs(path, dsm, grid, colours, keep)?;
    let cells = Cells {
        dsm,
        grid,
        colours,
        keep,
    };
    let ext = raster::formats::extension_of(path);
    match ext.as_str() {
        "las" | "laz" => las_file::write(path, grid, &cells, ext == "laz"),
        "ply" => ply_file::write(path, grid, &cells),
        _ => Err(ProductsError::point_cloud(
            path,
            format!(
                "unsupported point cloud extension {ext:?} (supported: {})",
                POINT_CLOUD_EXTENSIONS.join(", ")
            ),
        )),
    }
}

/// Sizes and channels of the inputs, checked against the grid.
fn check_inputs(
    path: &Path,
    dsm: &Image,
    grid: &DsmGrid,
    colours: Option<&Image>,
    keep: Option<&[bool]>,
) -> Result<()> {
    grid.check_heights(dsm, &path.display().to_string())?;
    let size = (grid.width, grid.height);
    let mismatch = |what: &str, got: String| {
        Err(ProductsError::Input(format!(
            "{}: the {what} is {got} but the grid is {}x{}",
            path.display(),
            grid.width,
            grid.height
        )))
    };
    if let Some(c) = colours.filter(|c| c.size() != size || c.channels() != 3) {
        let (w, h, ch) = (c.width(), c.height(), c.channels());
        return mismatch("colour image (RGB expected)", format!("{w}x{h}x{ch}"));
    }
    if let Some(k) = keep.filter(|k| k.len() != size.0 * size.1) {
        return mismatch("keep mask", format!("{} flags", k.len()));
    }
    Ok(())
}
