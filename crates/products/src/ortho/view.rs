//! What the orthoimage is made from: the views, and how a cell's colour is chosen among them.

use std::path::PathBuf;

use camera::RpcModel;

/// One view of the scene: its image (a TIFF of any size; uint8, uint16 or float; 1 band, 3, or
/// more of which the first three are used) and its camera.
#[derive(Clone, Debug)]
pub struct OrthoView {
    pub image: PathBuf,
    pub rpc: RpcModel,
}

/// How a cell's colour is chosen among the views.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum OrthoBlend {
    /// The most nadir view that sees the cell (the least oblique: the sharpest, and the one
    /// whose small errors of height move the colour least).
    #[default]
    MostNadir,
    /// Per channel, the median of the views that see the cell: evens out the dates' lighting
    /// and hides a passing car, at the cost of some sharpness.
    Median,
}
