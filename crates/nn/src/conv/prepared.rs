//! A layer's weights as the kernels read them, prepared once per inference pass.
//!
//! Why: the ConvGRU, the motion encoders and the disparity heads run six or seven times per
//! MonSter++ pass with the same weights, and every run copied them out of their tensor and
//! re-laid them out (Winograd transform, tap order, `convz`/`convr` stacking). Inside
//! [`with_prepared_weights`] a layer's weights are prepared on first use and kept, by parameter
//! id, until the scope ends; outside it, every call prepares its own (as before). Parameters do
//! not change during an inference pass, which is what makes the id a sound key there and only
//! there: the cache is dropped when the outermost scope ends, and it is per thread.

use std::cell::{Cell, RefCell};
use std::collections::HashMap;
use std::sync::{Arc, OnceLock};

use burn::module::ParamId;

use super::kernels::tap_weights;
use super::winograd::transform_weights;

/// A convolution's weights `[co, ci, kh, kw]` (row-major), and the layouts derived from them on
/// first use.
#[derive(Debug)]
pub struct LayerWeights {
    raw: Vec<f32>,
    co: usize,
    taps: usize,
    winograd: OnceLock<Vec<f32>>,
    tap_major: OnceLock<Vec<f32>>,
}

impl LayerWeights {
    /// `raw` is `[co, ci, kh, kw]` with `taps = kh·kw`.
    pub fn new(raw: Vec<f32>, co: usize, taps: usize) -> Self {
        assert!(
            co > 0 && taps > 0 && raw.len().is_multiple_of(co * taps),
            "LayerWeights: {} values are not [{co}, ci, {taps} taps]",
            raw.len()
        );
        LayerWeights {
            raw,
            co,
            taps,
            winograd: OnceLock::new(),
            tap_major: OnceLock::new(),
        }
    }

    /// As stored: `[co, ci, kh, kw]`.
    pub fn raw(&self) -> &[f32] {
        &self.raw
    }

    /// Output channels.
    pub fn co(&self) -> usize {
        self.co
    }

    fn ci(&self) -> usize {
        self.raw.len() / (self.co * self.taps)
    }

    /// Winograd's `U = G·g·Gᵀ` (3×3 kernels only), `[co, 16, ci]`.
    pub(super) fn winograd(&self) -> &[f32] {
        assert_eq!(self.taps, 9, "Winograd F(2×2, 3×3) needs 3×3 kernels");
        self.winograd
            .get_or_init(|| transform_weights(&self.raw, self.co, self.ci()))
    }

    /// Tap-major `[taps, co, ci]`: one `[co, ci]` matrix per kernel tap.
    pub(super) fn tap_major(&self) -> &[f32] {
        self.tap_major
            .get_or_init(|| tap_weights(&self.raw, self.co, self.ci(), self.taps))
    }
}

type Cache = HashMap<(ParamId, &'static str), Arc<LayerWeights>>;

thread_local! {
    static DEPTH: Cell<usize> = const { Cell::new(0) };
    static CACHE: RefCell<Cache> = RefCell::new(HashMap::new());
}

/// Runs `f` (one inference pass) with layer weights prepared once and reused; nested scopes share
/// the outermost one's cache.
pub fn with_prepared_weights<R>(f: impl FnOnce() -> R) -> R {
    struct Scope;
    impl Drop for Scope {
        fn drop(&mut self) {
            let depth = DEPTH.with(|d| {
                d.set(d.get() - 1);
                d.get()
            });
            if depth == 0 {
                CACHE.with(|c| c.borrow_mut().clear());
            }
        }
    }
    DEPTH.with(|d| d.set(d.get() + 1));
    let _scope = Scope;
    f()
}

/// The weights of parameter `id` (`what` tells apart several layouts kept for one parameter),
/// from the scope's cache, or made by `make` (and kept when a scope is open).
pub(crate) fn prepared(
    id: ParamId,
    what: &'static str,
    make: impl FnOnce() -> LayerWeights,
) -> Arc<LayerWeights> {
    if DEPTH.with(Cell::get) == 0 {
        return Arc::new(make());
    }
    if let Some(hit) = CACHE.with(|c| c.borrow().get(&(id, what)).cloned()) {
        return hit;
    }
    let made = Arc::new(make());
    CACHE.with(|c| c.borrow_mut().insert((id, what), made.clone()));
    made
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kept_only_inside_a_scope() {
        let id = ParamId::new();
        let make = || LayerWeights::new(vec![1.0; 18], 2, 9);
        let a = prepared(id, "w", make);
        let b = prepared(id, "w", make);
        assert!(!Arc::ptr_eq(&a, &b), "no scope: nothing kept");
        with_prepared_weights(|| {
            let a = prepared(id, "w", make);
            let b = with_prepared_weights(|| prepared(id, "w", make));
            assert!(
                Arc::ptr_eq(&a, &b),
                "kept for the scope, nested scopes share it"
            );
            let other = prepared(id, "other", make);
            assert!(
                !Arc::ptr_eq(&a, &other),
                "another layout of the same parameter"
            );
        });
        let c = with_prepared_weights(|| prepared(id, "w", make));
        let d = with_prepared_weights(|| prepared(id, "w", make));
        assert!(
            !Arc::ptr_eq(&c, &d),
            "dropped when the outermost scope ends"
        );
    }
}
