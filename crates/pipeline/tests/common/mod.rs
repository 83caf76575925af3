//! What the real-data tests share.

use std::path::{Path, PathBuf};

/// A file of the DFC2019 JAX_068 development data, read in place.
pub fn jax(rel: &str) -> PathBuf {
    let p = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../../../shared/data/dfc2019-jax068-dev")
        .join(rel);
    assert!(
        p.exists(),
        "development data {} is missing: these tests need /work/shared/data",
        p.display()
    );
    p
}
