//! Access: every `/v1` handler takes one of [`Reader`], [`Writer`], [`Admin`], extractors that
//! check `Authorization: Bearer <key>` against the store and the key's role.
//!
//! No or unknown/revoked key → 401; a key whose role is too low → 403.

use std::marker::PhantomData;

use axum::extract::FromRequestParts;
use axum::http::header::AUTHORIZATION;
use axum::http::request::Parts;

use super::AppState;
use super::error::AppError;
use super::ratelimit::VerifiedKey;
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
