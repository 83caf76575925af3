//! burn's autodiff bookkeeping for the crate's custom operations, written once: each kernel's
//! `Autodiff` impl records its backward step with [`RecordOp`], and each backward step starts
//! from [`step_inputs`] and hands its parents' gradients to [`register`].
//!
//! Why: burn's sequence (prepare the parents' nodes, mark the op compute-bound, branch on
//! whether any parent tracks gradients, checkpoint or clone the state, run the forward in both
//! branches, register each parent's gradient) was spelled out in every operation.

use burn::backend::autodiff::checkpoint::base::Checkpointer;
use burn::backend::autodiff::checkpoint::strategy::CheckpointStrategy;
use burn::backend::autodiff::grads::Gradients;
use burn::backend::autodiff::ops::{Backward, Ops, OpsKind, OpsPrep, Tracked};
use burn::backend::autodiff::NodeId;
use burn::backend::tensor::FloatTensor;
use burn::backend::{Autodiff, Backend};

/// A tracked operation before its forward: what a [`RecordOp::record`] state checkpoints with.
pub(crate) type TrackedOp<O, B, C, const N: usize> =
    OpsPrep<O, B, <O as Backward<B, N>>::State, C, N, Tracked>;

/// Per parent of a backward step, its node's id where it takes a gradient.
pub(crate) type ParentIds<const N: usize> = [Option<NodeId>; N];

/// An operation's input tensor on the autodiff backend over `B`.
pub(crate) type Tracking<B, C> = FloatTensor<Autodiff<B, C>>;

/// Recording a backward step (`self`) for an operation of `N` differentiable parents.
pub(crate) trait RecordOp<B: Backend, const N: usize>: Backward<B, N> {
    /// `forward(parents, extra)` on the inner backend, with `self` as its backward step where a
    /// parent tracks gradients; `state(prep, parents, extra)` is what the step keeps, taken
    /// only then and before the forward (so it can checkpoint the parents or clone what the
    /// forward consumes). `extra` is what the forward takes besides the parents.
    #[inline]
    fn record<C: CheckpointStrategy, E>(
        self,
        parents: [Tracking<B, C>; N],
        extra: E,
        state: impl FnOnce(&mut TrackedOp<Self, B, C, N>, &[Tracking<B, C>; N], &E) -> Self::State,
        forward: impl FnOnce([FloatTensor<B>; N], E) -> FloatTensor<B>,
    ) -> Tracking<B, C> {
        let nodes = parents.each_ref().map(|parent| parent.node());
        match self.prepare::<C>(nodes).compute_bound().stateful() {
            OpsKind::Tracked(mut prep) => {
                let state = state(&mut prep, &parents, &extra);
                let out = forward(parents.map(|parent| parent.into_primitive()), extra);
                prep.finish(state, out)
            }
            OpsKind::UnTracked(prep) => prep.finish(forward(
                parents.map(|parent| parent.into_primitive()),
                extra,
            )),
        }
    }

    /// [`record`](Self::record) for a step whose state is made from the operation's output.
    #[inline]
    fn record_from_output<C: CheckpointStrategy>(
        self,
        parents: [Tracking<B, C>; N],
        forward: impl FnOnce([FloatTensor<B>; N]) -> FloatTensor<B>,
        state: impl FnOnce(FloatTensor<B>) -> Self::State,
    ) -> Tracking<B, C> {
        let nodes = parents.each_ref().map(|parent| parent.node());
        match self.prepare::<C>(nodes).compute_bound().stateful() {
            OpsKind::Tracked(prep) => {
                let out = forward(parents.map(|parent| parent.into_primitive()));
                prep.finish(state(out.clone()), out)
            }
            OpsKind::UnTracked(prep) => {
                prep.finish(forward(parents.map(|parent| parent.into_primitive())))
            }
        }
    }
}

impl<B: Backend, O: Backward<B, N>, const N: usize> RecordOp<B, N> for O {}

/// What a backward step starts from: the gradient of the operation's output (taken out of
/// `grads`), the recorded state, and the ids of the parents that take a gradient.
pub(crate) fn step_inputs<B: Backend, S, const N: usize>(
    ops: Ops<S, N>,
    grads: &mut Gradients,
) -> (FloatTensor<B>, S, ParentIds<N>) {
    let grad = grads.consume::<B>(&ops.node);
    (grad, ops.state, ops.parents.map(|p| p.map(|node| node.id)))
}

/// Registers `grad()` as the gradient of `parent` where it takes one; `grad` runs only then.
pub(crate) fn register<B: Backend>(
    grads: &mut Gradients,
    parent: Option<NodeId>,
    grad: impl FnOnce() -> FloatTensor<B>,
) {
    if let Some(id) = parent {
        grads.register::<B>(id, grad());
    }
}

/// A state checkpointing the first two parents (a layer's input and weight) with the layer's
/// `geometry`: the convolutions keep no copy of their input, burn's checkpointer holds it.
pub(crate) fn checkpoint_input_and_weight<O, B, C, G, const N: usize>(
    prep: &mut TrackedOp<O, B, C, N>,
    parents: &[Tracking<B, C>; N],
    geometry: &G,
) -> ([NodeId; 2], G)
where
    O: Backward<B, N, State = ([NodeId; 2], G)>,
    B: Backend,
    C: CheckpointStrategy,
    G: Clone + Send + std::fmt::Debug + 'static,
{
    let ids = [prep.checkpoint(&parents[0]), prep.checkpoint(&parents[1])];
    (ids, geometry.clone())
}

/// [`step_inputs`] of a step recorded with [`checkpoint_input_and_weight`]: the output gradient,
/// the input and the weight, the geometry and the parents' ids.
pub(crate) fn checkpointed_step_inputs<B: Backend, G, const N: usize>(
    ops: Ops<([NodeId; 2], G), N>,
    grads: &mut Gradients,
    checkpointer: &mut Checkpointer,
) -> (FloatTensor<B>, [FloatTensor<B>; 2], G, ParentIds<N>) {
    let (grad, (ids, geometry), parents) = step_inputs::<B, _, N>(ops, grads);
    let saved = ids.map(|id| checkpointer.retrieve_node_output(id));
    (grad, saved, geometry, parents)
}
