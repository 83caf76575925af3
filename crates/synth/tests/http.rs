//! The Gemini client against a fake HTTP/1.1 server on 127.0.0.1: success, retries (429 with
//! Retry-After, persistent 503), timeouts, malformed answers, the cache, the concurrency limit,
//! and the API key never showing up in logs, errors or Debug output.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, OnceLock};
use std::time::{Duration, Instant};

use base64::Engine;
use raster::Image;
use serde_json::{json, Value};
use synth::api::{ApiKey, GeminiConfig, GeminiGenerator, LogSink, DEFAULT_MODEL};
use synth::{Season, SeasonGenerator, SourceImage, SynthError};

const KEY: &str = "sk-TEST-SECRET-4242";

// ---------------------------------------------------------------- captured `log` records

static LOG_LINES: Mutex<Vec<String>> = Mutex::new(Vec::new());

struct Capture;

impl log::Log for Capture {
    fn enabled(&self, _: &log::Metadata<'_>) -> bool {
        true
    }
    fn log(&self, record: &log::Record<'_>) {
        let line = format!("{} {}: {}", record.level(), record.target(), record.args());
        LOG_LINES.lock().unwrap().push(line);
    }
    fn flush(&self) {}
}

/// Captures every `log` record of the process (ureq's debug and trace lines included).
fn capture_logs() {
    static INIT: OnceLock<()> = OnceLock::new();
    INIT.get_or_init(|| {
        log::set_logger(&Capture).unwrap();
        log::set_max_level(log::LevelFilter::Trace);
    });
}

// ---------------------------------------------------------------- fake server

#[derive(Clone)]
struct Reply {
    delay: Duration,
    status: u16,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Reply {
    fn new(status: u16, body: impl Into<Vec<u8>>) -> Self {
        Self {
            delay: Duration::ZERO,
            status,
            headers: Vec::new(),
            body: body.into(),
        }
    }
    fn header(mut self, name: &str, value: &str) -> Self {
        self.headers.push((name.into(), value.into()));
        self
    }
    fn after(mut self, delay: Duration) -> Self {
        self.delay = delay;
        self
    }
}

struct Request {
    path: String,
    headers: Vec<(String, String)>,
    body: Vec<u8>,
}

impl Request {
    fn header(&self, name: &str) -> Option<&str> {
        self.headers
            .iter()
            .find(|(n, _)| n.eq_ignore_ascii_case(name))
            .map(|(_, v)| v.as_str())
    }
}

struct FakeServer {
    url: String,
    requests: Arc<Mutex<Vec<Request>>>,
    peak_in_flight: Arc<AtomicUsize>,
}

impl FakeServer {
    /// Serves `script` in order, one reply per request, repeating the last one.
    fn start(script: Vec<Reply>) -> Self {
        let listener = TcpListener::bind("127.0.0.1:0").unwrap();
        let url = format!("http://{}", listener.local_addr().unwrap());
        let requests = Arc::new(Mutex::new(Vec::new()));
        let peak = Arc::new(AtomicUsize::new(0));
        let in_flight = Arc::new(AtomicUsize::new(0));
        let counter = Arc::new(AtomicUsize::new(0));
        let (reqs, pk) = (requests.clone(), peak.clone());
        std::thread::spawn(move || {
            for stream in listener.incoming() {
                let Ok(stream) = stream else { continue };
                let i = counter.fetch_add(1, Ordering::SeqCst);
                let reply = script[i.min(script.len() - 1)].clone();
                let (reqs, pk, inf) = (reqs.clone(), pk.clone(), in_flight.clone());
                std::thread::spawn(move || {
                    let now = inf.fetch_add(1, Ordering::SeqCst) + 1;
                    pk.fetch_max(now, Ordering::SeqCst);
                    let _ = serve(stream, &reply, &reqs);
                    inf.fetch_sub(1, Ordering::SeqCst);
                });
            }
        });
        Self {
            url,
            requests,
            peak_in_flight: peak,
        }
    }

    fn request_count(&self) -> usize {
        self.requests.lock().unwrap().len()
    }
}

fn serve(stream: TcpStream, reply: &Reply, log: &Mutex<Vec<Request>>) -> std::io::Result<()> {
    let mut reader = BufReader::new(stream.try_clone()?);
    let mut line = String::new();
    reader.read_line(&mut line)?;
    let path = line.split_whitespace().nth(1).unwrap_or("").to_string();
    let mut headers = Vec::new();
    loop {
        let mut h = String::new();
        reader.read_line(&mut h)?;
        let h = h.trim_end();
        if h.is_empty() {
            break;
        }
        if let Some((n, v)) = h.split_once(':') {
            headers.push((n.trim().to_string(), v.trim().to_string()));
        }
    }
    let len: usize = headers
        .iter()
        .find(|(n, _)| n.eq_ignore_ascii_case("content-length"))
        .and_then(|(_, v)| v.parse().ok())
        .unwrap_or(0);
    let mut body = vec![0u8; len];
    reader.read_exact(&mut body)?;
    log.lock().unwrap().push(Request {
        path,
        headers,
        body,
    });
    std::thread::sleep(reply.delay);
    let mut out = stream;
    let mut head = format!(
        "HTTP/1.1 {} Fake\r\ncontent-length: {}\r\nconnection: close\r\ncontent-type: application/json\r\n",
        reply.status,
        reply.body.len()
    );
    for (n, v) in &reply.headers {
        head.push_str(&format!("{n}: {v}\r\n"));
    }
    head.push_str("\r\n");
    out.write_all(head.as_bytes())?;
    out.write_all(&reply.body)?;
    out.flush()
}

// ---------------------------------------------------------------- helpers

fn png_bytes(w: u32, h: u32, rgb: [u8; 3]) -> Vec<u8> {
    let (w, h) = (w as usize, h as usize);
    let data = (0..w * h).flat_map(|_| rgb.map(f32::from)).collect();
    let image = Image::new(w, h, 3, data).unwrap();
    raster::formats::encode_png(&image, raster::formats::PngDepth::Eight).unwrap()
}

fn image_answer(w: u32, h: u32, rgb: [u8; 3]) -> Vec<u8> {
    let data = base64::engine::general_purpose::STANDARD.encode(png_bytes(w, h, rgb));
    json!({"candidates": [{"content": {"parts": [
        {"text": "Here is the edited image."},
        {"inlineData": {"mimeType": "image/png", "data": data}}
    ]}}]})
    .to_string()
    .into_bytes()
}

fn source_image() -> Image {
    Image::new(
        16,
        16,
        3,
        (0..16 * 16)
            .flat_map(|i| [(i % 256) as f32, 100.0, 200.0])
            .collect(),
    )
    .unwrap()
}

fn config(server: &FakeServer) -> GeminiConfig {
    GeminiConfig {
        base_url: server.url.clone(),
        timeout: Duration::from_secs(5),
        max_retries: 3,
        initial_backoff: Duration::from_millis(10),
        max_backoff: Duration::from_millis(50),
        ..GeminiConfig::default()
    }
}

/// A client whose log lines are collected in the returned vector.
fn client(config: GeminiConfig) -> (GeminiGenerator, Arc<Mutex<Vec<String>>>) {
    capture_logs();
    let lines = Arc::new(Mutex::new(Vec::new()));
    let sink_lines = lines.clone();
    let sink: LogSink = Arc::new(move |l: &str| sink_lines.lock().unwrap().push(l.to_string()));
    let g = GeminiGenerator::with_api_key(config, ApiKey::new(KEY).unwrap())
        .unwrap()
        .with_log_sink(sink);
    (g, lines)
}

fn assert_no_key(what: &str, text: &str) {
    assert!(
        !text.contains(KEY),
        "the API key leaked into {what}: {text}"
    );
}

// ---------------------------------------------------------------- tests

#[test]
fn success_sends_the_release_request_and_resizes_the_answer() {
    let server = FakeServer::start(vec![Reply::new(200, image_answer(24, 24, [120, 60, 30]))]);
    let (g, _) = client(config(&server));
    let src = source_image();
    let out = g
        .generate_detailed(&SourceImage::new("JAX_004_001_RGB", &src), Season::Winter)
        .unwrap();
    assert_eq!(out.image.size(), (16, 16));
    assert_eq!(out.returned_size, (24, 24));
    assert!(out.resized && !out.from_cache && out.attempts == 1);
    for px in out.image.data().chunks_exact(3) {
        assert!(
            (px[0] - 120.0).abs() < 0.5 && (px[1] - 60.0).abs() < 0.5 && (px[2] - 30.0).abs() < 0.5
        );
    }

    let reqs = server.requests.lock().unwrap();
    assert_eq!(reqs.len(), 1);
    let r = &reqs[0];
    assert_eq!(
        r.path,
        format!("/v1beta/models/{DEFAULT_MODEL}:generateContent")
    );
    assert_eq!(r.header("x-goog-api-key"), Some(KEY));
    assert!(!r.path.contains(KEY), "the key must not be in the URL");
    let body: Value = serde_json::from_slice(&r.body).unwrap();
    let text = body
        .pointer("/contents/0/parts/0/text")
        .unwrap()
        .as_str()
        .unwrap();
    assert!(
        text.contains("winter") && text.contains("snow on rooftops"),
        "{text}"
    );
    let inline = body.pointer("/contents/0/parts/1/inline_data").unwrap();
    assert_eq!(inline["mime_type"], "image/png");
    let sent = base64::engine::general_purpose::STANDARD
        .decode(inline["data"].as_str().unwrap())
        .unwrap();
    assert!(sent.starts_with(b"\x89PNG"));
    let cfg = &body["generationConfig"];
    assert_eq!(cfg["responseModalities"], json!(["IMAGE"]));
    assert!((cfg["temperature"].as_f64().unwrap() - 0.2).abs() < 1e-6);
    assert_eq!(
        cfg["imageConfig"],
        json!({"aspectRatio": "1:1", "imageSize": "1K"})
    );
    assert_eq!(g.stats().requests, 1);
    assert_eq!(g.name(), format!("gemini:{DEFAULT_MODEL}"));
}

#[test]
fn rate_limit_is_retried_after_retry_after() {
    let server = FakeServer::start(vec![
        Reply::new(
            429,
            r#"{"error":{"code":429,"message":"Resource exhausted"}}"#,
        )
        .header("Retry-After", "1"),
        Reply::new(200, image_answer(16, 16, [1, 2, 3])),
    ]);
    let (g, lines) = client(config(&server));
    let src = source_image();
    let start = Instant::now();
    let out = g
        .generate_detailed(&SourceImage::new("a", &src), Season::Summer)
        .unwrap();
    let elapsed = start.elapsed();
    assert_eq!(out.attempts, 2);
    assert!(!out.resized);
    assert_eq!(server.request_count(), 2);
    let stats = g.stats();
    assert_eq!((stats.requests, stats.retries), (2, 1));
    // Backoff alone would wait ~10 ms: the 1 s is the server's Retry-After.
    assert!(elapsed >= Duration::from_millis(950), "{elapsed:?}");
    let lines = lines.lock().unwrap();
    assert!(
        lines
            .iter()
            .any(|l| l.contains("HTTP 429") && l.contains("retrying")),
        "{lines:?}"
    );
}

#[test]
fn persistent_server_errors_fail_after_the_retries() {
    let server = FakeServer::start(vec![Reply::new(
        503,
        r#"{"error":{"message":"overloaded"}}"#,
    )]);
    let cfg = GeminiConfig {
        max_retries: 2,
        ..config(&server)
    };
    let (g, _) = client(cfg);
    let src = source_image();
    let err = g
        .generate(&SourceImage::new("a", &src), Season::Autumn)
        .unwrap_err();
    match &err {
        SynthError::Http {
            status, attempts, ..
        } => assert_eq!((*status, *attempts), (503, 3)),
        other => panic!("unexpected error {other:?}"),
    }
    assert!(err.to_string().contains("overloaded"), "{err}");
    assert_eq!(server.request_count(), 3);
    assert_eq!(g.stats().retries, 2);
}

#[test]
fn client_errors_are_not_retried_and_give_a_hint() {
    let server = FakeServer::start(vec![Reply::new(
        403,
        r#"{"error":{"code":403,"message":"Permission denied"}}"#,
    )]);
    let (g, _) = client(config(&server));
    let src = source_image();
    let err = g
        .generate(&SourceImage::new("a", &src), Season::Spring)
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("403") && err.contains("Permission denied") && err.contains("API key"),
        "{err}"
    );
    assert_eq!(server.request_count(), 1);
}

#[test]
fn timeouts_are_retried_then_reported() {
    let server = FakeServer::start(vec![
        Reply::new(200, image_answer(16, 16, [1, 2, 3])).after(Duration::from_millis(1500))
    ]);
    let cfg = GeminiConfig {
        timeout: Duration::from_millis(200),
        max_retries: 1,
        ..config(&server)
    };
    let (g, _) = client(cfg);
    let src = source_image();
    let start = Instant::now();
    let err = g
        .generate(&SourceImage::new("a", &src), Season::Winter)
        .unwrap_err();
    assert!(
        start.elapsed() < Duration::from_millis(1400),
        "{:?}",
        start.elapsed()
    );
    match &err {
        SynthError::Transport {
            attempts, message, ..
        } => {
            assert_eq!(*attempts, 2);
            assert!(message.to_lowercase().contains("timeout"), "{message}");
        }
        other => panic!("unexpected error {other:?}"),
    }
    assert_eq!(g.stats().requests, 2);
}

#[test]
fn malformed_answers_give_clear_errors() {
    let cases: Vec<(Vec<u8>, &str)> = vec![
        (b"<html>gateway</html>".to_vec(), "not JSON"),
        (
            br#"{"candidates":[{"finishReason":"IMAGE_SAFETY","content":{"parts":[{"text":"Sorry"}]}}]}"#.to_vec(),
            "IMAGE_SAFETY",
        ),
        (
            br#"{"candidates":[{"content":{"parts":[{"inlineData":{"mimeType":"image/png","data":"%%%"}}]}}]}"#.to_vec(),
            "base64",
        ),
        (
            json!({"candidates":[{"content":{"parts":[{"inlineData":{"mimeType":"image/png",
                "data": base64::engine::general_purpose::STANDARD.encode(b"GIF89a....")}}]}}]})
            .to_string()
            .into_bytes(),
            "neither PNG nor JPEG",
        ),
    ];
    for (body, expected) in cases {
        let server = FakeServer::start(vec![Reply::new(200, body)]);
        let (g, _) = client(config(&server));
        let src = source_image();
        let err = g
            .generate(&SourceImage::new("OMA_1", &src), Season::Summer)
            .unwrap_err();
        assert!(matches!(err, SynthError::Response { .. }), "{err:?}");
        let text = err.to_string();
        assert!(
            text.contains(expected) && text.contains("OMA_1 summer"),
            "{text}"
        );
        assert_eq!(
            server.request_count(),
            1,
            "a malformed answer is not retried"
        );
    }
}

#[test]
fn cache_serves_reruns_without_a_request() {
    let server = FakeServer::start(vec![Reply::new(200, image_answer(16, 16, [9, 8, 7]))]);
    let dir = tempfile::tempdir().unwrap();
    let cfg = GeminiConfig {
        cache_dir: Some(dir.path().join("cache")),
        ..config(&server)
    };
    let src = source_image();
    let source = SourceImage::new("a", &src);
    let (g, _) = client(cfg.clone());
    let first = g.generate_detailed(&source, Season::Winter).unwrap();
    assert!(!first.from_cache);
    // A new client (a rerun of the program) with the same cache directory.
    let (g2, lines) = client(cfg);
    let second = g2.generate_detailed(&source, Season::Winter).unwrap();
    assert!(second.from_cache && second.attempts == 0);
    assert_eq!(first.image.data(), second.image.data());
    assert_eq!(server.request_count(), 1);
    assert_eq!(g2.stats().cache_hits, 1);
    assert!(lines
        .lock()
        .unwrap()
        .iter()
        .any(|l| l.contains("from cache")));
    // Another season is another request.
    g2.generate_detailed(&source, Season::Spring).unwrap();
    assert_eq!(server.request_count(), 2);
}

#[test]
fn concurrency_limit_holds_across_threads() {
    let server = FakeServer::start(vec![
        Reply::new(200, image_answer(16, 16, [1, 1, 1])).after(Duration::from_millis(150))
    ]);
    let cfg = GeminiConfig {
        max_concurrent: 1,
        ..config(&server)
    };
    let (g, _) = client(cfg);
    let src = source_image();
    std::thread::scope(|s| {
        for season in Season::ALL {
            let (g, src) = (&g, &src);
            s.spawn(move || g.generate(&SourceImage::new("a", src), season).unwrap());
        }
    });
    assert_eq!(server.request_count(), 4);
    assert_eq!(server.peak_in_flight.load(Ordering::SeqCst), 1);
}

#[test]
fn the_api_key_never_leaks() {
    // The server echoes the key in its error message, as a misconfigured proxy might.
    let echo = format!(r#"{{"error":{{"message":"bad key {KEY}"}}}}"#);
    let server = FakeServer::start(vec![Reply::new(500, echo.clone()), Reply::new(400, echo)]);
    let (g, lines) = client(config(&server));
    let src = source_image();
    let err = g
        .generate(&SourceImage::new("a", &src), Season::Winter)
        .unwrap_err();
    assert_eq!(server.request_count(), 2);
    assert!(err.to_string().contains("[redacted]"), "{err}");
    assert_no_key("the error message", &err.to_string());
    assert_no_key("the error's Debug", &format!("{err:?}"));
    assert_no_key("the generator's Debug", &format!("{g:?}"));
    assert_no_key(
        "the key's Debug",
        &format!("{:?}", ApiKey::new(KEY).unwrap()),
    );

    // Also a successful exchange, so ureq logs a full request at debug level.
    let ok = FakeServer::start(vec![Reply::new(200, image_answer(16, 16, [1, 2, 3]))]);
    let (g2, lines2) = client(config(&ok));
    g2.generate(&SourceImage::new("a", &src), Season::Winter)
        .unwrap();

    let sink: Vec<String> = lines
        .lock()
        .unwrap()
        .iter()
        .chain(lines2.lock().unwrap().iter())
        .cloned()
        .collect();
    assert!(sink.iter().any(|l| l.contains("[redacted]")), "{sink:?}");
    for l in &sink {
        assert_no_key("a client log line", l);
    }
    let global = LOG_LINES.lock().unwrap();
    assert!(
        global.iter().any(|l| l.contains("ureq")),
        "ureq's own debug lines are captured too"
    );
    for l in global.iter() {
        assert_no_key("a `log` record", l);
    }
}

#[test]
fn a_missing_key_names_the_variable() {
    let cfg = GeminiConfig {
        api_key_env: "SYNTH_TEST_SURELY_UNSET_KEY_VAR".into(),
        ..GeminiConfig::default()
    };
    let err = GeminiGenerator::new(cfg).unwrap_err();
    assert!(matches!(err, SynthError::MissingApiKey { .. }));
    assert!(
        err.to_string().contains("SYNTH_TEST_SURELY_UNSET_KEY_VAR"),
        "{err}"
    );
    let err = GeminiGenerator::with_api_key(
        GeminiConfig {
            base_url: "ftp://example".into(),
            ..GeminiConfig::default()
        },
        ApiKey::new(KEY).unwrap(),
    )
    .unwrap_err();
    assert!(err.to_string().contains("http://"), "{err}");
}
