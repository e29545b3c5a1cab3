//! Sign-in (an API key for a signed session cookie) and sign-out.

use axum::body::Bytes;
use axum::extract::State;
use axum::http::header::SET_COOKIE;
use axum::http::request::Parts;
use axum::http::{HeaderValue, StatusCode};
use axum::response::{IntoResponse, Redirect, Response};
use maud::{Markup, html};
use serde::Deserialize;

use crate::api::session::{self, SessionKey, clear_cookie};
use crate::api::state::AppState;
use crate::web::layout::page;
use crate::web::{PageResult, WebError, form};

#[derive(Deserialize)]
struct LoginForm {
    key: String,
}

/// The sign-in form; `message` (a failed sign-in) is shown above it as an alert.
fn login_form(message: Option<&str>) -> Markup {
    html! {
        h1 { "Sign in" }
        @if let Some(m) = message {
            p.msg role="alert" { (m) }
        }
        form method="post" action="/login" {
            p {
                label for="key" { "API key" }
                br;
                input #key name="key" type="password" size="60" autocomplete="off" required;
            }
            p { button type="submit" { "Sign in" } }
        }
        p.note { "Any reader, writer or admin key works; acknowledging alerts needs a writer key." }
    }
}

pub async fn login_page(State(st): State<AppState>, parts: Parts) -> Response {
    let signed_in = session::cookie_value(&parts)
        .and_then(|v| st.sessions.verify(&v))
        .is_some();
    if signed_in {
        return Redirect::to("/fleet").into_response();
    }
    page("Sign in", None, login_form(None))
}

pub async fn login(State(st): State<AppState>, body: Bytes) -> PageResult {
    let f: LoginForm = form(&body).map_err(WebError::from)?;
    let Some(key) = st.store.verify_api_key(f.key.trim()).await? else {
        let mut r = page(
            "Sign-in failed",
            None,
            login_form(Some("Unknown or revoked API key.")),
        );
        *r.status_mut() = StatusCode::UNAUTHORIZED;
        return Ok(r);
    };
    tracing::info!(key_id = key.id, "web sign-in");
    Ok(with_cookie(
        Redirect::to("/fleet").into_response(),
        &st.sessions,
        Some(key.id),
    ))
}

fn with_cookie(mut r: Response, k: &SessionKey, key_id: Option<i64>) -> Response {
    let c = match key_id {
        Some(id) => k.cookie(id),
        None => clear_cookie(),
    };
    if let Ok(v) = HeaderValue::from_str(&c) {
        r.headers_mut().insert(SET_COOKIE, v);
    }
    r
}

pub async fn logout(State(st): State<AppState>) -> Response {
    with_cookie(Redirect::to("/").into_response(), &st.sessions, None)
}
