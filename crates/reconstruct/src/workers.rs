//! A fixed number of threads working through a list, each taking the next item in turn: the
//! tiles' memory budget allows only so many at once, whatever the number of cores.

use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use anyhow::Result;

use workflow::progress::Progress;

/// Runs `job` on every item (by index) on `workers` threads, advancing `progress` after each.
/// The first error stops the workers from taking new items and is returned; otherwise the
/// number of items done.
pub fn run_on_workers<T: Sync>(
    items: &[T],
    workers: usize,
    job: impl Fn(usize, &T) -> Result<()> + Sync,
    progress: &dyn Progress,
) -> Result<usize> {
    let next = AtomicUsize::new(0);
    let done = AtomicUsize::new(0);
    let failure: Mutex<Option<anyhow::Error>> = Mutex::new(None);
    let worker = || loop {
        if failure.lock().map_or(true, |f| f.is_some()) {
            return;
        }
        let i = next.fetch_add(1, Ordering::SeqCst);
        let Some(item) = items.get(i) else { return };
        if let Err(e) = job(i, item) {
            if let Ok(mut f) = failure.lock() {
                f.get_or_insert(e);
            }
            return;
        }
        progress.advance(done.fetch_add(1, Ordering::SeqCst) + 1);
    };
    std::thread::scope(|s| {
        for _ in 0..workers {
            s.spawn(worker);
        }
    });
    match failure.into_inner().ok().flatten() {
        Some(e) => Err(e),
        None => Ok(done.into_inner()),
    }
}
