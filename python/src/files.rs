//! The steps on files: `rectify` a raw pair, a disparity file to a DSM (`dsm`), `read_dsm`, and
//! `score` a DSM against the benchmark's truth.

use std::path::PathBuf;

use numpy::PyArray2;
use pyo3::prelude::*;
use seasonstereo::{flags, DsmOptions, Finishing, RectifyOptions, Roi};

use crate::arrays::to_numpy;
use crate::errors::{compute, exception, value_error};
use crate::progress::Callback;
use crate::values::{crs, rectify_summary, to_python, transform};

/// A DSM as numpy heights (NaN = no data), its rasterio transform and its CRS.
type Dsm<'py> = (Bound<'py, PyArray2<f32>>, [f64; 6], String);

/// Rectifies the raw pair `left`, `right` from its RPCs into the folder `out`; returns what was
/// written (`left`, `right`, `homography`) and the `disparity_range` to pass to `predict`.
#[pyfunction]
#[pyo3(signature = (left, right, out, *, rpc_left=None, rpc_right=None, roi=None, alt_range=None, stem=None, progress=None))]
#[allow(clippy::too_many_arguments)] // Python's keywords, one per command-line flag
pub fn rectify(
    py: Python<'_>,
    left: PathBuf,
    right: PathBuf,
    out: PathBuf,
    rpc_left: Option<PathBuf>,
    rpc_right: Option<PathBuf>,
    roi: Option<[usize; 4]>,
    alt_range: Option<[f64; 2]>,
    stem: Option<String>,
    progress: Option<Py<PyAny>>,
) -> PyResult<PyObject> {
    let options = RectifyOptions {
        left,
        right,
        out_dir: out,
        roi: roi.map(|[x, y, w, h]| Roi::new(x, y, w, h)),
        rpc_left,
        rpc_right,
        alt_range: alt_range.map(|[lo, hi]| (lo, hi)),
        stem,
    };
    let callback = Callback::new(py, progress)?;
    let result = compute(py, || {
        options.check_output()?;
        seasonstereo::rectify(&options, &callback)
    });
    to_python(py, &rectify_summary(&callback.finish(result)?))
}

/// Triangulates the disparity file of a rectified pair into the DSM GeoTIFF `out` (the command
/// line's `dsm`, same defaults: highest point per cell, no filling) and returns it; an existing
/// `out` is replaced only with `overwrite`.
#[pyfunction]
#[pyo3(signature = (disparity, homography, rpc_left, rpc_right, out, *, like=None, resolution=flags::RESOLUTION, bounds=None, epsg=None, gridding="max", fill_holes=0, median_filter=0, border=0, overwrite=false))]
#[allow(clippy::too_many_arguments)] // Python's keywords, one per command-line flag
pub fn dsm<'py>(
    py: Python<'py>,
    disparity: PathBuf,
    homography: PathBuf,
    rpc_left: PathBuf,
    rpc_right: PathBuf,
    out: PathBuf,
    like: Option<PathBuf>,
    resolution: f64,
    bounds: Option<[f64; 4]>,
    epsg: Option<u32>,
    gridding: &str,
    fill_holes: usize,
    median_filter: usize,
    border: usize,
    overwrite: bool,
) -> PyResult<Dsm<'py>> {
    let options = DsmOptions {
        disparity,
        homography,
        rpc_left,
        rpc_right,
        grid: flags::grid(like, resolution, bounds, epsg),
        border,
        finishing: Finishing::new(
            flags::gridding(gridding).map_err(exception)?,
            flags::fill_cells(fill_holes),
            None,
            flags::median_cells(median_filter),
        ),
        output: out.clone(),
        compare: None,
    };
    compute(py, || {
        options.check_output(overwrite)?;
        seasonstereo::dsm(&options)
    })?;
    read_dsm(py, out, None)
}

/// Reads a DSM: a GeoTIFF, or a DFC2019 plain TIFF with its `.txt` beside it (then `utm_zone`,
/// e.g. `"17N"`, names its zone).
#[pyfunction]
#[pyo3(signature = (path, utm_zone=None))]
pub fn read_dsm<'py>(py: Python<'py>, path: PathBuf, utm_zone: Option<&str>) -> PyResult<Dsm<'py>> {
    let zone = utm_zone
        .map(flags::utm_zone)
        .transpose()
        .map_err(value_error)?;
    let raster = compute(py, || Ok(seasonstereo::read_dsm(&path, zone)?))?;
    let (t, c) = (transform(&raster.grid), crs(&raster.grid));
    Ok((to_numpy(py, raster.image)?, t, c))
}

/// The benchmark's scores of the DSM file `dsm` (on the truth's grid, or cut onto it) against
/// the ground truth `truth` (`<AOI>_DSM.tif`, its `_CLS.tif` beside it); `utm_zone` as in
/// [`read_dsm`], by default the DSM's.
#[pyfunction]
#[pyo3(signature = (dsm, truth, utm_zone=None))]
pub fn score(
    py: Python<'_>,
    dsm: PathBuf,
    truth: PathBuf,
    utm_zone: Option<&str>,
) -> PyResult<PyObject> {
    let zone = utm_zone
        .map(flags::utm_zone)
        .transpose()
        .map_err(value_error)?;
    let scores = compute(py, || {
        let zone = seasonstereo::truth_zone(&dsm, zone)?;
        let truth = seasonstereo::read_truth(&truth, zone)?;
        Ok(serde_json::to_value(seasonstereo::score(&dsm, &truth)?)?)
    })?;
    to_python(py, &scores)
}
