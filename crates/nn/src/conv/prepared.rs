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
    flipped: OnceLock<Box<LayerWeights>>,
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
            flipped: OnceLock::new(),
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

    /// Input channels.
    pub fn ci(&self) -> usize {
        self.raw.len() / (self.co * self.taps)
    }

    /// Winograd's `U = G·g·Gᵀ` (3×3 kernels only), `[co, 16, ci]`.
    pub(super) fn winograd(&self) -> &[f32] {
        assert_eq!(self.taps, 9, "Winograd F(2×2, 3×3) needs 3×3 kernels");
        self.winograd
            .get_or_init(|| transform_weights(&self.raw, self.co, self.ci()))
    }

    /// The kernel rotated by 180° with its channels swapped (`[ci, co, kh, kw]`): the weights
    /// of the stride-1 convolution that gives a convolution's input gradient.
    pub fn flipped(&self) -> &LayerWeights {
        self.flipped.get_or_init(|| {
            let (co, ci, taps) = (self.co, self.ci(), self.taps);
            let mut out = vec![0.0f32; self.raw.len()];
            for o in 0..co {
                for i in 0..ci {
                    let src = &self.raw[(o * ci + i) * taps..][..taps];
                    let dst = &mut out[(i * co + o) * taps..][..taps];
                    for (d, s) in dst.iter_mut().zip(src.iter().rev()) {
                        *d = *s;
                    }
                }
            }
            Box::new(LayerWeights::new(out, ci, taps))
        })
    }

    /// Tap-major `[taps, co, ci]`: one `[co, ci]` matrix per kernel tap.
    pub(super) fn tap_major(&self) -> &[f32] {
        self.tap_major
            .get_or_init(|| tap_weights(&self.raw, self.co, self.ci(), self.taps))
    }
}

/// What a cache entry was made from: a parameter (one layout of it per `&str`), or a tensor's
/// buffer, by the address and length of its values.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
enum Key {
    Param(ParamId, &'static str),
    Buffer(usize, usize),
}

/// A cache entry; `_pin` keeps the buffer an entry was made from alive (and, shared, immutable),
/// so that no other tensor can take its address while the entry lives.
struct Entry {
    weights: Arc<LayerWeights>,
    _pin: Option<Box<dyn std::any::Any>>,
}

type Cache = HashMap<Key, Entry>;

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
    cached(Key::Param(id, what), None, make)
}

/// The weights made from the values `raw` of a tensor, from the scope's cache or made by `make`.
/// `pin` is the tensor (a shared handle on its buffer), kept with the entry: while it lives the
/// buffer is neither freed nor written in place (burn copies a shared buffer before writing),
/// so its address names these values. What a training step uses: its forward and backward run
/// the same weight tensors many times (the ConvGRU's iterations, the input gradients), and
/// the tensors change only in the optimiser step, outside the scope.
pub(crate) fn prepared_for_buffer(
    raw: &[f32],
    pin: impl std::any::Any,
    make: impl FnOnce() -> LayerWeights,
) -> Arc<LayerWeights> {
    let key = Key::Buffer(raw.as_ptr() as usize, raw.len());
    cached(key, Some(Box::new(pin)), make)
}

fn cached(
    key: Key,
    pin: Option<Box<dyn std::any::Any>>,
    make: impl FnOnce() -> LayerWeights,
) -> Arc<LayerWeights> {
    if DEPTH.with(Cell::get) == 0 {
        return Arc::new(make());
    }
    if let Some(hit) = CACHE.with(|c| c.borrow().get(&key).map(|e| e.weights.clone())) {
        return hit;
    }
    let weights = Arc::new(make());
    let entry = Entry {
        weights: weights.clone(),
        _pin: pin,
    };
    CACHE.with(|c| c.borrow_mut().insert(key, entry));
    weights
}

/// `[co, ci, taps]` → `[taps, co, ci]`: one contiguous `co × ci` matrix per tap.
fn tap_weights(weight: &[f32], co: usize, ci: usize, taps: usize) -> Vec<f32> {
    let mut out = vec![0.0f32; weight.len()];
    for (o, per_out) in weight.chunks_exact(ci * taps).enumerate() {
        for (i, per_in) in per_out.chunks_exact(taps).enumerate() {
            for (t, &v) in per_in.iter().enumerate() {
                out[(t * co + o) * ci + i] = v;
            }
        }
    }
    out
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

    #[test]
    fn buffers_kept_by_address_inside_a_scope() {
        let values = vec![1.0f32; 18];
        let make = || LayerWeights::new(values.clone(), 2, 9);
        with_prepared_weights(|| {
            let a = prepared_for_buffer(&values, (), make);
            let b = prepared_for_buffer(&values, (), make);
            assert!(Arc::ptr_eq(&a, &b), "the same buffer: kept");
            let c = prepared_for_buffer(&values[..9], (), || LayerWeights::new(vec![1.0; 9], 1, 9));
            assert!(!Arc::ptr_eq(&a, &c), "another length: another entry");
        });
        let d = prepared_for_buffer(&values, (), make);
        let e = prepared_for_buffer(&values, (), make);
        assert!(!Arc::ptr_eq(&d, &e), "no scope: nothing kept");
    }

    #[test]
    fn flipped_rotates_the_kernel_and_swaps_channels() {
        // co = 2, ci = 3, 2 taps: w[o, i, t] = 100·o + 10·i + t.
        let raw: Vec<f32> = (0..2)
            .flat_map(|o| {
                (0..3).flat_map(move |i| (0..2).map(move |t| (100 * o + 10 * i + t) as f32))
            })
            .collect();
        let w = LayerWeights::new(raw, 2, 2);
        let f = w.flipped();
        assert_eq!((f.co(), f.ci()), (3, 2));
        for i in 0..3 {
            for o in 0..2 {
                for t in 0..2 {
                    let want = (100 * o + 10 * i + (1 - t)) as f32;
                    assert_eq!(f.raw()[(i * 2 + o) * 2 + t], want, "flipped[{i}, {o}, {t}]");
                }
            }
        }
    }
}
