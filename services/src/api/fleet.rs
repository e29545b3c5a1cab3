//! The fleet: vehicles with their pantographs and each joint's latest status, a joint's history
//! over time, and fleet health (a row per pantograph, worst first, filtered and paginated).

use axum::Json;
use axum::extract::State;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::auth::Reader;
use super::error::{AppError, Problem};
use super::extract::{ApiPath, ApiQuery};
use super::state::AppState;
use crate::health::{self, Param, ParamTrend};
use crate::ids::{JointName, Serial, VehicleId};
use crate::store::{
    FleetFilter, FleetRow, JointPoint, Page, Status, VehicleDetail, VehicleSummary,
};

/// Largest page of `GET /v1/fleet/health`.
pub const MAX_LIMIT: u32 = 500;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_vehicles))
        .routes(routes!(get_vehicle))
        .routes(routes!(joint_history))
        .routes(routes!(fleet_health))
        .routes(routes!(static_force))
}

/// The predicted static contact force of a pantograph over its type's working range, raising and
/// lowering, with 95 % bands from its current dry-friction intervals (each from the latest test
/// that informed it) and the findings against the type's limits (issue 20); with the latest
/// force-gauge measurement's readings (`measured`) when the pantograph has one.
#[utoipa::path(get, path = "/v1/pantographs/{serial}/static-force", tag = "fleet",
    params(("serial" = Serial, Path, description = "pantograph serial")),
    responses(
        (status = 200, description = "The prediction, its bands and findings", body = crate::static_force::StaticForceView),
        (status = 400, description = "Malformed serial", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such pantograph, or its type has no static-force model", body = Problem, content_type = "application/problem+json"),
        (status = 422, description = "The stored parameters give no static equilibrium", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn static_force(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(serial): ApiPath<String>,
) -> Result<Json<crate::static_force::StaticForceView>, AppError> {
    let serial = Serial::parse("serial", &serial).map_err(AppError::parameter_id)?;
    let mut v = crate::static_force::predict(&st.store, serial.as_str())
        .await
        .map_err(AppError::from)?;
    v.measured = crate::static_force::latest_measurement(&st.store, serial.as_str()).await?;
    Ok(Json(v))
}

/// Every vehicle.
#[derive(Debug, Serialize, ToSchema)]
pub struct VehicleList {
    pub vehicles: Vec<VehicleSummary>,
}

/// Every vehicle, by id, with its pantograph and trace counts and last test.
#[utoipa::path(get, path = "/v1/vehicles", tag = "fleet",
    responses((status = 200, description = "Every vehicle", body = VehicleList)),
    security(("bearer" = ["reader"])))]
pub async fn list_vehicles(
    State(st): State<AppState>,
    _auth: Reader,
) -> Result<Json<VehicleList>, AppError> {
    Ok(Json(VehicleList {
        vehicles: st.store.list_vehicles().await?,
    }))
}

/// A vehicle, its pantographs as mounted now, and each joint's latest status.
#[utoipa::path(get, path = "/v1/vehicles/{vehicle_id}", tag = "fleet",
    params(("vehicle_id" = VehicleId, Path, description = "vehicle id")),
    responses(
        (status = 200, description = "The vehicle and its pantographs", body = VehicleDetail),
        (status = 400, description = "Malformed vehicle id", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn get_vehicle(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(raw): ApiPath<String>,
) -> Result<Json<VehicleDetail>, AppError> {
    let id = VehicleId::parse("vehicle_id", &raw).map_err(AppError::parameter_id)?;
    st.store
        .get_vehicle(id.as_str())
        .await?
        .map(Json)
        .ok_or_else(|| AppError::NotFound(format!("no vehicle `{id}`")))
}

/// A joint's fits over time, with each parameter's trend and alarm-band forecast.
#[derive(Debug, Serialize, ToSchema)]
pub struct JointHistory {
    pub serial: String,
    pub joint: String,
    /// One point per fitted trace of this joint, by `recorded_at`.
    pub points: Vec<JointPoint>,
    pub trends: JointTrends,
}

/// Per parameter: robust trend (each point weighted by its interval) with its interval,
/// `no_trend` when the data do not support one, and the forecast date of reaching the alarm band
/// (drift alarm band × Table 4 baseline) with its interval.
#[derive(Debug, Serialize, ToSchema)]
pub struct JointTrends {
    pub viscous: ParamTrend,
    pub dry: ParamTrend,
}

/// The trends of a joint's history (baselines from the latest fit result).
pub async fn joint_trends(
    st: &AppState,
    joint: &str,
    points: &[JointPoint],
) -> Result<JointTrends, AppError> {
    let (bv, bd) = match points.last() {
        Some(p) => match st.store.get_fit(&p.trace_id).await? {
            Some(f) => health::baselines(&f.result()?, joint),
            None => (None, None),
        },
        None => (None, None),
    };
    let alarm = st.alerts.alarm;
    Ok(JointTrends {
        viscous: health::param_trend(points, Param::Viscous, bv, alarm),
        dry: health::param_trend(points, Param::Dry, bd, alarm),
    })
}

/// Every fit of one joint of one pantograph, oldest test first, with the wear trend and the
/// forecast of the alarm-band crossing per parameter.
#[utoipa::path(get, path = "/v1/pantographs/{serial}/joints/{joint}/history", tag = "fleet",
    params(
        ("serial" = Serial, Path, description = "pantograph serial"),
        ("joint" = JointName, Path, description = "J1 … J9, J2', custom"),
    ),
    responses(
        (status = 200, description = "The joint's fits, trends and forecasts", body = JointHistory),
        (status = 400, description = "Malformed serial or unknown joint", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such pantograph", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn joint_history(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath((serial, joint)): ApiPath<(String, String)>,
) -> Result<Json<JointHistory>, AppError> {
    let serial = Serial::parse("serial", &serial).map_err(AppError::parameter_id)?;
    let joint = JointName::parse("joint", &joint).map_err(AppError::parameter_id)?;
    if !st.store.pantograph_exists(serial.as_str()).await? {
        return Err(AppError::NotFound(format!("no pantograph `{serial}`")));
    }
    let points = st
        .store
        .joint_history(serial.as_str(), joint.as_str())
        .await?;
    let trends = joint_trends(&st, joint.as_str(), &points).await?;
    Ok(Json(JointHistory {
        serial: serial.to_string(),
        joint: joint.to_string(),
        points,
        trends,
    }))
}

/// Query of `GET /v1/fleet/health`. A key given must hold a value of its kind (an empty one
/// is refused, not read as absent).
#[derive(Debug, Default, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct FleetQuery {
    /// Only pantographs whose worst status is this.
    #[param(value_type = Option<Status>)]
    pub status: Option<String>,
    /// Only pantographs mounted on this vehicle now.
    #[param(value_type = Option<VehicleId>)]
    pub vehicle: Option<String>,
    /// Page size (default 50).
    #[param(value_type = Option<u32>, minimum = 1, maximum = 500)]
    pub limit: Option<String>,
    /// Rows to skip (default 0).
    #[param(value_type = Option<u64>, minimum = 0, maximum = 9223372036854775807_u64)]
    pub offset: Option<String>,
}

/// A page of fleet health.
#[derive(Debug, Serialize, ToSchema)]
pub struct FleetHealth {
    /// Rows matching the filter over all pages.
    pub total: u64,
    pub limit: u32,
    pub offset: u64,
    /// Worst first (`alarm`, `watch`, `ok`, `unknown`, not yet fitted), then by serial.
    pub rows: Vec<FleetRow>,
}

fn parse_num<T: std::str::FromStr>(parameter: &str, v: &str) -> Result<T, AppError> {
    v.parse::<T>()
        .map_err(|_| AppError::bad_parameter(parameter, format!("`{v}` is not a whole number ≥ 0")))
}

/// A row per pantograph: worst latest joint status, the joints that are not ok, last test.
#[utoipa::path(get, path = "/v1/fleet/health", tag = "fleet",
    params(FleetQuery),
    responses(
        (status = 200, description = "A page of rows", body = FleetHealth),
        (status = 400, description = "A bad filter or page (`parameter` names it)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn fleet_health(
    State(st): State<AppState>,
    _auth: Reader,
    ApiQuery(q): ApiQuery<FleetQuery>,
) -> Result<Json<FleetHealth>, AppError> {
    let status = q
        .status
        .as_deref()
        .map(|s| {
            s.parse::<Status>().map_err(|_| {
                AppError::bad_parameter("status", "must be one of alarm, watch, ok, unknown")
            })
        })
        .transpose()?;
    let vehicle_id = q
        .vehicle
        .as_deref()
        .map(|v| VehicleId::parse("vehicle", v).map_err(AppError::parameter_id))
        .transpose()?
        .map(|v| v.to_string());
    let limit = match q.limit.as_deref() {
        None => Page::default().limit,
        Some(v) => parse_num::<u32>("limit", v)?,
    };
    if !(1..=MAX_LIMIT).contains(&limit) {
        return Err(AppError::bad_parameter(
            "limit",
            format!("must be from 1 to {MAX_LIMIT}"),
        ));
    }
    let offset = match q.offset.as_deref() {
        None => 0,
        Some(v) => parse_num::<u64>("offset", v)?,
    };
    if offset > i64::MAX as u64 {
        return Err(AppError::bad_parameter("offset", "too large"));
    }
    let page = st
        .store
        .fleet_health(&FleetFilter { status, vehicle_id }, Page { limit, offset })
        .await?;
    Ok(Json(FleetHealth {
        total: page.total,
        limit,
        offset,
        rows: page.rows,
    }))
}
