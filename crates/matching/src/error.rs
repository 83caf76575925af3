/// Why a pair could not be matched.
#[derive(Debug, thiserror::Error)]
pub enum MatchError {
    /// The two images do not have the same width and height.
    #[error("left and right images differ in size ({}x{} vs {}x{})", left.0, left.1, right.0, right.1)]
    SizeMismatch {
        left: (usize, usize),
        right: (usize, usize),
    },
    /// An image has no pixel.
    #[error("empty image ({0}x{1})")]
    EmptyImage(usize, usize),
    /// `d_max < d_min`: no disparity to test.
    #[error("empty disparity range [{d_min}, {d_max}]")]
    EmptyRange { d_min: i32, d_max: i32 },
    /// The cost volume would not fit in the allowed (or available) memory.
    #[error("matching needs {needed} bytes, more than the {limit} allowed; reduce the disparity range or tile the image")]
    TooLarge { needed: usize, limit: usize },
    /// The volumes could not be allocated.
    #[error("cannot allocate the {needed} bytes matching needs; reduce the disparity range or tile the image")]
    OutOfMemory { needed: usize },
    /// A parameter is out of its domain.
    #[error("invalid matching parameter: {0}")]
    InvalidParams(String),
    /// The disparity range could not be estimated (textureless or unrelated images).
    #[error("cannot estimate the disparity range: {0}")]
    RangeEstimation(String),
}
