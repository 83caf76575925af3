//! The native module of the Python package `seasonstereo`: thin bindings over the library
//! façade (`seasonstereo` crate), which the command line calls too, so both give the same
//! values and the same error messages. No stereo logic lives here, only conversions: numpy
//! arrays to images and back, keywords to the library's flag values, library errors to Python
//! exceptions, summaries to dicts.
//!
//! Every call releases the GIL while it computes (threads run in parallel) and turns a panic
//! into a one-line `RuntimeError` (no backtrace on stderr) instead of unwinding into Python. The Python layer
//! (`seasonstereo/__init__.py`) adds the conveniences that are Python's own: RPCs given as
//! dicts, the `Dsm` named tuple.

use pyo3::prelude::*;

mod arrays;
mod errors;
mod files;
mod keywords;
mod many;
mod predict;
mod progress;
mod reconstruct;
mod values;

/// The functions and the version, as `seasonstereo._seasonstereo`.
#[pymodule]
fn _seasonstereo(m: &Bound<'_, PyModule>) -> PyResult<()> {
    errors::quiet_panics();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add(
        "NothingProduced",
        m.py().get_type::<errors::NothingProduced>(),
    )?;
    m.add_function(wrap_pyfunction!(predict::predict, m)?)?;
    m.add_function(wrap_pyfunction!(files::rectify, m)?)?;
    m.add_function(wrap_pyfunction!(files::dsm, m)?)?;
    m.add_function(wrap_pyfunction!(files::read_dsm, m)?)?;
    m.add_function(wrap_pyfunction!(files::score, m)?)?;
    m.add_function(wrap_pyfunction!(reconstruct::reconstruct, m)?)?;
    m.add_function(wrap_pyfunction!(many::reconstruct_many, m)?)?;
    m.add_function(wrap_pyfunction!(errors::panic_for_tests, m)?)?;
    Ok(())
}
