//! Plain values in and out of burn's CPU tensor (`FlexTensor`), for the kernels that run as burn
//! backend extensions ([`crate::conv`], [`crate::interp`]).

use std::borrow::Cow;

use burn::backend::flex::FlexTensor;
use burn::tensor::{DType, Shape, Tensor, TensorData};

/// Elements per parallel task of the element-wise kernels ([`crate::activation`],
/// [`crate::gate`]): large enough that handing a piece to the pool costs little beside it.
pub(crate) const ELEMENTWISE_CHUNK: usize = 1 << 14;

/// The dimensions of a tensor known to have `D` of them.
pub(crate) fn dims<const D: usize>(t: &FlexTensor) -> [usize; D] {
    let shape = t.layout().shape();
    assert_eq!(
        shape.num_dims(),
        D,
        "expected a {D}-d tensor, got {shape:?}"
    );
    std::array::from_fn(|i| shape[i])
}

/// The tensor's `f32` values in row-major order, copied only where its layout is not contiguous.
pub(crate) fn values(t: &FlexTensor) -> Cow<'_, [f32]> {
    match t.as_slice::<f32>() {
        Some(v) => Cow::Borrowed(v),
        None => Cow::Owned(
            t.to_contiguous()
                .as_slice::<f32>()
                .expect("an f32 tensor (callers check the dtype)")
                .to_vec(),
        ),
    }
}

/// `t` with `update` applied to its `f32` values in row-major order: in place where `t` alone
/// owns a buffer holding exactly its values (a gradient handed to a backward usually does), else
/// on a copy.
pub(crate) fn updated(mut t: FlexTensor, update: impl FnOnce(&mut [f32])) -> FlexTensor {
    let n = t.layout().shape().num_elements();
    if t.as_slice::<f32>().is_some() {
        if let Some(v) = t.try_storage_mut::<f32>().filter(|v| v.len() == n) {
            update(v);
            return t;
        }
    }
    let shape = t.layout().shape().clone();
    let mut v = values(&t).into_owned();
    update(&mut v);
    tensor(v, shape)
}

/// A tensor of `values` in row-major order.
pub(crate) fn tensor(values: Vec<f32>, shape: impl Into<Shape>) -> FlexTensor {
    FlexTensor::from_data(TensorData::new(values, shape))
}

/// Whether every tensor holds `f32` (the only dtype the kernels have).
pub(crate) fn all_f32<'a>(tensors: impl IntoIterator<Item = &'a FlexTensor>) -> bool {
    tensors.into_iter().all(|t| t.dtype() == DType::F32)
}

/// A burn tensor's values as `f32`, in row-major order.
pub(crate) fn f32_vec<const D: usize>(t: Tensor<D>) -> Vec<f32> {
    t.into_data()
        .try_into_vec_as::<f32>()
        .expect("a float tensor converts to f32 values")
}
