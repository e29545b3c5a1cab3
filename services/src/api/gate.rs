//! The layer in front of every route: tells the caller apart (bearer key, web session, peer
//! address) and charges the rate limit before the key lookup, in the order the
//! [`ratelimit`](super::ratelimit) module doc gives. Above the state it reads; nothing below
//! imports it.

use std::net::{IpAddr, Ipv4Addr, SocketAddr};
use std::time::Duration;

use axum::extract::{ConnectInfo, Request, State};
use axum::middleware::Next;
use axum::response::Response;

use super::auth::{VerifiedKey, bearer};
use super::ratelimit::{EXEMPT_PATHS, KnownKeys, RateKey, RateLimit, too_many_requests};
use super::session;
use super::state::AppState;

/// Charges the request before any database work, looks its bearer key up, then charges the
/// budget the lookup names (module doc); answers 429 when one is spent. Leaves the request's
/// [`RateKey`] and, for a bearer key, the [`VerifiedKey`] for `Auth`. A store failure while
/// verifying leaves the error to `Auth` (it asks again and answers 503). Without a limiter, or
/// on an exempt path, the request passes untouched.
pub async fn gate(State(st): State<AppState>, req: Request, next: Next) -> Response {
    let Some(rl) = st.rate_limit.clone() else {
        return next.run(req).await;
    };
    if EXEMPT_PATHS.contains(&req.uri().path()) {
        return next.run(req).await;
    }
    let peer = peer_ip(&req);
    let (mut parts, body) = req.into_parts();
    let presented = bearer(&parts)
        .ok()
        .map(|secret| (secret.to_owned(), KnownKeys::digest(secret)));
    // 1. What the request can be told apart by without the database.
    let first = match &presented {
        Some((_, digest)) => rl
            .known
            .get(digest)
            .map_or(RateKey::Lookup(peer), RateKey::Key),
        None => session::cookie_value(&parts)
            .and_then(|v| st.sessions.verify(&v))
            // A signed session names its key; `WebUser` still checks that it is unrevoked.
            .map_or(RateKey::Peer(peer), RateKey::Key),
    };
    if let Err(wait) = rl.check(&first) {
        return refuse(first, wait, &rl);
    }
    // 2. The lookup; 3. the budget it names, when step 1 charged another.
    let mut key = first;
    if let Some((secret, digest)) = presented
        && let Ok(found) = st.store.verify_api_key(&secret).await
    {
        rl.known.learn(digest, found.as_ref().map(|k| k.id));
        key = found
            .as_ref()
            .map_or(RateKey::Peer(peer), |k| RateKey::Key(k.id));
        parts.extensions.insert(VerifiedKey(found));
        if key != first
            && let Err(wait) = rl.check(&key)
        {
            return refuse(key, wait, &rl);
        }
    }
    let mut req = Request::from_parts(parts, body);
    req.extensions_mut().insert(key);
    next.run(req).await
}

fn peer_ip(req: &Request) -> IpAddr {
    req.extensions()
        .get::<ConnectInfo<SocketAddr>>()
        .map_or(IpAddr::V4(Ipv4Addr::UNSPECIFIED), |ConnectInfo(a)| a.ip())
}

fn refuse(key: RateKey, wait: Duration, rl: &RateLimit) -> Response {
    match key {
        RateKey::Key(id) => tracing::debug!(key_id = id, "rate limit exceeded"),
        RateKey::Lookup(_) => {
            tracing::debug!("rate limit of key lookups exceeded for an address")
        }
        RateKey::Peer(_) => {
            tracing::debug!("rate limit exceeded for a caller without a valid key")
        }
    }
    too_many_requests(wait, rl)
}
