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
/// run (resumed), as on the command line. `threads`: this call's worker threads (default: every
/// core, shared by all calls).
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
    let threads = keywords.threads()?;
    keywords.finish()?;
    let callback = Callback::new(py, progress)?;
    let result = compute(py, || {
        options.check_output(overwrite)?;
        seasonstereo::with_threads(threads, || seasonstereo::reconstruct(&options, &callback))
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
    k.finishing(&mut o.finishing, true)?;
    k.tiling(&mut o.tile, &mut o.collar, &mut o.max_memory)?;
    o.both_views = !k.take("single_view")?.unwrap_or(false);
    o.adjust_pointing = !k.take("no_pointing_correction")?.unwrap_or(false);
    o.products = k.products()?;
    shard_keywords(k, &mut o)?;
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

/// `shard` ("I/N"), `merge`, `keep_intermediates`: how this call takes part in a sharded run.
fn shard_keywords(k: &Keywords<'_>, o: &mut ReconstructOptions) -> PyResult<()> {
    if let Some(shard) = k.take::<String>("shard")? {
        o.shard = shard.parse::<Shard>().map_err(value_error)?;
    }
    o.merge_only = k.take("merge")?.unwrap_or(false);
    o.keep_intermediates = k.take("keep_intermediates")?.unwrap_or(false);
    Ok(())
}
