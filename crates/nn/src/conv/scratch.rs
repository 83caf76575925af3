//! Buffers kept per thread between kernel calls.

use std::cell::Cell;

pub(super) type Slot = std::thread::LocalKey<Cell<Vec<f32>>>;

thread_local! {
    /// The full-width output rows of the tap GEMMs.
    pub(super) static WIDE: Cell<Vec<f32>> = const { Cell::new(Vec::new()) };
    /// The zero-padded input of the tap GEMMs.
    pub(super) static PADDED: Cell<Vec<f32>> = const { Cell::new(Vec::new()) };
    /// The unfolded input (im2col) of strided and thin convolutions, and the per-pixel
    /// products of the transposed convolution.
    pub(super) static COLUMNS: Cell<Vec<f32>> = const { Cell::new(Vec::new()) };
}

/// A buffer kept per thread between calls: a fresh allocation of this size costs more in page
/// faults than the work done in it. Taken out of its slot while in use, so a nested call (rayon
/// may run another convolution on this thread while the GEMM waits) gets a buffer of its own.
/// Its contents are garbage from the last use: callers write before they read.
pub(super) struct Scratch {
    buffer: Vec<f32>,
    len: usize,
}

impl Scratch {
    /// The slot's buffer, grown to at least `len` (never shrunk: a shrink and the next growth
    /// would zero the same memory again).
    pub(super) fn take(slot: &'static Slot, len: usize) -> Self {
        let mut buffer = slot.with(Cell::take);
        if buffer.len() < len {
            buffer.resize(len, 0.0);
        }
        Scratch { buffer, len }
    }

    pub(super) fn give_back(self, slot: &'static Slot) {
        slot.with(|s| s.set(self.buffer));
    }
}

impl std::ops::Deref for Scratch {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        &self.buffer[..self.len]
    }
}

impl std::ops::DerefMut for Scratch {
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.buffer[..self.len]
    }
}
