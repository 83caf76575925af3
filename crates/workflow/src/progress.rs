//! Progress reporting for long loops, decoupled from how it is shown.

use std::sync::Mutex;

/// Receives the progress of a stage's long loops. Implementations must be cheap: `advance` may be
/// called from many threads, once per row.
pub trait Progress: Sync {
    /// A new loop of `total` steps starts.
    fn begin(&self, label: &str, total: usize);
    /// `done` of the current loop's steps are finished.
    fn advance(&self, done: usize);
    /// The current loop is over.
    fn end(&self);
    /// A line for the log, said as it happens (what was decided, what was found); shown by
    /// default nowhere.
    fn note(&self, _line: &str) {}
    /// The count goes on from `done` of a new `total` under a new label: the next part of one
    /// count over a whole run ([`Sequence`]). By default a new loop, started at `done`.
    fn resume(&self, label: &str, total: usize, done: usize) {
        self.begin(label, total);
        self.advance(done);
    }
}

/// Shows nothing (tests, library use).
pub struct Silent;

impl Progress for Silent {
    fn begin(&self, _: &str, _: usize) {}
    fn advance(&self, _: usize) {}
    fn end(&self) {}
}

/// Runs `work` as one loop named `label`, handing it a `(done, total)` callback for the libraries.
pub fn track<T>(
    progress: &dyn Progress,
    label: &str,
    total: usize,
    work: impl FnOnce(&(dyn Fn(usize, usize) + Sync)) -> T,
) -> T {
    progress.begin(label, total);
    let result = work(&|done, _| progress.advance(done));
    progress.end();
    result
}

/// One count over loops run one after the other (the pairs of a many-date run, each a loop of
/// tiles): loop `k` of `n` goes on from where the earlier ones ended, under the label
/// `"{label} {k+1}/{n}"`, its total re-estimated as the steps done plus `n − k` loops the size
/// of the current one (pairs differ in tiles). `done` never goes back; a display keeping one
/// bar overrides [`Progress::resume`], the others see a new loop per part as before.
pub struct Sequence<'a> {
    inner: &'a dyn Progress,
    label: String,
    parts: usize,
    /// The current part, the steps of the parts before it, the current loop's steps, and
    /// whether the count has begun.
    state: Mutex<(usize, usize, usize, bool)>,
}

impl<'a> Sequence<'a> {
    /// A count over `parts` loops shown as `label` on `inner`.
    pub fn new(inner: &'a dyn Progress, label: &str, parts: usize) -> Self {
        Sequence {
            inner,
            label: label.to_string(),
            parts,
            state: Mutex::new((0, 0, 0, false)),
        }
    }

    /// Part `k` (from 0) runs next: the steps of the part before are counted as done.
    pub fn enter(&self, k: usize) {
        if let Ok(mut s) = self.state.lock() {
            *s = (k, s.1 + s.2, 0, s.3);
        }
    }
}

impl Progress for Sequence<'_> {
    fn begin(&self, _label: &str, total: usize) {
        let Ok(mut s) = self.state.lock() else { return };
        s.2 = total;
        let label = format!("{} {}/{}", self.label, s.0 + 1, self.parts);
        let all = s.1 + total * self.parts.saturating_sub(s.0).max(1);
        if s.3 {
            self.inner.resume(&label, all, s.1);
        } else {
            s.3 = true;
            self.inner.begin(&label, all);
            self.inner.advance(s.1);
        }
    }

    fn advance(&self, done: usize) {
        let before = self.state.lock().map_or(0, |s| s.1 + done.min(s.2));
        self.inner.advance(before);
    }

    fn end(&self) {
        self.inner.end();
    }

    fn note(&self, line: &str) {
        self.inner.note(line);
    }
}
