//! The frame every page shares — head with the site's style, the header with the navigation and
//! the sign-out button when signed in — and the status badges. Written with `maud`, which escapes
//! every value it splices into text or a (double-quoted) attribute.

use axum::http::HeaderValue;
use axum::http::header::CACHE_CONTROL;
use axum::response::{IntoResponse, Response};
use maud::{DOCTYPE, Markup, PreEscaped, html};

use crate::store::{ApiKey, Severity, Status};

/// The site's style sheet, inline (the content security policy allows own inline styles only).
/// A status class (`alarm`, `watch`, `ok`, `unknown`) colours both a badge (its background) and
/// a chart point (its fill and stroke), so a badge and a point of one status share one colour.
pub const STYLE: &str = "body{font:15px/1.4 system-ui,sans-serif;margin:0;color:#111}\
header{background:#1d3557;color:#fff;padding:.6em 1em;display:flex;gap:1.2em;align-items:center}\
header a{color:#fff}header form{margin-left:auto}main{padding:1em}\
table{border-collapse:collapse}th,td{border-bottom:1px solid #ccc;padding:.3em .6em;text-align:left}\
.alarm{background:#c62828;color:#fff;fill:#c62828;stroke:#c62828}\
.watch{background:#f9a825;color:#000;fill:#f9a825;stroke:#f9a825}\
.ok{background:#2e7d32;color:#fff;fill:#2e7d32;stroke:#2e7d32}\
.unknown{background:#757575;color:#fff;fill:#757575;stroke:#757575}\
.badge{padding:.1em .5em;border-radius:.3em;font-weight:600}\
.note{color:#555}figure{margin:1em 0}figcaption{font-size:.9em;color:#333}\
.msg{background:#e3f2fd;padding:.5em;border-left:4px solid #1565c0}\
svg.age{vertical-align:middle;margin-right:.4em}svg.age rect.track{fill:#eee;stroke:none}";

/// A whole page; `user` (the key signed in) adds the navigation and the sign-out button.
pub fn page(title: &str, user: Option<&ApiKey>, body: Markup) -> Response {
    let html = html! {
        (DOCTYPE)
        html lang="en" {
            head {
                meta charset="utf-8";
                meta name="viewport" content="width=device-width";
                title { (title) " · pantowatch" }
                style { (PreEscaped(STYLE)) }
            }
            body {
                header {
                    strong { "pantowatch" }
                    @if let Some(k) = user {
                        a href="/fleet" { "Fleet" }
                        a href="/alerts" { "Alerts" }
                        form method="post" action="/logout" {
                            span { (k.role) " key " (k.id) }
                            " "
                            button type="submit" { "Sign out" }
                        }
                    }
                }
                main { (body) }
            }
        }
    };
    let mut r = html.into_response();
    r.headers_mut()
        .insert(CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

/// A joint's or pantograph's status as a badge; `None`: not fitted yet.
pub fn badge(s: Option<Status>) -> Markup {
    match s {
        Some(s) => html! { span.badge.(s.as_str()) { (s.as_str()) } },
        None => html! { span.badge.unknown { "not fitted" } },
    }
}

/// An alert's severity as a badge (the status colours).
pub fn sev_badge(s: Severity) -> Markup {
    html! { span.badge.(s) { (s) } }
}

/// A joint's evidence age at a glance: a bar filled to age / allowed age (full past it), green
/// under half, amber to the limit, red past it (a test due); grey and full when never measured;
/// then the age in days. SVG attributes, not inline styles (the content security policy).
pub fn age_bar(age_days: Option<f64>, max_age_days: Option<f64>) -> Markup {
    let (fill, class) = match (age_days, max_age_days) {
        (None, _) => (1.0, "unknown"),
        (Some(a), Some(m)) if m > 0.0 => {
            let f = a / m;
            (
                f.min(1.0),
                if f > 1.0 {
                    "alarm"
                } else if f > 0.5 {
                    "watch"
                } else {
                    "ok"
                },
            )
        }
        (Some(_), _) => (0.0, "ok"),
    };
    let w = format!("{:.1}", 80.0 * fill);
    html! {
        svg.age width="80" height="10" role="img" aria-label="evidence age" {
            rect.track x="0" y="0" width="80" height="10" {}
            rect.(class) x="0" y="0" width=(w) height="10" {}
        }
        span.age-days {
            @match age_days {
                Some(a) => { (format!("{a:.0} d")) },
                None => { "never measured" },
            }
        }
    }
}
