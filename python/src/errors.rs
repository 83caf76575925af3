//! Library errors as Python exceptions, and the one way every binding runs library code: without
//! the GIL (threads compute in parallel) and with panics caught, so that no Rust panic unwinds
//! into the interpreter.

use std::io::ErrorKind;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Mutex;

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
        Err(panic) => {
            let at = PANIC_AT.lock().ok().and_then(|mut p| p.take());
            Err(PyRuntimeError::new_err(format!(
                "internal error in seasonstereo (please report it): {}{}",
                panic_message(panic.as_ref()).replace('\n', " "),
                at.map_or(String::new(), |at| format!(" (at {at})"))
            )))
        }
    }
}

/// Where the last panic was raised, for the exception's message.
static PANIC_AT: Mutex<Option<String>> = Mutex::new(None);

/// Silences this module's panics (its own copy of the standard library's hook, other
/// extensions keep theirs): [`compute`] turns them into one-line exceptions, which the default
/// hook's message and backtrace on stderr would only repeat or bury. With `RUST_BACKTRACE` set
/// (a developer chasing one) the default hook stays.
pub fn quiet_panics() {
    if std::env::var_os("RUST_BACKTRACE").is_some() {
        return;
    }
    std::panic::set_hook(Box::new(|info| {
        if let (Some(l), Ok(mut at)) = (info.location(), PANIC_AT.lock()) {
            *at = Some(format!("{}:{}", l.file(), l.line()));
        }
    }));
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

/// Panics inside [`compute`] with `message`: how the tests check that a bug in the library
/// reaches Python as one line, nothing printed. Not part of the API.
#[pyfunction(name = "_panic_for_tests")]
pub fn panic_for_tests(py: Python<'_>, message: String) -> PyResult<()> {
    compute(py, move || -> seasonstereo::Result<()> {
        panic!("{message}")
    })
}
