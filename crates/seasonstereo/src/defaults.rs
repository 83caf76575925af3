//! The defaults of the options that the command line shows and the Python keywords take, each
//! declared once where its work is done. (The DSM's cell size is [`crate::flags::RESOLUTION`].)

pub use eval::aggregate::OMAHA_MAX_DISPARITY;
#[cfg(feature = "network")]
pub use nn::infer::DEFAULT_TILE_OVERLAP as NETWORK_TILE_OVERLAP;
pub use reconstruct::finishing::{
    DEFAULT_FILL_CELLS as FILL_CELLS, DEFAULT_FILL_REACH as FILL_REACH,
    DEFAULT_MEDIAN_CELLS as MEDIAN_CELLS, FUSED_MEDIAN_CELLS,
};
pub use reconstruct::many::DEFAULT_PAIRS as PAIRS;
pub use reconstruct::options::{
    DEFAULT_COLLAR as COLLAR, DEFAULT_MEMORY_GIB as MEMORY_GIB, DEFAULT_TILE as TILE,
};
pub use stages::curate::features::DINOV3_NORMALISATION;
pub use stages::masks::SEGFORMER_PRESET;
pub use stages::synthesize::DEFAULT_CROP as SYNTHESIZE_CROP;
pub use synth::api::{
    DEFAULT_API_KEY_ENV as GEMINI_API_KEY_ENV, DEFAULT_BASE_URL as GEMINI_BASE_URL,
    DEFAULT_MODEL as GEMINI_MODEL,
};
