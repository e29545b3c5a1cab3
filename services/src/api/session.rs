//! Web sign-in: an API key exchanged for a signed session cookie (`key id . expiry . HMAC`;
//! `HttpOnly; Secure; SameSite=Strict` — browsers keep `Secure` cookies on http://localhost and
//! 127.0.0.1, so the demo signs in without TLS), and
//! the check of a cookie's value; `auth::WebUser` is the extractor that asks it — and that the
//! key is still unrevoked — on every page.

use axum::http::header::COOKIE;
use axum::http::request::Parts;
use chrono::Utc;

use crate::webhooks::{hmac_sha256, hmac_sha256_hex};

/// Name of the session cookie.
pub const COOKIE_NAME: &str = "pw_session";

/// The server key that signs session cookies, and how long a sign-in lasts.
pub struct SessionKey {
    key: Vec<u8>,
    pub hours: u64,
}

impl SessionKey {
    /// A random key: sessions end with the process.
    pub fn random(hours: u64) -> Self {
        let mut key = vec![0u8; 32];
        if getrandom::fill(&mut key).is_err() {
            // No randomness: a key nobody can guess is impossible, so no session will verify.
            key.clear();
        }
        SessionKey { key, hours }
    }

    /// A key from the configured secret.
    pub fn from_secret(secret: &str, hours: u64) -> Self {
        SessionKey {
            key: secret.as_bytes().to_vec(),
            hours,
        }
    }

    fn sign(&self, msg: &str) -> String {
        hmac_sha256_hex(&self.key, msg.as_bytes())
    }

    /// The `Set-Cookie` value of a new session for `key_id`.
    pub fn cookie(&self, key_id: i64) -> String {
        let secs = self.hours.saturating_mul(3600);
        let exp = Utc::now()
            .timestamp()
            .saturating_add(i64::try_from(secs).unwrap_or(i64::MAX));
        let msg = format!("{key_id}.{exp}");
        format!(
            "{COOKIE_NAME}={msg}.{}; Path=/; HttpOnly; Secure; SameSite=Strict; Max-Age={secs}",
            self.sign(&msg)
        )
    }

    /// The key id of a valid, unexpired session cookie value.
    pub fn verify(&self, value: &str) -> Option<i64> {
        if self.key.is_empty() {
            return None;
        }
        let (msg, sig) = value.rsplit_once('.')?;
        let sig = hex::decode(sig).ok()?;
        // The `hmac` crate's verify compares in constant time.
        hmac::Mac::verify_slice(
            hmac::Mac::chain_update(hmac_sha256(&self.key), msg.as_bytes()),
            &sig,
        )
        .ok()?;
        let (id, exp) = msg.split_once('.')?;
        let exp: i64 = exp.parse().ok()?;
        (exp > Utc::now().timestamp()).then_some(())?;
        id.parse().ok()
    }
}

/// The `Set-Cookie` value that ends a session.
pub fn clear_cookie() -> String {
    format!("{COOKIE_NAME}=; Path=/; HttpOnly; Secure; SameSite=Strict; Max-Age=0")
}

/// The session cookie's value in a request.
pub fn cookie_value(parts: &Parts) -> Option<String> {
    parts
        .headers
        .get_all(COOKIE)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(';'))
        .filter_map(|c| c.trim().split_once('='))
        .find(|(n, _)| *n == COOKIE_NAME)
        .map(|(_, v)| v.to_owned())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cookies_verify_only_when_signed_by_us_and_unexpired() {
        let k = SessionKey::from_secret("s3cret", 1);
        let c = k.cookie(7);
        let value = c
            .strip_prefix("pw_session=")
            .and_then(|c| c.split(';').next())
            .expect("value");
        assert_eq!(k.verify(value), Some(7));
        assert!(c.contains("HttpOnly") && c.contains("SameSite=Strict"));
        let forged = value.replacen('7', "8", 1);
        assert_eq!(k.verify(&forged), None);
        assert_eq!(SessionKey::from_secret("other", 1).verify(value), None);
        let msg = format!("7.{}", Utc::now().timestamp() - 10);
        let expired = format!("{msg}.{}", k.sign(&msg));
        assert_eq!(k.verify(&expired), None);
    }
}
