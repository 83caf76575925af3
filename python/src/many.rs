//! `reconstruct_many`: every acquisition of an area → the best pairs → one fused DSM, with every
//! option of the command line's `reconstruct-many` under its name (underscores for dashes) and
//! its defaults.

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyDict;
use seasonstereo::{flags, ReconstructManyOptions, ReconstructManySummary};
use serde_json::{json, Value};

use crate::errors::{compute, exception, value_error};
use crate::keywords::Keywords;
use crate::progress::Callback;
use crate::reconstruct::grid;
use crate::values::{crs, to_python, transform};

/// Chooses the best pairs of `images` (two or more; cameras `<stem>.json` in `rpc_dir`, else
/// the images' RPC tags), reconstructs each and fuses them into `out`; returns the summary the
/// report holds (chosen pairs with their score terms, per-pair outcomes, the fused DSM's files,
/// grid and coverage, scores, seconds) and the warnings (incomplete pairs). `threads`: this
/// call's worker threads (default: every core, shared by all calls). Fewer than two images are
/// refused here, as the library words it: it reads the first image before it counts them.
#[pyfunction]
#[pyo3(signature = (images, rpc_dir=None, *, out, method="mgm", overwrite=false, progress=None, **options))]
#[allow(clippy::too_many_arguments)] // Python's keywords
pub fn reconstruct_many(
    py: Python<'_>,
    images: Vec<PathBuf>,
    rpc_dir: Option<PathBuf>,
    out: PathBuf,
    method: &str,
    overwrite: bool,
    progress: Option<Py<PyAny>>,
    options: Option<&Bound<'_, PyDict>>,
) -> PyResult<PyObject> {
    if images.len() < 2 {
        return Err(value_error(format!(
            "reconstruct_many needs two or more images of the area, got {}{}: give every \
             acquisition (or use reconstruct for one pair)",
            images.len(),
            images
                .first()
                .map_or(String::new(), |p| format!(" ({})", p.display()))
        )));
    }
    let keywords = Keywords::new(py, options)?;
    let mut options = many_options(&keywords, method, images, rpc_dir, out)?;
    let threads = keywords.threads()?;
    keywords.finish()?;
    options.overwrite = overwrite;
    let callback = Callback::new(py, progress)?;
    let result = compute(py, || {
        let s = seasonstereo::with_threads(threads, || {
            seasonstereo::reconstruct_many(&options, &callback)
        })?;
        s.check_produced()?;
        Ok(s)
    });
    to_python(py, &many_summary(&callback.finish(result)?)?)
}

/// The library's options: its defaults (those of the command line), then the keywords given.
fn many_options(
    k: &Keywords<'_>,
    method: &str,
    images: Vec<PathBuf>,
    rpc_dir: Option<PathBuf>,
    out: PathBuf,
) -> PyResult<ReconstructManyOptions> {
    let matcher = k.classical(method)?.matcher().map_err(exception)?;
    let mut o = ReconstructManyOptions::new(images, rpc_dir, matcher, grid(k)?, out);
    o.work_dir = k.path("work")?;
    o.pairs = k.take("pairs")?.unwrap_or(o.pairs);
    o.dry_run = k.take("dry_run")?.unwrap_or(false);
    o.cluster_tolerance = k.take("cluster_tolerance")?.unwrap_or(o.cluster_tolerance);
    o.min_support = k.take("min_support")?;
    o.min_confidence = k.take("min_confidence")?;
    o.co_register = k.take("register")?.unwrap_or(false);
    o.weight_pairs = k.take("pair_weights")?.unwrap_or(false);
    k.finishing(&mut o.finishing, false)?;
    if let Some(cells) = k.take("pair_median_filter")? {
        o.pair_median_filter = flags::median_cells(cells);
    }
    o.both_views = !k.take("single_view")?.unwrap_or(false);
    o.adjust_pointing = !k.take("no_pointing_correction")?.unwrap_or(false);
    o.products = k.products()?;
    o.truth = k.path("truth")?;
    o.alt_range = k.take::<[f64; 2]>("alt_range")?.map(|[lo, hi]| (lo, hi));
    k.tiling(&mut o.tile, &mut o.collar, &mut o.max_memory)?;
    if let Some(shard) = k.take::<String>("shard")? {
        o.shard = shard.parse().map_err(value_error)?;
    }
    Ok(o)
}

/// The summary as the report writes it, the fused grid as a rasterio transform and CRS, and the
/// warnings the command line prints.
fn many_summary(s: &ReconstructManySummary) -> PyResult<Value> {
    let mut value = serde_json::to_value(s).map_err(value_error)?;
    if let (Some(f), Some(fused)) = (&s.fused, value.get_mut("fused")) {
        fused["transform"] = json!(transform(&f.grid));
        fused["crs"] = json!(crs(&f.grid));
    }
    value["warnings"] = json!(s.warnings());
    value["cameras"] = adjusted_cameras(s);
    Ok(value)
}

/// The cameras the bundle adjustment wrote, as rpcm dictionaries by image stem (empty when it
/// did not run).
fn adjusted_cameras(s: &ReconstructManySummary) -> Value {
    let mut cameras = serde_json::Map::new();
    if s.pointing.is_some() {
        for v in &s.views {
            let Some(file) = &v.rpc_file else { continue };
            let read = std::fs::read_to_string(file).ok();
            let value = read.and_then(|t| serde_json::from_str::<Value>(&t).ok());
            if let (Some(stem), Some(mut value)) = (v.image.file_stem(), value) {
                cameras.insert(stem.to_string_lossy().into_owned(), value["rpc"].take());
            }
        }
    }
    Value::Object(cameras)
}
