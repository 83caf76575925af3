//! OpenEarthMap class ids, as used by the SegFormer masks of the method.

pub const BACKGROUND: u8 = 0;
pub const BARELAND: u8 = 1;
pub const RANGELAND: u8 = 2;
pub const DEVELOPED: u8 = 3;
pub const ROAD: u8 = 4;
pub const TREE: u8 = 5;
pub const WATER: u8 = 6;
pub const AGRICULTURE: u8 = 7;
pub const BUILDING: u8 = 8;
/// Names indexed by id.
pub const NAMES: [&str; 9] = [
    "background",
    "bareland",
    "rangeland",
    "developed space",
    "road",
    "tree",
    "water",
    "agriculture land",
    "building",
];
