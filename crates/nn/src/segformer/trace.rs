//! Optional capture of named intermediate tensors, for parity checks against the reference.

use burn::tensor::{Tensor, TensorData};

/// Named intermediates of one forward pass (empty and free when disabled).
///
/// Names follow the fixture: `stage{1..4}.patch_embed`, `stage{s}.block{j}.{ln1,sr_kv,attn,mlp,out}`,
/// `stage{s}.out`, `decoder.concat`, `decoder.fused`.
#[derive(Debug, Default)]
pub struct Trace {
    enabled: bool,
    entries: Vec<(String, TensorData)>,
}

impl Trace {
    /// A trace that records nothing (the production path).
    pub fn off() -> Self {
        Self::default()
    }

    /// A trace that records every intermediate.
    pub fn on() -> Self {
        Self {
            enabled: true,
            entries: Vec::new(),
        }
    }

    /// Whether intermediates are recorded.
    pub fn is_enabled(&self) -> bool {
        self.enabled
    }

    /// Records `t` under `name()` when enabled (the name is only built then).
    pub fn record<const D: usize>(&mut self, name: impl FnOnce() -> String, t: &Tensor<D>) {
        if self.enabled {
            self.entries.push((name(), t.clone().into_data()));
        }
    }

    /// The tensor recorded under `name`.
    pub fn get(&self, name: &str) -> Option<&TensorData> {
        self.entries.iter().find(|(n, _)| n == name).map(|(_, d)| d)
    }

    /// Names in recording order.
    pub fn names(&self) -> impl Iterator<Item = &str> {
        self.entries.iter().map(|(n, _)| n.as_str())
    }
}
