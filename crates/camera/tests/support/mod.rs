//! Paths to the shared anchor data, read in place (never copied into the repository).
#![allow(dead_code)]

use std::path::PathBuf;

/// `<shared>/<dir>/<rel>`, panicking with a clear message when it is missing.
fn shared(dir: &str, rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/"))
        .join(dir)
        .join(rel);
    assert!(
        p.exists(),
        "shared data file {} is missing: these tests need /work/shared/{dir}",
        p.display()
    );
    p
}

/// `<shared>/anchors/data/<rel>`.
pub fn anchor(rel: &str) -> PathBuf {
    shared("anchors/data", rel)
}

pub const JAX_JSON: &str = "rpcm/tests/test_rpc_files/JAX_068_001_RGB.json";
pub const S2P_IMG1: &str = "s2p/tests/data/input_pair/img_01.tif";
pub const S2P_IMG2: &str = "s2p/tests/data/input_pair/img_02.tif";

/// `<shared>/data/dfc2019-jax068-dev/<rel>`: real WorldView-3 crops of JAX_068 with their
/// cameras and LiDAR truth, read in place.
pub fn jax_dev(rel: &str) -> PathBuf {
    shared("data/dfc2019-jax068-dev", rel)
}
