//! Progress of a long call, handed to an optional Python callable `progress(stage, done, total)`.
//!
//! One count over the whole call: every loop the library starts goes on from where the loops
//! before it ended, and a [`Progress::resume`] (the next pair of a many-date run) goes on under
//! a new stage with a new estimate of its total. A loop's size is known only when it starts, so
//! `total` grows then; neither `done` nor `total` ever goes back. The library reports from its
//! worker threads, once per row: the callback is called when the stage changes or the count
//! gains a whole percent, one call at a time and in order, so the GIL is taken about a hundred
//! times per loop, not once per row. An exception raised by the callback cannot stop the worker
//! threads; the first one is kept and raised when the call returns.

use std::sync::Mutex;

use pyo3::exceptions::PyTypeError;
use pyo3::prelude::*;
use seasonstereo::Progress;

/// The count over the whole call.
#[derive(Default)]
struct Count {
    stage: String,
    /// Steps of the loops finished before the current one.
    before: usize,
    /// Steps of the current loop.
    steps: usize,
    /// The last `(stage, done, total)` reported.
    reported: Option<(String, usize, usize)>,
}

/// A [`Progress`] calling a Python function, or nothing when there is none.
pub struct Callback {
    function: Option<Py<PyAny>>,
    count: Mutex<Count>,
    error: Mutex<Option<PyErr>>,
}

impl Callback {
    /// Calls `function` (when given; a `TypeError` when it is not callable) with
    /// `(stage, done, total)`.
    pub fn new(py: Python<'_>, function: Option<Py<PyAny>>) -> PyResult<Self> {
        if let Some(f) = &function {
            if !f.bind(py).is_callable() {
                return Err(PyTypeError::new_err(format!(
                    "progress is a function progress(stage, done, total), True or None, got {}",
                    f.bind(py).get_type().name()?
                )));
            }
        }
        Ok(Callback {
            function,
            count: Mutex::new(Count::default()),
            error: Mutex::new(None),
        })
    }

    /// `result`, or the first exception the callback raised. A call that succeeded reports its
    /// count complete (the last loops may end short of their estimate).
    pub fn finish<T>(self, result: PyResult<T>) -> PyResult<T> {
        if result.is_ok() {
            if let Ok(mut c) = self.count.lock() {
                if let Some((stage, _, total)) = c.reported.clone() {
                    self.report(&mut c, &stage, total, total);
                }
            }
        }
        match self.error.into_inner().ok().flatten() {
            Some(e) => Err(e),
            None => result,
        }
    }

    /// Reports `done` of `total` in `stage`, kept monotone, when the stage changed or the count
    /// gained a whole percent. Called with the count locked, so calls come in order.
    fn report(&self, c: &mut Count, stage: &str, done: usize, total: usize) {
        let Some(f) = &self.function else {
            return;
        };
        let (done, total, due) = match &c.reported {
            None => (done, total.max(done), true),
            Some((s, d, t)) => {
                let (done, total) = (done.max(*d), total.max(*t));
                let total = total.max(done);
                let percent = |d: usize, t: usize| 100 * d as u128 / t.max(1) as u128;
                let gained = percent(done, total) > percent(*d, *t) || (done == total && done > *d);
                (done, total, s != stage || gained)
            }
        };
        if !due {
            return;
        }
        c.reported = Some((stage.to_string(), done, total));
        Python::with_gil(|py| {
            if let (Err(e), Ok(mut slot)) = (f.call1(py, (stage, done, total)), self.error.lock()) {
                slot.get_or_insert(e);
            }
        });
    }
}

impl Progress for Callback {
    fn begin(&self, label: &str, total: usize) {
        if let Ok(mut c) = self.count.lock() {
            c.before += c.steps;
            c.steps = total;
            c.stage = label.to_string();
            let (done, all) = (c.before, c.before + total);
            self.report(&mut c, label, done, all);
        }
    }

    fn advance(&self, done: usize) {
        if self.function.is_none() {
            return;
        }
        if let Ok(mut c) = self.count.lock() {
            // Taken and put back: no allocation per row.
            let stage = std::mem::take(&mut c.stage);
            let (done, all) = (c.before + done.min(c.steps), c.before + c.steps);
            self.report(&mut c, &stage, done, all);
            c.stage = stage;
        }
    }

    fn end(&self) {}

    fn resume(&self, label: &str, total: usize, done: usize) {
        if let Ok(mut c) = self.count.lock() {
            c.steps = total;
            c.stage = label.to_string();
            let (done, all) = (c.before + done.min(total), c.before + total);
            self.report(&mut c, label, done, all);
        }
    }
}
