//! DSM gridding as the benchmark does it: ground points projected to the ground truth's UTM grid,
//! floored to a cell, highest point per cell, NaN where no point falls.

use std::path::Path;

use raster::formats::{read_tiff, write_geotiff, GeoRaster, GeoReference, GeoTiffMeta};
use raster::Image;
use rayon::prelude::*;

use crate::{CameraError, Points, Result, UtmZone};

/// A north-up UTM grid of square cells: cell (col, row) covers eastings
/// [x0 + col·res, x0 + (col+1)·res) and northings (y0 − (row+1)·res, y0 − row·res].
#[derive(Clone, Debug, PartialEq)]
pub struct DsmGrid {
    /// Easting of the west edge, metres.
    pub x0: f64,
    /// Northing of the north edge, metres.
    pub y0: f64,
    /// Cell size, metres.
    pub resolution: f64,
    pub width: usize,
    pub height: usize,
    /// WGS84/UTM EPSG code (326zz or 327zz).
    pub epsg: u32,
}

impl DsmGrid {
    /// A grid, checked: positive finite resolution, non-empty, a UTM EPSG code.
    pub fn new(
        x0: f64,
        y0: f64,
        resolution: f64,
        width: usize,
        height: usize,
        epsg: u32,
    ) -> Result<Self> {
        if !(resolution.is_finite() && resolution > 0.0) {
            return Err(CameraError::Input(format!(
                "DSM resolution must be positive, got {resolution}"
            )));
        }
        if !(x0.is_finite() && y0.is_finite()) {
            return Err(CameraError::Input("DSM origin must be finite".into()));
        }
        if width == 0 || height == 0 || width > 1 << 20 || height > 1 << 20 {
            return Err(CameraError::Input(format!(
                "DSM size {width}x{height} is empty or too large"
            )));
        }
        UtmZone::from_epsg(epsg)?;
        Ok(DsmGrid {
            x0,
            y0,
            resolution,
            width,
            height,
            epsg,
        })
    }

    /// The grid covering [x_min, x_max] × [y_min, y_max] (UTM metres) at `resolution`.
    pub fn from_bounds(
        x_min: f64,
        y_min: f64,
        x_max: f64,
        y_max: f64,
        resolution: f64,
        epsg: u32,
    ) -> Result<Self> {
        if !(x_max > x_min && y_max > y_min) {
            return Err(CameraError::Input(format!(
                "empty DSM bounds [{x_min}, {x_max}] × [{y_min}, {y_max}]"
            )));
        }
        let cells = |extent: f64| ((extent / resolution).ceil().max(1.0)) as usize;
        DsmGrid::new(
            x_min,
            y_max,
            resolution,
            cells(x_max - x_min),
            cells(y_max - y_min),
            epsg,
        )
    }

    /// The grid of a georeferenced raster of `width` × `height` pixels: north-up, square cells,
    /// UTM.
    pub fn from_georeference(georef: &GeoReference, width: usize, height: usize) -> Result<Self> {
        let gt = georef.geotransform;
        if gt[2] != 0.0 || gt[4] != 0.0 {
            return Err(CameraError::Georeference(format!(
                "rotated or sheared georeference {gt:?}: the DSM grid must be north-up"
            )));
        }
        if !(gt[1] > 0.0 && gt[5] < 0.0) {
            return Err(CameraError::Georeference(format!(
                "georeference {gt:?} is not north-up with eastward columns"
            )));
        }
        if ((gt[1] + gt[5]) / gt[1]).abs() > 1e-9 {
            return Err(CameraError::Georeference(format!(
                "non-square cells {} × {} m",
                gt[1], -gt[5]
            )));
        }
        let epsg = georef
            .epsg
            .ok_or_else(|| CameraError::Georeference("the georeference has no EPSG code".into()))?;
        DsmGrid::new(gt[0], gt[3], gt[1], width, height, epsg)
    }

    /// The grid of a raster read with [`read_tiff`]; an error if it is not georeferenced.
    pub fn of_raster(raster: &GeoRaster, origin: &str) -> Result<Self> {
        let georef = raster.georef.as_ref().ok_or_else(|| {
            CameraError::Georeference(format!("{origin}: the raster has no georeference"))
        })?;
        let (w, h) = raster.image.size();
        Self::from_georeference(georef, w, h).map_err(|e| match e {
            CameraError::Georeference(m) => CameraError::Georeference(format!("{origin}: {m}")),
            e => e,
        })
    }

    /// The grid of a (ground-truth) DSM GeoTIFF.
    pub fn read_geotiff(path: impl AsRef<Path>) -> Result<Self> {
        let path = path.as_ref();
        Self::of_raster(&read_tiff(path)?, &path.display().to_string())
    }

    /// The grid's UTM zone.
    pub fn zone(&self) -> UtmZone {
        UtmZone::from_epsg(self.epsg).expect("checked at construction")
    }

    /// The GDAL-style georeference to write the grid with.
    pub fn georeference(&self) -> GeoReference {
        GeoReference::from_origin_utm(self.x0, self.y0, self.resolution, self.epsg)
    }

    /// The (col, row) of the cell containing UTM (easting, northing): floor, as the benchmark.
    #[inline]
    pub fn cell_of(&self, easting: f64, northing: f64) -> Option<(usize, usize)> {
        let c = ((easting - self.x0) / self.resolution).floor();
        let r = ((self.y0 - northing) / self.resolution).floor();
        (c >= 0.0 && r >= 0.0 && c < self.width as f64 && r < self.height as f64)
            .then_some((c as usize, r as usize))
    }
}

/// The highest altitude of the points falling in each cell of `grid`, NaN where none does.
/// Projections run in parallel; the max makes the result independent of the order.
pub fn rasterize_max(points: &Points, grid: &DsmGrid) -> Image {
    let zone = grid.zone();
    let cells: Vec<(usize, f32)> = points
        .lonlatalt
        .par_iter()
        .with_min_len(4096)
        .map(|&[lon, lat, alt]| {
            if !(lon.is_finite() && lat.is_finite() && alt.is_finite()) {
                return (usize::MAX, 0.0);
            }
            let (e, n) = zone.forward(lon, lat);
            match grid.cell_of(e, n) {
                Some((c, r)) => (r * grid.width + c, alt as f32),
                None => (usize::MAX, 0.0),
            }
        })
        .collect();
    let mut dsm = Image::filled(grid.width, grid.height, 1, f32::NAN);
    let data = dsm.data_mut();
    for (i, alt) in cells {
        if i != usize::MAX {
            let v = &mut data[i];
            if v.is_nan() || alt > *v {
                *v = alt;
            }
        }
    }
    dsm
}

/// Writes a DSM as a float32 GeoTIFF on `grid` (georeference, EPSG, nodata NaN), atomically.
pub fn write_dsm(path: impl AsRef<Path>, image: &Image, grid: &DsmGrid) -> Result<()> {
    let path = path.as_ref();
    if image.size() != (grid.width, grid.height) || image.channels() != 1 {
        return Err(CameraError::Input(format!(
            "{}: DSM image is {}x{}x{} but the grid is {}x{}",
            path.display(),
            image.width(),
            image.height(),
            image.channels(),
            grid.width,
            grid.height
        )));
    }
    let meta = GeoTiffMeta {
        georef: Some(grid.georeference()),
        nodata: Some(f64::NAN),
        rpc: None,
    };
    write_geotiff(path, image, &meta)?;
    Ok(())
}
