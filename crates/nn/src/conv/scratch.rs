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
pub(super) struct Scratch(Vec<f32>);

impl Scratch {
    pub(super) fn take(slot: &'static Slot, len: usize) -> Self {
        let mut v = slot.with(Cell::take);
        v.resize(len, 0.0);
        Scratch(v)
    }

    pub(super) fn give_back(self, slot: &'static Slot) {
        slot.with(|s| s.set(self.0));
    }
}

impl std::ops::Deref for Scratch {
    type Target = [f32];
    fn deref(&self) -> &[f32] {
        &self.0
    }
}

impl std::ops::DerefMut for Scratch {
    fn deref_mut(&mut self) -> &mut [f32] {
        &mut self.0
    }
}
