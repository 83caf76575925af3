//! Which products a run writes beside its DSM, and writing them from the finished DSM file: the
//! one type `reconstruct`, `reconstruct-many`, the command line and Python share.

use std::path::{Path, PathBuf};
use std::time::Instant;

use camera::{read_dsm, write_grid_raster, Band, DsmGrid, Heights};
use raster::Image;

use crate::points::POINT_CLOUD_EXTENSIONS;
use crate::{
    orthoimage, write_ortho, write_point_cloud, write_preview, OrthoBlend, OrthoView,
    ProductsError, Result,
};

/// The products asked for beside a DSM; none by default.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Products {
    /// A true orthoimage on the DSM's grid (RGB GeoTIFF).
    pub ortho: Option<PathBuf>,
    /// How the orthoimage picks a cell's colour among the views.
    pub ortho_blend: OrthoBlend,
    /// A coloured point cloud of the measured cells (`.las`, `.laz` or `.ply`).
    pub points: Option<PathBuf>,
    /// A quicklook PNG of the DSM (heights in colour over a hillshade).
    pub preview: Option<PathBuf>,
    /// The DSM's vertical reference: the cameras' ellipsoidal heights as they are, or converted
    /// to heights above the EGM96 geoid (the DSM rewritten, the products made from it).
    pub heights: Heights,
}

/// What [`Products::write`] wrote.
#[derive(Clone, Debug, Default, PartialEq, serde::Serialize)]
pub struct ProductsWritten {
    /// Points in the point cloud, when one was written.
    pub points: Option<usize>,
    /// Seconds spent on all products.
    pub seconds: f64,
}

impl Products {
    /// The output files asked for, in the order they are written.
    pub fn paths(&self) -> Vec<&Path> {
        [&self.ortho, &self.points, &self.preview]
            .into_iter()
            .flatten()
            .map(PathBuf::as_path)
            .collect()
    }

    /// Refuses, before any work, a file name whose extension says another format: the
    /// orthoimage a GeoTIFF, the point cloud LAS/LAZ/PLY, the quicklook a PNG.
    pub fn check(&self) -> Result<()> {
        let rules: [(&Option<PathBuf>, &str, &[&str]); 3] = [
            (&self.ortho, "--ortho", &["tif", "tiff"]),
            (&self.points, "--points", POINT_CLOUD_EXTENSIONS),
            (&self.preview, "--preview", &["png"]),
        ];
        for (path, flag, allowed) in rules {
            if let Some(p) = path {
                if !allowed.contains(&raster::formats::extension_of(p).as_str()) {
                    return Err(ProductsError::Input(format!(
                        "{flag} {}: the file must end in .{} (the format is taken from the \
                         extension)",
                        p.display(),
                        allowed.join(", .")
                    )));
                }
            }
        }
        Ok(())
    }

    /// Whether anything is asked for beyond the ellipsoidal DSM.
    pub fn is_empty(&self) -> bool {
        self.paths().is_empty() && self.heights == Heights::Ellipsoid
    }

    /// Writes the products of the DSM at `dsm` (a GeoTIFF of ellipsoidal heights, as
    /// `reconstruct` writes it) seen by `views` (their cameras as the reconstruction used them,
    /// pointing corrected), after converting the DSM's heights to [`Products::heights`]. The
    /// point cloud keeps the cells `measured` says were triangulated (row-major, one flag per
    /// cell; every cell with a height when `None`), coloured from the orthoimage when one is
    /// made.
    pub fn write(
        &self,
        dsm: &Path,
        views: &[OrthoView],
        measured: Option<&[bool]>,
    ) -> Result<ProductsWritten> {
        let start = Instant::now();
        if self.is_empty() {
            return Ok(ProductsWritten::default());
        }
        let mut raster = read_dsm(dsm, None)?;
        if self.heights == Heights::Egm96 {
            camera::to_egm96(&mut raster.image, &raster.grid);
            write_grid_raster(
                dsm,
                &raster.image,
                &raster.grid,
                Band::Heights(self.heights),
            )?;
        }
        let (heights, grid) = (&raster.image, &raster.grid);
        let colours = match (&self.ortho, &self.points) {
            (None, None) => None,
            _ => Some(orthoimage(heights, grid, views, self.ortho_blend)?),
        };
        if let (Some(path), Some(ortho)) = (&self.ortho, &colours) {
            write_ortho(path, ortho, grid)?;
        }
        let points = match &self.points {
            Some(path) => Some(write_point_cloud(
                path,
                heights,
                grid,
                colours.as_ref(),
                measured,
            )?),
            None => None,
        };
        if let Some(path) = &self.preview {
            write_preview(path, heights, grid)?;
        }
        Ok(ProductsWritten {
            points,
            seconds: start.elapsed().as_secs_f64(),
        })
    }
}

/// The cells of a DSM that were measured: those with a height where `filled` (a `_filled.tif`
/// sidecar: 0 measured, 1 filled) says 0, or where `count` (a `_count.tif`: pairs per cell) is
/// positive.
pub fn measured_cells(marks: &Image, kind: MeasuredFrom) -> Vec<bool> {
    marks
        .data()
        .iter()
        .map(|&v| match kind {
            MeasuredFrom::Filled => v == 0.0,
            MeasuredFrom::Count => v > 0.0,
        })
        .collect()
}

/// Which sidecar [`measured_cells`] reads.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum MeasuredFrom {
    /// `reconstruct`'s `_filled.tif`.
    Filled,
    /// `reconstruct-many`'s `_count.tif`.
    Count,
}

/// The flags of [`measured_cells`] read from a sidecar on `grid`; `None` (every cell with a
/// height) when the sidecar is absent or on another grid.
pub fn measured_from_sidecar(path: &Path, grid: &DsmGrid, kind: MeasuredFrom) -> Option<Vec<bool>> {
    let raster = read_dsm(path, grid.zone()).ok()?;
    (raster.grid == *grid).then(|| measured_cells(&raster.image, kind))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_are_checked_by_extension() {
        let ok = Products {
            ortho: Some("o.tif".into()),
            points: Some("p.LAZ".into()),
            preview: Some("q.png".into()),
            ..Default::default()
        };
        ok.check().unwrap();
        assert_eq!(ok.paths().len(), 3);
        for bad in [
            Products {
                ortho: Some("o.png".into()),
                ..Default::default()
            },
            Products {
                points: Some("p.xyz".into()),
                ..Default::default()
            },
            Products {
                preview: Some("q.tif".into()),
                ..Default::default()
            },
        ] {
            let msg = bad.check().unwrap_err().to_string();
            assert!(msg.starts_with("--"), "{msg}");
        }
    }

    #[test]
    fn measured_cells_read_either_sidecar() {
        let marks = Image::new(3, 1, 1, vec![0.0, 1.0, f32::NAN]).unwrap();
        assert_eq!(
            measured_cells(&marks, MeasuredFrom::Filled),
            [true, false, false]
        );
        let counts = Image::new(3, 1, 1, vec![2.0, 0.0, f32::NAN]).unwrap();
        assert_eq!(
            measured_cells(&counts, MeasuredFrom::Count),
            [true, false, false]
        );
    }
}
