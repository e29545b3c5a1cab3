//! Administration: API keys (create, list, revoke) and re-fits after a model change. Admin keys
//! only.

use axum::Json;
use axum::extract::State;
use axum::http::StatusCode;
use chrono::{DateTime, Utc};
use pantowatch_models::report::MODEL_VERSION;
use serde::{Deserialize, Serialize};
use utoipa::ToSchema;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::auth::Admin;
use super::error::{AppError, Problem};
use super::extract::{ApiJson, ApiPath};
use super::state::AppState;
use crate::ids::VehicleId;
use crate::store::{ApiKey, Role};

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(create_key, list_keys))
        .routes(routes!(revoke_key))
        .routes(routes!(refit))
}

/// A key to create.
#[derive(Debug, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct NewKey {
    pub role: Role,
    /// Free text: who or what uses the key; at most 256 characters, no control characters.
    #[serde(default)]
    #[schema(max_length = 256, pattern = "^[^\\x00-\\x1F\\x7F-\\x9F]*$")]
    pub label: String,
}

/// A created key: `key` is shown this once and never stored.
#[derive(Debug, Serialize, ToSchema)]
pub struct CreatedKey {
    pub id: i64,
    pub key: String,
    pub prefix: String,
    pub role: Role,
    pub label: String,
    pub created_at: DateTime<Utc>,
}

/// Every key (never the key itself).
#[derive(Debug, Serialize, ToSchema)]
pub struct KeyList {
    pub keys: Vec<ApiKey>,
}

/// Create an API key; the answer holds the key, which is not shown again.
#[utoipa::path(post, path = "/v1/admin/keys", tag = "admin",
    request_body = NewKey,
    responses(
        (status = 201, description = "The key, shown this once", body = CreatedKey),
        (status = 400, description = "A bad role or label", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["admin"])))]
pub async fn create_key(
    State(st): State<AppState>,
    _auth: Admin,
    ApiJson(req): ApiJson<NewKey>,
) -> Result<(StatusCode, Json<CreatedKey>), AppError> {
    if req.label.chars().count() > 256 || req.label.chars().any(char::is_control) {
        return Err(AppError::bad_field(
            "label",
            "at most 256 characters, no control characters",
        ));
    }
    let (k, secret) = st.store.create_api_key(req.role, &req.label).await?;
    tracing::info!(key_id = k.id, role = %k.role, "API key created");
    Ok((
        StatusCode::CREATED,
        Json(CreatedKey {
            id: k.id,
            key: secret,
            prefix: k.prefix,
            role: k.role,
            label: k.label,
            created_at: k.created_at,
        }),
    ))
}

/// Every key, revoked ones included.
#[utoipa::path(get, path = "/v1/admin/keys", tag = "admin",
    responses((status = 200, description = "Every key", body = KeyList)),
    security(("bearer" = ["admin"])))]
pub async fn list_keys(
    State(st): State<AppState>,
    _auth: Admin,
) -> Result<Json<KeyList>, AppError> {
    Ok(Json(KeyList {
        keys: st.store.list_api_keys().await?,
    }))
}

/// Revoke a key: it stops working at once.
#[utoipa::path(delete, path = "/v1/admin/keys/{id}", tag = "admin",
    params(("id" = i64, Path, description = "key id")),
    responses(
        (status = 204, description = "Revoked"),
        (status = 404, description = "No such key, or already revoked", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["admin"])))]
pub async fn revoke_key(
    State(st): State<AppState>,
    _auth: Admin,
    ApiPath(raw): ApiPath<String>,
) -> Result<StatusCode, AppError> {
    let id: i64 = raw
        .parse()
        .map_err(|_| AppError::bad_parameter("id", "a key id is a whole number"))?;
    if st.store.revoke_api_key(id).await? {
        tracing::info!(key_id = id, "API key revoked");
        Ok(StatusCode::NO_CONTENT)
    } else {
        Err(AppError::NotFound(format!("no unrevoked key with id {id}")))
    }
}

/// What to re-fit.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RefitRequest {
    /// Only this vehicle's traces (default: all).
    #[schema(value_type = Option<VehicleId>)]
    pub vehicle_id: Option<String>,
}

/// Re-fits queued.
#[derive(Debug, Serialize, ToSchema)]
pub struct RefitQueued {
    /// Jobs created: traces without a fit by the current model version.
    pub queued: u64,
    pub model_version: String,
}

/// Queue a fit by the current model version for every trace (or a vehicle's) that has none.
#[utoipa::path(post, path = "/v1/admin/refit", tag = "admin",
    request_body = RefitRequest,
    responses(
        (status = 202, description = "The re-fits queued", body = RefitQueued),
    ),
    security(("bearer" = ["admin"])))]
pub async fn refit(
    State(st): State<AppState>,
    _auth: Admin,
    ApiJson(req): ApiJson<RefitRequest>,
) -> Result<(StatusCode, Json<RefitQueued>), AppError> {
    let queued = match req.vehicle_id {
        Some(v) => {
            let v = VehicleId::parse("vehicle_id", &v)?;
            st.store.requeue_vehicle(v.as_str(), MODEL_VERSION).await?
        }
        None => st.store.requeue_all(MODEL_VERSION).await?,
    };
    if queued > 0 {
        st.wake.notify_waiters();
    }
    tracing::info!(queued, "re-fit queued");
    Ok((
        StatusCode::ACCEPTED,
        Json(RefitQueued {
            queued,
            model_version: MODEL_VERSION.to_owned(),
        }),
    ))
}
