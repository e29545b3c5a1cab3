//! Rate limit per API key: each request is charged to the key it authenticates with (bearer
//! header or web session), or to its peer IP when it has no valid key; over the quota → 429.
//!
//! [`identify`] verifies the bearer key once and leaves the result for the `Auth` extractor
//! ([`VerifiedKey`]), so limiting costs no second store lookup. The quota and the keyed GCRA
//! state are tower_governor's ([`GovernorConfigBuilder`], [`RequestKey`] as its key extractor);
//! the middleware around them is ours so that `/healthz`, `/readyz` and `/metrics` (probes,
//! scrapers) are never limited and the 429 is the API's problem JSON with a `Retry-After` that
//! is never early. Assumptions: the limit is per process (each replica counts on its own, so a
//! fleet of N replicas admits up to N × the rate), and behind a proxy every keyless caller shares
//! the proxy's IP (forwarded headers are not trusted: any client could forge them).

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::sync::{Arc, Weak};
use std::time::Duration;

use axum::extract::{ConnectInfo, Request, State};
use axum::http::{HeaderValue, StatusCode, header};
use axum::middleware::Next;
use axum::response::Response;
use governor::clock::{Clock, QuantaInstant};
use governor::middleware::NoOpMiddleware;
use tower_governor::GovernorError;
use tower_governor::governor::{GovernorConfigBuilder, SharedRateLimiter};
use tower_governor::key_extractor::KeyExtractor;

use super::AppState;
use super::auth::bearer;
use super::error::{Problem, problem_response};
use crate::config::HttpSettings;
use crate::store::ApiKey;
use crate::web::session;

/// Paths that are never limited: liveness, readiness and metrics must answer their probes.
pub const EXEMPT_PATHS: [&str; 3] = ["/healthz", "/readyz", "/metrics"];

/// Whom a request is charged to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum RateKey {
    /// A valid API key (by id), presented as a bearer key or through a signed web session.
    Key(i64),
    /// No valid key: the peer address (unspecified when the server has no connect info).
    Peer(IpAddr),
}

/// The outcome of checking the request's bearer key (`None`: unknown or revoked), left in the
/// request's extensions by [`identify`] for the `Auth` extractor.
#[derive(Debug, Clone)]
pub struct VerifiedKey(pub Option<ApiKey>);

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

/// Sets the request's [`RateKey`] (and [`VerifiedKey`] when a bearer key was presented).
/// A store failure while verifying charges the peer and leaves the error to `Auth`.
pub async fn identify(State(st): State<AppState>, req: Request, next: Next) -> Response {
    let (mut parts, body) = req.into_parts();
    let mut key = None;
    if let Ok(secret) = bearer(&parts) {
        if let Ok(found) = st.store.verify_api_key(secret).await {
            key = found.as_ref().map(|k| RateKey::Key(k.id));
            parts.extensions.insert(VerifiedKey(found));
        }
    } else if let Some(id) = session::cookie_value(&parts).and_then(|v| st.sessions.verify(&v)) {
        // A signed session names its key; `WebUser` still checks that it is unrevoked.
        key = Some(RateKey::Key(id));
    }
    let mut req = Request::from_parts(parts, body);
    let key = key.unwrap_or_else(|| RateKey::Peer(peer_ip(&req)));
    req.extensions_mut().insert(key);
    next.run(req).await
}

fn peer_ip(req: &Request) -> IpAddr {
    req.extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |ConnectInfo(a)| a.ip())
}

/// Answers 429 when the request's key is over its quota (exempt paths pass untouched).
pub async fn limit(State(rl): State<RateLimit>, req: Request, next: Next) -> Response {
    if EXEMPT_PATHS.contains(&req.uri().path()) {
        return next.run(req).await;
    }
    let key = match RequestKey.extract(&req) {
        Ok(k) => k,
        // `identify` always runs first; without it, charge the peer.
        Err(_) => RateKey::Peer(peer_ip(&req)),
    };
    match rl.check(&key) {
        Ok(()) => next.run(req).await,
        Err(wait) => {
            if let RateKey::Key(id) = key {
                tracing::debug!(key_id = id, "rate limit exceeded");
            } else {
                tracing::debug!("rate limit exceeded for a caller without a valid key");
            }
            too_many_requests(wait, &rl)
        }
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
            "over the rate limit of {} requests/s (bursts of {}) for this key; retry in {secs} s",
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
