//! The API key: read from an environment variable, sent as a header, never shown.

use std::fmt;

use crate::SynthError;

/// A secret API key. It has no `Display`, its `Debug` prints `ApiKey([redacted])`, and the client
/// scrubs it from every log line and error message, so it cannot leak into logs or reports.
#[derive(Clone)]
pub struct ApiKey(String);

impl ApiKey {
    /// Wraps a key given directly (tests, key stores); fails when it is empty.
    pub fn new(key: impl Into<String>) -> Result<Self, SynthError> {
        let key = key.into().trim().to_string();
        if key.is_empty() {
            return Err(SynthError::Input("the API key is empty".into()));
        }
        Ok(Self(key))
    }

    /// Reads the key from the environment variable `var` (e.g. `GEMINI_API_KEY`).
    pub fn from_env(var: &str) -> Result<Self, SynthError> {
        let missing = || SynthError::MissingApiKey {
            var: var.to_string(),
        };
        let value = std::env::var(var).map_err(|_| missing())?;
        Self::new(value).map_err(|_| missing())
    }

    /// The secret itself, for the request header only.
    pub(crate) fn expose(&self) -> &str {
        &self.0
    }

    /// `text` with every occurrence of the key replaced by `[redacted]`.
    pub(crate) fn redact(&self, text: &str) -> String {
        text.replace(&self.0, "[redacted]")
    }
}

impl fmt::Debug for ApiKey {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str("ApiKey([redacted])")
    }
}
