//! Where a forward pass spends its time: wall-clock seconds per module group, collected only
//! while a [`Recording`] is alive (`seasonstereo bench … --profile`). A span synchronises the
//! device before and after its work, so the times of asynchronous (GPU) backends are of the work
//! itself; when nothing records, a span costs one atomic load.

use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Mutex;
use std::time::{Duration, Instant};

use burn::tensor::Device;

static ACTIVE: AtomicBool = AtomicBool::new(false);
static STATE: Mutex<Option<State>> = Mutex::new(None);

struct State {
    device: Device,
    groups: Vec<GroupTime>,
}

/// The time of one module group over a recording.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct GroupTime {
    /// Group name, the same as the PyTorch comparison script's (`scripts/peers/`).
    pub group: &'static str,
    /// Summed wall-clock time of the group's spans.
    pub seconds: f64,
    /// Number of spans.
    pub calls: usize,
}

/// Runs `work` as a span of `group`: timed when a [`Recording`] is alive, plain otherwise.
/// Spans must not nest (the outer one would count the inner one's time twice).
pub fn span<T>(group: &'static str, work: impl FnOnce() -> T) -> T {
    if !ACTIVE.load(Ordering::Relaxed) {
        return work();
    }
    sync();
    let start = Instant::now();
    let out = work();
    sync();
    record(group, start.elapsed());
    out
}

fn sync() {
    let state = STATE.lock().unwrap_or_else(|e| e.into_inner());
    if let Some(s) = state.as_ref() {
        // A failed sync leaves the time unsynchronised, not wrong work: the pass itself reports
        // the backend's error.
        let _ = s.device.sync();
    }
}

fn record(group: &'static str, elapsed: Duration) {
    let mut state = STATE.lock().unwrap_or_else(|e| e.into_inner());
    let Some(s) = state.as_mut() else { return };
    match s.groups.iter_mut().find(|g| g.group == group) {
        Some(g) => {
            g.seconds += elapsed.as_secs_f64();
            g.calls += 1;
        }
        None => s.groups.push(GroupTime {
            group,
            seconds: elapsed.as_secs_f64(),
            calls: 1,
        }),
    }
}

/// Collects span times from its start to [`Recording::finish`]; one at a time per process.
pub struct Recording(());

impl Recording {
    /// Starts recording the spans of work on `device`; `None` when a recording is already alive.
    pub fn start(device: &Device) -> Option<Self> {
        let mut state = STATE.lock().unwrap_or_else(|e| e.into_inner());
        if state.is_some() {
            return None;
        }
        *state = Some(State {
            device: device.clone(),
            groups: Vec::new(),
        });
        ACTIVE.store(true, Ordering::Relaxed);
        Some(Recording(()))
    }

    /// The groups in the order they first ran.
    pub fn finish(self) -> Vec<GroupTime> {
        let groups = take();
        std::mem::forget(self);
        groups
    }
}

impl Drop for Recording {
    fn drop(&mut self) {
        take();
    }
}

fn take() -> Vec<GroupTime> {
    ACTIVE.store(false, Ordering::Relaxed);
    let mut state = STATE.lock().unwrap_or_else(|e| e.into_inner());
    state.take().map(|s| s.groups).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_are_timed_only_while_recording() {
        let device = Device::flex();
        assert_eq!(span("before", || 1), 1);
        let rec = Recording::start(&device).expect("no other recording");
        assert!(
            Recording::start(&device).is_none(),
            "one recording at a time"
        );
        span("a", || std::thread::sleep(Duration::from_millis(20)));
        span("b", || ());
        span("a", || std::thread::sleep(Duration::from_millis(20)));
        let groups = rec.finish();
        let names: Vec<_> = groups.iter().map(|g| (g.group, g.calls)).collect();
        assert_eq!(names, [("a", 2), ("b", 1)]);
        assert!(groups[0].seconds >= 0.04, "{groups:?}");
        span("after", || ());
        let rec = Recording::start(&device).expect("the first one finished");
        assert!(
            rec.finish().is_empty(),
            "spans after a recording are not kept"
        );
    }
}
