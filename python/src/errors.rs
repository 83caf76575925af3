//! Library errors as Python exceptions, and the one way every binding runs library code: without
//! the GIL (threads compute in parallel) and with panics caught, so that no Rust panic unwinds
//! into the interpreter.

use std::io::ErrorKind;
use std::panic::{catch_unwind, AssertUnwindSafe};

use pyo3::create_exception;
use pyo3::exceptions::{
    PyFileExistsError, PyFileNotFoundError, PyOSError, PyPermissionError, PyRuntimeError,
    PyValueError,
};
use pyo3::prelude::*;
use seasonstereo::Incomplete;

create_exception!(
    seasonstereo,
    NothingProduced,
    PyRuntimeError,
    "A run that produced nothing: every tile (or pair) failed or was empty, no DSM written (the \
     command line's exit code 3). The message names the first failure."
);

/// The exception of a library error, with the command line's message (one line, each cause
/// once): a run that produced nothing is a `NothingProduced` (exit code 3), a missing file a
/// `FileNotFoundError`, an existing output without `overwrite` a `FileExistsError`, other
/// file-system failures `OSError`s, and everything else a bad value, `ValueError`.
pub fn exception(e: seasonstereo::Error) -> PyErr {
    let message = seasonstereo::error_line(&e);
    if let Some(Incomplete::Nothing { .. }) = e.downcast_ref::<Incomplete>() {
        return NothingProduced::new_err(message);
    }
    match seasonstereo::io_error_kind(&e) {
        Some(ErrorKind::NotFound) => PyFileNotFoundError::new_err(message),
        Some(ErrorKind::AlreadyExists) => PyFileExistsError::new_err(message),
        Some(ErrorKind::PermissionDenied) => PyPermissionError::new_err(message),
        Some(_) => PyOSError::new_err(message),
        None => PyValueError::new_err(message),
    }
}

/// A `ValueError` with `message` (bad keyword values found before any work).
pub fn value_error(message: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(message.to_string())
}

/// Runs `work` with the GIL released; its error becomes the matching exception, a panic a
/// `RuntimeError` (a bug in the library, never the caller's fault).
pub fn compute<T: Send>(
    py: Python<'_>,
    work: impl FnOnce() -> seasonstereo::Result<T> + Send,
) -> PyResult<T> {
    match py.allow_threads(|| catch_unwind(AssertUnwindSafe(work))) {
        Ok(result) => result.map_err(exception),
        Err(panic) => Err(PyRuntimeError::new_err(format!(
            "internal error in seasonstereo (please report it): {}",
            panic_message(panic.as_ref())
        ))),
    }
}

/// The text a panic was raised with.
fn panic_message(panic: &(dyn std::any::Any + Send)) -> &str {
    if let Some(s) = panic.downcast_ref::<&str>() {
        s
    } else if let Some(s) = panic.downcast_ref::<String>() {
        s
    } else {
        "a panic without message"
    }
}
