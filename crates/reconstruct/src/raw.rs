//! Windows of the raw images: a (Geo)TIFF is read by windows, never whole (a WorldView-3 scene
//! is 35,000 × 40,000 px); other formats (PNG, NPY) are read once and cropped.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context, Result};
use camera::RpcModel;
use raster::formats::TiffReader;
use raster::Image;

/// A raw image, opened once for its size and metadata; [`RawImage::window`] reads a region.
pub struct RawImage {
    path: PathBuf,
    size: (usize, usize),
    bands: usize,
    /// The nodata value of a TIFF (its samples become NaN).
    nodata: Option<f32>,
    /// Formats without windowed reading, held whole.
    whole: Option<Arc<Image>>,
    /// The RPC of the TIFF tag, if any.
    pub rpc: Option<RpcModel>,
}

fn is_tiff(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| e.eq_ignore_ascii_case("tif") || e.eq_ignore_ascii_case("tiff"))
}

impl RawImage {
    /// Opens the `which` ("left"/"right") image.
    pub fn open(path: &Path, which: &str) -> Result<Self> {
        let context = || format!("reading the {which} image");
        if !is_tiff(path) {
            let image = raster::read_image(path).with_context(context)?;
            return Ok(RawImage {
                path: path.to_path_buf(),
                size: image.size(),
                bands: image.channels(),
                nodata: None,
                whole: Some(Arc::new(image)),
                rpc: None,
            });
        }
        let reader = TiffReader::open(path).with_context(context)?;
        let rpc = reader
            .rpc
            .as_ref()
            .map(RpcModel::from_tiff_tag)
            .transpose()
            .with_context(|| format!("the RPC tag of {}", path.display()))?;
        Ok(RawImage {
            path: path.to_path_buf(),
            size: reader.size(),
            bands: reader.bands(),
            nodata: reader.nodata.filter(|v| !v.is_nan()).map(|v| v as f32),
            whole: None,
            rpc,
        })
    }

    /// `(width, height)`, pixels.
    pub fn size(&self) -> (usize, usize) {
        self.size
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Number of bands.
    pub fn bands(&self) -> usize {
        self.bands
    }

    /// The window `(x0, y0, width, height)` (inside the image), nodata as NaN. Each call opens
    /// its own reader, so tiles read in parallel.
    pub fn window(&self, x0: usize, y0: usize, width: usize, height: usize) -> Result<Image> {
        if let Some(image) = &self.whole {
            return Ok(raster::geometry::crop(image, x0, y0, width, height)?);
        }
        let mut reader = TiffReader::open(&self.path)
            .with_context(|| format!("reopening {}", self.path.display()))?;
        let mut image = reader.read_window(x0, y0, width, height)?;
        if let Some(nodata) = self.nodata {
            for v in image.data_mut() {
                if *v == nodata {
                    *v = f32::NAN;
                }
            }
        }
        Ok(image)
    }
}
