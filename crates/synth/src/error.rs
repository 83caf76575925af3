use std::path::PathBuf;

/// What went wrong while generating or checking a seasonal variant. Messages name the file, the
/// endpoint or the input at fault and, where there is one, the fix. None of them ever contains
/// the API key.
#[derive(Debug, thiserror::Error)]
pub enum SynthError {
    /// The source image, its class map or a parameter cannot be used as given.
    #[error("{0}")]
    Input(String),
    /// Reading or writing a raster failed.
    #[error(transparent)]
    Raster(#[from] raster::RasterError),
    /// The environment variable that should hold the API key is unset or empty.
    #[error(
        "environment variable {var} holds no API key: export your key there (or choose another \
         variable in the generator settings), or use the built-in seasonal model instead"
    )]
    MissingApiKey { var: String },
    /// The API answered with an error status (after retries, where the status was retryable).
    #[error("{url}: HTTP {status} after {attempts} attempt(s): {message}")]
    Http {
        url: String,
        status: u16,
        attempts: u32,
        message: String,
    },
    /// No answer from the API: connection failure or timeout, after retries.
    #[error("{url}: no response after {attempts} attempt(s): {message}")]
    Transport {
        url: String,
        attempts: u32,
        message: String,
    },
    /// The API answered 200 but the body is not a usable image response.
    #[error("{url}: unusable response: {message}")]
    Response { url: String, message: String },
    /// The prompts file is missing, unreadable or incomplete.
    #[error("{}: {message}", path.display())]
    Prompts { path: PathBuf, message: String },
    /// The on-disk response cache could not be read or written.
    #[error("response cache {}: {source}", path.display())]
    Cache {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
}
