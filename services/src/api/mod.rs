//! The REST API: axum routes under `/v1` (traces, fleet, alerts, admin) plus `/healthz`, `/readyz`,
//! `/metrics` and `/openapi.json`, the OpenAPI document generated from these handlers.
//!
//! Each module has a `router()`; [`routes`] merges them. The whole HTTP application (these
//! routes, the web pages of `crate::web`, fallbacks and layers) is put together in `crate::app`:
//! the API knows nothing of the pages; the pages use the API's state, errors and sessions.

pub mod admin;
pub mod alerts;
pub mod auth;
pub mod error;
pub mod extract;
pub mod fleet;
pub mod gate;
pub mod ops;
pub mod ratelimit;
pub mod session;
pub mod state;
pub mod telemetry;
pub mod traces;
pub mod webhooks;

use utoipa::openapi::security::{Http, HttpAuthScheme, SecurityScheme};
use utoipa::openapi::{ContentBuilder, Ref, RefOr, ResponseBuilder};
use utoipa::{Modify, OpenApi};
use utoipa_axum::router::OpenApiRouter;

use error::{PROBLEM_JSON, Problem};
pub use state::AppState;

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

pub fn routes() -> OpenApiRouter<AppState> {
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
    routes().split_for_parts().1
}
