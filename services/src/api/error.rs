//! One error type for every handler, answered as RFC 9457 problem JSON
//! (`application/problem+json`: `type`, `title`, `status`, `detail`, `field`).
//!
//! Server faults are logged with `tracing` and answered without details; user input never
//! produces a 5xx. Database faults an operator can act on are named: unavailable (503 with
//! `Retry-After`), read-only (503), full (507).

use axum::http::{HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use chrono::{DateTime, Utc};
use serde::Serialize;
use utoipa::ToSchema;

use crate::ids::IdError;
use crate::ingest::IngestError;
use crate::store::{DbFault, Job, JobState, StoreError};
use crate::trace::TraceError;

/// Media type of every error answer.
pub const PROBLEM_JSON: &str = "application/problem+json";

/// An error answer (RFC 9457).
#[derive(Debug, Clone, Serialize, ToSchema, PartialEq)]
pub struct Problem {
    /// A URI reference naming the kind of problem (`/problems/<slug>`).
    #[serde(rename = "type")]
    pub kind: String,
    /// Short summary of the kind of problem.
    pub title: String,
    /// The HTTP status code.
    pub status: u16,
    /// What went wrong with this request.
    pub detail: String,
    /// The offending field of the request's body or headers (`channels.t_s[17]`, `test.joint`,
    /// `Authorization`, `Content-Type`, …). Every 4xx names one, or a `parameter` instead.
    pub field: Option<String>,
    /// The offending path segment or query key (`trace_id`, `vehicle_id`, `id`, `limit`,
    /// `state`; `path` for a resource the path names that does not exist or a request target
    /// over the limit), on answers about the request's address rather than its body.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub parameter: Option<String>,
    /// For `GET /v1/traces/{trace_id}/fit` before the fit exists: the trace's fit job.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub job: Option<JobView>,
}

/// Everything a handler can answer besides success.
#[derive(Debug, thiserror::Error)]
pub enum AppError {
    #[error("{detail}")]
    BadRequest {
        field: Option<String>,
        detail: String,
    },
    /// A path segment or query value that does not parse: 400 naming it as `parameter`.
    #[error("{detail}")]
    BadParameter { parameter: String, detail: String },
    #[error("{detail}")]
    Malformed {
        field: Option<String>,
        detail: String,
    },
    #[error("{detail}")]
    Invalid {
        field: Option<String>,
        detail: String,
    },
    #[error("{0}")]
    Unauthorized(String),
    #[error("{0}")]
    Forbidden(String),
    #[error("{0}")]
    NotFound(String),
    #[error("{detail}")]
    FitNotReady {
        detail: String,
        job: Option<JobView>,
    },
    /// The request contradicts what is stored; `field` names the part that does.
    #[error("{detail}")]
    Conflict { field: String, detail: String },
    #[error("{0}")]
    UnsupportedMediaType(String),
    #[error("request body larger than {0} bytes")]
    PayloadTooLarge(usize),
    #[error("{0}")]
    MethodNotAllowed(String),
    #[error("{0}")]
    Unavailable(String),
    /// The database refuses writes (read-only file, database or standby).
    #[error("{0}")]
    ReadOnly(String),
    /// The database has no space left for the write.
    #[error("{0}")]
    StorageFull(String),
    #[error("request took longer than {0} s")]
    Timeout(u64),
    /// A server fault: logged, never shown.
    #[error("internal error: {0}")]
    Internal(String),
}

impl AppError {
    pub fn bad_field(field: impl Into<String>, detail: impl Into<String>) -> Self {
        AppError::BadRequest {
            field: Some(field.into()),
            detail: detail.into(),
        }
    }

    /// A path segment or query value `parameter` that does not parse.
    pub fn bad_parameter(parameter: impl Into<String>, detail: impl Into<String>) -> Self {
        AppError::BadParameter {
            parameter: parameter.into(),
            detail: detail.into(),
        }
    }

    /// An id read from the address (path segment or query value) that is not one: 400 naming
    /// it as `parameter` (the same id in a body is a `field`: `From<IdError>`).
    pub fn parameter_id(e: IdError) -> Self {
        AppError::BadParameter {
            parameter: e.field,
            detail: e.message,
        }
    }

    fn parts(&self) -> (StatusCode, &'static str, &'static str) {
        use AppError::*;
        match self {
            BadRequest { .. } | BadParameter { .. } => {
                (StatusCode::BAD_REQUEST, "bad-request", "Bad request")
            }
            Malformed { .. } => (StatusCode::BAD_REQUEST, "malformed-body", "Malformed body"),
            Invalid { .. } => (
                StatusCode::UNPROCESSABLE_ENTITY,
                "invalid-trace",
                "The trace breaks a rule of the trace format",
            ),
            Unauthorized(_) => (StatusCode::UNAUTHORIZED, "unauthorized", "Unauthorized"),
            Forbidden(_) => (StatusCode::FORBIDDEN, "forbidden", "Forbidden"),
            NotFound(_) => (StatusCode::NOT_FOUND, "not-found", "Not found"),
            FitNotReady { .. } => (StatusCode::NOT_FOUND, "fit-not-ready", "No fit yet"),
            Conflict { .. } => (StatusCode::CONFLICT, "conflict", "Conflict"),
            UnsupportedMediaType(_) => (
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                "unsupported-media-type",
                "Unsupported media type",
            ),
            PayloadTooLarge(_) => (
                StatusCode::PAYLOAD_TOO_LARGE,
                "payload-too-large",
                "Request body too large",
            ),
            MethodNotAllowed(_) => (
                StatusCode::METHOD_NOT_ALLOWED,
                "method-not-allowed",
                "Method not allowed",
            ),
            Unavailable(_) => (
                StatusCode::SERVICE_UNAVAILABLE,
                "unavailable",
                "Service unavailable",
            ),
            ReadOnly(_) => (
                StatusCode::SERVICE_UNAVAILABLE,
                "database-read-only",
                "Database is read-only",
            ),
            StorageFull(_) => (
                StatusCode::INSUFFICIENT_STORAGE,
                "database-full",
                "Database is full",
            ),
            Timeout(_) => (
                StatusCode::SERVICE_UNAVAILABLE,
                "timeout",
                "Request timed out",
            ),
            Internal(_) => (
                StatusCode::INTERNAL_SERVER_ERROR,
                "internal",
                "Internal server error",
            ),
        }
    }

    /// Seconds a client should wait before retrying, for answers that say "not now".
    pub fn retry_after_s(&self) -> Option<u32> {
        match self {
            // A restarting database is usually back within seconds.
            AppError::Unavailable(_) | AppError::Timeout(_) => Some(1),
            // Someone has to act (free space, lift read-only): poll slowly.
            AppError::ReadOnly(_) | AppError::StorageFull(_) => Some(30),
            _ => None,
        }
    }

    /// The problem document of this error.
    pub fn problem(&self) -> Problem {
        let (status, slug, title) = self.parts();
        let (detail, field, job) = match self {
            AppError::BadRequest { field, detail }
            | AppError::Malformed { field, detail }
            | AppError::Invalid { field, detail } => (detail.clone(), field.clone(), None),
            AppError::BadParameter { detail, .. } => (detail.clone(), None, None),
            AppError::Unauthorized(_) => (self.to_string(), Some("Authorization".into()), None),
            AppError::FitNotReady { detail, job } => (detail.clone(), None, job.clone()),
            AppError::Internal(_) => (
                "the server failed to answer; the error is in its log".to_owned(),
                None,
                None,
            ),
            AppError::PayloadTooLarge(_) => (self.to_string(), Some("body".into()), None),
            AppError::UnsupportedMediaType(_) => {
                (self.to_string(), Some("Content-Type".into()), None)
            }
            // The key is valid but its role is too low: the credential is what to change.
            AppError::Forbidden(_) => (self.to_string(), Some("Authorization".into()), None),
            AppError::Conflict { field, detail } => (detail.clone(), Some(field.clone()), None),
            AppError::MethodNotAllowed(_) => (self.to_string(), Some("method".into()), None),
            _ => (self.to_string(), None, None),
        };
        let parameter = match self {
            AppError::BadParameter { parameter, .. } => Some(parameter.clone()),
            // A 404 is about the address: the resource the path names does not exist.
            AppError::NotFound(_) | AppError::FitNotReady { .. } => Some("path".to_owned()),
            _ => None,
        };
        Problem {
            kind: format!("/problems/{slug}"),
            title: title.to_owned(),
            status: status.as_u16(),
            detail,
            field,
            parameter,
            job,
        }
    }
}

/// A problem answer with its status and media type.
pub fn problem_response(p: &Problem) -> Response {
    let status = StatusCode::from_u16(p.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
    let body = serde_json::to_vec(p).unwrap_or_default();
    let mut resp = (status, body).into_response();
    resp.headers_mut()
        .insert(header::CONTENT_TYPE, HeaderValue::from_static(PROBLEM_JSON));
    if status == StatusCode::UNAUTHORIZED {
        resp.headers_mut().insert(
            header::WWW_AUTHENTICATE,
            HeaderValue::from_static("Bearer realm=\"pantowatch\""),
        );
    }
    resp
}

impl IntoResponse for AppError {
    fn into_response(self) -> Response {
        if let AppError::Internal(e) = &self {
            tracing::error!(error = %e, "request failed");
        }
        let mut resp = problem_response(&self.problem());
        if let Some(s) = self.retry_after_s() {
            resp.headers_mut()
                .insert(header::RETRY_AFTER, HeaderValue::from(s));
        }
        resp
    }
}

impl From<crate::static_force::PredictError> for AppError {
    fn from(e: crate::static_force::PredictError) -> Self {
        use crate::static_force::PredictError as P;
        match e {
            P::NoPantograph(_) | P::NoModel(_) => AppError::NotFound(e.to_string()),
            P::Model(_) => AppError::Invalid {
                field: Some("parameters".to_owned()),
                detail: e.to_string(),
            },
            P::Store(s) => s.into(),
        }
    }
}

impl From<StoreError> for AppError {
    fn from(e: StoreError) -> Self {
        match e {
            // The store refused a value of the caller's, naming it (the trace checks come
            // first, so this is rare).
            StoreError::InvalidField { field, message } => AppError::Invalid {
                detail: format!("`{field}`: {message}"),
                field: Some(field),
            },
            // The store refused a value this code built (a fit result, an alert's evidence): a
            // server fault, logged.
            StoreError::Invalid(m) => AppError::Internal(format!("the store refused: {m}")),
            other => match other.fault() {
                Some(f) => {
                    tracing::warn!(error = %other, "database fault: {}", f.describe());
                    let detail = f.describe().to_owned();
                    match f {
                        DbFault::Unavailable => AppError::Unavailable(detail),
                        DbFault::ReadOnly => AppError::ReadOnly(detail),
                        DbFault::Full => AppError::StorageFull(detail),
                    }
                }
                None => AppError::Internal(other.to_string()),
            },
        }
    }
}

impl From<IdError> for AppError {
    fn from(e: IdError) -> Self {
        AppError::BadRequest {
            field: Some(e.field),
            detail: e.message,
        }
    }
}

fn trace_error(e: TraceError, malformed: bool) -> AppError {
    let detail = format!("`{}`: {}", e.field, e.message);
    if malformed {
        AppError::Malformed {
            field: Some(e.field),
            detail,
        }
    } else {
        AppError::Invalid {
            field: Some(e.field),
            detail,
        }
    }
}

impl From<IngestError> for AppError {
    fn from(e: IngestError) -> Self {
        match e {
            IngestError::Malformed(t) => trace_error(t, true),
            IngestError::Invalid(t) => trace_error(t, false),
            IngestError::Conflict(id) => AppError::Conflict {
                field: "trace_id".into(),
                detail: format!(
                    "trace `{id}` is already stored with other content; choose another trace_id"
                ),
            },
            IngestError::Store(s) => s.into(),
        }
    }
}

/// A fit job, as shown with a trace.
#[derive(Debug, Clone, PartialEq, Serialize, ToSchema)]
pub struct JobView {
    pub id: i64,
    pub state: JobState,
    pub attempts: i64,
    pub model_version: String,
    /// Why the last attempt failed (e.g. `lift` traces cannot be fitted yet).
    pub last_error: Option<String>,
    pub updated_at: DateTime<Utc>,
}

impl From<Job> for JobView {
    fn from(j: Job) -> Self {
        JobView {
            id: j.id,
            state: j.state,
            attempts: j.attempts,
            model_version: j.model_version,
            last_error: j.last_error,
            updated_at: j.updated_at,
        }
    }
}
