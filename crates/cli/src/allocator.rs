//! When the allocator hands freed pages back to the kernel.

/// `mi_option_purge_delay` of mimalloc's `mi_option_e` (`mimalloc.h`).
const MI_OPTION_PURGE_DELAY: libmimalloc_sys::mi_option_t = 15;

/// Freed pages are never handed back to the kernel. mimalloc's default returns the pages of a
/// network's tensors between two layers and faults them in again, zeroed, for the next (32,000
/// page faults and a tenth of a MonSter++ pass, BENCHMARKS.md); a stage's memory then stays at
/// its peak until the process ends, which is the figure a memory budget plans for. Called
/// before any thread starts.
pub fn keep_freed_pages() {
    set_purge_delay(-1);
}

/// Freed pages go back to the kernel `ms` milliseconds after they are freed (mimalloc's default
/// is 10): for runs of steps of different sizes, so the process holds the largest step's peak
/// rather than the sum of all of them.
pub fn return_freed_pages_after(ms: std::ffi::c_long) {
    set_purge_delay(ms);
}

fn set_purge_delay(ms: std::ffi::c_long) {
    // SAFETY: sets a plain integer option of the allocator; mimalloc reads it atomically.
    unsafe { libmimalloc_sys::mi_option_set(MI_OPTION_PURGE_DELAY, ms) };
}
