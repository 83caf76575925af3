//! What the real-data tests share.

use std::path::PathBuf;

/// The DFC2019 JAX_068 development data: a test reading it starts with
/// `testdata::require!(common::JAX_DEV)`.
pub const JAX_DEV: &str = "data/dfc2019-jax068-dev";

/// A file of the DFC2019 JAX_068 development data, read in place.
pub fn jax(rel: &str) -> PathBuf {
    testdata::checked(JAX_DEV).join(rel)
}
