//! Client of a generative image-editing API (Gemini `generateContent` with image output, the
//! "Nano Banana Pro" model of the paper), as a [`SeasonGenerator`].
//!
//! One request per (image, season): `POST {base}/v1beta/models/{model}:generateContent` with the
//! season's prompt and the source as an inline PNG (the release's request format),
//! the key in the `x-goog-api-key` header. Robust for dataset builds of thousands of requests:
//! - timeouts, and retries with exponential backoff and jitter on 429, 408, 5xx, timeouts and
//!   connection failures, honouring `Retry-After`;
//! - a concurrency limit shared by all threads using the generator;
//! - an on-disk cache keyed by a hash of (model, prompt, generation settings, image bytes): a
//!   rerun never pays twice;
//! - the answer is resized back to the source size when the model returns another size
//!   ([`Generated::returned_size`] says so).
//!
//! The API key is read from an environment variable, sent only as a header, and never appears
//! in a log line, an error message or a `Debug` output.

mod cache;
mod codec;
mod key;
mod protocol;
mod retry;
mod semaphore;

use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Arc;
use std::time::{Duration, SystemTime};

use raster::Image;
use serde_json::{json, Value};

use crate::prompts::Prompts;
use crate::{Season, SeasonGenerator, SourceImage, SynthError};
use cache::ResponseCache;
use retry::{parse_retry_after, retryable_status};
use semaphore::Semaphore;

pub use key::ApiKey;

/// The model the release uses (`single_generation.py`, `batch_generation.py`).
pub const DEFAULT_MODEL: &str = "gemini-3-pro-image-preview";
/// The public Gemini API endpoint.
pub const DEFAULT_BASE_URL: &str = "https://generativelanguage.googleapis.com";
/// Environment variable holding the key by default.
pub const DEFAULT_API_KEY_ENV: &str = "GEMINI_API_KEY";

/// Settings of [`GeminiGenerator`].
#[derive(Clone, Debug)]
pub struct GeminiConfig {
    /// Scheme, host and port of the API (a loopback fake server in tests).
    pub base_url: String,
    pub model: String,
    /// Environment variable the key is read from by [`GeminiGenerator::new`].
    pub api_key_env: String,
    pub prompts: Prompts,
    /// Sampling temperature (the release: 0.2).
    pub temperature: f32,
    /// Output aspect ratio; `None` picks the supported ratio nearest to the source's (1:1 for
    /// the paper's 1024² crops, as in the release).
    pub aspect_ratio: Option<String>,
    /// Output size class (`"1K"` in the release); `None` leaves it to the model.
    pub image_size: Option<String>,
    /// Whole-request timeout (connect, send, wait, receive).
    pub timeout: Duration,
    /// Retries after the first attempt.
    pub max_retries: u32,
    /// First backoff delay, doubled at each retry up to `max_backoff`.
    pub initial_backoff: Duration,
    pub max_backoff: Duration,
    /// Longest `Retry-After` honoured (longer ones are cut to this).
    pub max_retry_after: Duration,
    /// Requests in flight at once, over all threads.
    pub max_concurrent: usize,
    /// Directory of the response cache; `None` disables caching.
    pub cache_dir: Option<PathBuf>,
}

impl Default for GeminiConfig {
    fn default() -> Self {
        Self {
            base_url: DEFAULT_BASE_URL.into(),
            model: DEFAULT_MODEL.into(),
            api_key_env: DEFAULT_API_KEY_ENV.into(),
            prompts: Prompts::default(),
            temperature: 0.2,
            aspect_ratio: None,
            image_size: Some("1K".into()),
            timeout: Duration::from_secs(300),
            max_retries: 5,
            initial_backoff: Duration::from_secs(2),
            max_backoff: Duration::from_secs(120),
            max_retry_after: Duration::from_secs(600),
            max_concurrent: 4,
            cache_dir: None,
        }
    }
}

/// Receives the client's log lines (already scrubbed of the key). The default forwards them to
/// the `log` crate (target `synth::api`).
pub type LogSink = Arc<dyn Fn(&str) + Send + Sync>;

/// One generated variant with how it was obtained.
#[derive(Clone, Debug)]
pub struct Generated {
    /// RGB 0–255, the source's size.
    pub image: Image,
    /// Taken from the cache (no request made).
    pub from_cache: bool,
    /// HTTP attempts made for it (0 when cached).
    pub attempts: u32,
    /// Size of the image the API returned; differs from the source's when it was resized back.
    pub returned_size: (usize, usize),
    pub resized: bool,
}

/// Counters over the generator's lifetime.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ClientStats {
    /// HTTP requests sent (retries included).
    pub requests: u64,
    /// Of which retries.
    pub retries: u64,
    /// Variants served from the cache.
    pub cache_hits: u64,
    /// Variants generated and stored in the cache.
    pub cache_writes: u64,
}

#[derive(Default)]
struct Counters {
    requests: AtomicU64,
    retries: AtomicU64,
    cache_hits: AtomicU64,
    cache_writes: AtomicU64,
    jitter: AtomicU64,
}

/// The generative backend. See the [module documentation](self).
pub struct GeminiGenerator {
    config: GeminiConfig,
    key: ApiKey,
    agent: ureq::Agent,
    endpoint: String,
    semaphore: Semaphore,
    cache: Option<ResponseCache>,
    log: LogSink,
    counters: Counters,
}

impl std::fmt::Debug for GeminiGenerator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("GeminiGenerator")
            .field("endpoint", &self.endpoint)
            .field("key", &self.key)
            .field("config", &self.config)
            .finish_non_exhaustive()
    }
}

/// Outcome of one HTTP attempt.
enum Attempt {
    Done(Vec<u8>),
    Retry {
        why: String,
        retry_after: Option<Duration>,
        /// The HTTP status, when the server answered.
        status: Option<u16>,
    },
    Fail(SynthError),
}

impl GeminiGenerator {
    /// A client reading its key from `config.api_key_env`.
    pub fn new(config: GeminiConfig) -> Result<Self, SynthError> {
        let key = ApiKey::from_env(&config.api_key_env)?;
        Self::with_api_key(config, key)
    }

    /// A client with an explicit key.
    pub fn with_api_key(config: GeminiConfig, key: ApiKey) -> Result<Self, SynthError> {
        let base = config.base_url.trim_end_matches('/');
        if !(base.starts_with("http://") || base.starts_with("https://")) {
            return Err(SynthError::Input(format!(
                "API base URL {base:?} must start with http:// or https://"
            )));
        }
        if config.model.is_empty() || config.model.contains(['/', '?', '#', ' ']) {
            return Err(SynthError::Input(format!(
                "model name {:?} is not a plain model id (e.g. {DEFAULT_MODEL})",
                config.model
            )));
        }
        let endpoint = format!("{base}/v1beta/models/{}:generateContent", config.model);
        let loopback = ["http://127.0.0.1", "http://localhost", "http://[::1]"]
            .iter()
            .any(|p| base.starts_with(p));
        let mut builder = ureq::Agent::config_builder()
            .http_status_as_error(false)
            .timeout_global(Some(config.timeout))
            .user_agent(concat!("seasonstereo-synth/", env!("CARGO_PKG_VERSION")));
        if loopback {
            // A local (test) server is never reached through an environment proxy.
            builder = builder.proxy(None);
        }
        let agent: ureq::Agent = builder.build().into();
        let log: LogSink = Arc::new(|line: &str| log::info!(target: "synth::api", "{line}"));
        Ok(Self {
            semaphore: Semaphore::new(config.max_concurrent),
            cache: config.cache_dir.clone().map(ResponseCache::new),
            endpoint,
            agent,
            key,
            log,
            counters: Counters::default(),
            config,
        })
    }

    /// Sends the client's log lines to `sink` instead of the `log` crate.
    pub fn with_log_sink(mut self, sink: LogSink) -> Self {
        self.log = sink;
        self
    }

    pub fn config(&self) -> &GeminiConfig {
        &self.config
    }

    /// The request URL (it carries no secret).
    pub fn endpoint(&self) -> &str {
        &self.endpoint
    }

    pub fn stats(&self) -> ClientStats {
        let c = &self.counters;
        ClientStats {
            requests: c.requests.load(Ordering::Relaxed),
            retries: c.retries.load(Ordering::Relaxed),
            cache_hits: c.cache_hits.load(Ordering::Relaxed),
            cache_writes: c.cache_writes.load(Ordering::Relaxed),
        }
    }

    fn log(&self, line: &str) {
        (self.log)(&self.key.redact(line));
    }

    /// The generation settings sent with every request (and hashed into the cache key).
    fn generation_config(&self, width: usize, height: usize) -> Value {
        let mut image_config = serde_json::Map::new();
        let ratio = self
            .config
            .aspect_ratio
            .clone()
            .unwrap_or_else(|| protocol::nearest_aspect_ratio(width, height));
        image_config.insert("aspectRatio".into(), ratio.into());
        if let Some(size) = &self.config.image_size {
            image_config.insert("imageSize".into(), size.clone().into());
        }
        json!({
            "responseModalities": ["IMAGE"],
            "temperature": self.config.temperature,
            "imageConfig": image_config,
        })
    }

    /// Generates (or fetches from the cache) the `season` variant of `source`.
    pub fn generate_detailed(
        &self,
        source: &SourceImage<'_>,
        season: Season,
    ) -> Result<Generated, SynthError> {
        source.validate()?;
        let (w, h) = source.image.size();
        let input = codec::encode_rgb_png(source.image)
            .map_err(|e| SynthError::Input(format!("{}: cannot encode as PNG: {e}", source.id)))?;
        let prompt = self.config.prompts.prompt(season);
        let generation = self.generation_config(w, h);
        let generation_text = generation.to_string();
        let cache_key = ResponseCache::key(&[
            self.config.model.as_bytes(),
            prompt.as_bytes(),
            generation_text.as_bytes(),
            &input,
        ]);
        let label = format!("{} {season}", source.id);

        if let Some(cache) = &self.cache {
            if let Some((path, bytes)) = cache.get(&cache_key)? {
                match codec::decode_image(&bytes) {
                    Ok(image) => {
                        self.counters.cache_hits.fetch_add(1, Ordering::Relaxed);
                        self.log(&format!("{label}: from cache {}", path.display()));
                        return self.finish(image, (w, h), true, 0, &label);
                    }
                    Err(e) => self.log(&format!(
                        "{label}: ignoring unreadable cache entry {}: {e}",
                        path.display()
                    )),
                }
            }
        }

        let body = protocol::request_body(&prompt, &input, &generation).to_string();
        let (bytes, attempts) = self.post_with_retries(&body, &label)?;
        let response_error = |message: String| SynthError::Response {
            url: self.endpoint.clone(),
            message: self.key.redact(&format!("{label}: {message}")),
        };
        let (mime, image_bytes) = protocol::extract_image(&bytes).map_err(response_error)?;
        let image = codec::decode_image(&image_bytes).map_err(response_error)?;
        if let Some(cache) = &self.cache {
            let path = cache.put(&cache_key, &mime, &image_bytes)?;
            self.counters.cache_writes.fetch_add(1, Ordering::Relaxed);
            self.log(&format!("{label}: cached as {}", path.display()));
        }
        self.finish(image, (w, h), false, attempts, &label)
    }

    /// Resizes the returned image to the source size when needed.
    fn finish(
        &self,
        image: Image,
        (w, h): (usize, usize),
        from_cache: bool,
        attempts: u32,
        label: &str,
    ) -> Result<Generated, SynthError> {
        let returned_size = image.size();
        let resized = returned_size != (w, h);
        let image = if resized {
            self.log(&format!(
                "{label}: the model returned {}x{}, resized back to {w}x{h}",
                returned_size.0, returned_size.1
            ));
            raster::resize::resize_pil_lanczos_u8(&image, w, h)?
        } else {
            image
        };
        let image = clamp_to_dn(image);
        Ok(Generated {
            image,
            from_cache,
            attempts,
            returned_size,
            resized,
        })
    }

    /// POSTs `body`, retrying transient failures; returns the 200 body and the attempt count.
    fn post_with_retries(&self, body: &str, label: &str) -> Result<(Vec<u8>, u32), SynthError> {
        let _permit = self.semaphore.acquire();
        let max_attempts = self.config.max_retries + 1;
        let (mut last, mut last_status) = (String::new(), None);
        for attempt in 1..=max_attempts {
            if attempt > 1 {
                self.counters.retries.fetch_add(1, Ordering::Relaxed);
            }
            self.counters.requests.fetch_add(1, Ordering::Relaxed);
            let retry_after = match self.attempt(body) {
                Attempt::Done(bytes) => return Ok((bytes, attempt)),
                Attempt::Fail(e) => return Err(e),
                Attempt::Retry {
                    why,
                    retry_after,
                    status,
                } => {
                    (last, last_status) = (why, status);
                    retry_after
                }
            };
            if attempt == max_attempts {
                break;
            }
            let jitter = self.jitter_unit();
            let wait = retry::delay(
                attempt - 1,
                self.config.initial_backoff,
                self.config.max_backoff,
                retry_after,
                self.config.max_retry_after,
                jitter,
            );
            self.log(&format!(
                "{label}: attempt {attempt}/{max_attempts} failed ({last}); retrying in {:.1} s",
                wait.as_secs_f64()
            ));
            std::thread::sleep(wait);
        }
        self.log(&format!(
            "{label}: giving up after {max_attempts} attempt(s): {last}"
        ));
        Err(match last_status {
            Some(status) => SynthError::Http {
                url: self.endpoint.clone(),
                status,
                attempts: max_attempts,
                message: format!("{label}: {last}"),
            },
            None => SynthError::Transport {
                url: self.endpoint.clone(),
                attempts: max_attempts,
                message: format!("{label}: {last}"),
            },
        })
    }

    /// One HTTP attempt, classified.
    fn attempt(&self, body: &str) -> Attempt {
        let result = self
            .agent
            .post(&self.endpoint)
            .header("x-goog-api-key", self.key.expose())
            .header("content-type", "application/json")
            .send(body);
        let mut response = match result {
            Ok(r) => r,
            Err(e) => {
                let why = self.key.redact(&e.to_string());
                return match e {
                    ureq::Error::Timeout(_)
                    | ureq::Error::Io(_)
                    | ureq::Error::ConnectionFailed
                    | ureq::Error::HostNotFound
                    | ureq::Error::Protocol(_) => Attempt::Retry {
                        why,
                        retry_after: None,
                        status: None,
                    },
                    _ => Attempt::Fail(SynthError::Transport {
                        url: self.endpoint.clone(),
                        attempts: 1,
                        message: why,
                    }),
                };
            }
        };
        let status = response.status().as_u16();
        let retry_after = response
            .headers()
            .get("retry-after")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| parse_retry_after(v, SystemTime::now()));
        let bytes = response
            .body_mut()
            .with_config()
            .limit(256 * 1024 * 1024)
            .read_to_vec();
        let bytes = match bytes {
            Ok(b) => b,
            Err(e) => {
                return Attempt::Retry {
                    why: self
                        .key
                        .redact(&format!("reading the response failed: {e}")),
                    retry_after: None,
                    status: None,
                }
            }
        };
        if status == 200 {
            return Attempt::Done(bytes);
        }
        let message = self.key.redact(&protocol::error_message(&bytes));
        if retryable_status(status) {
            Attempt::Retry {
                why: format!("HTTP {status}: {message}"),
                retry_after,
                status: Some(status),
            }
        } else {
            let hint = match status {
                400 => " (check the model name and the request settings)",
                401 | 403 => " (check the API key and that the model is enabled for it)",
                404 => " (check the base URL and the model name)",
                _ => "",
            };
            Attempt::Fail(SynthError::Http {
                url: self.endpoint.clone(),
                status,
                attempts: 1,
                message: format!("{message}{hint}"),
            })
        }
    }

    /// A pseudo-random number in [0, 1) for backoff jitter (no need for a crypto RNG).
    fn jitter_unit(&self) -> f64 {
        let n = self.counters.jitter.fetch_add(1, Ordering::Relaxed);
        let t = SystemTime::now()
            .duration_since(SystemTime::UNIX_EPOCH)
            .map(|d| d.subsec_nanos())
            .unwrap_or(0);
        let h = crate::builtin::random::splitmix64(n ^ (u64::from(t) << 20));
        (h >> 11) as f64 / (1u64 << 53) as f64
    }
}

fn clamp_to_dn(mut image: Image) -> Image {
    for v in image.data_mut() {
        *v = v.clamp(0.0, 255.0);
    }
    image
}

impl SeasonGenerator for GeminiGenerator {
    fn name(&self) -> String {
        format!("gemini:{}", self.config.model)
    }

    fn generate(&self, source: &SourceImage<'_>, season: Season) -> Result<Image, SynthError> {
        self.generate_detailed(source, season).map(|g| g.image)
    }
}
