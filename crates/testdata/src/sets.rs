//! The data sets the tests read: one entry per set, saying what it is and where it comes from
//! publicly, so that a skipped test tells a user what to fetch.

/// A data set: the folder `<data root>/<name>`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct DataSet {
    /// Its path under the data root, e.g. `data/dfc2019-jax068-dev`.
    pub name: &'static str,
    /// What it holds.
    pub what: &'static str,
    /// Where it comes from publicly.
    pub source: &'static str,
}

/// Every data set a test reads. A set's folder keeps the upstream paths below it, and its own
/// README (where it has one) records versions, seeds and how it was made.
pub const SETS: &[DataSet] = &[
    DataSet {
        name: "data/dfc2019-jax068-dev",
        what: "ten DFC2019 WorldView-3 crops of JAX_068 with RPCs, LiDAR truth and s2p DSMs",
        source: "DFC2019 Track 3 on IEEE DataPort, SatNeRF's layout; README inside",
    },
    DataSet {
        name: "anchors/data/s2p",
        what: "s2p's test data: Pléiades images with RPCs, s2p's rectified tile and DSMs",
        source: "tests/data of github.com/centreborelli/s2p at 4a0b2d8",
    },
    DataSet {
        name: "anchors/data/rpcm",
        what: "rpcm's test RPC file JAX_068_001_RGB.json",
        source: "tests/test_rpc_files of github.com/centreborelli/rpcm at 1c6cc5b",
    },
    DataSet {
        name: "fixtures/monsterpp-tiny",
        what: "MonSter++ parity fixture: tiny configuration, random weights, reference tensors",
        source:
            "github.com/Junda24/MonSter-plusplus at 9167101 run as its README and meta.json say",
    },
    DataSet {
        name: "fixtures/dinov3-tiny",
        what: "DINOv3 ViT parity fixture: tiny configuration, random weights, reference tensors",
        source: "HF transformers 4.57.6 DINOv3ViTModel run as its README and meta.json say",
    },
    DataSet {
        name: "fixtures/segformer-tiny",
        what: "SegFormer parity fixture: tiny configuration, random weights, reference tensors",
        source: "HF transformers 4.57.6 SegformerForSemanticSegmentation run as its README and \
                 meta.json say",
    },
];

/// The entry of set `name`; an unknown name is a mistake in the test, not missing data.
pub(crate) fn find(name: &str) -> &'static DataSet {
    SETS.iter().find(|s| s.name == name).unwrap_or_else(|| {
        let known: Vec<&str> = SETS.iter().map(|s| s.name).collect();
        panic!(
            "testdata: no data set {name:?} (known: {})",
            known.join(", ")
        )
    })
}
