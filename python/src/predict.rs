//! `predict`: the disparity of a rectified pair given as numpy arrays.

use numpy::PyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use seasonstereo::RangeSource;

use crate::arrays::{to_numpy, ImageArray};
use crate::errors::{compute, exception};
use crate::keywords::Keywords;
use crate::progress::Callback;

/// The disparity of the rectified pair `left`, `right` (`x_R = x_L − d`, NaN where invalid), by
/// census + MGM (`method="mgm"`) or SGM over `disparity_range` (inclusive; estimated from the
/// images when `None`). The options are the command line's: `p1`, `p2`, `census`, ...; and
/// `threads`, the worker threads of this call (default: all cores, shared).
#[pyfunction]
#[pyo3(signature = (left, right, disparity_range=None, method="mgm", progress=None, **options))]
pub fn predict<'py>(
    py: Python<'py>,
    left: ImageArray<'py>,
    right: ImageArray<'py>,
    disparity_range: Option<[i32; 2]>,
    method: &str,
    progress: Option<Py<PyAny>>,
    options: Option<&Bound<'py, PyDict>>,
) -> PyResult<Bound<'py, PyArray2<f32>>> {
    let keywords = Keywords::new(py, options)?;
    let matcher = keywords.classical(method)?.matcher().map_err(exception)?;
    let threads = keywords.threads()?;
    keywords.finish()?;
    let (left, right) = (left.to_image()?, right.to_image()?);
    let range = RangeSource::flag_or_estimate(disparity_range.map(|[lo, hi]| (lo, hi)));
    let callback = Callback::new(progress);
    let result = compute(py, || {
        seasonstereo::with_threads(threads, || {
            seasonstereo::predict(&left, &right, &matcher, range, &callback)
        })
    });
    to_numpy(py, callback.finish(result)?.disparity)
}
