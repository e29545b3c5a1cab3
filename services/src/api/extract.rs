//! Extractors with our own rejections: every refusal is a problem answer that names its field
//! (axum's defaults answer plain text, and some of them with a 5xx-free but opaque message).

use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::StatusCode;
use axum::http::header::CONTENT_TYPE;
use axum::http::request::Parts;
use serde::de::DeserializeOwned;

use super::AppState;
use super::error::AppError;
use crate::ingest::BodyFormat;

fn read_error(e: BytesRejection, limit: usize) -> AppError {
    if e.status() == StatusCode::PAYLOAD_TOO_LARGE {
        AppError::PayloadTooLarge(limit)
    } else {
        AppError::Malformed {
            field: Some("body".into()),
            detail: format!("could not read the request body: {e}"),
        }
    }
}

fn content_type(req: &Request) -> Option<&str> {
    req.headers()
        .get(CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
}

/// A trace upload: its format (from `Content-Type`) and its bytes (within the body limit).
pub struct TraceUpload {
    pub format: BodyFormat,
    pub body: Bytes,
}

impl FromRequest<AppState> for TraceUpload {
    type Rejection = AppError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, AppError> {
        let format = content_type(&req)
            .and_then(BodyFormat::from_content_type)
            .ok_or_else(|| {
                AppError::UnsupportedMediaType(
                    "a trace is uploaded as `application/json` (the trace format) or `text/csv` \
                     (the logger shape)"
                        .into(),
                )
            })?;
        let body = Bytes::from_request(req, state)
            .await
            .map_err(|e| read_error(e, state.body_limit))?;
        Ok(TraceUpload { format, body })
    }
}

/// A JSON request body; a field that does not deserialize is named by its path.
pub struct ApiJson<T>(pub T);

impl<T: DeserializeOwned + Send> FromRequest<AppState> for ApiJson<T> {
    type Rejection = AppError;

    async fn from_request(req: Request, state: &AppState) -> Result<Self, AppError> {
        if content_type(&req).and_then(BodyFormat::from_content_type) != Some(BodyFormat::Json) {
            return Err(AppError::UnsupportedMediaType(
                "this route takes `application/json`".into(),
            ));
        }
        let body = Bytes::from_request(req, state)
            .await
            .map_err(|e| read_error(e, state.body_limit))?;
        if let Ok(Some(key)) = crate::json_keys::first_duplicate_key(&body) {
            return Err(AppError::Invalid {
                detail: format!("`{key}` appears twice in its object"),
                field: Some(key),
            });
        }
        let de = &mut serde_json::Deserializer::from_slice(&body);
        serde_path_to_error::deserialize(de)
            .map(ApiJson)
            .map_err(|e| {
                let path = e.path().to_string();
                let field = if path == "." { "body".to_owned() } else { path };
                let syntax = e.inner().is_syntax() || e.inner().is_eof();
                let detail = e.into_inner().to_string();
                if syntax {
                    AppError::Malformed {
                        field: Some("body".into()),
                        detail: format!("not valid JSON: {detail}"),
                    }
                } else {
                    AppError::BadRequest {
                        field: Some(field),
                        detail,
                    }
                }
            })
    }
}

/// Query parameters; values arrive as strings and handlers parse them with named errors.
pub struct ApiQuery<T>(pub T);

impl<T: DeserializeOwned + Send> FromRequestParts<AppState> for ApiQuery<T> {
    type Rejection = AppError;

    async fn from_request_parts(parts: &mut Parts, _: &AppState) -> Result<Self, AppError> {
        let q = parts.uri.query().unwrap_or("");
        let de = serde_urlencoded::Deserializer::new(form_urlencoded::parse(q.as_bytes()));
        serde_path_to_error::deserialize(de)
            .map(ApiQuery)
            .map_err(|e| {
                let path = e.path().to_string();
                AppError::BadRequest {
                    field: Some(if path == "." { "query".into() } else { path }),
                    detail: format!("query string: {}", e.into_inner()),
                }
            })
    }
}

/// Path parameters as text; handlers parse them into domain ids.
pub struct ApiPath<T>(pub T);

impl<T: DeserializeOwned + Send> FromRequestParts<AppState> for ApiPath<T> {
    type Rejection = AppError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, AppError> {
        axum::extract::Path::<T>::from_request_parts(parts, state)
            .await
            .map(|p| ApiPath(p.0))
            .map_err(|e| AppError::BadRequest {
                field: Some("path".into()),
                detail: e.body_text(),
            })
    }
}
