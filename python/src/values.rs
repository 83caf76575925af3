//! What the library returns, as Python values: summaries as dicts (through JSON values, so
//! paths become `str`, tuples lists and `None` stays `None`), grids as a rasterio transform and
//! CRS.

use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use seasonstereo::{
    DsmGrid, DsmSummary, ReconstructOptions, ReconstructSummary, RectifySummary, TileStatus,
};
use serde_json::{json, Value};

/// A JSON value as the Python object `json.loads` would give.
pub fn to_python(py: Python<'_>, value: &Value) -> PyResult<PyObject> {
    Ok(match value {
        Value::Null => py.None(),
        Value::Bool(b) => b.into_pyobject(py)?.to_owned().into_any().unbind(),
        Value::Number(n) => match (n.as_i64(), n.as_f64()) {
            (Some(i), _) => i.into_pyobject(py)?.into_any().unbind(),
            (None, f) => f.unwrap_or(f64::NAN).into_pyobject(py)?.into_any().unbind(),
        },
        Value::String(s) => s.into_pyobject(py)?.into_any().unbind(),
        Value::Array(items) => {
            let items: Vec<PyObject> = items
                .iter()
                .map(|v| to_python(py, v))
                .collect::<PyResult<_>>()?;
            PyList::new(py, items)?.into_any().unbind()
        }
        Value::Object(map) => {
            let dict = PyDict::new(py);
            for (k, v) in map {
                dict.set_item(k, to_python(py, v)?)?;
            }
            dict.into_any().unbind()
        }
    })
}

/// The grid's affine transform in rasterio's order `(a, b, c, d, e, f)`: x = a·col + b·row + c,
/// y = d·col + e·row + f (`rasterio.Affine(*t)`; GDAL's order is `(c, a, b, f, d, e)`).
pub fn transform(grid: &DsmGrid) -> [f64; 6] {
    let r = grid.resolution;
    [r, 0.0, grid.x0, 0.0, -r, grid.y0]
}

/// The grid's CRS as rasterio and pyproj read it, e.g. `EPSG:32617`.
pub fn crs(grid: &DsmGrid) -> String {
    format!("EPSG:{}", grid.epsg)
}

/// What `rectify` wrote and found.
pub fn rectify_summary(s: &RectifySummary) -> Value {
    json!({
        "stem": s.stem, "left": s.left, "right": s.right, "homography": s.homography,
        "report": s.report, "roi": [s.roi.x, s.roi.y, s.roi.width, s.roi.height],
        "alt_range": s.alt_range, "alt_source": s.alt_source,
        "disparity_range": s.disparity_range, "size": s.size,
        "max_row_error": s.max_row_error, "pixels_per_metre": s.pixels_per_metre,
        "right_coverage": s.right_coverage,
    })
}

/// A DSM's grid and coverage: measured cells, and cells with a height after filling.
pub fn dsm_summary(d: &DsmSummary) -> Value {
    let cells = (d.grid.width * d.grid.height).max(1) as f64;
    json!({
        "width": d.grid.width, "height": d.grid.height, "resolution": d.grid.resolution,
        "transform": transform(&d.grid), "crs": crs(&d.grid), "points": d.points,
        "coverage": d.measured_cells as f64 / cells, "filled": d.filled_cells as f64 / cells,
    })
}

/// What `reconstruct` did: its tiles, the DSM, the scores, each step's time, and the warnings
/// the command line prints.
pub fn reconstruct_summary(s: &ReconstructSummary, o: &ReconstructOptions) -> PyResult<Value> {
    let ids = |status| -> Vec<&str> {
        s.records
            .iter()
            .filter(|r| r.status == status)
            .map(|r| r.tile.id.as_str())
            .collect()
    };
    let seconds: serde_json::Map<String, Value> = s
        .seconds
        .iter()
        .map(|(k, t)| (k.to_string(), json!(t)))
        .collect();
    let scores = serde_json::to_value(&s.scores).map_err(crate::errors::value_error)?;
    let pointing = serde_json::to_value(&s.pointing).map_err(crate::errors::value_error)?;
    let products = serde_json::to_value(&s.products).map_err(crate::errors::value_error)?;
    Ok(json!({
        "stem": s.stem, "work": s.work,
        "tiles": {
            "total": s.records.len() + s.missing.len(), "done": ids(TileStatus::Done),
            "empty": ids(TileStatus::Empty), "failed": ids(TileStatus::Failed),
            "missing": s.missing, "ran": s.ran, "in_flight": s.in_flight,
        },
        "disparity_range": s.disparity_range(), "matched": s.matched(),
        "dsm": s.dsm.as_ref().map(dsm_summary), "scores": scores, "seconds": seconds,
        "output": o.output, "warnings": s.warnings(o), "pointing": pointing,
        "products": products,
    }))
}
