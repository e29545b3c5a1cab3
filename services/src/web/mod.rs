//! The depot's web pages, served by the service: plain HTML with inline SVG, readable without
//! JavaScript — sign-in (API key → signed session cookie), fleet, pantograph, trace and alerts.
//!
//! Every page but the sign-in needs a session; the acknowledge form calls the same code as
//! `POST /v1/alerts/{id}/acknowledge`. The HTML is written with `maud` (every value escaped):
//! [`layout`] holds the frame and the badges, [`svg`] the charts, [`pages`] one module per page.
//! Errors — the API's [`AppError`], and the pages' own malformed paths and queries — are shown
//! as the site's HTML error page ([`error`]) with the same status, never as problem JSON.

pub mod error;
pub mod layout;
pub mod pages;
pub mod svg;

use axum::Router;
use axum::body::Bytes;
use axum::http::request::Parts;
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use chrono::{DateTime, Utc};
use maud::Markup;

use crate::api::auth::WebUser;
use crate::api::error::AppError;
use crate::api::state::AppState;
use crate::store::{AlertFilter, Severity};
pub use error::WebError;

/// The pages (no OpenAPI: they are for people).
pub fn router() -> Router<AppState> {
    Router::new()
        .route("/", get(pages::login::login_page))
        .route("/login", post(pages::login::login))
        .route("/logout", post(pages::login::logout))
        .route("/fleet", get(pages::fleet::fleet_page))
        .route(
            "/pantographs/{serial}",
            get(pages::pantograph::pantograph_page),
        )
        .route("/traces/{id}", get(pages::trace::trace_page))
        .route("/alerts", get(pages::alerts::alerts_page))
        .route(
            "/alerts/{id}/acknowledge",
            post(pages::alerts::acknowledge_form),
        )
}

/// What a page handler answers: the page, or the error page.
pub type PageResult = Result<Response, WebError>;

/// A signed-in page from its body, or the error page — with the navigation either way.
pub fn signed_in_page(user: &WebUser, title: &str, body: Result<Markup, AppError>) -> PageResult {
    match body {
        Ok(b) => Ok(layout::page(title, Some(&user.key), b)),
        Err(e) => Err(WebError::from(e).signed_in(user)),
    }
}

/// A request no route answers, from a browser asking for a page: the site's 404 page (with the
/// navigation when signed in).
pub async fn not_found_page(st: &AppState, parts: &Parts, e: AppError) -> Response {
    WebError::of_request(e, parts, st).await.into_response()
}

/// Percent-encoding of a path segment.
fn seg(s: &str) -> String {
    form_urlencoded::byte_serialize(s.as_bytes())
        .collect::<String>()
        .replace('+', "%20")
}

fn day(t: DateTime<Utc>) -> String {
    t.format("%Y-%m-%d").to_string()
}

fn form<T: serde::de::DeserializeOwned>(body: &Bytes) -> Result<T, AppError> {
    serde_urlencoded::from_bytes(body).map_err(|e| AppError::BadRequest {
        field: Some("body".into()),
        detail: format!("form: {e}"),
    })
}

/// The demo's last words: where the pages are and which alerts it left open.
pub async fn print_banner(store: &crate::store::Store, url: &str) -> anyhow::Result<()> {
    let live = store
        .list_alerts(&AlertFilter {
            live: true,
            ..AlertFilter::default()
        })
        .await?;
    let alarms = live
        .iter()
        .filter(|a| a.severity == Severity::Alarm)
        .count();
    println!(
        "Web pages: {url}/  (sign in with the reader or writer key; the writer can acknowledge)"
    );
    println!(
        "  {} alerts open: {alarms} alarm, {} watch — {url}/alerts, GET {url}/v1/alerts?state=open",
        live.len(),
        live.len() - alarms
    );
    Ok(())
}
