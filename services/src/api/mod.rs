//! The REST API: axum routes under `/v1` (traces, fleet, alerts, admin) plus `/healthz`, `/readyz`,
//! `/metrics` and `/openapi.json`, the OpenAPI document generated from these handlers.
//!
//! Each module has a `router()`; [`routes`] merges them. The whole HTTP application (these
//! routes, the web pages of `crate::web`, fallbacks and layers) is put together in `crate::app`:
//! the API knows nothing of the pages; the pages use the API's state, errors and sessions.

pub mod admin;
pub mod alerts;
pub mod auth;
pub mod doc;
pub mod error;
pub mod extract;
pub mod fleet;
pub mod gate;
pub mod ops;
pub mod plan;
pub mod prior;
pub mod ratelimit;
pub mod session;
pub mod state;
pub mod telemetry;
pub mod traces;
pub mod webhooks;

use utoipa::openapi::security::{Http, HttpAuthScheme, SecurityScheme};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;

use crate::ids::{JointName, Serial, TraceId, VehicleId};
use error::Problem;
pub use state::AppState;

#[derive(OpenApi)]
#[openapi(
    info(
        title = "pantowatch",
        description = "Joint wear of railway pantographs: upload test traces, read each joint's \
            fitted friction, its drift status and the fleet's health. Every `/v1` route needs \
            `Authorization: Bearer <key>`; its security requirement names the least role it \
            needs (reader < writer < admin). Errors are `application/problem+json` with `type`, \
            `title`, `status`, `detail` and `field` or `parameter`. Requests are rate-limited \
            per key (429 with `Retry-After`), except `/healthz`, `/readyz` and `/metrics`."
    ),
    modifiers(&Security),
    components(schemas(Problem, TraceId, VehicleId, Serial, JointName)),
    tags(
        (name = "traces", description = "Upload traces, read them and their fits"),
        (name = "fleet", description = "Vehicles, joint histories, fleet health"),
        (name = "alerts", description = "Joint alerts: list, history, acknowledge, resolve"),
        (name = "admin", description = "API keys, re-fits and webhook subscriptions (admin keys)"),
        (name = "ops", description = "Liveness, readiness, metrics (no key)"),
    )
)]
struct ApiDoc;

/// Adds the bearer scheme.
struct Security;

impl Modify for Security {
    fn modify(&self, openapi: &mut utoipa::openapi::OpenApi) {
        let components = openapi.components.get_or_insert_with(Default::default);
        components.add_security_scheme(
            doc::BEARER,
            SecurityScheme::Http(Http::new(HttpAuthScheme::Bearer)),
        );
    }
}

/// Every route with its OpenAPI document, the answers they share included ([`doc`]).
pub fn routes() -> OpenApiRouter<AppState> {
    let mut router = OpenApiRouter::with_openapi(ApiDoc::openapi())
        .merge(traces::router())
        .merge(fleet::router())
        .merge(plan::router())
        .merge(prior::router())
        .merge(admin::router())
        .merge(alerts::router())
        .merge(webhooks::router())
        .merge(ops::router());
    doc::add_shared_answers(router.get_openapi_mut());
    doc::add_alert_evidence(router.get_openapi_mut());
    router
}

/// The OpenAPI document of the API (what `/openapi.json` serves).
pub fn openapi() -> utoipa::openapi::OpenApi {
    routes().split_for_parts().1
}
