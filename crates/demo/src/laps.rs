//! The wall time of each step of a demo run, for its report's timings table.

use std::time::Instant;

/// Steps timed one after the other: each lap ends one step and starts the next.
pub struct Laps {
    clock: Instant,
    /// (step, seconds), in order.
    pub seconds: Vec<(String, f64)>,
}

impl Laps {
    pub fn start() -> Self {
        Laps {
            clock: Instant::now(),
            seconds: Vec::new(),
        }
    }

    /// Ends the step `name` and starts the next one.
    pub fn lap(&mut self, name: &str) {
        self.seconds
            .push((name.to_string(), self.clock.elapsed().as_secs_f64()));
        self.clock = Instant::now();
    }
}
