//! `reconstruct`: from a raw pair to a DSM GeoTIFF, tile by tile, with every option of the
//! command line's `reconstruct` under its name (underscores for dashes) and its defaults.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;
use seasonstereo::{flags, GridChoice, ReconstructOptions, Roi, Shard};

use crate::errors::{compute, exception, value_error};
use crate::keywords::Keywords;
use crate::progress::Callback;
use crate::values::{reconstruct_summary, to_python};

/// Reconstructs the DSM of the raw pair `left`, `right` into `out`; returns a dict with the
/// tiles, the DSM's grid (`transform`, `crs`) and coverage, the scores (with `truth`), each
/// step's time in seconds and the warnings (failed tiles, suspect cameras). An existing `out`
/// is replaced only with `overwrite` or when it is the product of this work folder's earlier
/// run (resumed), as on the command line.
#[pyfunction]
#[pyo3(signature = (left, right, *, out, method="mgm", overwrite=false, progress=None, **options))]
#[allow(clippy::too_many_arguments)] // Python's keywords
pub fn reconstruct(
    py: Python<'_>,
    left: PathBuf,
    right: PathBuf,
    out: PathBuf,
    method: &str,
    overwrite: bool,
    progress: Option<Py<PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyObject> {
    let keywords = Keywords::new(py, options)?;
    let options = reconstruct_options(&keywords, method, [left, right], out)?;
    keywords.finish()?;
    let callback = Callback::new(progress);
    let result = compute(py, || {
        options.check_output(overwrite)?;
        seasonstereo::reconstruct(&options, &callback)
    });
    to_python(
        py,
        &reconstruct_summary(&callback.finish(result)?, &options)?,
    )
}

/// The library's options: its defaults (those of the command line), then the keywords given.
fn reconstruct_options(
    k: &Keywords<'_>,
    method: &str,
    [left, right]: [PathBuf; 2],
    out: PathBuf,
) -> PyResult<ReconstructOptions> {
    let matcher = k.classical(method)?.matcher().map_err(exception)?;
    let mut o = ReconstructOptions::new(left, right, matcher, grid(k)?, out);
    o.rpc_left = k.path("rpc_left")?;
    o.rpc_right = k.path("rpc_right")?;
    o.roi = k
        .take::<[usize; 4]>("roi")?
        .map(|[x, y, w, h]| Roi::new(x, y, w, h));
    o.roi_lonlat = k.take("roi_lonlat")?;
    o.alt_range = k.take::<[f64; 2]>("alt_range")?.map(|[lo, hi]| (lo, hi));
    o.work_dir = k.path("work")?;
    o.truth = k.path("truth")?;
    dsm_keywords(k, &mut o)?;
    tiling_keywords(k, &mut o)?;
    Ok(o)
}

/// The grid of `like` (a DSM), or of `resolution` (metres) and `epsg` (default: the scene's UTM
/// zone): the command line's `--like`, `--resolution`, `--epsg`.
pub fn grid(k: &Keywords<'_>) -> PyResult<GridChoice> {
    let resolution = k.take("resolution")?.unwrap_or(flags::RESOLUTION);
    Ok(flags::grid(
        k.path("like")?,
        resolution,
        None,
        k.take("epsg")?,
    ))
}

/// `gridding` ("median" or "max"), `fill_holes` and `median_filter` (cells, 0 = none).
fn dsm_keywords(k: &Keywords<'_>, o: &mut ReconstructOptions) -> PyResult<()> {
    if let Some(g) = k.take::<String>("gridding")? {
        o.gridding = flags::gridding(&g).map_err(exception)?;
    }
    if let Some(cells) = k.take("fill_holes")? {
        o.fill_holes = flags::fill_cells(cells);
    }
    if let Some(cells) = k.take("median_filter")? {
        o.median_filter = flags::median_cells(cells);
    }
    Ok(())
}

/// `tile`, `collar` (pixels), `max_memory` (GiB), `shard` ("I/N"), `merge`, `keep_intermediates`.
fn tiling_keywords(k: &Keywords<'_>, o: &mut ReconstructOptions) -> PyResult<()> {
    o.tile = k.take("tile")?.unwrap_or(o.tile);
    o.collar = k.take("collar")?.unwrap_or(o.collar);
    if let Some(gib) = k.take("max_memory")? {
        o.max_memory = flags::memory_bytes(gib).map_err(exception)?;
    }
    if let Some(shard) = k.take::<String>("shard")? {
        o.shard = shard.parse::<Shard>().map_err(value_error)?;
    }
    o.merge_only = k.take("merge")?.unwrap_or(false);
    o.keep_intermediates = k.take("keep_intermediates")?.unwrap_or(false);
    Ok(())
}
