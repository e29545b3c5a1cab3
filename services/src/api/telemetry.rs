//! Request telemetry and the last line of defence: per-route Prometheus counters and latency,
//! a log line per request, the request timeout, and any non-problem error turned into one.

use std::sync::OnceLock;
use std::time::{Duration, Instant};

use axum::extract::{MatchedPath, Request, State};
use axum::http::{StatusCode, header};
use axum::middleware::Next;
use axum::response::{IntoResponse, Response};
use metrics_exporter_prometheus::{Matcher, PrometheusBuilder, PrometheusHandle};

use super::error::{AppError, PROBLEM_JSON, Problem, problem_response};

/// The longest request target answered (path and query): 8 KiB, what common proxies and
/// browsers allow; longer ones get 414 in problem form (hyper refuses far longer heads itself).
pub const MAX_URI_BYTES: usize = 8 * 1024;

/// The process-wide Prometheus recorder (installed on first use).
pub fn prometheus() -> PrometheusHandle {
    static HANDLE: OnceLock<PrometheusHandle> = OnceLock::new();
    HANDLE
        .get_or_init(|| {
            // Up to 120 s: fits run up to worker.fit_budget_secs (60 s by default).
            let seconds = [
                0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0, 30.0,
                60.0, 120.0,
            ];
            // Model evaluations per fit, against worker.fit_max_evaluations (10,000).
            let evaluations = [10.0, 30.0, 100.0, 300.0, 1e3, 3e3, 1e4, 2e4, 1e5];
            let builder = PrometheusBuilder::new()
                .set_buckets_for_metric(Matcher::Suffix("_seconds".into()), &seconds)
                .and_then(|b| {
                    b.set_buckets_for_metric(
                        Matcher::Full("pantowatch_fit_evaluations".into()),
                        &evaluations,
                    )
                })
                .unwrap_or_else(|_| PrometheusBuilder::new());
            let recorder = builder.build_recorder();
            let handle = recorder.handle();
            if metrics::set_global_recorder(recorder).is_err() {
                tracing::warn!("a metrics recorder was already installed; /metrics may be empty");
            }
            handle
        })
        .clone()
}

/// Times, counts and logs every request; answers 503 after `timeout`; turns a bare error
/// answer (axum's own 405, a panic) into problem JSON.
pub async fn track(State(timeout): State<Duration>, req: Request, next: Next) -> Response {
    let method = req.method().clone();
    let route = req
        .extensions()
        .get::<MatchedPath>()
        .map_or_else(|| "unmatched".to_owned(), |p| p.as_str().to_owned());
    let start = Instant::now();
    if req.uri().to_string().len() > MAX_URI_BYTES {
        let resp = problemize(StatusCode::URI_TOO_LONG.into_response()).await;
        metrics::counter!("http_requests_total", "method" => method.to_string(), "route" => route, "status" => "414")
            .increment(1);
        return resp;
    }
    let resp = match tokio::time::timeout(timeout, next.run(req)).await {
        Ok(r) => r,
        Err(_) => AppError::Timeout(timeout.as_secs()).into_response(),
    };
    let resp = problemize(resp).await;
    let secs = start.elapsed().as_secs_f64();
    let status = resp.status().as_u16().to_string();
    metrics::counter!("http_requests_total", "method" => method.to_string(), "route" => route.clone(), "status" => status.clone())
        .increment(1);
    metrics::histogram!("http_request_duration_seconds", "method" => method.to_string(), "route" => route.clone())
        .record(secs);
    tracing::info!(target: "pantowatch::http", %method, %route, status = %status, ms = secs * 1e3, "request");
    resp
}

async fn problemize(resp: Response) -> Response {
    let status = resp.status();
    if !(status.is_client_error() || status.is_server_error()) {
        return resp;
    }
    let ct = resp
        .headers()
        .get(header::CONTENT_TYPE)
        .and_then(|v| v.to_str().ok())
        .unwrap_or("");
    // Problem answers pass, and so do the web pages' own HTML error pages (a failed sign-in,
    // 403, 404 in the site's style): only bare framework answers are rewritten (issue 18).
    if ct.starts_with(PROBLEM_JSON) || ct.starts_with("text/html") {
        return resp;
    }
    let allow = resp.headers().get(header::ALLOW).cloned();
    let body = axum::body::to_bytes(resp.into_body(), 64 * 1024)
        .await
        .unwrap_or_default();
    let text = String::from_utf8_lossy(&body).trim().to_owned();
    let detail = if status.is_server_error() {
        "the server failed to answer; the error is in its log".to_owned()
    } else if text.is_empty() {
        status.canonical_reason().unwrap_or("error").to_owned()
    } else {
        text
    };
    let (slug, field, parameter) = named_part(status);
    let mut out = problem_response(&Problem {
        kind: format!("/problems/{slug}"),
        title: status.canonical_reason().unwrap_or("Error").to_owned(),
        status: status.as_u16(),
        detail,
        field: field.map(str::to_owned),
        parameter: parameter.map(str::to_owned),
        job: None,
    });
    if let Some(a) = allow {
        out.headers_mut().insert(header::ALLOW, a);
    }
    out
}

/// What a bare framework answer of `status` is about — `(slug, field, parameter)`: every 4xx
/// names what to change, a field of the request (a header by its name, `body`) or a parameter
/// of its address (`path`). The handlers' own answers are problems already and never come
/// here; what does is the framework's: axum's 405 and 404, the body limit's 413, hyper's 414,
/// the decompression layer's 415 (an encoding other than gzip: `Content-Encoding`). A client
/// error no layer says more about is named `request`, the request as a whole, rather than a
/// part it may not be about.
fn named_part(status: StatusCode) -> (&'static str, Option<&'static str>, Option<&'static str>) {
    match status {
        StatusCode::METHOD_NOT_ALLOWED => ("method-not-allowed", Some("method"), None),
        StatusCode::NOT_FOUND => ("not-found", None, Some("path")),
        StatusCode::PAYLOAD_TOO_LARGE => ("payload-too-large", Some("body"), None),
        StatusCode::URI_TOO_LONG => ("uri-too-long", None, Some("path")),
        StatusCode::UNSUPPORTED_MEDIA_TYPE => {
            ("unsupported-media-type", Some("Content-Encoding"), None)
        }
        StatusCode::REQUEST_TIMEOUT => ("request-timeout", Some("body"), None),
        StatusCode::LENGTH_REQUIRED => ("length-required", Some("Content-Length"), None),
        StatusCode::NOT_ACCEPTABLE => ("not-acceptable", Some("Accept"), None),
        StatusCode::RANGE_NOT_SATISFIABLE => ("range-not-satisfiable", Some("Range"), None),
        StatusCode::EXPECTATION_FAILED => ("expectation-failed", Some("Expect"), None),
        StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE => {
            ("header-fields-too-large", Some("headers"), None)
        }
        s if s.is_server_error() => ("internal", None, None),
        StatusCode::BAD_REQUEST => ("bad-request", Some("request"), None),
        _ => ("client-error", Some("request"), None),
    }
}

/// Answer of a handler that panicked (the panic is logged, never shown).
pub fn panic_response(err: Box<dyn std::any::Any + Send + 'static>) -> Response {
    let msg = err
        .downcast_ref::<String>()
        .cloned()
        .or_else(|| err.downcast_ref::<&str>().map(|s| (*s).to_owned()))
        .unwrap_or_else(|| "unknown panic".into());
    AppError::Internal(format!("handler panicked: {msg}")).into_response()
}

/// The span of one request: its id (`x-request-id`, kept from the caller or made here), method
/// and path. The request log line and everything logged while answering are inside it.
pub fn request_span<B>(req: &axum::http::Request<B>) -> tracing::Span {
    let id = req
        .headers()
        .get("x-request-id")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("-");
    tracing::info_span!("http", request_id = %id, method = %req.method(), path = %req.uri().path())
}

#[cfg(test)]
mod tests {
    use super::*;

    async fn problem_of(status: StatusCode) -> serde_json::Value {
        let bare = (status, "plain text from a layer").into_response();
        let resp = problemize(bare).await;
        assert_eq!(resp.status(), status);
        let ct = resp.headers()[header::CONTENT_TYPE]
            .to_str()
            .unwrap()
            .to_owned();
        assert!(ct.starts_with(PROBLEM_JSON), "{status}: {ct}");
        let body = axum::body::to_bytes(resp.into_body(), 1 << 16)
            .await
            .unwrap();
        serde_json::from_slice(&body).unwrap()
    }

    /// Issue 18: a bare framework answer becomes a problem naming what it is about — a header
    /// by its name, `path`, or `request` when nothing says more — never `body` for an answer
    /// that is not about the body (the catch-all named `body` for every other 4xx).
    #[tokio::test]
    async fn bare_client_errors_name_the_part_they_are_about() {
        for (status, field, parameter) in [
            (StatusCode::METHOD_NOT_ALLOWED, Some("method"), None),
            (StatusCode::NOT_FOUND, None, Some("path")),
            (StatusCode::PAYLOAD_TOO_LARGE, Some("body"), None),
            (StatusCode::URI_TOO_LONG, None, Some("path")),
            (
                StatusCode::UNSUPPORTED_MEDIA_TYPE,
                Some("Content-Encoding"),
                None,
            ),
            (StatusCode::LENGTH_REQUIRED, Some("Content-Length"), None),
            (
                StatusCode::REQUEST_HEADER_FIELDS_TOO_LARGE,
                Some("headers"),
                None,
            ),
            (StatusCode::BAD_REQUEST, Some("request"), None),
            (StatusCode::IM_A_TEAPOT, Some("request"), None),
        ] {
            let v = problem_of(status).await;
            assert_eq!(v["field"].as_str(), field, "{status}: {v}");
            assert_eq!(v["parameter"].as_str(), parameter, "{status}: {v}");
            assert_eq!(v["status"], status.as_u16());
        }
        let v = problem_of(StatusCode::BAD_GATEWAY).await;
        assert!(v["field"].is_null() && v["parameter"].is_null(), "{v}");
        assert!(!v["detail"].as_str().unwrap().contains("plain text"), "{v}");
    }
}
