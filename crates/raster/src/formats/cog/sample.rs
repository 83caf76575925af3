//! The tiles' side and how their samples are stored: what the layout and the writer share.

/// Side of the internal tiles, pixels.
pub const COG_TILE: usize = 256;

/// How samples are stored.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Sample {
    F32,
    /// Rounded and clamped to 0–255; NaN becomes 0.
    U8,
}
