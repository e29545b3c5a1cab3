//! The whole HTTP application: the API's routes (`crate::api`), the web pages (`crate::web`),
//! `/openapi.json`, the fallbacks and the layers. The one place that knows both; neither
//! imports it.

use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::http::{HeaderName, HeaderValue, Method, header};
use axum::middleware::from_fn_with_state;
use axum::routing::get;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::decompression::RequestDecompressionLayer;
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::set_header::SetResponseHeaderLayer;
use tower_http::trace::TraceLayer;

use crate::api::error::AppError;
use crate::api::state::AppState;
use crate::{api, web};

/// No route: a problem answer, or — for a browser asking for a page outside `/v1` — the site's
/// HTML 404 page.
async fn not_found(
    axum::extract::State(st): axum::extract::State<AppState>,
    parts: axum::http::request::Parts,
) -> axum::response::Response {
    use axum::response::IntoResponse;
    let e = AppError::NotFound(format!("no route {} {}", parts.method, parts.uri.path()));
    let wants_html = parts
        .headers
        .get(header::ACCEPT)
        .and_then(|v| v.to_str().ok())
        .is_some_and(|a| a.contains("text/html"));
    if wants_html && !parts.uri.path().starts_with("/v1") {
        web::not_found_page(&st, &parts, e).await
    } else {
        e.into_response()
    }
}

/// CORS for the configured origins only: their requests (and preflights) get the headers a
/// browser needs to call the API with a bearer key; any other origin gets none. No
/// credentials mode, so a foreign page can never ride a web session cookie.
fn cors(origins: &[HeaderValue]) -> Option<CorsLayer> {
    if origins.is_empty() {
        return None;
    }
    Some(
        CorsLayer::new()
            .allow_origin(AllowOrigin::list(origins.iter().cloned()))
            .allow_methods([
                Method::GET,
                Method::POST,
                Method::PUT,
                Method::PATCH,
                Method::DELETE,
            ])
            .allow_headers([header::AUTHORIZATION, header::CONTENT_TYPE, header::ACCEPT])
            .expose_headers([
                header::RETRY_AFTER,
                header::LOCATION,
                header::WWW_AUTHENTICATE,
            ])
            .max_age(Duration::from_secs(600)),
    )
}

/// Headers every answer carries: a content security policy for pages with no script (inline
/// styles and SVG only, forms post to this origin, never framed), no MIME sniffing, no referrer
/// to other sites.
pub const SECURITY_HEADERS: [(&str, &str); 4] = [
    (
        "content-security-policy",
        "default-src 'none'; style-src 'unsafe-inline'; img-src 'self' data:; \
         form-action 'self'; frame-ancestors 'none'; base-uri 'none'",
    ),
    ("x-content-type-options", "nosniff"),
    ("x-frame-options", "DENY"),
    ("referrer-policy", "same-origin"),
];

/// The whole HTTP application. Layers, outermost first: security headers, request id and
/// trace span, panic guard, CORS, telemetry and timeout, rate limit with key identification
/// (when configured: charged before the key lookup, `api::gate::gate`), body limit. The
/// security headers are outermost so that every answer carries them: a panic's 500 and a CORS
/// preflight, which the layers inside answer themselves, included.
pub fn router(state: AppState) -> Router {
    let (routes, doc) = api::routes().split_for_parts();
    let doc = Arc::new(doc);
    let limit = state.body_limit;
    let timeout = state.timeout;
    let limited = state.rate_limit.is_some();
    let cors = cors(&state.cors_origins);
    let gate_state = state.clone();
    let mut app = routes
        .route(
            "/openapi.json",
            get(move || {
                let doc = doc.clone();
                async move { axum::Json(doc.as_ref().clone()) }
            }),
        )
        .merge(web::router())
        .fallback(not_found)
        .with_state(state)
        .layer(DefaultBodyLimit::max(limit))
        // `Content-Encoding: gzip` bodies are inflated as they are read, so the body limit
        // above bounds the decompressed size; another encoding is refused with 415.
        .layer(RequestDecompressionLayer::new());
    if limited {
        app = app.layer(from_fn_with_state(gate_state, api::gate::gate));
    }
    app = app.layer(from_fn_with_state(timeout, api::telemetry::track));
    if let Some(cors) = cors {
        app = app.layer(cors);
    }
    // Request ids (issue 18): a caller's `x-request-id` is kept (else a UUID is made), echoed in
    // the answer, and every log line of the request carries it through the TraceLayer's span.
    let x_request_id = HeaderName::from_static("x-request-id");
    app = app
        .layer(CatchPanicLayer::custom(api::telemetry::panic_response))
        .layer(PropagateRequestIdLayer::new(x_request_id.clone()))
        .layer(
            TraceLayer::new_for_http()
                .make_span_with(api::telemetry::request_span)
                .on_request(())
                .on_response(())
                .on_failure(()),
        )
        .layer(SetRequestIdLayer::new(x_request_id, MakeRequestUuid));
    // Security headers on every answer (issue 18), outermost: the pages run no script and embed
    // nothing, so the policy allows only their own inline styles, images and form posts, and
    // no framing.
    for (name, value) in SECURITY_HEADERS {
        app = app.layer(SetResponseHeaderLayer::if_not_present(
            HeaderName::from_static(name),
            HeaderValue::from_static(value),
        ));
    }
    app
}
