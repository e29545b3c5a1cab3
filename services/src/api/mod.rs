//! The REST API: axum routes under `/v1` (traces, fleet, alerts, admin) plus `/healthz`, `/readyz`,
//! `/metrics` and `/openapi.json`, the OpenAPI document generated from these handlers.
//!
//! Each module has a `router()`; [`router`] merges them (and the web pages, `crate::web`) in one
//! place, adds the fallbacks and the layers (body limit, rate limit per key, telemetry and
//! timeout, CORS from the configured origins, panic guard).

pub mod admin;
pub mod alerts;
pub mod auth;
pub mod error;
pub mod extract;
pub mod fleet;
pub mod ops;
pub mod ratelimit;
pub mod telemetry;
pub mod traces;
pub mod webhooks;

use std::sync::Arc;
use std::time::Duration;

use axum::Router;
use axum::extract::DefaultBodyLimit;
use axum::http::{HeaderName, HeaderValue, Method, header};
use axum::middleware::from_fn_with_state;
use axum::routing::get;
use metrics_exporter_prometheus::PrometheusHandle;
use tokio::sync::Notify;
use tower_http::catch_panic::CatchPanicLayer;
use tower_http::cors::{AllowOrigin, CorsLayer};
use tower_http::decompression::RequestDecompressionLayer;
use tower_http::request_id::{MakeRequestUuid, PropagateRequestIdLayer, SetRequestIdLayer};
use tower_http::set_header::SetResponseHeaderLayer;
use tower_http::trace::TraceLayer;
use utoipa::openapi::security::{Http, HttpAuthScheme, SecurityScheme};
use utoipa::openapi::{ContentBuilder, Ref, RefOr, ResponseBuilder};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;

use crate::alerts::AlertOptions;
use crate::config::Settings;
use crate::ingest::Intake;
use crate::store::Store;
use error::{AppError, PROBLEM_JSON, Problem};

/// What every handler can reach.
#[derive(Clone)]
pub struct AppState {
    pub store: Store,
    pub intake: Intake,
    /// Wakes in-process workers (uploads, re-fits).
    pub wake: Arc<Notify>,
    pub metrics: PrometheusHandle,
    pub body_limit: usize,
    pub timeout: Duration,
    /// Alert rules (horizon, alarm band) for trends and forecasts.
    pub alerts: AlertOptions,
    /// Wakes this process's webhook deliverer after an alert change.
    pub alert_wake: Arc<Notify>,
    /// Signs the web pages' session cookies.
    pub sessions: Arc<crate::web::session::SessionKey>,
    /// Requests per key (or per peer IP without a key); `None`: no limit.
    pub rate_limit: Option<ratelimit::RateLimit>,
    /// Origins answered with CORS headers (empty: none).
    pub cors_origins: Vec<HeaderValue>,
}

impl AppState {
    pub fn new(store: Store, wake: Arc<Notify>, body_limit: usize, timeout: Duration) -> Self {
        AppState {
            intake: Intake::new(store.clone(), wake.clone()),
            store,
            wake,
            metrics: telemetry::prometheus(),
            body_limit,
            timeout,
            alerts: AlertOptions::default(),
            alert_wake: Arc::new(Notify::new()),
            sessions: Arc::new(crate::web::session::SessionKey::random(12)),
            rate_limit: None,
            cors_origins: Vec::new(),
        }
    }

    /// Takes the alert rules, session, rate-limit and CORS settings from `settings`.
    pub fn configure(
        mut self,
        settings: &Settings,
        alert_wake: Arc<Notify>,
    ) -> anyhow::Result<Self> {
        self.alerts = AlertOptions {
            horizon_days: settings.alerts.horizon_days,
            alarm: settings.drift.alarm,
        };
        self.alert_wake = alert_wake;
        let hours = settings.web.session_hours;
        let secret = settings.web.session_secret.expose_secret();
        self.sessions = Arc::new(if secret.is_empty() {
            crate::web::session::SessionKey::random(hours)
        } else {
            crate::web::session::SessionKey::from_secret(secret, hours)
        });
        self.rate_limit = ratelimit::RateLimit::from_settings(&settings.http);
        self.cors_origins = settings
            .http
            .cors_origins
            .iter()
            .map(|o| {
                HeaderValue::from_str(&o.to_ascii_lowercase())
                    .map_err(|_| anyhow::anyhow!("http.cors_origins: {o:?} is not a header value"))
            })
            .collect::<anyhow::Result<_>>()?;
        Ok(self)
    }
}

#[derive(OpenApi)]
#[openapi(
    info(
        title = "pantowatch",
        description = "Joint wear of railway pantographs: upload test traces, read each joint's \
            fitted friction, its drift status and the fleet's health. Every `/v1` route needs \
            `Authorization: Bearer <key>` (roles: reader < writer < admin). Errors are \
            `application/problem+json` with `type`, `title`, `status`, `detail` and `field`."
    ),
    modifiers(&Security),
    components(schemas(Problem)),
    tags(
        (name = "traces", description = "Upload traces, read them and their fits"),
        (name = "fleet", description = "Vehicles, joint histories, fleet health"),
        (name = "alerts", description = "Joint alerts: list, history, acknowledge, resolve"),
        (name = "admin", description = "API keys, re-fits and webhook subscriptions (admin keys)"),
        (name = "ops", description = "Liveness, readiness, metrics (no key)"),
    )
)]
struct ApiDoc;

/// Adds the bearer scheme and the 401/403 answers shared by every `/v1` operation.
struct Security;

impl Modify for Security {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            "bearer",
            SecurityScheme::Http(Http::new(HttpAuthScheme::Bearer)),
        );
        let problem = || {
            ContentBuilder::new()
                .schema(Some(Ref::from_schema_name("Problem")))
                .build()
        };
        for (name, text) in [
            ("Unauthorized", "No key, or an unknown or revoked key"),
            ("Forbidden", "The key's role is too low for this route"),
        ] {
            components.responses.insert(
                name.into(),
                RefOr::T(
                    ResponseBuilder::new()
                        .description(text)
                        .content(PROBLEM_JSON, problem())
                        .build(),
                ),
            );
        }
        for (path, item) in openapi.paths.paths.iter_mut() {
            if !path.starts_with("/v1/") {
                continue;
            }
            for op in [
                &mut item.get,
                &mut item.post,
                &mut item.put,
                &mut item.delete,
                &mut item.patch,
            ]
            .into_iter()
            .flatten()
            {
                for (code, name) in [("401", "Unauthorized"), ("403", "Forbidden")] {
                    op.responses
                        .responses
                        .insert(code.into(), RefOr::Ref(Ref::from_response_name(name)));
                }
            }
        }
    }
}

fn api_routes() -> OpenApiRouter<AppState> {
    OpenApiRouter::with_openapi(ApiDoc::openapi())
        .merge(traces::router())
        .merge(fleet::router())
        .merge(admin::router())
        .merge(alerts::router())
        .merge(webhooks::router())
        .merge(ops::router())
}

/// The OpenAPI document of the API (what `/openapi.json` serves).
pub fn openapi() -> utoipa::openapi::OpenApi {
    api_routes().split_for_parts().1
}

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
        crate::web::not_found_page(&st, &parts, e).await
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
/// (when configured: charged before the key lookup, `ratelimit::gate`), body limit. The
/// security headers are outermost so that every answer carries them: a panic's 500 and a CORS
/// preflight, which the layers inside answer themselves, included.
pub fn router(state: AppState) -> Router {
    let (routes, doc) = api_routes().split_for_parts();
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
        .merge(crate::web::router())
        .fallback(not_found)
        .with_state(state)
        .layer(DefaultBodyLimit::max(limit))
        // `Content-Encoding: gzip` bodies are inflated as they are read, so the body limit
        // above bounds the decompressed size; another encoding is refused with 415.
        .layer(RequestDecompressionLayer::new());
    if limited {
        app = app.layer(from_fn_with_state(gate_state, ratelimit::gate));
    }
    app = app.layer(from_fn_with_state(timeout, telemetry::track));
    if let Some(cors) = cors {
        app = app.layer(cors);
    }
    // Request ids (issue 18): a caller's `x-request-id` is kept (else a UUID is made), echoed in
    // the answer, and every log line of the request carries it through the TraceLayer's span.
    let x_request_id = HeaderName::from_static("x-request-id");
    app = app
        .layer(CatchPanicLayer::custom(telemetry::panic_response))
        .layer(PropagateRequestIdLayer::new(x_request_id.clone()))
        .layer(
            TraceLayer::new_for_http()
                .make_span_with(telemetry::request_span)
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
