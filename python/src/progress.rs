//! Progress of a long call, handed to an optional Python callable `progress(label, done, total)`.
//!
//! The library reports progress from its worker threads, once per row: the callback is called
//! only when a loop starts, ends, or gains a whole percent, so the GIL is taken about a hundred
//! times per loop, not once per row. An exception raised by the callback cannot stop the worker
//! threads; the first one is kept and raised when the call returns.

use std::sync::Mutex;

use pyo3::prelude::*;
use seasonstereo::Progress;

/// A [`Progress`] calling a Python function, or nothing when there is none.
pub struct Callback {
    function: Option<Py<PyAny>>,
    /// The current loop: label, total steps and the last percent reported.
    current: Mutex<(String, usize, usize)>,
    error: Mutex<Option<PyErr>>,
}

impl Callback {
    /// Calls `function` (when given) with `(label, done, total)`.
    pub fn new(function: Option<Py<PyAny>>) -> Self {
        Callback {
            function,
            current: Mutex::new((String::new(), 0, 0)),
            error: Mutex::new(None),
        }
    }

    /// `result`, or the first exception the callback raised.
    pub fn finish<T>(self, result: PyResult<T>) -> PyResult<T> {
        match self.error.into_inner().ok().flatten() {
            Some(e) => Err(e),
            None => result,
        }
    }

    fn call(&self, label: &str, done: usize, total: usize) {
        let Some(f) = &self.function else {
            return;
        };
        Python::with_gil(|py| {
            if let (Err(e), Ok(mut slot)) = (f.call1(py, (label, done, total)), self.error.lock()) {
                slot.get_or_insert(e);
            }
        });
    }
}

impl Progress for Callback {
    fn begin(&self, label: &str, total: usize) {
        if let Ok(mut c) = self.current.lock() {
            *c = (label.to_string(), total, 0);
        }
        self.call(label, 0, total);
    }

    fn advance(&self, done: usize) {
        let report = self.current.lock().ok().and_then(|mut c| {
            let percent = 100 * done / c.1.max(1);
            (percent > c.2).then(|| {
                c.2 = percent;
                (c.0.clone(), c.1)
            })
        });
        if let Some((label, total)) = report {
            self.call(&label, done, total);
        }
    }

    fn end(&self) {}
}
