//! Webhook subscriptions (admin keys): create (the signing secret is shown once), list, delete,
//! and each subscription's delivery log.

use axum::Json;
use axum::extract::State;
use axum::http::StatusCode;
use chrono::{DateTime, Utc};
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::auth::Admin;
use super::error::{AppError, Problem};
use super::extract::{ApiJson, ApiPath};
use super::state::AppState;
use crate::store::{Delivery, Severity, Webhook};

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_webhook, list_webhooks))
        .routes(routes!(delete_webhook))
        .routes(routes!(list_deliveries))
}

/// A subscription to create.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewWebhook {
    /// `http://` or `https://` URL with a host, that receives `POST`s; at most 2048
    /// characters, no whitespace or control characters.
    #[schema(
        format = "uri",
        max_length = 2048,
        pattern = "^[Hh][Tt][Tt][Pp][Ss]?://[^\\s\\x00-\\x1F\\x7F-\\x9F]+$"
    )]
    pub url: String,
    /// Which alert severities to send (default both).
    #[serde(default = "both")]
    #[schema(min_items = 1)]
    pub severities: Vec<Severity>,
}

fn both() -> Vec<Severity> {
    vec![Severity::Watch, Severity::Alarm]
}

/// A created subscription: `secret` signs every delivery and is shown this once.
#[derive(Debug, Serialize, ToSchema)]
pub struct CreatedWebhook {
    pub id: i64,
    pub url: String,
    pub severities: Vec<Severity>,
    pub secret: String,
    pub created_at: DateTime<Utc>,
}

/// Every subscription (never the secret).
#[derive(Debug, Serialize, ToSchema)]
pub struct WebhookList {
    pub webhooks: Vec<Webhook>,
}

/// The newest 100 deliveries of a subscription.
#[derive(Debug, Serialize, ToSchema)]
pub struct DeliveryLog {
    pub webhook_id: i64,
    pub deliveries: Vec<Delivery>,
}

fn check_url(raw: &str) -> Result<(), AppError> {
    // The URL parser would drop surrounding spaces and tabs or newlines inside: refused instead,
    // so that what is stored is what was sent.
    if raw.chars().any(|c| c.is_whitespace() || c.is_control()) {
        return Err(AppError::bad_field(
            "url",
            "must not contain whitespace or control characters",
        ));
    }
    let u = reqwest::Url::parse(raw)
        .map_err(|e| AppError::bad_field("url", format!("not a URL: {e}")))?;
    if !matches!(u.scheme(), "http" | "https") || u.host_str().is_none() {
        return Err(AppError::bad_field(
            "url",
            "must be an http:// or https:// URL with a host",
        ));
    }
    if raw.chars().count() > 2048 {
        return Err(AppError::bad_field("url", "at most 2048 characters"));
    }
    Ok(())
}

fn parse_id(raw: &str) -> Result<i64, AppError> {
    raw.parse::<i64>()
        .map_err(|_| AppError::bad_parameter("id", "a webhook id is a whole number"))
}

/// Subscribe a URL to alert changes (opened, escalated, resolved) of the given severities.
#[utoipa::path(post, path = "/v1/admin/webhooks", tag = "admin",
    request_body = NewWebhook,
    responses(
        (status = 201, description = "The subscription and its signing secret, shown this once", body = CreatedWebhook),
        (status = 400, description = "A bad URL or severities", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["admin"])))]
pub async fn create_webhook(
    State(st): State<AppState>,
    _auth: Admin,
    ApiJson(req): ApiJson<NewWebhook>,
) -> Result<(StatusCode, Json<CreatedWebhook>), AppError> {
    check_url(&req.url)?;
    if req.severities.is_empty() {
        return Err(AppError::bad_field(
            "severities",
            "name at least one of watch, alarm",
        ));
    }
    let mut sev = req.severities.clone();
    sev.sort();
    sev.dedup();
    let (w, secret) = st.store.create_webhook(req.url.trim(), &sev).await?;
    tracing::info!(webhook = w.id, "webhook subscription created");
    Ok((
        StatusCode::CREATED,
        Json(CreatedWebhook {
            id: w.id,
            url: w.url,
            severities: w.severities,
            secret,
            created_at: w.created_at,
        }),
    ))
}

/// Every subscription, deleted ones included.
#[utoipa::path(get, path = "/v1/admin/webhooks", tag = "admin",
    responses((status = 200, description = "Every subscription", body = WebhookList)),
    security(("bearer" = ["admin"])))]
pub async fn list_webhooks(
    State(st): State<AppState>,
    _auth: Admin,
) -> Result<Json<WebhookList>, AppError> {
    Ok(Json(WebhookList {
        webhooks: st.store.list_webhooks().await?,
    }))
}

/// Delete a subscription: nothing more is sent to it; its pending deliveries fail.
#[utoipa::path(delete, path = "/v1/admin/webhooks/{id}", tag = "admin",
    params(("id" = i64, Path, description = "webhook id")),
    responses(
        (status = 204, description = "Deleted"),
        (status = 404, description = "No such subscription, or deleted already", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["admin"])))]
pub async fn delete_webhook(
    State(st): State<AppState>,
    _auth: Admin,
    ApiPath(raw): ApiPath<String>,
) -> Result<StatusCode, AppError> {
    let id = parse_id(&raw)?;
    if st.store.delete_webhook(id).await? {
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(AppError::NotFound(format!("no live webhook {id}")))
    }
}

/// The delivery log of a subscription: newest first, each with attempts, last status and error.
/// A deleted subscription keeps its log (it is listed with its `deleted_at`, and its pending
/// deliveries show why they failed): only an id never created is 404.
#[utoipa::path(get, path = "/v1/admin/webhooks/{id}/deliveries", tag = "admin",
    params(("id" = i64, Path, description = "webhook id")),
    responses(
        (status = 200, description = "The newest deliveries, of a live or deleted subscription", body = DeliveryLog),
    ),
    security(("bearer" = ["admin"])))]
pub async fn list_deliveries(
    State(st): State<AppState>,
    _auth: Admin,
    ApiPath(raw): ApiPath<String>,
) -> Result<Json<DeliveryLog>, AppError> {
    let id = parse_id(&raw)?;
    if !st.store.list_webhooks().await?.iter().any(|w| w.id == id) {
        return Err(AppError::NotFound(format!("no webhook {id}")));
    }
    Ok(Json(DeliveryLog {
        webhook_id: id,
        deliveries: st.store.list_deliveries(id, 100).await?,
    }))
}
