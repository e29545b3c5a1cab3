//! `/v1/traces`: upload (JSON or CSV, idempotent on `trace_id`), metadata, samples (JSON or
//! CSV) and the fit of a trace.

use std::collections::BTreeMap;

use axum::Json;
use axum::extract::State;
use axum::http::{HeaderMap, HeaderValue, StatusCode, header};
use axum::response::{IntoResponse, Response};
use chrono::{DateTime, Utc};
use serde::Serialize;
use serde_json::Value;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::auth::{Reader, Writer};
use super::error::{AppError, JobView, Problem};
use super::extract::{ApiPath, TraceUpload};
use super::state::AppState;
use crate::ids::{Serial, TraceId, VehicleId};
use crate::ingest::{self, Accepted};
use crate::store::{JobState, Status, TraceMeta};
use crate::trace_csv;
use pantowatch_models::report::{
    CombinationResult, FitDetails, JointResult, PooledRig, PooledTests, Quantity, ResidualResult,
};

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(upload_trace))
        .routes(routes!(get_trace))
        .routes(routes!(get_samples))
        .routes(routes!(get_fit))
        .routes(routes!(get_fit_curve))
}

/// Links of a trace.
#[derive(Debug, Serialize, ToSchema)]
pub struct TraceLinks {
    #[serde(rename = "self")]
    pub self_: String,
    pub samples: String,
    pub fit: String,
    pub curve: String,
}

impl TraceLinks {
    fn of(id: &str) -> Self {
        TraceLinks {
            self_: format!("/v1/traces/{id}"),
            samples: format!("/v1/traces/{id}/samples"),
            fit: format!("/v1/traces/{id}/fit"),
            curve: format!("/v1/traces/{id}/fit/curve"),
        }
    }
}

/// Answer to an upload: the same for a repeated identical upload.
#[derive(Debug, Serialize, ToSchema)]
pub struct TraceAccepted {
    pub trace_id: String,
    /// State of the trace's fit job.
    pub status: JobState,
    pub links: TraceLinks,
}

impl From<Accepted> for TraceAccepted {
    fn from(a: Accepted) -> Self {
        TraceAccepted {
            links: TraceLinks::of(&a.trace_id),
            trace_id: a.trace_id,
            status: a.job_state,
        }
    }
}

/// The pantograph of a trace.
#[derive(Debug, Serialize, ToSchema)]
pub struct PantographRef {
    /// The pantograph type (e.g. `160EC`).
    #[schema(min_length = 1, max_length = 256)]
    pub model: String,
    #[schema(value_type = Option<Serial>)]
    pub serial: Option<String>,
}

/// Summary of a trace's current fit.
#[derive(Debug, Serialize, ToSchema)]
pub struct FitSummary {
    pub fit_id: i64,
    pub model_version: String,
    pub fitted_at: DateTime<Utc>,
    /// Worst joint status.
    pub status: Option<Status>,
}

/// A stored trace (metadata; the samples are at `links.samples`).
#[derive(Debug, Serialize, ToSchema)]
pub struct TraceView {
    pub trace_id: String,
    pub vehicle_id: String,
    pub pantograph: PantographRef,
    pub recorded_at: DateTime<Utc>,
    /// The document's `test` object.
    #[schema(value_type = Object)]
    pub test: Value,
    /// Channel names, `t_s` first.
    pub channels: Vec<String>,
    pub sample_count: i64,
    /// Size of the stored (packed, compressed) samples.
    pub samples_bytes: i64,
    /// SHA-256 of the canonical document: the idempotency key with `trace_id`.
    pub content_sha256: String,
    pub created_at: DateTime<Utc>,
    /// The latest fit job.
    pub job: Option<JobView>,
    /// The current fit.
    pub fit: Option<FitSummary>,
    pub links: TraceLinks,
}

/// The samples of a trace.
#[derive(Debug, Serialize, ToSchema)]
pub struct SamplesView {
    pub trace_id: String,
    /// Channel name → values (bit-identical to the upload).
    pub channels: BTreeMap<String, Vec<f64>>,
}

/// The trace's current fit: the trace format's fit result plus where it came from.
#[derive(Debug, Serialize, ToSchema)]
pub struct FitView {
    pub trace_id: String,
    pub fit_id: i64,
    pub model_version: String,
    pub fitted_at: DateTime<Utc>,
    /// Worst joint status.
    pub status: Option<Status>,
    /// Per joint: `viscous` and `dry` (`value`, `ci95`, `baseline`, `unit`), `identifiable`,
    /// `status`. (Each part of the fit result is the models' type — `pantowatch_models::report`
    /// — written as the store holds it: keys sorted, a non-finite number `null`.)
    #[schema(value_type = Vec<JointResult>)]
    pub joints: Value,
    #[schema(value_type = Quantity)]
    pub rmse: Value,
    /// `effects`, `rmse_before`, `rmse_after`, `holdout_rmse_before`, `holdout_rmse_after`.
    #[schema(value_type = ResidualResult)]
    pub residual: Value,
    /// Identification details (release, sensor zero, iterations, …).
    #[schema(value_type = FitDetails)]
    pub fit: Value,
    /// A pooled lift fit's tests: `{ trace_ids (newest first), window_days }`; absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<PooledTests>)]
    pub pooled: Option<Value>,
    /// Parameters the test informs only together (lift fits, issue 15): `[{ label, members:
    /// [{ joint, kind, weight }], value, ci95, identifiable, status }]`; each is also an entry
    /// of `joints` (e.g. `J1+J3`). Absent when there are none.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<Vec<CombinationResult>>)]
    pub combinations: Option<Value>,
    /// A pooled single-joint fit across recordings of one rig (issue 36, point 5; the uploads'
    /// `test.rig_id`): each recording's errors alone and pooled, before and after, and the
    /// pooled verdict; absent otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    #[schema(value_type = Option<PooledRig>)]
    pub pooled_rig: Option<Value>,
}

/// The trace document (`pantograph-trace/1`) as uploaded; see the trace format.
#[derive(Debug, Serialize, ToSchema)]
pub struct TraceDocument {
    #[schema(pattern = "^pantograph-trace/1$")]
    pub format: String,
    /// Optional client-chosen id (letters, digits, `- _ . :`); uploads with the same id are
    /// idempotent.
    #[schema(value_type = Option<TraceId>)]
    pub trace_id: Option<String>,
    #[schema(value_type = VehicleId)]
    pub vehicle_id: String,
    pub pantograph: PantographRef,
    /// RFC 3339.
    #[schema(format = DateTime)]
    pub recorded_at: String,
    /// `{ kind: pendulum|slider|lift|quadrangle_swing|static_force, joint, rig, protocol, release_t_s, gauge_resolution_n }`.
    #[schema(value_type = Object)]
    pub test: Value,
    /// `t_s` (strictly increasing) and the kind's channels, all of one length, finite.
    pub channels: BTreeMap<String, Vec<f64>>,
}

fn trace_id(raw: &str) -> Result<TraceId, AppError> {
    TraceId::parse("trace_id", raw).map_err(AppError::parameter_id)
}

fn not_found(id: &TraceId) -> AppError {
    AppError::NotFound(format!("no trace `{id}`"))
}

/// Upload a trace.
///
/// The body is the trace format's JSON document, or CSV from a data logger (`# key: value`
/// metadata lines, a header row of channel names with `t_s` first, then one row per sample).
/// Both are validated by the same rules; nothing is stored when one is broken. The fit runs in
/// the background: follow `links.fit`. Uploading the same `trace_id` with the same content
/// answers the same; with other content, 409.
#[utoipa::path(post, path = "/v1/traces", tag = "traces",
    request_body(description = "A trace document (JSON, `application/json`) or the CSV a data \
        logger writes (`text/csv`): `# key: value` metadata lines (the document's field paths: \
        `format`, `trace_id`, `vehicle_id`, `pantograph.model`, `pantograph.serial`, \
        `recorded_at`, `test.kind`, `test.joint`, `test.rig`, `test.protocol`, \
        `test.gauge_resolution_n`), a header row of channel names with `t_s` first, then one row \
        per sample, separated by `,` (or `;` with a decimal comma). A CSV not of this shape is \
        400; either form breaking a rule of the trace format (../shared/contract/TRACE_FORMAT.md: \
        `t_s` strictly increasing, channels of one length, the kind's channels, finite values, \
        rig values within the type's limits) is 422.",
        content((TraceDocument = "application/json"), (String = "text/csv"))),
    responses(
        (status = 202, description = "Stored; its fit is queued", body = TraceAccepted),
        (status = 400, description = "Not JSON, or not CSV of the shape the request body describes (`field` names the line or field)", body = Problem, content_type = "application/problem+json"),
        (status = 409, description = "The trace_id is stored with other content", body = Problem, content_type = "application/problem+json"),
        (status = 413, description = "Body larger than the limit", body = Problem, content_type = "application/problem+json"),
        (status = 415, description = "Neither application/json nor text/csv", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "A rule of the trace format is broken (`field` names it)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["writer"])))]
pub async fn upload_trace(
    State(st): State<AppState>,
    _auth: Writer,
    upload: TraceUpload,
) -> Result<(StatusCode, HeaderMap, Json<TraceAccepted>), AppError> {
    let accepted = st.intake.upload(upload.format, upload.body).await?;
    let mut headers = HeaderMap::new();
    if let Ok(v) = HeaderValue::from_str(&format!("/v1/traces/{}", accepted.trace_id)) {
        headers.insert(header::LOCATION, v);
    }
    Ok((StatusCode::ACCEPTED, headers, Json(accepted.into())))
}

/// A trace's metadata, its fit job and current fit.
#[utoipa::path(get, path = "/v1/traces/{trace_id}", tag = "traces",
    params(("trace_id" = TraceId, Path, description = "trace id")),
    responses(
        (status = 200, description = "The trace's metadata, fit job and current fit", body = TraceView),
        (status = 400, description = "Malformed trace id", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn get_trace(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(raw): ApiPath<String>,
) -> Result<Json<TraceView>, AppError> {
    let id = trace_id(&raw)?;
    let meta = st
        .store
        .get_trace(id.as_str())
        .await?
        .ok_or_else(|| not_found(&id))?;
    let job = st.store.latest_job(id.as_str()).await?.map(JobView::from);
    let fit = st.store.get_fit(id.as_str()).await?.map(|f| FitSummary {
        fit_id: f.id,
        model_version: f.model_version,
        fitted_at: f.created_at,
        status: f.status,
    });
    Ok(Json(trace_view(meta, job, fit)))
}

fn trace_view(m: TraceMeta, job: Option<JobView>, fit: Option<FitSummary>) -> TraceView {
    TraceView {
        links: TraceLinks::of(&m.trace_id),
        test: serde_json::from_str(&m.test_json).unwrap_or(Value::Null),
        trace_id: m.trace_id,
        vehicle_id: m.vehicle_id,
        pantograph: PantographRef {
            model: m.model,
            serial: m.serial,
        },
        recorded_at: m.recorded_at,
        channels: m.channel_names,
        sample_count: m.sample_count,
        samples_bytes: m.samples_bytes,
        content_sha256: m.content_sha256,
        created_at: m.created_at,
        job,
        fit,
    }
}

/// True when the client asks for CSV (`Accept: text/csv`) rather than JSON.
fn wants_csv(headers: &HeaderMap) -> bool {
    headers
        .get_all(header::ACCEPT)
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .any(|m| {
            m.split(';')
                .next()
                .is_some_and(|e| e.trim().eq_ignore_ascii_case("text/csv"))
        })
}

/// A trace's samples: JSON, or with `Accept: text/csv` the whole trace in the CSV upload shape.
#[utoipa::path(get, path = "/v1/traces/{trace_id}/samples", tag = "traces",
    params(("trace_id" = TraceId, Path, description = "trace id")),
    responses(
        (status = 200, description = "The samples, bit-identical to the upload",
            content((SamplesView = "application/json"), (String = "text/csv"))),
        (status = 400, description = "Malformed trace id", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn get_samples(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(raw): ApiPath<String>,
    headers: HeaderMap,
) -> Result<Response, AppError> {
    let id = trace_id(&raw)?;
    let (Some(meta), Some(channels)) = (
        st.store.get_trace(id.as_str()).await?,
        st.store.get_samples(id.as_str()).await?,
    ) else {
        return Err(not_found(&id));
    };
    if wants_csv(&headers) {
        let doc = ingest::stored_doc_as_sent(&meta, channels).map_err(AppError::Internal)?;
        let text = tokio::task::spawn_blocking(move || trace_csv::write(&doc))
            .await
            .map_err(|e| AppError::Internal(e.to_string()))?;
        return Ok(([(header::CONTENT_TYPE, "text/csv; charset=utf-8")], text).into_response());
    }
    Ok(Json(SamplesView {
        trace_id: meta.trace_id,
        channels: channels.into_iter().collect(),
    })
    .into_response())
}

/// A trace's current fit (the trace format's fit result). 404 with the job's state until the
/// fit is written (`job.state`: `queued`, `running`, or `failed` with `job.last_error`).
#[utoipa::path(get, path = "/v1/traces/{trace_id}/fit", tag = "traces",
    params(("trace_id" = TraceId, Path, description = "trace id")),
    responses(
        (status = 200, description = "The fit result", body = FitView),
        (status = 400, description = "Malformed trace id", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such trace, or no fit yet (then `job` says why)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn get_fit(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(raw): ApiPath<String>,
) -> Result<Json<FitView>, AppError> {
    let id = trace_id(&raw)?;
    if let Some(f) = st.store.get_fit(id.as_str()).await? {
        // The stored result, typed, written back part by part: the JSON the store holds
        // (every object's keys in sorted order, a non-finite number `null`).
        let r = f.result()?;
        let fit_id = f.id;
        let json = |v: serde_json::Result<Value>| {
            v.map_err(|e| AppError::Internal(format!("fit {fit_id}: {e}")))
        };
        return Ok(Json(FitView {
            joints: json(serde_json::to_value(&r.joints))?,
            rmse: json(serde_json::to_value(&r.rmse))?,
            residual: json(serde_json::to_value(&r.residual))?,
            fit: json(serde_json::to_value(&r.fit))?,
            pooled: r
                .pooled
                .as_ref()
                .map(|p| json(serde_json::to_value(p)))
                .transpose()?,
            combinations: (!r.combinations.is_empty())
                .then(|| json(serde_json::to_value(&r.combinations)))
                .transpose()?,
            pooled_rig: r
                .pooled_rig
                .as_ref()
                .map(|p| json(serde_json::to_value(p)))
                .transpose()?,
            trace_id: f.trace_id,
            fit_id: f.id,
            model_version: f.model_version,
            fitted_at: f.created_at,
            status: f.status,
        }));
    }
    if st.store.get_trace(id.as_str()).await?.is_none() {
        return Err(not_found(&id));
    }
    let job = st.store.latest_job(id.as_str()).await?.map(JobView::from);
    let detail = match &job {
        Some(j) if j.state == JobState::Failed => format!(
            "the fit of `{id}` failed: {}",
            j.last_error.as_deref().unwrap_or("no reason recorded")
        ),
        Some(j) => format!("the fit of `{id}` is {}", j.state),
        None => format!("no fit of `{id}` is queued (an admin can re-queue it)"),
    };
    Err(AppError::FitNotReady { detail, job })
}

/// Measured vs model of a fit, as stored with it (thinned to a plot's width).
#[derive(Debug, Serialize, ToSchema)]
pub struct CurveView {
    pub trace_id: String,
    pub fit_id: i64,
    /// The fitted channel (`alpha_deg`, `h_mm`, `H_m`) and its unit.
    pub channel: String,
    pub unit: String,
    pub t_s: Vec<f64>,
    pub measured: Vec<f64>,
    pub model: Vec<f64>,
    /// Model − measured at each sample.
    pub residual: Vec<f64>,
}

/// The measured and model curves of a trace's current fit, stored when it was fitted (no
/// refit). 404 when the trace has no fit, or its fit was stored without a curve (fits written
/// before curves were kept, pooled fits).
#[utoipa::path(get, path = "/v1/traces/{trace_id}/fit/curve", tag = "traces",
    params(("trace_id" = TraceId, Path, description = "trace id")),
    responses(
        (status = 200, description = "The stored curves", body = CurveView),
        (status = 400, description = "Malformed trace id", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such trace, no fit, or a fit without a curve", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn get_fit_curve(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(raw): ApiPath<String>,
) -> Result<Json<CurveView>, AppError> {
    let id = trace_id(&raw)?;
    let Some(f) = st.store.get_fit(id.as_str()).await? else {
        return Err(AppError::NotFound(format!("no fit of trace `{id}`")));
    };
    let Some(c) = st.store.fit_curve(f.id).await? else {
        return Err(AppError::NotFound(format!(
            "fit {} of trace `{id}` was stored without a curve",
            f.id
        )));
    };
    let residual = c.residual();
    Ok(Json(CurveView {
        trace_id: f.trace_id,
        fit_id: f.id,
        channel: c.channel,
        unit: c.unit,
        t_s: c.t_s,
        measured: c.measured,
        model: c.model,
        residual,
    }))
}
