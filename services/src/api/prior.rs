//! The fleet prior (issue 37, point 3; `crate::fleet_prior`): read the current version (or one
//! by number), and relearn it from the store's workshop fits (admin), which publishes a new
//! version when it moved and queues the refit of every lift fitted under an older one.

use axum::Json;
use axum::extract::State;
use axum::http::StatusCode;
use serde::Deserialize;
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::auth::{Admin, Reader};
use super::error::{AppError, Problem};
use super::extract::{ApiJson, ApiQuery};
use super::state::AppState;
use crate::fleet_prior::{self, FleetPriorView, PriorError, Relearned};

/// The pantograph type a request names when it names none: the one type compiled in.
const DEFAULT_MODEL: &str = "160EC";

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new().routes(routes!(get_prior, relearn))
}

fn prior_error(e: PriorError, model_field: &str) -> AppError {
    match e {
        PriorError::NoModel(m) => AppError::bad_parameter(
            model_field,
            format!("pantograph type `{m}` has no data here"),
        ),
        PriorError::Store(s) => s.into(),
    }
}

/// Which prior to read.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct PriorQuery {
    /// The pantograph type (default `160EC`).
    pub model: Option<String>,
    /// A version (default the newest; 0 the type file's).
    #[param(value_type = Option<i64>, minimum = 0)]
    pub version: Option<String>,
}

/// The fleet prior the lift fits use now (or version `version`): per joint and parameter the
/// mean, sd and between-unit spread in Table 4 units, the fits each rests on, whether its
/// spread is the fleet's (`learned`) or the type file's floor; version 0 when none has been
/// learned (the type file's Table 4 ± floor).
#[utoipa::path(get, path = "/v1/fleet/prior", tag = "fleet",
    params(PriorQuery),
    responses(
        (status = 200, description = "The prior", body = FleetPriorView),
        (status = 400, description = "A bad `version`", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such version, or the type `model` has no data here", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn get_prior(
    State(st): State<AppState>,
    _auth: Reader,
    ApiQuery(q): ApiQuery<PriorQuery>,
) -> Result<Json<FleetPriorView>, AppError> {
    let model = q.model.as_deref().unwrap_or(DEFAULT_MODEL);
    let version = match q.version.as_deref() {
        None => None,
        Some(v) => Some(v.parse::<i64>().ok().filter(|n| *n >= 0).ok_or_else(|| {
            AppError::bad_parameter("version", format!("`{v}` is not a whole number ≥ 0"))
        })?),
    };
    // A type without data has no prior to read: not found, as the plan answers for it.
    let view = fleet_prior::view(&st.store, model, version)
        .await
        .map_err(|e| match e {
            PriorError::NoModel(m) => AppError::NotFound(format!(
                "no fleet prior of pantograph type `{m}`: the type has no data here"
            )),
            other => prior_error(other, "model"),
        })?;
    if let Some(v) = version
        && view.version != v
    {
        return Err(AppError::NotFound(format!(
            "no fleet prior version {v} of `{model}`"
        )));
    }
    Ok(Json(view))
}

/// What to relearn.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct RelearnRequest {
    /// The pantograph type (default `160EC`).
    pub model: Option<String>,
}

/// Relearn the fleet prior from the workshop fits in the store (each pantograph's latest
/// informing pendulum, slider or swing test per joint and parameter; empirical Bayes with the
/// type file's floor). A new version is published only when some joint's mean or sd moved by
/// more than `[fleet_prior] version_tolerance_relative` (201); then every lift and force-gauge
/// record fitted under an older prior is queued for a refit under it. Otherwise the current prior stands (200).
#[utoipa::path(post, path = "/v1/fleet/prior", tag = "admin",
    request_body = RelearnRequest,
    responses(
        (status = 201, description = "A new version published, refits queued", body = Relearned),
        (status = 200, description = "Unchanged: the current prior", body = Relearned),
        (status = 400, description = "An unknown `model`", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["admin"])))]
pub async fn relearn(
    State(st): State<AppState>,
    _auth: Admin,
    ApiJson(req): ApiJson<RelearnRequest>,
) -> Result<(StatusCode, Json<Relearned>), AppError> {
    let model = req.model.as_deref().unwrap_or(DEFAULT_MODEL);
    let r = fleet_prior::relearn(&st.store, model)
        .await
        .map_err(|e| match e {
            PriorError::NoModel(m) => {
                AppError::bad_field("model", format!("pantograph type `{m}` has no data here"))
            }
            other => prior_error(other, "model"),
        })?;
    if r.queued > 0 {
        st.wake.notify_waiters();
    }
    let code = if r.published {
        StatusCode::CREATED
    } else {
        StatusCode::OK
    };
    Ok((code, Json(r)))
}
