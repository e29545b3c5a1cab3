//! Alerts over REST: list and filter, one alert with its history, acknowledge and resolve (writer
//! keys; `who` is the key). The web page's acknowledge form calls the same functions.

use axum::Json;
use axum::extract::State;
use serde::{Deserialize, Serialize};
use utoipa::{IntoParams, ToSchema};
use utoipa_axum::router::OpenApiRouter;
use utoipa_axum::routes;

use super::auth::{Reader, Writer};
use super::error::{AppError, Problem};
use super::extract::{ApiJson, ApiPath, ApiQuery};
use super::state::AppState;
use crate::ids::VehicleId;
use crate::store::{Alert, AlertEvent, AlertFilter, AlertState, ApiKey, Severity, Transition};

pub fn router() -> OpenApiRouter<AppState> {
    OpenApiRouter::new()
        .routes(routes!(list_alerts))
        .routes(routes!(get_alert))
        .routes(routes!(acknowledge_alert))
        .routes(routes!(resolve_alert))
}

/// Query of `GET /v1/alerts`. A key given must hold a value of its kind (an empty one is
/// refused, not read as absent).
#[derive(Debug, Default, Deserialize, IntoParams)]
#[serde(deny_unknown_fields)]
#[into_params(parameter_in = Query)]
pub struct AlertQuery {
    /// `open`, `acknowledged`, `resolved`, or `live` (open or acknowledged).
    #[param(value_type = Option<String>, pattern = "^(?:open|acknowledged|resolved|live)$")]
    pub state: Option<String>,
    #[param(value_type = Option<Severity>)]
    pub severity: Option<String>,
    /// Only alerts of this vehicle.
    #[param(value_type = Option<VehicleId>)]
    pub vehicle: Option<String>,
}

/// Alerts, newest first.
#[derive(Debug, Serialize, ToSchema)]
pub struct AlertList {
    pub alerts: Vec<Alert>,
}

/// An alert and its history, oldest event first.
#[derive(Debug, Serialize, ToSchema)]
pub struct AlertDetail {
    pub alert: Alert,
    pub events: Vec<AlertEvent>,
}

/// A note for acknowledge or resolve.
#[derive(Debug, Default, Deserialize, ToSchema)]
#[serde(deny_unknown_fields)]
pub struct AlertNote {
    /// Free text, at most 2000 characters; no control characters but tab, CR and LF.
    #[serde(default)]
    #[schema(
        max_length = 2000,
        pattern = "^[^\\x00-\\x08\\x0B\\x0C\\x0E-\\x1F\\x7F-\\x9F]*$"
    )]
    pub note: String,
}

/// Who acted: the key's label and id.
pub fn actor(key: &ApiKey) -> String {
    if key.label.trim().is_empty() {
        format!("key {}", key.id)
    } else {
        format!("{} (key {})", key.label.trim(), key.id)
    }
}

fn check_note(note: &str) -> Result<(), AppError> {
    if note.chars().count() > 2000
        || note
            .chars()
            .any(|c| c.is_control() && !matches!(c, '\n' | '\r' | '\t'))
    {
        return Err(AppError::bad_field(
            "note",
            "at most 2000 characters, no control characters",
        ));
    }
    Ok(())
}

/// Parses an alert id from the path.
pub fn parse_id(raw: &str) -> Result<i64, AppError> {
    raw.parse::<i64>()
        .map_err(|_| AppError::bad_parameter("id", "an alert id is a whole number"))
}

fn done(t: Transition, id: i64, what: &str) -> Result<Alert, AppError> {
    match t {
        Transition::Done(a) => Ok(a),
        Transition::NotFound => Err(AppError::NotFound(format!("no alert {id}"))),
        Transition::Refused(a) => Err(AppError::Conflict {
            field: "state".into(),
            detail: format!("alert {id} is {}: it cannot be {what}", a.state),
        }),
    }
}

/// Acknowledge (`open` → `acknowledged`): the API and the web page.
pub async fn acknowledge(
    st: &AppState,
    key: &ApiKey,
    id: i64,
    note: &str,
) -> Result<Alert, AppError> {
    check_note(note)?;
    let t = st
        .store
        .acknowledge_alert(id, &actor(key), note.trim())
        .await?;
    let a = done(t, id, "acknowledged")?;
    tracing::info!(alert = id, key_id = key.id, "alert acknowledged");
    Ok(a)
}

/// Resolve by hand (`open`/`acknowledged` → `resolved`); webhooks are told.
pub async fn resolve(st: &AppState, key: &ApiKey, id: i64, note: &str) -> Result<Alert, AppError> {
    check_note(note)?;
    let t = st.store.resolve_alert(id, &actor(key), note.trim()).await?;
    let a = done(t, id, "resolved")?;
    st.alert_wake.notify_waiters();
    tracing::info!(alert = id, key_id = key.id, "alert resolved by hand");
    Ok(a)
}

/// Parses the filter of `GET /v1/alerts`.
pub fn filter(q: &AlertQuery) -> Result<AlertFilter, AppError> {
    let mut f = AlertFilter::default();
    match q.state.as_deref() {
        None => {}
        Some("live") => f.live = true,
        Some(s) => {
            f.state = Some(s.parse::<AlertState>().map_err(|_| {
                AppError::bad_parameter(
                    "state",
                    "must be one of open, acknowledged, resolved, live",
                )
            })?)
        }
    }
    if let Some(s) = q.severity.as_deref() {
        f.severity = Some(
            s.parse::<Severity>()
                .map_err(|_| AppError::bad_parameter("severity", "must be watch or alarm"))?,
        );
    }
    if let Some(v) = q.vehicle.as_deref() {
        f.vehicle_id = Some(
            VehicleId::parse("vehicle", v)
                .map_err(AppError::parameter_id)?
                .to_string(),
        );
    }
    Ok(f)
}

/// Alerts, newest first, filtered by state, severity and vehicle.
#[utoipa::path(get, path = "/v1/alerts", tag = "alerts",
    params(AlertQuery),
    responses(
        (status = 200, description = "The alerts, newest first", body = AlertList),
        (status = 400, description = "A bad filter (`field` names it)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["reader"])))]
pub async fn list_alerts(
    State(st): State<AppState>,
    _auth: Reader,
    ApiQuery(q): ApiQuery<AlertQuery>,
) -> Result<Json<AlertList>, AppError> {
    let f = filter(&q)?;
    Ok(Json(AlertList {
        alerts: st.store.list_alerts(&f).await?,
    }))
}

/// One alert with its evidence and full history.
#[utoipa::path(get, path = "/v1/alerts/{id}", tag = "alerts",
    params(("id" = i64, Path, description = "alert id")),
    responses(
        (status = 200, description = "The alert and its history", body = AlertDetail),
    ),
    security(("bearer" = ["reader"])))]
pub async fn get_alert(
    State(st): State<AppState>,
    _auth: Reader,
    ApiPath(raw): ApiPath<String>,
) -> Result<Json<AlertDetail>, AppError> {
    let id = parse_id(&raw)?;
    let alert = st
        .store
        .get_alert(id)
        .await?
        .ok_or_else(|| AppError::NotFound(format!("no alert {id}")))?;
    let events = st.store.alert_events(id).await?;
    Ok(Json(AlertDetail { alert, events }))
}

/// Acknowledge an open alert: who (this key) and a note.
#[utoipa::path(post, path = "/v1/alerts/{id}/acknowledge", tag = "alerts",
    params(("id" = i64, Path, description = "alert id")),
    request_body = AlertNote,
    responses(
        (status = 200, description = "The alert as it is now", body = Alert),
        (status = 409, description = "Not open (acknowledged or resolved already)", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["writer"])))]
pub async fn acknowledge_alert(
    State(st): State<AppState>,
    auth: Writer,
    ApiPath(raw): ApiPath<String>,
    ApiJson(body): ApiJson<AlertNote>,
) -> Result<Json<Alert>, AppError> {
    let id = parse_id(&raw)?;
    acknowledge(&st, &auth.key, id, &body.note).await.map(Json)
}

/// Resolve an alert by hand (webhooks are told).
#[utoipa::path(post, path = "/v1/alerts/{id}/resolve", tag = "alerts",
    params(("id" = i64, Path, description = "alert id")),
    request_body = AlertNote,
    responses(
        (status = 200, description = "The alert as it is now", body = Alert),
        (status = 409, description = "Resolved already", body = Problem, content_type = "application/problem+json"),
    ),
    security(("bearer" = ["writer"])))]
pub async fn resolve_alert(
    State(st): State<AppState>,
    auth: Writer,
    ApiPath(raw): ApiPath<String>,
    ApiJson(body): ApiJson<AlertNote>,
) -> Result<Json<Alert>, AppError> {
    let id = parse_id(&raw)?;
    resolve(&st, &auth.key, id, &body.note).await.map(Json)
}
