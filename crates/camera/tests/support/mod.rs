//! The anchor data and development imagery the camera tests read in place (never copied into the
//! repository), found through `testdata`: a test starts with `testdata::require!(<set>)`.
#![allow(dead_code)]

use std::path::PathBuf;

/// s2p's test data (Pléiades images with RPCs, s2p's reference outputs).
pub const S2P: &str = "anchors/data/s2p";
/// rpcm's test RPC file.
pub const RPCM: &str = "anchors/data/rpcm";
/// Real WorldView-3 crops of JAX_068 with their cameras and LiDAR truth.
pub const JAX_DEV: &str = "data/dfc2019-jax068-dev";

pub const JAX_JSON: &str = "tests/test_rpc_files/JAX_068_001_RGB.json";
pub const S2P_IMG1: &str = "tests/data/input_pair/img_01.tif";
pub const S2P_IMG2: &str = "tests/data/input_pair/img_02.tif";

/// `<s2p>/<rel>`.
pub fn s2p(rel: &str) -> PathBuf {
    testdata::checked(S2P).join(rel)
}

/// `<rpcm>/<rel>`.
pub fn rpcm(rel: &str) -> PathBuf {
    testdata::checked(RPCM).join(rel)
}

/// `<dfc2019-jax068-dev>/<rel>`.
pub fn jax_dev(rel: &str) -> PathBuf {
    testdata::checked(JAX_DEV).join(rel)
}
