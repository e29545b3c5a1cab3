//! Rate limit per API key, charged before any database work: each request is charged to the key
//! it authenticates with (bearer header or web session), or to its peer IP when it has no valid
//! key; over the quota → 429.
//!
//! [`gate`](super::gate::gate) charges in this order (issue 18, point H: the key lookup, one database query, ran
//! before anything was charged, so a flood of over-quota or made-up keys cost a query each):
//! 1. Before the database: a bearer key this process has verified before ([`KnownKeys`], by the
//!    SHA-256 of the presented text) is charged to that key; a web session (signed, checked
//!    without the database) to its key; a bearer key not known here to its peer address's
//!    *lookup* budget ([`RateKey::Lookup`]); no key to the peer address. Over → 429, no query.
//! 2. The lookup ([`Store::verify_api_key`](crate::store::Store::verify_api_key)), left for the
//!    `Auth` extractor ([`VerifiedKey`]) so that authenticating costs no second query.
//! 3. When the lookup names another budget than step 1 charged — a key seen for the first time
//!    (its own), an unknown or revoked one (the peer's, as without a key) — that one too.
//!
//! So a key over its quota and a flood of made-up keys from one address are both refused
//! without a query; only a key's first request after the process started (or after the cache
//! of known keys was full and cleared) is charged twice, to its address's lookup budget and to
//! itself. The cache only picks the budget: every admitted request is still verified, so a
//! revoked key is refused at once (and forgotten here). The quota and the keyed GCRA state are
//! tower_governor's ([`GovernorConfigBuilder`], [`RequestKey`] as its key extractor); the
//! middleware around them is ours so that `/healthz`, `/readyz` and `/metrics` (probes,
//! scrapers) are never limited nor looked up, and the 429 is the API's problem JSON naming
//! `Authorization` with a `Retry-After` that is never early. Assumptions: the limit is per
//! process (each replica counts on its own, so a fleet of N replicas admits up to N × the
//! rate), and behind a proxy every keyless caller shares the proxy's IP (forwarded headers are
//! not trusted: any client could forge them).

use std::collections::HashMap;
use std::net::IpAddr;
use std::sync::{Arc, Mutex, Weak};
use std::time::Duration;

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::Response;
use governor::clock::{Clock, QuantaInstant};
use governor::middleware::NoOpMiddleware;
use sha2::{Digest, Sha256};
use tower_governor::GovernorError;
use tower_governor::governor::{GovernorConfigBuilder, SharedRateLimiter};
use tower_governor::key_extractor::KeyExtractor;

use super::error::{Problem, problem_response};
use crate::config::HttpSettings;

/// Paths that are never limited: liveness, readiness and metrics must answer their probes.
pub const EXEMPT_PATHS: [&str; 3] = ["/healthz", "/readyz", "/metrics"];

/// Whom a request is charged to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RateKey {
    /// A valid API key (by id), presented as a bearer key or through a signed web session.
    Key(i64),
    /// No valid key: the peer address (unspecified when the server has no connect info).
    Peer(IpAddr),
    /// A bearer key this process has not verified yet, before it is looked up: the peer
    /// address's budget of key lookups.
    Lookup(IpAddr),
}

/// How many verified keys [`KnownKeys`] holds before it starts over (each entry 40 bytes).
pub const KNOWN_KEYS_MAX: usize = 10_000;

/// Bearer keys this process has verified: the SHA-256 of the presented text → the key's id.
/// Names the budget to charge before the lookup; grants nothing (every admitted request is
/// still verified by the store). Cleared when full, so a scan cannot grow it for ever.
#[derive(Debug, Clone, Default)]
pub struct KnownKeys(Arc<Mutex<HashMap<[u8; 32], i64>>>);

impl KnownKeys {
    pub(super) fn digest(secret: &str) -> [u8; 32] {
        Sha256::digest(secret.as_bytes()).into()
    }

    fn lock(&self) -> std::sync::MutexGuard<'_, HashMap<[u8; 32], i64>> {
        // The map holds no invariant a panic could break: take it back if poisoned.
        self.0.lock().unwrap_or_else(|e| e.into_inner())
    }

    pub(super) fn get(&self, digest: &[u8; 32]) -> Option<i64> {
        self.lock().get(digest).copied()
    }

    pub(super) fn learn(&self, digest: [u8; 32], found: Option<i64>) {
        let mut m = self.lock();
        match found {
            Some(id) => {
                if m.len() >= KNOWN_KEYS_MAX && !m.contains_key(&digest) {
                    m.clear();
                }
                m.insert(digest, id);
            }
            None => {
                m.remove(&digest);
            }
        }
    }
}

/// tower_governor key extractor: the [`RateKey`] that [`identify`] put on the request.
#[derive(Debug, Clone, Copy)]
pub struct RequestKey;

impl KeyExtractor for RequestKey {
    type Key = RateKey;

    fn extract<T>(&self, req: &axum::http::Request<T>) -> Result<RateKey, GovernorError> {
        req.extensions()
            .get::<RateKey>()
            .copied()
            .ok_or(GovernorError::UnableToExtractKey)
    }
}

/// The per-key limiter of one process.
#[derive(Clone)]
pub struct RateLimit {
    limiter: SharedRateLimiter<RateKey, NoOpMiddleware<QuantaInstant>>,
    burst: u32,
    per_s: f64,
    pub(super) known: KnownKeys,
}

impl std::fmt::Debug for RateLimit {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("RateLimit")
            .field("per_s", &self.per_s)
            .field("burst", &self.burst)
            .finish()
    }
}

impl RateLimit {
    /// The limiter of `http.rate_limit_per_s` / `http.rate_limit_burst`; `None` when the rate
    /// is 0 (no limit) or the values cannot make a quota (validated settings never do that).
    pub fn from_settings(http: &HttpSettings) -> Option<Self> {
        let per_s = http.rate_limit_per_s;
        if !(per_s.is_finite() && per_s > 0.0) {
            return None;
        }
        // One request's worth of quota comes back every 1/rate seconds (at least 1 ns).
        let period = Duration::from_secs_f64(1.0 / per_s).max(Duration::from_nanos(1));
        let config = GovernorConfigBuilder::default()
            .key_extractor(RequestKey)
            .period(period)
            .burst_size(http.rate_limit_burst)
            .finish()?;
        let limit = RateLimit {
            limiter: config.limiter().clone(),
            burst: http.rate_limit_burst,
            per_s,
            known: KnownKeys::default(),
        };
        limit.spawn_cleanup();
        Some(limit)
    }

    /// Forgets keys whose quota is full again, once a minute, so that a scan from many
    /// addresses does not grow the table for ever. Ends when the limiter is dropped.
    fn spawn_cleanup(&self) {
        let Ok(rt) = tokio::runtime::Handle::try_current() else {
            return;
        };
        let weak: Weak<_> = Arc::downgrade(&self.limiter);
        rt.spawn(async move {
            let mut tick = tokio::time::interval(Duration::from_secs(60));
            tick.tick().await;
            loop {
                tick.tick().await;
                let Some(limiter) = weak.upgrade() else {
                    return;
                };
                limiter.retain_recent();
                limiter.shrink_to_fit();
            }
        });
    }

    /// Charges one request to `key`: `Err(wait)` when over the quota, `wait` the time until
    /// the next request would be admitted.
    pub fn check(&self, key: &RateKey) -> Result<(), Duration> {
        self.limiter
            .check_key(key)
            .map_err(|not_until| not_until.wait_time_from(self.limiter.clock().now()))
    }
}

/// The 429 problem answer; `Retry-After` is `wait` rounded up to whole seconds (never 0).
pub fn too_many_requests(wait: Duration, rl: &RateLimit) -> Response {
    let secs = wait.as_secs() + u64::from(wait.subsec_nanos() > 0);
    let secs = secs.max(1);
    let mut resp = problem_response(&Problem {
        kind: "/problems/too-many-requests".into(),
        title: "Too many requests".into(),
        status: StatusCode::TOO_MANY_REQUESTS.as_u16(),
        detail: format!(
            "over the rate limit of {} requests/s (bursts of {}) for this key (or, without a \
             known key, this address); retry in {secs} s",
            rl.per_s, rl.burst
        ),
        // The key (or, keyless, the address) whose budget is spent.
        field: Some("Authorization".into()),
        parameter: None,
        job: None,
    });
    resp.headers_mut()
        .insert(header::RETRY_AFTER, HeaderValue::from(secs));
    resp
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::net::Ipv4Addr;

    fn limit(per_s: f64, burst: u32) -> RateLimit {
        RateLimit::from_settings(&HttpSettings {
            rate_limit_per_s: per_s,
            rate_limit_burst: burst,
            ..HttpSettings::default()
        })
        .expect("a limit")
    }

    #[test]
    fn a_burst_then_refusal_per_key_and_keys_are_independent() {
        let rl = limit(0.5, 3);
        let a = RateKey::Key(1);
        for i in 0..3 {
            assert!(rl.check(&a).is_ok(), "request {i} of the burst");
        }
        let wait = rl.check(&a).expect_err("over the burst");
        // One request's quota returns every 2 s: the wait is at most that.
        assert!(
            wait > Duration::ZERO && wait <= Duration::from_secs(2),
            "{wait:?}"
        );
        assert!(
            rl.check(&RateKey::Key(2)).is_ok(),
            "another key is unaffected"
        );
        assert!(
            rl.check(&RateKey::Peer(IpAddr::V4(Ipv4Addr::LOCALHOST)))
                .is_ok(),
            "a keyless caller has its own quota"
        );
    }

    #[test]
    fn zero_rate_means_no_limiter() {
        let http = HttpSettings {
            rate_limit_per_s: 0.0,
            ..HttpSettings::default()
        };
        assert!(RateLimit::from_settings(&http).is_none());
    }

    #[test]
    fn retry_after_rounds_up_and_is_never_zero() {
        let rl = limit(1.0, 1);
        for (wait, want) in [
            (Duration::from_millis(1), "1"),
            (Duration::from_millis(1500), "2"),
            (Duration::from_secs(3), "3"),
        ] {
            let r = too_many_requests(wait, &rl);
            assert_eq!(r.status(), StatusCode::TOO_MANY_REQUESTS);
            assert_eq!(r.headers()[header::RETRY_AFTER], want, "{wait:?}");
        }
    }
}
