//! What each joint's state rests on and which workshop test to do next (issue 37): a
//! pantograph's evidence per joint and parameter, its test plan, and the fleet's plan
//! (`crate::evidence`; the numbers from `models::contract::{evidence, plan}`).

use axum::Json;
use axum::extract::State;
use chrono::{DateTime, Utc};
use serde::Deserialize;
use utoipa::IntoParams;
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::auth::Reader;
use super::error::{AppError, Problem};
use super::extract::{ApiPath, ApiQuery};
use super::state::AppState;
use crate::evidence::{self, EvidenceError, FleetPlan, PantographEvidence, PantographPlan};
use crate::ids::Serial;

/// Largest `limit` of `GET /v1/fleet/plan`.
pub const MAX_PLAN_LIMIT: usize = 1000;

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(pantograph_evidence))
        .routes(routes!(pantograph_plan))
        .routes(routes!(fleet_plan))
}

impl From<EvidenceError> for AppError {
    fn from(e: EvidenceError) -> Self {
        match e {
            EvidenceError::NoPantograph(_) | EvidenceError::NoModel(_) => {
                AppError::NotFound(e.to_string())
            }
            EvidenceError::Store(s) => s.into(),
        }
    }
}

/// When the evidence is read.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct AtQuery {
    /// The time ages and intervals are at (RFC 3339; default now).
    #[param(value_type = Option<String>, format = DateTime)]
    pub at: Option<String>,
}

/// The fleet plan's query.
#[derive(Debug, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct FleetPlanQuery {
    /// The time ages and intervals are at (RFC 3339; default now).
    #[param(value_type = Option<String>, format = DateTime)]
    pub at: Option<String>,
    /// Most tests listed (default 50).
    #[param(value_type = Option<u32>, minimum = 1, maximum = 1000)]
    pub limit: Option<String>,
}

pub fn parse_at(at: Option<&str>) -> Result<DateTime<Utc>, AppError> {
    match at {
        None => Ok(Utc::now()),
        Some(s) => DateTime::parse_from_rfc3339(s)
            .map(|t| t.with_timezone(&Utc))
            .map_err(|_| AppError::bad_parameter("at", format!("`{s}` is not an RFC 3339 time"))),
    }
}

/// Each joint's evidence: per parameter the test that last informed it (kind, trace, date), its
/// value and interval then, and the interval now — widened by the time since at the wear rate
/// of the joint's trend or the fleet's; `never_measured`, `measured` or `uncertain` (measured on
/// a date, now wider than the watch band); and whether a workshop test is due.
#[utoipa::path(get, path = "/v1/pantographs/{serial}/evidence", tag = "fleet",
    params(("serial" = Serial, Path, description = "pantograph serial"), AtQuery),
    responses(
        (status = 200, description = "Each joint's evidence", body = PantographEvidence),
        (status = 400, description = "Malformed serial or `at`", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such pantograph, or its type has no data here", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn pantograph_evidence(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(serial): ApiPath<String>,
    ApiQuery(q): ApiQuery<AtQuery>,
) -> Result<Json<PantographEvidence>, AppError> {
    let serial = Serial::parse("serial", &serial).map_err(AppError::parameter_id)?;
    let at = parse_at(q.at.as_deref())?;
    let (ev, _) = evidence::load(&st.store, serial.as_str(), at).await?;
    Ok(Json(ev))
}

/// The workshop tests to do next on a pantograph, ranked by what they buy: the probability
/// that a joint they inform has crossed its watch band unseen, times the share of its
/// uncertainty the test removes (its Fisher information); the information in bits.
#[utoipa::path(get, path = "/v1/pantographs/{serial}/plan", tag = "fleet",
    params(("serial" = Serial, Path, description = "pantograph serial"), AtQuery),
    responses(
        (status = 200, description = "The ranked tests", body = PantographPlan),
        (status = 400, description = "Malformed serial or `at`", body = Problem, content_type = "application/problem+json"),
        (status = 404, description = "No such pantograph, or its type has no data here", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn pantograph_plan(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(serial): ApiPath<String>,
    ApiQuery(q): ApiQuery<AtQuery>,
) -> Result<Json<PantographPlan>, AppError> {
    let serial = Serial::parse("serial", &serial).map_err(AppError::parameter_id)?;
    let at = parse_at(q.at.as_deref())?;
    let (_, tests) = evidence::load(&st.store, serial.as_str(), at).await?;
    Ok(Json(PantographPlan {
        serial: serial.as_str().to_owned(),
        at,
        tests,
    }))
}

/// The fleet's plan: each pantograph's best test, ranked across the fleet by what it buys
/// (`at` defaults to now to the minute; the evidence rows are kept in memory until a fit
/// changes them).
#[utoipa::path(get, path = "/v1/fleet/plan", tag = "fleet",
    params(FleetPlanQuery),
    responses(
        (status = 200, description = "The ranked tests", body = FleetPlan),
        (status = 400, description = "A bad `at` or `limit` (`parameter` names it)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn fleet_plan(
    State(st): State<AppState>,
    _auth: Reader,
    ApiQuery(q): ApiQuery<FleetPlanQuery>,
) -> Result<Json<FleetPlan>, AppError> {
    // Default now, to the minute: requests within a minute share one computed plan.
    let at = match q.at.as_deref() {
        None => {
            let now = Utc::now();
            now - chrono::TimeDelta::nanoseconds(i64::from(now.timestamp_subsec_nanos()))
                - chrono::TimeDelta::seconds(now.timestamp() % 60)
        }
        Some(s) => parse_at(Some(s))?,
    };
    let limit = match q.limit.as_deref() {
        None => 50,
        Some(v) => v.parse::<usize>().map_err(|_| {
            AppError::bad_parameter("limit", format!("`{v}` is not a whole number ≥ 1"))
        })?,
    };
    if !(1..=MAX_PLAN_LIMIT).contains(&limit) {
        return Err(AppError::bad_parameter(
            "limit",
            format!("must be from 1 to {MAX_PLAN_LIMIT}"),
        ));
    }
    Ok(Json(st.plan_cache.fleet_plan(&st.store, at, limit).await?))
}
