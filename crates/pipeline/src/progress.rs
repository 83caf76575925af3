//! Progress reporting for long loops, decoupled from how it is shown.

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
