//! When to retry and how long to wait: exponential backoff with jitter, and the server's
//! `Retry-After` (seconds or HTTP date) honoured as a lower bound.

use std::time::{Duration, SystemTime, UNIX_EPOCH};

/// Whether an HTTP status is worth retrying: rate limiting, request timeout, server errors.
pub(crate) fn retryable_status(status: u16) -> bool {
    status == 429 || status == 408 || (500..600).contains(&status)
}

/// Delay before retry number `retry` (0 for the first retry): `initial · 2^retry`, capped at
/// `max`, plus up to 25 % random jitter (so parallel workers do not retry in lockstep); never
/// shorter than `retry_after` (itself capped at `max_retry_after`).
pub(crate) fn delay(
    retry: u32,
    initial: Duration,
    max: Duration,
    retry_after: Option<Duration>,
    max_retry_after: Duration,
    jitter_unit: f64,
) -> Duration {
    let exp = initial.saturating_mul(1u32.checked_shl(retry.min(30)).unwrap_or(u32::MAX));
    let base = exp.min(max);
    let jittered = base.mul_f64(1.0 + 0.25 * jitter_unit.clamp(0.0, 1.0));
    match retry_after {
        Some(ra) => jittered.max(ra.min(max_retry_after)),
        None => jittered,
    }
}

/// Parses a `Retry-After` value: delta seconds, or an IMF-fixdate
/// (`Sun, 06 Nov 1994 08:49:37 GMT`) relative to `now`.
pub(crate) fn parse_retry_after(value: &str, now: SystemTime) -> Option<Duration> {
    let value = value.trim();
    if let Ok(secs) = value.parse::<u64>() {
        return Some(Duration::from_secs(secs));
    }
    if let Ok(secs) = value.parse::<f64>() {
        return (secs.is_finite() && secs >= 0.0).then(|| Duration::from_secs_f64(secs));
    }
    let at = parse_http_date(value)?;
    let now = now.duration_since(UNIX_EPOCH).ok()?.as_secs();
    Some(Duration::from_secs(at.saturating_sub(now)))
}

/// Seconds since the Unix epoch of an IMF-fixdate (an RFC 2822 date).
fn parse_http_date(s: &str) -> Option<u64> {
    let at = chrono::DateTime::parse_from_rfc2822(s).ok()?;
    u64::try_from(at.timestamp()).ok()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn backoff_doubles_is_capped_and_honours_retry_after() {
        let (i, m, cap) = (
            Duration::from_millis(100),
            Duration::from_secs(1),
            Duration::from_secs(60),
        );
        assert_eq!(delay(0, i, m, None, cap, 0.0), Duration::from_millis(100));
        assert_eq!(delay(2, i, m, None, cap, 0.0), Duration::from_millis(400));
        assert_eq!(delay(9, i, m, None, cap, 0.0), Duration::from_secs(1));
        assert_eq!(delay(0, i, m, None, cap, 1.0), Duration::from_millis(125));
        assert_eq!(
            delay(0, i, m, Some(Duration::from_secs(3)), cap, 0.0),
            Duration::from_secs(3)
        );
        assert_eq!(
            delay(0, i, m, Some(Duration::from_secs(900)), cap, 0.0),
            cap
        );
    }

    #[test]
    fn retry_after_in_seconds_or_http_date() {
        let now = UNIX_EPOCH + Duration::from_secs(784_111_770); // Sun, 06 Nov 1994 08:49:30 GMT
        assert_eq!(parse_retry_after("7", now), Some(Duration::from_secs(7)));
        assert_eq!(
            parse_retry_after("Sun, 06 Nov 1994 08:49:37 GMT", now),
            Some(Duration::from_secs(7))
        );
        assert_eq!(parse_retry_after("soon", now), None);
        assert!(retryable_status(429) && retryable_status(503) && !retryable_status(400));
    }
}
