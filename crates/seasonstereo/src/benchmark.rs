//! The benchmark's evaluation ([`crate::eval`] with [`crate::EvalOptions`]): the test splits,
//! where the disparities come from, which AOI a pair belongs to and which scoring rules apply.

pub use eval::{AoiRule, Method, Protocol, Split};
