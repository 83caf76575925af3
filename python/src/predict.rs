//! `predict`: the disparity of a rectified pair given as numpy arrays.

use numpy::PyArray2;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use seasonstereo::{flags, RangeSource};

use crate::arrays::{gib, to_numpy, ImageArray};
use crate::errors::{compute, exception};
use crate::keywords::Keywords;
use crate::progress::Callback;

/// `predict`'s memory budget by default, in GiB: the whole pair is matched at once, so the
/// tiled commands' budget would refuse ordinary crops.
const MAX_MEMORY_GIB: f64 = 16.0;

/// The disparity of the rectified pair `left`, `right` (`x_R = x_L − d`, NaN where invalid), by
/// census + MGM (`method="mgm"`) or SGM over `disparity_range` (inclusive; estimated from the
/// images when `None`). The options are the command line's: `p1`, `p2`, `census`, ...;
/// `threads`, the worker threads of this call (default: all cores, shared); and `max_memory`
/// (GiB): a pair whose matching needs more is refused before anything is allocated.
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
    let max_memory = flags::memory_bytes(keywords.take("max_memory")?.unwrap_or(MAX_MEMORY_GIB))
        .map_err(exception)?;
    keywords.finish()?;
    let left = left.to_image("left", max_memory)?;
    let right = right.to_image("right", max_memory)?;
    let callback = Callback::new(py, progress)?;
    let result = compute(py, || {
        let source = RangeSource::flag_or_estimate(disparity_range.map(|[lo, hi]| (lo, hi)));
        // The library's message names the command line's flag; this one the keyword.
        let range = source.resolve(&left, &right).map_err(|e| {
            seasonstereo::Error::msg(format!(
                "estimating the disparity range (give one: disparity_range=(min, max)): {}",
                e.root_cause()
            ))
        })?;
        let needed = matcher.memory_bytes(left.size(), range);
        if needed > max_memory {
            return Err(seasonstereo::Error::msg(format!(
                "matching this pair over disparities {}:{} needs about {:.1} GiB, more than \
                 max_memory ({} GiB): narrow disparity_range, crop the pair, or raise max_memory",
                range.0,
                range.1,
                gib(needed),
                gib(max_memory)
            )));
        }
        seasonstereo::with_threads(threads, || {
            seasonstereo::predict(
                &left,
                &right,
                &matcher,
                RangeSource::Given(range),
                &callback,
            )
        })
    });
    to_numpy(py, callback.finish(result)?.disparity)
}
