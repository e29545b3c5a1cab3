//! Access: every `/v1` handler takes one of [`Reader`], [`Writer`], [`Admin`], extractors that
//! check `Authorization: Bearer <key>` against the store and the key's role.
//!
//! No or unknown/revoked key → 401; a key whose role is too low → 403. The web pages take
//! [`WebUser`]: a signed session cookie (`super::session`) whose key is still unrevoked.

use std::marker::PhantomData;

use axum::extract::FromRequestParts;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;
use axum::response::{IntoResponse, Redirect, Response};

use super::error::AppError;
use super::session::cookie_value;
use super::state::AppState;
use crate::store::{ApiKey, Role};

/// The least role a route needs.
pub trait MinRole: Send + Sync {
    const ROLE: Role;
}

/// Marker: readers and up.
pub struct ReaderRole;
/// Marker: writers and admins.
pub struct WriterRole;
/// Marker: admins only.
pub struct AdminRole;

impl MinRole for ReaderRole {
    const ROLE: Role = Role::Reader;
}
impl MinRole for WriterRole {
    const ROLE: Role = Role::Writer;
}
impl MinRole for AdminRole {
    const ROLE: Role = Role::Admin;
}

/// A caller whose key has at least role `R`.
pub struct Auth<R> {
    pub key: ApiKey,
    _role: PhantomData<R>,
}

/// Reads.
pub type Reader = Auth<ReaderRole>;
/// Reads and uploads.
pub type Writer = Auth<WriterRole>;
/// Everything, including keys and re-fits.
pub type Admin = Auth<AdminRole>;

/// The key presented in an `Authorization: Bearer <key>` header.
pub(crate) fn bearer(parts: &Parts) -> Result<&str, AppError> {
    let value = parts.headers.get(AUTHORIZATION).ok_or_else(|| {
        AppError::Unauthorized("this route needs `Authorization: Bearer <key>`".into())
    })?;
    let text = value
        .to_str()
        .map_err(|_| AppError::Unauthorized("the Authorization header is not text".into()))?;
    let (scheme, key) = text.trim().split_once(' ').unwrap_or((text, ""));
    if !scheme.eq_ignore_ascii_case("bearer") || key.trim().is_empty() {
        return Err(AppError::Unauthorized(
            "the Authorization header must be `Bearer <key>`".into(),
        ));
    }
    Ok(key.trim())
}

impl<R: MinRole> FromRequestParts<AppState> for Auth<R> {
    type Rejection = AppError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, AppError> {
        let secret = bearer(parts)?;
        // The rate limiter's `identify` has usually checked this very header already.
        let verified = match parts.extensions.get::<VerifiedKey>() {
            Some(VerifiedKey(found)) => found.clone(),
            None => state.store.verify_api_key(secret).await?,
        };
        let key =
            verified.ok_or_else(|| AppError::Unauthorized("unknown or revoked API key".into()))?;
        if key.role < R::ROLE {
            return Err(AppError::Forbidden(format!(
                "this route needs a {} key; this key is a {} key",
                R::ROLE,
                key.role
            )));
        }
        Ok(Auth {
            key,
            _role: PhantomData,
        })
    }
}

/// The outcome of checking the request's bearer key (`None`: unknown or revoked), left in the
/// request's extensions by `ratelimit::identify` for the `Auth` extractor.
#[derive(Debug, Clone)]
pub struct VerifiedKey(pub Option<ApiKey>);

/// A signed-in person: the key they signed in with (still unrevoked).
pub struct WebUser {
    pub key: ApiKey,
}

/// Not signed in: to the sign-in page.
pub struct SignIn;

impl IntoResponse for SignIn {
    fn into_response(self) -> Response {
        Redirect::to("/").into_response()
    }
}

/// The unrevoked key a request's session cookie names, if any (a store failure is logged and
/// read as "not signed in").
pub async fn signed_in(parts: &Parts, st: &AppState) -> Option<ApiKey> {
    let id = cookie_value(parts).and_then(|v| st.sessions.verify(&v))?;
    let keys = st
        .store
        .list_api_keys()
        .await
        .map_err(|e| tracing::error!(error = %e, "session check failed"))
        .ok()?;
    keys.into_iter()
        .find(|k| k.id == id && k.revoked_at.is_none())
}

impl FromRequestParts<AppState> for WebUser {
    type Rejection = SignIn;

    async fn from_request_parts(parts: &mut Parts, st: &AppState) -> Result<Self, SignIn> {
        let key = signed_in(parts, st).await.ok_or(SignIn)?;
        Ok(WebUser { key })
    }
}
