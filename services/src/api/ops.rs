//! Operations, outside `/v1` and without keys: `/healthz` (the process answers), `/readyz`
//! (database reachable, migrations applied), `/metrics` (Prometheus text).

use axum::Json;
use axum::extract::State;
use axum::http::header;
use axum::response::{IntoResponse, Response};
use metrics_exporter_prometheus::PrometheusHandle;
use serde::Serialize;
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::error::{AppError, Problem};
use super::state::AppState;
use crate::store::{BackendKind, Store};

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(healthz))
        .routes(routes!(readyz))
        .routes(routes!(metrics))
}

/// Liveness / readiness answer.
#[derive(Debug, Serialize, ToSchema)]
pub struct Health {
    /// `ok` (live) or `ready`.
    pub status: String,
    /// `sqlite` or `postgresql` (`/readyz` only).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub database: Option<String>,
}

/// The process is up.
#[utoipa::path(get, path = "/healthz", tag = "ops", responses((status = 200, description = "The process answers", body = Health)))]
pub async fn healthz() -> Json<Health> {
    Json(Health {
        status: "ok".into(),
        database: None,
    })
}

/// The database answers and every migration is applied.
#[utoipa::path(get, path = "/readyz", tag = "ops",
    responses(
        (status = 200, description = "Ready", body = Health),
        (status = 503, description = "Database unreachable or not migrated", body = Problem, content_type = "application/problem+json"),
    ))]
pub async fn readyz(State(st): State<AppState>) -> Result<Json<Health>, AppError> {
    if let Err(e) = st.store.ping().await {
        tracing::warn!(error = %e, "readiness: database unreachable");
        return Err(AppError::Unavailable("the database does not answer".into()));
    }
    match st.store.migrations_applied().await {
        Ok(true) => {}
        Ok(false) => {
            return Err(AppError::Unavailable(
                "database migrations are not all applied".into(),
            ));
        }
        Err(e) => {
            tracing::warn!(error = %e, "readiness: migrations unknown");
            return Err(AppError::Unavailable(
                "could not read the migration state".into(),
            ));
        }
    }
    Ok(Json(Health {
        status: "ready".into(),
        database: Some(
            match st.store.kind() {
                BackendKind::Sqlite => "sqlite",
                BackendKind::Postgres => "postgresql",
            }
            .into(),
        ),
    }))
}

/// Prometheus metrics: HTTP requests and latency per route, jobs processed and failed, fit
/// duration, jobs per state.
#[utoipa::path(get, path = "/metrics", tag = "ops",
    responses((status = 200, description = "Prometheus text format", body = String, content_type = "text/plain")))]
pub async fn metrics(State(st): State<AppState>) -> impl IntoResponse {
    prometheus_answer(&st.store, &st.metrics).await
}

/// The Prometheus answer of an API or a worker process: this process's counters and
/// histograms, and the queue gauges read from the store at scrape time — jobs per state
/// (`pantowatch_jobs{state}`), the oldest queued job's age
/// (`pantowatch_queue_oldest_job_age_seconds`, 0 when none waits) and the webhook outbox
/// backlog (`pantowatch_webhook_outbox_backlog`).
pub async fn prometheus_answer(store: &Store, handle: &PrometheusHandle) -> Response {
    match store.job_counts().await {
        Ok(c) => {
            for (state, n) in [
                ("queued", c.queued),
                ("running", c.running),
                ("done", c.done),
                ("failed", c.failed),
            ] {
                metrics::gauge!("pantowatch_jobs", "state" => state).set(n as f64);
            }
        }
        Err(e) => tracing::warn!(error = %e, "metrics: job counts unavailable"),
    }
    match store.queue_stats().await {
        Ok(q) => {
            metrics::gauge!("pantowatch_queue_oldest_job_age_seconds")
                .set(q.oldest_queued_age_s.unwrap_or(0.0).max(0.0));
            metrics::gauge!("pantowatch_webhook_outbox_backlog").set(q.outbox_backlog as f64);
        }
        Err(e) => tracing::warn!(error = %e, "metrics: queue stats unavailable"),
    }
    handle.run_upkeep();
    (
        [(
            header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        handle.render(),
    )
        .into_response()
}
