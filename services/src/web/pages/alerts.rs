//! The alerts, live first (worst first), then the latest resolved; a writer acknowledges an open
//! one with a note through the same code as `POST /v1/alerts/{id}/acknowledge`.

use axum::body::Bytes;
use axum::extract::State;
use axum::http::header::{CONTENT_TYPE, LOCATION};
use axum::http::{HeaderValue, StatusCode};
use axum::response::IntoResponse;
use maud::{Markup, html};
use serde::Deserialize;

use crate::api::alerts::{acknowledge, parse_id};
use crate::api::auth::WebUser;
use crate::api::error::AppError;
use crate::api::state::AppState;
use crate::store::{Alert, AlertFilter, AlertState, Role};
use crate::web::error::{WebPath, WebQuery};
use crate::web::layout::sev_badge;
use crate::web::{PageResult, WebError, day, form, seg, signed_in_page};

#[derive(Deserialize, Default)]
pub struct AlertsQuery {
    done: Option<String>,
}

pub async fn alerts_page(
    State(st): State<AppState>,
    user: WebUser,
    WebQuery(q): WebQuery<AlertsQuery>,
) -> PageResult {
    signed_in_page(&user, "Alerts", alerts(&st, &user, &q).await)
}

async fn alerts(st: &AppState, user: &WebUser, q: &AlertsQuery) -> Result<Markup, AppError> {
    let all = st.store.list_alerts(&AlertFilter::default()).await?;
    let can_ack = user.key.role >= Role::Writer;
    let mut live: Vec<&Alert> = all
        .iter()
        .filter(|a| a.state != AlertState::Resolved)
        .collect();
    live.sort_by(|a, b| b.severity.cmp(&a.severity).then(a.id.cmp(&b.id)));
    let shown = live.iter().copied().chain(
        all.iter()
            .filter(|a| a.state == AlertState::Resolved)
            .take(50),
    );
    let done = q.done.as_deref().and_then(|d| d.parse::<i64>().ok());
    Ok(html! {
        h1 { "Alerts" }
        @if let Some(id) = done {
            p.msg role="status" { "Alert " (id) " acknowledged." }
        }
        @if !can_ack {
            p.note { "Signed in with a reader key: acknowledging needs a writer key." }
        }
        table #alerts {
            thead {
                tr {
                    th { "id" } th { "severity" } th { "state" } th { "pantograph" } th { "joint" }
                    th { "vehicle" } th { "why" } th { "opened" } th { "acknowledged" } th {}
                }
            }
            tbody {
                @for a in shown {
                    tr id={ "alert-" (a.id) } data-state=(a.state) {
                        td { (a.id) }
                        td { (sev_badge(a.severity)) }
                        td { (a.state) }
                        td { a href={ "/pantographs/" (seg(&a.serial)) } { (a.serial) } }
                        td { (a.joint) }
                        td { (a.vehicle_id.as_deref().unwrap_or("—")) }
                        td { (a.reason) }
                        td { (day(a.opened_at)) }
                        td {
                            @match (&a.acknowledged_by, a.acknowledged_at) {
                                (Some(w), Some(t)) => { (w) " " (day(t)) },
                                _ => "—",
                            }
                        }
                        td {
                            @if a.state == AlertState::Open && can_ack {
                                form method="post" action={ "/alerts/" (a.id) "/acknowledge" } {
                                    label for={ "note-" (a.id) } { "Note" } " "
                                    input id={ "note-" (a.id) } name="note" size="24";
                                    " "
                                    button type="submit" { "Acknowledge" }
                                }
                            }
                        }
                    }
                }
            }
        }
    })
}

#[derive(Deserialize)]
struct AckForm {
    #[serde(default)]
    note: String,
}

pub async fn acknowledge_form(
    State(st): State<AppState>,
    user: WebUser,
    WebPath(raw): WebPath<String>,
    body: Bytes,
) -> PageResult {
    let acked = async {
        let id = parse_id(&raw)?;
        if user.key.role < Role::Writer {
            return Err(AppError::Forbidden(
                "acknowledging needs a writer key".into(),
            ));
        }
        let f: AckForm = form(&body)?;
        acknowledge(&st, &user.key, id, &f.note).await?;
        Ok(id)
    }
    .await;
    let id = acked.map_err(|e| WebError::from(e).signed_in(&user))?;
    let mut r = StatusCode::SEE_OTHER.into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/alerts?done={id}")) {
        r.headers_mut().insert(LOCATION, v);
    }
    r.headers_mut()
        .insert(CONTENT_TYPE, HeaderValue::from_static("text/plain"));
    Ok(r)
}
