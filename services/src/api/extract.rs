//! Extractors with our own rejections: every refusal is a problem answer that names its field
//! (axum's defaults answer plain text, and some of them with a 5xx-free but opaque message).

use axum::body::Bytes;
use axum::extract::rejection::BytesRejection;
use axum::extract::{FromRequest, FromRequestParts, Request};
use axum::http::StatusCode;
use axum::http::header::CONTENT_TYPE;
use axum::http::request::Parts;
use serde::de::DeserializeOwned;

use super::error::AppError;
use super::state::AppState;
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
                let syntax = e.inner().is_syntax() || e.inner().is_eof();
                let detail = e.into_inner().to_string();
                // serde names an unknown or missing key only in its message
                // ("unknown field `x`, expected …"): the field is that key, under its object.
                let key = ["unknown field `", "missing field `"]
                    .iter()
                    .find_map(|p| detail.strip_prefix(p))
                    .and_then(|rest| rest.split('`').next());
                // serde_path_to_error's path ends at an unknown key already, at its object for
                // a missing one.
                let field = match (path.as_str(), key) {
                    (".", Some(k)) => k.to_owned(),
                    (".", None) => "body".to_owned(),
                    (p, Some(k)) if p != k && !p.ends_with(&format!(".{k}")) => {
                        format!("{p}.{k}")
                    }
                    (p, _) => p.to_owned(),
                };
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

/// Query parameters; values arrive as strings and handlers parse them with named errors. A
/// query that does not deserialize (a key the route does not take, a key given twice) is
/// refused naming that key as `parameter` (`query` when no single key is to blame).
pub struct ApiQuery<T>(pub T);

/// The query key to blame for `T` refusing query `q`: a key given twice, else the first pair
/// that `T` refuses on its own (an unknown key; a value of the wrong shape).
fn culprit<T: DeserializeOwned>(q: &str) -> Option<String> {
    let mut seen = std::collections::HashSet::new();
    for (k, v) in form_urlencoded::parse(q.as_bytes()) {
        if !seen.insert(k.clone()) {
            return Some(k.into_owned());
        }
        let one = form_urlencoded::Serializer::new(String::new())
            .append_pair(&k, &v)
            .finish();
        let de = serde_urlencoded::Deserializer::new(form_urlencoded::parse(one.as_bytes()));
        if T::deserialize(de).is_err() {
            return Some(k.into_owned());
        }
    }
    None
}

impl<T: DeserializeOwned + Send> FromRequestParts<AppState> for ApiQuery<T> {
    type Rejection = AppError;

    async fn from_request_parts(parts: &mut Parts, _: &AppState) -> Result<Self, AppError> {
        let q = parts.uri.query().unwrap_or("");
        let de = serde_urlencoded::Deserializer::new(form_urlencoded::parse(q.as_bytes()));
        serde_path_to_error::deserialize(de)
            .map(ApiQuery)
            .map_err(|e| {
                let path = e.path().to_string();
                let parameter = if path == "." {
                    culprit::<T>(q).unwrap_or_else(|| "query".into())
                } else {
                    path
                };
                AppError::bad_parameter(parameter, format!("query string: {}", e.into_inner()))
            })
    }
}

/// Path parameters as text; handlers parse them into domain ids. A segment that is not text
/// (invalid UTF-8 once percent-decoded) is refused naming it as `parameter` — the route's name
/// for it (`trace_id`, `vehicle_id`, `id`) — or `path` when axum does not say which.
pub struct ApiPath<T>(pub T);

impl<T: DeserializeOwned + Send> FromRequestParts<AppState> for ApiPath<T> {
    type Rejection = AppError;

    async fn from_request_parts(parts: &mut Parts, state: &AppState) -> Result<Self, AppError> {
        use axum::extract::path::ErrorKind;
        use axum::extract::rejection::PathRejection;
        axum::extract::Path::<T>::from_request_parts(parts, state)
            .await
            .map(|p| ApiPath(p.0))
            .map_err(|e| {
                let key = match &e {
                    PathRejection::FailedToDeserializePathParams(f) => match f.kind() {
                        ErrorKind::InvalidUtf8InPathParam { key }
                        | ErrorKind::ParseErrorAtKey { key, .. }
                        | ErrorKind::DeserializeError { key, .. } => Some(key.clone()),
                        _ => None,
                    },
                    _ => None,
                };
                AppError::bad_parameter(key.unwrap_or_else(|| "path".into()), e.body_text())
            })
    }
}
