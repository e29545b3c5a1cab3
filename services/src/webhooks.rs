//! Webhook delivery from the durable outbox: claim due deliveries under a lease, POST each signed
//! (`X-Pantowatch-Signature: sha256=<HMAC-SHA256(secret, timestamp "." body)>`), retry with
//! exponential back-off until delivered or out of attempts — at least once, keyed by delivery id.

use std::sync::Arc;
use std::time::Duration;

use chrono::Utc;
use sha2::Sha256;
use tokio::sync::{Notify, watch};
use tokio::task::JoinSet;

use crate::store::{AttemptResult, DueDelivery, Store};

/// How deliveries are made.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct DeliveryOptions {
    /// Wait before the second attempt; doubles per attempt, capped at an hour.
    pub backoff_base: Duration,
    pub max_attempts: u32,
    /// Connect + answer.
    pub timeout: Duration,
    pub poll: Duration,
}

impl Default for DeliveryOptions {
    fn default() -> Self {
        DeliveryOptions {
            backoff_base: Duration::from_secs(1),
            max_attempts: 6,
            timeout: Duration::from_secs(10),
            poll: Duration::from_secs(1),
        }
    }
}

/// HMAC-SHA256 (RFC 2104, the `hmac` crate) of `msg` under `key`, as lowercase hex.
pub fn hmac_sha256_hex(key: &[u8], msg: &[u8]) -> String {
    use hmac::Mac;
    hex::encode(hmac_sha256(key).chain_update(msg).finalize().into_bytes())
}

/// An HMAC-SHA256 keyed with `key` (any length is a valid HMAC key).
pub fn hmac_sha256(key: &[u8]) -> hmac::Hmac<Sha256> {
    use hmac::Mac;
    <hmac::Hmac<Sha256> as Mac>::new_from_slice(key).expect("HMAC takes a key of any length")
}

/// The `X-Pantowatch-Signature` value for a body sent at `timestamp` (Unix seconds, as text).
pub fn signature(secret: &str, timestamp: &str, body: &str) -> String {
    let msg = format!("{timestamp}.{body}");
    format!(
        "sha256={}",
        hmac_sha256_hex(secret.as_bytes(), msg.as_bytes())
    )
}

/// Wait after failed attempt number `attempts` (1-based).
pub fn backoff(base: Duration, attempts: i64) -> Duration {
    let exp = u32::try_from(attempts.saturating_sub(1).clamp(0, 20)).unwrap_or(20);
    base.saturating_mul(2u32.saturating_pow(exp))
        .min(Duration::from_secs(3600))
}

/// The HTTP client of the deliveries (timeouts always set).
pub fn client(opts: &DeliveryOptions) -> reqwest::Result<reqwest::Client> {
    reqwest::Client::builder()
        .timeout(opts.timeout)
        .connect_timeout(opts.timeout)
        .redirect(reqwest::redirect::Policy::none())
        .user_agent(concat!("pantowatch/", env!("CARGO_PKG_VERSION")))
        .build()
}

/// One attempt of one delivery.
pub async fn attempt(
    client: &reqwest::Client,
    d: &DueDelivery,
    opts: &DeliveryOptions,
) -> AttemptResult {
    let ts = Utc::now().timestamp().to_string();
    let sent = client
        .post(&d.url)
        .header("content-type", "application/json")
        .header("x-pantowatch-timestamp", &ts)
        .header(
            "x-pantowatch-signature",
            signature(&d.secret, &ts, &d.payload),
        )
        .header("idempotency-key", d.id.to_string())
        .body(d.payload.clone())
        .send()
        .await;
    let (status, error) = match sent {
        Ok(r) if r.status().is_success() => {
            return AttemptResult::Delivered {
                status: i64::from(r.status().as_u16()),
            };
        }
        Ok(r) => (
            Some(i64::from(r.status().as_u16())),
            format!("HTTP {}", r.status()),
        ),
        Err(e) if e.is_timeout() => (None, format!("no answer within {:?}", opts.timeout)),
        Err(e) if e.is_connect() => (None, format!("could not connect: {e}")),
        Err(e) => (None, format!("request failed: {e}")),
    };
    if d.attempts >= i64::from(opts.max_attempts) {
        AttemptResult::Failed { status, error }
    } else {
        let wait = chrono::TimeDelta::from_std(backoff(opts.backoff_base, d.attempts))
            .unwrap_or(chrono::TimeDelta::hours(1));
        AttemptResult::Retry {
            status,
            error,
            next_at: Utc::now() + wait,
        }
    }
}

/// Delivers due webhooks until `shutdown` turns true; `wake` shortens the idle wait.
pub async fn run(
    store: Store,
    opts: DeliveryOptions,
    wake: Arc<Notify>,
    mut shutdown: watch::Receiver<bool>,
) {
    let client = match client(&opts) {
        Ok(c) => c,
        Err(e) => {
            tracing::error!(error = %e, "webhook client could not be built: no deliveries");
            return;
        }
    };
    // A claim outlives its attempt: then a dead process's deliveries are due again.
    let lease = opts.timeout + Duration::from_secs(5);
    loop {
        if *shutdown.borrow() {
            break;
        }
        let due = match store.claim_deliveries(16, lease).await {
            Ok(d) => d,
            Err(e) => {
                tracing::error!(error = %e, "webhook outbox unreadable");
                Vec::new()
            }
        };
        let busy = !due.is_empty();
        let mut set = JoinSet::new();
        for d in due {
            let (client, store) = (client.clone(), store.clone());
            set.spawn(async move {
                let r = attempt(&client, &d, &opts).await;
                match &r {
                    AttemptResult::Delivered { status } => {
                        tracing::info!(delivery = d.id, status, "webhook delivered")
                    }
                    AttemptResult::Retry { error, .. } => {
                        tracing::warn!(delivery = d.id, attempt = d.attempts, %error, "webhook attempt failed; will retry")
                    }
                    AttemptResult::Failed { error, .. } => {
                        tracing::warn!(delivery = d.id, attempt = d.attempts, %error, "webhook delivery failed for good")
                    }
                }
                if let Err(e) = store.finish_delivery(d.id, d.attempts, &r).await {
                    tracing::error!(delivery = d.id, error = %e, "webhook attempt not recorded; it will be retried");
                }
            });
        }
        while set.join_next().await.is_some() {}
        if busy {
            continue;
        }
        tokio::select! {
            _ = wake.notified() => {}
            _ = tokio::time::sleep(opts.poll) => {}
            _ = shutdown.changed() => {}
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hmac_matches_rfc_4231() {
        // Test case 2.
        assert_eq!(
            hmac_sha256_hex(b"Jefe", b"what do ya want for nothing?"),
            "5bdcc146bf60754e6a042426089575c75a003f089d2739839dec58b964ec3843"
        );
        // Test case 6: a key longer than the block.
        assert_eq!(
            hmac_sha256_hex(
                &[0xaa; 131],
                b"Test Using Larger Than Block-Size Key - Hash Key First"
            ),
            "60e431591ee0b67f0d8a26aacbf5b77f8e0bc6213728c5140546040f0ee37f54"
        );
        assert_eq!(
            signature("s", "1", "{}"),
            format!("sha256={}", hmac_sha256_hex(b"s", b"1.{}"))
        );
    }

    #[test]
    fn backoff_doubles_and_caps() {
        let b = Duration::from_millis(100);
        assert_eq!(backoff(b, 1), Duration::from_millis(100));
        assert_eq!(backoff(b, 3), Duration::from_millis(400));
        assert_eq!(backoff(b, 60), Duration::from_secs(3600));
    }
}
