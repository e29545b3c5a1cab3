//! The depot's web pages, served by the service: plain HTML with inline SVG, readable without
//! JavaScript — sign-in (API key → signed session cookie), fleet, pantograph, trace and alerts.
//!
//! Every page but the sign-in needs a session; the acknowledge form calls the same code as
//! `POST /v1/alerts/{id}/acknowledge`. Errors are the API's [`AppError`], shown as an HTML page.

pub mod session;
pub mod svg;

use std::collections::{BTreeMap, HashMap};
use std::fmt::Write;

use axum::Router;
use axum::body::Bytes;
use axum::extract::{Path, Query, State};
use axum::http::header::{CACHE_CONTROL, CONTENT_TYPE, LOCATION, SET_COOKIE};
use axum::http::{HeaderValue, StatusCode};
use axum::response::{Html, IntoResponse, Redirect, Response};
use axum::routing::{get, post};
use chrono::{DateTime, Utc};
use pantowatch_models::drift::DriftThresholds;
use serde::Deserialize;

use crate::api::AppState;
use crate::api::alerts::{acknowledge, parse_id};
use crate::api::error::AppError;
use crate::health::{self, Param, ParamTrend};
use crate::ids::Serial;
use crate::ingest::stored_doc;
use crate::store::{
    Alert, AlertFilter, AlertState, FleetFilter, JointPoint, Page, Role, Severity, Status,
};
use session::{SessionKey, WebUser, clear_cookie};
use svg::{Frame, fmt_num, thin};

/// The pages (no OpenAPI: they are for people).
pub fn router() -> Router<AppState> {
    Router::new()
        .route("/", get(login_page))
        .route("/login", post(login))
        .route("/logout", post(logout))
        .route("/fleet", get(fleet_page))
        .route("/pantographs/{serial}", get(pantograph_page))
        .route("/traces/{id}", get(trace_page))
        .route("/alerts", get(alerts_page))
        .route("/alerts/{id}/acknowledge", post(acknowledge_form))
}

/// HTML text escaping.
pub fn esc(s: &str) -> String {
    let mut o = String::with_capacity(s.len());
    for c in s.chars() {
        match c {
            '&' => o.push_str("&amp;"),
            '<' => o.push_str("&lt;"),
            '>' => o.push_str("&gt;"),
            '"' => o.push_str("&quot;"),
            '\'' => o.push_str("&#39;"),
            c => o.push(c),
        }
    }
    o
}

/// Percent-encoding of a path segment.
fn seg(s: &str) -> String {
    form_urlencoded::byte_serialize(s.as_bytes())
        .collect::<String>()
        .replace('+', "%20")
}

const STYLE: &str = "body{font:15px/1.4 system-ui,sans-serif;margin:0;color:#111}\
header{background:#1d3557;color:#fff;padding:.6em 1em;display:flex;gap:1.2em;align-items:center}\
header a{color:#fff}header form{margin-left:auto}main{padding:1em}\
table{border-collapse:collapse}th,td{border-bottom:1px solid #ccc;padding:.3em .6em;text-align:left}\
.alarm{background:#c62828;color:#fff}.watch{background:#f9a825;color:#000}\
.ok{background:#2e7d32;color:#fff}.unknown{background:#757575;color:#fff}\
.badge{padding:.1em .5em;border-radius:.3em;font-weight:600}\
.note{color:#555}figure{margin:1em 0}figcaption{font-size:.9em;color:#333}\
.msg{background:#e3f2fd;padding:.5em;border-left:4px solid #1565c0}";

/// A whole page; `user` adds the navigation and the sign-out button.
fn page(title: &str, user: Option<&WebUser>, body: &str) -> Response {
    let nav = match user {
        Some(u) => format!(
            r#"<header><strong>pantowatch</strong><a href="/fleet">Fleet</a><a href="/alerts">Alerts</a>
<form method="post" action="/logout"><span>{}</span> <button type="submit">Sign out</button></form></header>"#,
            esc(&format!("{} key {}", u.key.role, u.key.id))
        ),
        None => "<header><strong>pantowatch</strong></header>".to_owned(),
    };
    let html = format!(
        r#"<!doctype html><html lang="en"><head><meta charset="utf-8"><meta name="viewport" content="width=device-width">
<title>{} · pantowatch</title><style>{STYLE}</style></head><body>{nav}<main>{body}</main></body></html>"#,
        esc(title)
    );
    let mut r = Html(html).into_response();
    r.headers_mut()
        .insert(CACHE_CONTROL, HeaderValue::from_static("no-store"));
    r
}

/// An [`AppError`] as an HTML page with the same status.
pub struct WebError(AppError);

impl From<AppError> for WebError {
    fn from(e: AppError) -> Self {
        WebError(e)
    }
}

impl From<crate::store::StoreError> for WebError {
    fn from(e: crate::store::StoreError) -> Self {
        WebError(e.into())
    }
}

impl IntoResponse for WebError {
    fn into_response(self) -> Response {
        if let AppError::Internal(e) = &self.0 {
            tracing::error!(error = %e, "page failed");
        }
        let p = self.0.problem();
        let mut r = page(
            &p.title,
            None,
            &format!(
                r#"<h1>{}</h1><p>{}</p><p><a href="/fleet">Back to the fleet</a></p>"#,
                esc(&p.title),
                esc(&p.detail)
            ),
        );
        *r.status_mut() =
            StatusCode::from_u16(p.status).unwrap_or(StatusCode::INTERNAL_SERVER_ERROR);
        r
    }
}

type PageResult = Result<Response, WebError>;

fn badge(s: Option<Status>) -> String {
    match s {
        Some(s) => format!(r#"<span class="badge {s}">{s}</span>"#),
        None => r#"<span class="badge unknown">not fitted</span>"#.to_owned(),
    }
}

fn sev_badge(s: Severity) -> String {
    format!(r#"<span class="badge {s}">{s}</span>"#)
}

fn day(t: DateTime<Utc>) -> String {
    t.format("%Y-%m-%d").to_string()
}

fn form<T: serde::de::DeserializeOwned>(body: &Bytes) -> Result<T, WebError> {
    serde_urlencoded::from_bytes(body).map_err(|e| {
        WebError(AppError::BadRequest {
            field: Some("body".into()),
            detail: format!("form: {e}"),
        })
    })
}

// ------------------------------------------------------------------ sign-in

#[derive(Deserialize)]
struct LoginForm {
    key: String,
}

fn login_form(message: &str) -> String {
    let msg = if message.is_empty() {
        String::new()
    } else {
        format!(r#"<p class="msg" role="alert">{}</p>"#, esc(message))
    };
    format!(
        r#"<h1>Sign in</h1>{msg}<form method="post" action="/login">
<p><label for="key">API key</label><br><input id="key" name="key" type="password" size="60" autocomplete="off" required></p>
<p><button type="submit">Sign in</button></p></form>
<p class="note">Any reader, writer or admin key works; acknowledging alerts needs a writer key.</p>"#
    )
}

async fn login_page(State(st): State<AppState>, parts: axum::http::request::Parts) -> Response {
    let signed_in = session::cookie_value(&parts)
        .and_then(|v| st.sessions.verify(&v))
        .is_some();
    if signed_in {
        return Redirect::to("/fleet").into_response();
    }
    page("Sign in", None, &login_form(""))
}

async fn login(State(st): State<AppState>, body: Bytes) -> PageResult {
    let f: LoginForm = form(&body)?;
    let Some(key) = st.store.verify_api_key(f.key.trim()).await? else {
        let mut r = page("Sign in", None, &login_form("Unknown or revoked API key."));
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

async fn logout(State(st): State<AppState>) -> Response {
    with_cookie(Redirect::to("/").into_response(), &st.sessions, None)
}

// ------------------------------------------------------------------ fleet

/// Earliest forecast crossing in a live alert's evidence.
fn alert_forecast(a: &Alert) -> Option<DateTime<Utc>> {
    a.evidence
        .get("trends")?
        .as_array()?
        .iter()
        .filter_map(|t| t.pointer("/forecast/date")?.as_str())
        .filter_map(|d| DateTime::parse_from_rfc3339(d).ok())
        .map(|d| d.with_timezone(&Utc))
        .min()
}

async fn fleet_page(State(st): State<AppState>, user: WebUser) -> PageResult {
    let fleet = st
        .store
        .fleet_health(
            &FleetFilter::default(),
            Page {
                limit: 100_000,
                offset: 0,
            },
        )
        .await?;
    let live = st
        .store
        .list_alerts(&AlertFilter {
            live: true,
            ..AlertFilter::default()
        })
        .await?;
    let mut alerts: HashMap<&str, Vec<&Alert>> = HashMap::new();
    for a in &live {
        alerts.entry(a.serial.as_str()).or_default().push(a);
    }
    let mut rows: Vec<_> = fleet
        .rows
        .iter()
        .map(|r| {
            let mine = alerts.get(r.serial.as_str()).cloned().unwrap_or_default();
            let forecast = mine.iter().filter_map(|a| alert_forecast(a)).min();
            (r, mine, forecast)
        })
        .collect();
    // Risk: alarm first, then watch (…), then the earliest forecast crossing, then serial.
    rows.sort_by(|a, b| {
        b.0.worst_status
            .cmp(&a.0.worst_status)
            .then_with(|| match (a.2, b.2) {
                (Some(x), Some(y)) => x.cmp(&y),
                (Some(_), None) => std::cmp::Ordering::Less,
                (None, Some(_)) => std::cmp::Ordering::Greater,
                (None, None) => std::cmp::Ordering::Equal,
            })
            .then_with(|| a.0.serial.cmp(&b.0.serial))
    });
    let mut t = String::new();
    for (i, (r, mine, forecast)) in rows.iter().enumerate() {
        let joints: Vec<String> = r
            .not_ok
            .iter()
            .map(|j| format!("{} {}", esc(&j.joint), badge(Some(j.status))))
            .collect();
        let _ = write!(
            t,
            r#"<tr data-serial="{s}"><td>{}</td><td><a href="/pantographs/{}">{s}</a></td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>"#,
            i + 1,
            seg(&r.serial),
            esc(r.vehicle_id.as_deref().unwrap_or("—")),
            badge(r.worst_status),
            joints.join(", "),
            if mine.is_empty() {
                "—".to_owned()
            } else {
                format!(r#"<a href="/alerts">{}</a>"#, mine.len())
            },
            forecast.map_or("—".to_owned(), day),
            r.last_test.map_or("—".to_owned(), day),
            s = esc(&r.serial),
        );
    }
    let n = |s: Status| rows.iter().filter(|r| r.0.worst_status == Some(s)).count();
    let body = format!(
        r#"<h1>Fleet</h1><p>{} pantographs: {} alarm, {} watch, {} ok, {} unknown. {} alerts open or acknowledged.</p>
<table id="fleet"><caption>Pantographs by risk: alarm first, then watch, then the earliest forecast date of reaching the alarm band.</caption>
<thead><tr><th>#</th><th>serial</th><th>vehicle</th><th>worst</th><th>joints not ok</th><th>alerts</th><th>forecast alarm</th><th>last test</th></tr></thead><tbody>{t}</tbody></table>"#,
        rows.len(),
        n(Status::Alarm),
        n(Status::Watch),
        n(Status::Ok),
        n(Status::Unknown),
        live.len()
    );
    Ok(page("Fleet", Some(&user), &body))
}

// ------------------------------------------------------------------ pantograph

fn param_chart(
    serial: &str,
    joint: &str,
    history: &[JointPoint],
    tr: &ParamTrend,
    unit: &str,
    watch: [f64; 2],
) -> String {
    let Some(t0) = history.first().map(|p| p.recorded_at) else {
        return String::new();
    };
    let days = |t: DateTime<Utc>| (t - t0).num_seconds() as f64 / 86_400.0;
    let pts: Vec<(f64, f64, f64, f64, &JointPoint)> = history
        .iter()
        .filter_map(|p| {
            let (v, lo, hi) = tr.param.of(p)?;
            Some((days(p.recorded_at), v, lo, hi, p))
        })
        .collect();
    if pts.is_empty() {
        return format!("<p>No {} values for {}.</p>", tr.param.as_str(), esc(joint));
    }
    let last_x = pts.iter().map(|p| p.0).fold(0.0, f64::max);
    let fc_x = tr.forecast.as_ref().map(|f| days(f.date));
    let x1 = fc_x
        .map_or(last_x, |f| f.clamp(last_x, last_x + 730.0))
        .max(last_x + 1.0);
    let mut ylo = pts.iter().map(|p| p.2).fold(f64::INFINITY, f64::min);
    let mut yhi = pts.iter().map(|p| p.3).fold(f64::NEG_INFINITY, f64::max);
    if let Some(b) = tr.baseline {
        ylo = ylo.min(b * watch[0]);
        yhi = yhi.max(b * watch[1]);
    }
    if let Some([_, hi]) = tr.alarm_band
        && tr.forecast.as_ref().is_some_and(|f| f.threshold >= hi)
    {
        yhi = yhi.max(hi);
    }
    let mut f = Frame::new((0.0, x1), (ylo, yhi));
    if let Some(b) = tr.baseline {
        f.hband(
            b * watch[0],
            b * watch[1],
            "#e8f5e9",
            "Table 4 band (watch band × baseline)",
        );
        f.hline(b, "#2e7d32", true);
    }
    if let Some([lo, hi]) = tr.alarm_band {
        f.hline(lo, "#c62828", true);
        f.hline(hi, "#c62828", true);
    }
    if let Some(t) = &tr.trend {
        let end = fc_x.map_or(last_x, |x| x.min(x1));
        let a = t.level + t.slope_per_day * (0.0 - days(t.level_at));
        let b = t.level + t.slope_per_day * (end - days(t.level_at));
        let color = if t.significant { "#1565c0" } else { "#9e9e9e" };
        f.polyline(&[(0.0, a), (end, b)], color, 2.0, !t.significant);
    }
    if let (Some(fc), Some(x)) = (&tr.forecast, fc_x)
        && x <= x1
    {
        f.vline(x, "#c62828", &format!("alarm {}", day(fc.date)));
    }
    if let Some(d) = tr.crossed_on {
        let x = days(d);
        if x >= 0.0 && x <= x1 {
            f.vline(x, "#c62828", &format!("crossed on {}", day(d)));
        }
    }
    for (x, v, lo, hi, p) in &pts {
        // The point's colour is its parameter's verdict in that test (the joint's when the
        // result has none per parameter): the same status the badge and the alerts use.
        let param_status = match tr.param {
            Param::Viscous => p.fit.viscous_status,
            Param::Dry => p.fit.dry_status,
        }
        .unwrap_or(p.fit.status);
        let fill = match param_status {
            Status::Alarm => "#c62828",
            Status::Watch => "#f9a825",
            Status::Ok => "#2e7d32",
            Status::Unknown => "#757575",
        };
        let label = format!(
            "{} {}: {} [{}, {}] {}",
            day(p.recorded_at),
            p.trace_id,
            fmt_num(*v),
            fmt_num(*lo),
            fmt_num(*hi),
            param_status
        );
        f.point_with_interval(*x, *v, *lo, *hi, fill, &label);
    }
    let x_labels = vec![
        (0.0, day(t0)),
        (last_x, day(pts.last().map_or(t0, |p| p.4.recorded_at))),
    ];
    let title = format!("{serial} {joint} {} over time", tr.param.as_str());
    let desc = describe(
        joint,
        tr,
        &pts.iter()
            .map(|p| (p.4.recorded_at, p.1))
            .collect::<Vec<_>>(),
    );
    let svg = f.finish(&title, &desc, &x_labels, unit);
    format!(
        "<figure>{svg}<figcaption>{}</figcaption></figure>",
        esc(&desc)
    )
}

/// The chart in words (its `<desc>` and caption).
fn describe(joint: &str, tr: &ParamTrend, pts: &[(DateTime<Utc>, f64)]) -> String {
    let mut d = format!(
        "{} {} of {joint}: {} tests",
        tr.param.as_str(),
        if tr.param == Param::Viscous {
            "damping"
        } else {
            "friction"
        },
        pts.len()
    );
    if let (Some(a), Some(b)) = (pts.first(), pts.last()) {
        let _ = write!(
            d,
            " from {} ({}) to {} ({})",
            day(a.0),
            fmt_num(a.1),
            day(b.0),
            fmt_num(b.1)
        );
    }
    if let Some(b) = tr.baseline {
        let _ = write!(d, "; Table 4 baseline {}", fmt_num(b));
    }
    match &tr.trend {
        Some(t) if t.significant => {
            let _ = write!(
                d,
                "; trend {} per day (95 % interval {} to {})",
                fmt_num(t.slope_per_day),
                fmt_num(t.slope_ci95[0]),
                fmt_num(t.slope_ci95[1])
            );
        }
        _ => d.push_str("; no trend"),
    }
    if let Some(f) = &tr.forecast {
        let r = |x: Option<DateTime<Utc>>| x.map_or("open".to_owned(), day);
        let _ = write!(
            d,
            "; forecast to reach the alarm band ({}) on {} (95 % interval {} to {})",
            fmt_num(f.threshold),
            day(f.date),
            r(f.date_ci95[0]),
            r(f.date_ci95[1])
        );
    }
    d.push('.');
    d
}

async fn pantograph_page(
    State(st): State<AppState>,
    user: WebUser,
    Path(raw): Path<String>,
) -> PageResult {
    let serial = Serial::parse("serial", &raw).map_err(AppError::from)?;
    if !st.store.pantograph_exists(serial.as_str()).await? {
        return Err(AppError::NotFound(format!("no pantograph `{serial}`")).into());
    }
    let points = st.store.serial_history(serial.as_str()).await?;
    // Each joint's health as fleet health and the alerts see it (issue 15).
    let states = st.store.joint_states(serial.as_str()).await?;
    let mut by_joint: BTreeMap<String, Vec<JointPoint>> = BTreeMap::new();
    for p in points {
        by_joint.entry(p.fit.joint.clone()).or_default().push(p);
    }
    let watch = DriftThresholds::default().watch;
    let mut body = format!("<h1>Pantograph {}</h1>", esc(serial.as_str()));
    let live = st
        .store
        .list_alerts(&AlertFilter {
            live: true,
            ..AlertFilter::default()
        })
        .await?;
    for a in live.iter().filter(|a| a.serial == serial.as_str()) {
        let _ = write!(
            body,
            r#"<p>{} alert on {}: {} — <a href="/alerts">alerts</a></p>"#,
            sev_badge(a.severity),
            esc(&a.joint),
            esc(&a.reason)
        );
    }
    let _ = write!(
        body,
        "<p class=\"note\">Each point is one test with its 95 % interval; the green band is Table 4's \
         watch band around the baseline (dashed green), red dashed lines the alarm band, the blue line \
         the robust trend (grey dashed: no trend), the red marker the forecast date of reaching the alarm band.</p>"
    );
    for (joint, history) in &by_joint {
        let last = history.last();
        let (bv, bd) = match last {
            Some(p) => match st.store.get_fit(&p.trace_id).await? {
                Some(f) => health::baselines(&f.result, joint),
                None => (None, None),
            },
            None => (None, None),
        };
        let state = states.iter().find(|s| &s.joint == joint);
        let _ = write!(
            body,
            r#"<section id="joint-{}"><h2>{} {}</h2>"#,
            esc(joint),
            esc(joint),
            badge(state.map(|s| s.status).or(last.map(|p| p.fit.status)))
        );
        match state {
            Some(s) if s.informed => {
                let _ = write!(
                    body,
                    r#"<p>Status from the {} test of {} (<a href="/traces/{}">{}</a>); tests that could not inform this joint change nothing.</p>"#,
                    esc(&s.kind),
                    day(s.recorded_at),
                    seg(&s.trace_id),
                    esc(&s.trace_id)
                );
            }
            _ => {
                if let Some(p) = last {
                    let _ = write!(
                        body,
                        r#"<p>No test has informed this joint yet; latest test {} (<a href="/traces/{}">{}</a>).</p>"#,
                        day(p.recorded_at),
                        seg(&p.trace_id),
                        esc(&p.trace_id)
                    );
                }
            }
        }
        for (param, b) in [(Param::Viscous, bv), (Param::Dry, bd)] {
            let tr = health::param_trend(history, param, b, st.alerts.alarm);
            let unit = match param {
                Param::Viscous => "viscous",
                Param::Dry => "dry",
            };
            body.push_str(&param_chart(
                serial.as_str(),
                joint,
                history,
                &tr,
                unit,
                watch,
            ));
        }
        body.push_str("</section>");
    }
    if by_joint.is_empty() {
        body.push_str("<p>No fitted tests yet.</p>");
    }
    Ok(page(serial.as_str(), Some(&user), &body))
}

// ------------------------------------------------------------------ trace

async fn trace_page(
    State(st): State<AppState>,
    user: WebUser,
    Path(id): Path<String>,
) -> PageResult {
    let meta = st
        .store
        .get_trace(&id)
        .await?
        .ok_or_else(|| AppError::NotFound(format!("no trace `{id}`")))?;
    let fit = st.store.get_fit(&id).await?;
    let mut body = format!("<h1>Trace {}</h1>", esc(&meta.trace_id));
    let _ = write!(
        body,
        r#"<p>{} test of {} on pantograph {} (vehicle {}), recorded {}.</p>"#,
        esc(&meta.kind),
        // A lift or a quadrangle swing tests the assembly, not one joint (issue 18).
        match (meta.joint.as_deref(), meta.kind.as_str()) {
            (Some(j), _) => format!("joint {}", esc(j)),
            (None, "lift") => "the whole pantograph".to_owned(),
            (None, "quadrangle_swing") => "the lower quadrangle (J1, J2, J2′, J3)".to_owned(),
            (None, _) => "the pantograph".to_owned(),
        },
        meta.serial.as_deref().map_or("—".to_owned(), |s| format!(
            r#"<a href="/pantographs/{}">{}</a>"#,
            seg(s),
            esc(s)
        )),
        esc(&meta.vehicle_id),
        meta.recorded_at.format("%Y-%m-%d %H:%M UTC")
    );
    let Some(fit) = fit else {
        body.push_str("<p>Not fitted yet.</p>");
        return Ok(page(&meta.trace_id, Some(&user), &body));
    };
    let _ = write!(
        body,
        "<p>Fit {} by <code>{}</code>, status {}.</p>",
        fit.id,
        esc(&fit.model_version),
        badge(fit.status)
    );
    body.push_str("<table><thead><tr><th>joint</th><th>parameter</th><th>value</th><th>95 % interval</th><th>baseline</th><th>status</th></tr></thead><tbody>");
    for j in fit
        .result
        .get("joints")
        .and_then(|v| v.as_array())
        .into_iter()
        .flatten()
    {
        for p in ["viscous", "dry"] {
            let g = |k: &str| j.pointer(&format!("/{p}/{k}")).and_then(|v| v.as_f64());
            let _ = write!(
                body,
                "<tr><td>{}</td><td>{p}</td><td>{}</td><td>[{}, {}]</td><td>{}</td><td>{}</td></tr>",
                esc(j.get("joint").and_then(|v| v.as_str()).unwrap_or("")),
                g("value").map_or("—".into(), fmt_num),
                g("ci95/0").map_or("—".into(), fmt_num),
                g("ci95/1").map_or("—".into(), fmt_num),
                g("baseline").map_or("—".into(), fmt_num),
                esc(j
                    .pointer(&format!("/{p}/status"))
                    .and_then(|v| v.as_str())
                    .unwrap_or("")),
            );
        }
    }
    body.push_str("</tbody></table>");
    body.push_str(&residual_finding(&fit.result));
    body.push_str(&trace_charts(&st, &meta).await);
    Ok(page(&meta.trace_id, Some(&user), &body))
}

/// The residual block in words.
fn residual_finding(result: &serde_json::Value) -> String {
    let Some(r) = result.get("residual") else {
        return String::new();
    };
    let num = |k: &str| {
        r.get(k)
            .and_then(|v| v.as_f64())
            .map_or("—".into(), fmt_num)
    };
    // Each named effect with its parameters (a value and its `_ci95` as "v [lo, hi]").
    let effects: Vec<String> = r
        .get("effects")
        .and_then(|v| v.as_array())
        .into_iter()
        .flatten()
        .filter_map(|e| {
            let name = esc(e.get("name")?.as_str()?);
            let params = e.get("params").and_then(|p| p.as_object());
            let shown: Vec<String> = params
                .into_iter()
                .flatten()
                .filter(|(k, _)| !k.ends_with("_ci95"))
                .map(|(k, v)| {
                    let ci = params
                        .and_then(|p| p.get(&format!("{k}_ci95")))
                        .and_then(|c| Some((c.get(0)?.as_f64()?, c.get(1)?.as_f64()?)))
                        .map_or(String::new(), |(lo, hi)| {
                            format!(" [{}, {}]", fmt_num(lo), fmt_num(hi))
                        });
                    let v = v
                        .as_f64()
                        .map_or_else(|| esc(v.as_str().unwrap_or("")), fmt_num);
                    format!("{} {v}{ci}", esc(k))
                })
                .collect();
            Some(if shown.is_empty() {
                name
            } else {
                format!("{name} ({})", shown.join(", "))
            })
        })
        .collect();
    let finding = if !effects.is_empty() {
        format!("effects found: {}", effects.join(", "))
    } else if let Some(v) = r.get("verdict").and_then(|v| v.as_str()) {
        format!("verdict: {}", esc(v))
    } else {
        "no structure left that an effect would explain".to_owned()
    };
    let correlates: Vec<String> = r
        .get("correlates_with")
        .and_then(|v| v.as_array())
        .into_iter()
        .flatten()
        .filter_map(|p| {
            let name = p.get(0)?.as_str()?;
            let c = p.get(1)?.as_f64()?;
            Some(format!("{} ({c:+.2})", esc(name)))
        })
        .collect();
    let follows = if correlates.is_empty() {
        String::new()
    } else {
        format!(" The residual follows {}.", correlates.join(", "))
    };
    let excess = r
        .get("excess_ratio")
        .and_then(|v| v.as_f64())
        .map_or(String::new(), |x| {
            format!(" Residual RMS {} × the sensor noise.", fmt_num(x))
        });
    // A lift whose residual shows a model error (issue 16): the joints above are withheld.
    let withheld = r
        .get("joints_withheld")
        .and_then(|v| v.as_str())
        .map_or(String::new(), |w| {
            format!(
                r#"<p id="withheld" class="alarm"><b>Joint statuses withheld:</b> {}.</p>"#,
                esc(w)
            )
        });
    let holdout_note = r
        .get("holdout_note")
        .and_then(|v| v.as_str())
        .map_or(String::new(), |w| {
            format!(r#"<p id="holdout-note">{}.</p>"#, esc(w))
        });
    // The residual's autocorrelation (lift fits): after, and before where an effect was named.
    let acf = |k: &str| -> Vec<(f64, f64)> {
        r.get(k)
            .and_then(|v| v.as_array())
            .into_iter()
            .flatten()
            .filter_map(|p| Some((p.get(0)?.as_f64()?, p.get(1)?.as_f64()?)))
            .collect()
    };
    let (after, before) = (acf("autocorrelation"), acf("autocorrelation_before"));
    let acf_table = if after.is_empty() {
        String::new()
    } else {
        let mut t =
            String::from(r#"<table id="acf"><thead><tr><th>lag (s)</th><th>autocorrelation</th>"#);
        if !before.is_empty() {
            t.push_str("<th>before the effect</th>");
        }
        t.push_str("</tr></thead><tbody>");
        for (i, (lag, a)) in after.iter().enumerate() {
            let _ = write!(t, "<tr><td>{}</td><td>{a:+.3}</td>", fmt_num(*lag));
            if let Some((_, b)) = before.get(i) {
                let _ = write!(t, "<td>{b:+.3}</td>");
            }
            t.push_str("</tr>");
        }
        t.push_str("</tbody></table>");
        t
    };
    format!(
        r#"<h2>Residual finding</h2><p id="finding">{finding}. RMSE before {} / after {}; held-out {} / {}.{excess}{follows}</p>{withheld}{holdout_note}{acf_table}"#,
        num("rmse_before"),
        num("rmse_after"),
        num("holdout_rmse_before"),
        num("holdout_rmse_after")
    )
}

/// Measured vs model and the residual. The model curve comes from re-running the fit on the
/// stored samples off the runtime (5–30 ms; the same code and data give the stored fit).
async fn trace_charts(st: &AppState, meta: &crate::store::TraceMeta) -> String {
    if !matches!(meta.kind.as_str(), "pendulum" | "slider") {
        return format!(
            "<p>The measured and model curves of a {} test are drawn by <code>pantowatch fit TRACE --plot</code>; this page lists its parameters.</p>",
            esc(&meta.kind)
        );
    }
    let channels = match st.store.get_samples(&meta.trace_id).await {
        Ok(Some(c)) => c,
        Ok(None) => return "<p>The samples are missing.</p>".into(),
        Err(e) => {
            tracing::error!(error = %e, "samples unreadable");
            return "<p>The samples could not be read.</p>".into();
        }
    };
    let doc = match stored_doc(meta, channels) {
        Ok(d) => d,
        Err(e) => return format!("<p>{}</p>", esc(&e)),
    };
    let run = tokio::task::spawn_blocking(move || {
        let (test, _) = doc.joint_test().map_err(|e| e.to_string())?;
        let (_, o) = crate::fitting::fit_with_outcome(&doc, &DriftThresholds::default())
            .map_err(|e| e.to_string())?;
        Ok::<_, String>((test, o))
    })
    .await;
    let (test, o) = match run {
        Ok(Ok(x)) => x,
        Ok(Err(e)) => return format!("<p>No model curve: {}</p>", esc(&e)),
        Err(e) => return format!("<p>No model curve: {}</p>", esc(&e.to_string())),
    };
    let end = (o.start + o.n_fit)
        .min(test.t_s.len())
        .min(o.start + o.model_y.len());
    let t = &test.t_s[o.start..end];
    let y = &test.y[o.start..end];
    let m = &o.model_y[..end - o.start];
    let idx = thin(t.len(), 1200);
    let (lo, hi) = y
        .iter()
        .chain(m)
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let (t0, t1) = (
        t.first().copied().unwrap_or(0.0),
        t.last().copied().unwrap_or(1.0),
    );
    let mut f = Frame::new((t0, t1), (lo, hi));
    f.polyline(
        &idx.iter().map(|&i| (t[i], y[i])).collect::<Vec<_>>(),
        "#757575",
        1.0,
        false,
    );
    f.polyline(
        &idx.iter().map(|&i| (t[i], m[i])).collect::<Vec<_>>(),
        "#1565c0",
        1.0,
        false,
    );
    let xl = vec![(t0, format!("{t0:.2} s")), (t1, format!("{t1:.2} s"))];
    let desc = format!(
        "Measured {} (wide grey) and the fitted model (thin blue) over {} samples from {:.2} s to {:.2} s; RMSE {} {}.",
        test.unit,
        t.len(),
        t0,
        t1,
        fmt_num(o.rmse),
        test.unit
    );
    let top = f.finish("Measured vs model", &desc, &xl, test.unit);
    let res: Vec<f64> = m.iter().zip(y).map(|(a, b)| a - b).collect();
    let (rlo, rhi) = res
        .iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), v| {
            (a.min(*v), b.max(*v))
        });
    let mut g = Frame::new((t0, t1), (rlo, rhi));
    g.hline(0.0, "#999", true);
    g.polyline(
        &idx.iter().map(|&i| (t[i], res[i])).collect::<Vec<_>>(),
        "#c62828",
        1.0,
        false,
    );
    let rdesc = format!(
        "Residual (model − measured) from {} to {} {}.",
        fmt_num(rlo),
        fmt_num(rhi),
        test.unit
    );
    let bottom = g.finish("Residual", &rdesc, &xl, test.unit);
    format!(
        "<h2>Measured vs model</h2><figure>{top}<figcaption>{}</figcaption></figure><figure>{bottom}<figcaption>{}</figcaption></figure>",
        esc(&desc),
        esc(&rdesc)
    )
}

// ------------------------------------------------------------------ alerts

#[derive(Deserialize, Default)]
struct AlertsQuery {
    done: Option<String>,
}

async fn alerts_page(
    State(st): State<AppState>,
    user: WebUser,
    Query(q): Query<AlertsQuery>,
) -> PageResult {
    let all = st.store.list_alerts(&AlertFilter::default()).await?;
    let can_ack = user.key.role >= Role::Writer;
    let mut body = String::from("<h1>Alerts</h1>");
    if let Some(id) = q.done.as_deref().and_then(|d| d.parse::<i64>().ok()) {
        let _ = write!(
            body,
            r#"<p class="msg" role="status">Alert {id} acknowledged.</p>"#
        );
    }
    if !can_ack {
        body.push_str(
            "<p class=\"note\">Signed in with a reader key: acknowledging needs a writer key.</p>",
        );
    }
    let mut live: Vec<&Alert> = all
        .iter()
        .filter(|a| a.state != AlertState::Resolved)
        .collect();
    live.sort_by(|a, b| b.severity.cmp(&a.severity).then(a.id.cmp(&b.id)));
    body.push_str(r#"<table id="alerts"><thead><tr><th>id</th><th>severity</th><th>state</th><th>pantograph</th><th>joint</th><th>vehicle</th><th>why</th><th>opened</th><th>acknowledged</th><th></th></tr></thead><tbody>"#);
    for a in live.iter().copied().chain(
        all.iter()
            .filter(|a| a.state == AlertState::Resolved)
            .take(50),
    ) {
        let action = if a.state == AlertState::Open && can_ack {
            format!(
                r#"<form method="post" action="/alerts/{id}/acknowledge"><label for="note-{id}">Note</label> <input id="note-{id}" name="note" size="24"> <button type="submit">Acknowledge</button></form>"#,
                id = a.id
            )
        } else {
            String::new()
        };
        let ack = match (&a.acknowledged_by, a.acknowledged_at) {
            (Some(w), Some(t)) => format!("{} {}", esc(w), day(t)),
            _ => "—".into(),
        };
        let _ = write!(
            body,
            r#"<tr id="alert-{}" data-state="{}"><td>{}</td><td>{}</td><td>{}</td><td><a href="/pantographs/{}">{}</a></td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td><td>{}</td></tr>"#,
            a.id,
            a.state,
            a.id,
            sev_badge(a.severity),
            a.state,
            seg(&a.serial),
            esc(&a.serial),
            esc(&a.joint),
            esc(a.vehicle_id.as_deref().unwrap_or("—")),
            esc(&a.reason),
            day(a.opened_at),
            ack,
            action
        );
    }
    body.push_str("</tbody></table>");
    Ok(page("Alerts", Some(&user), &body))
}

#[derive(Deserialize)]
struct AckForm {
    #[serde(default)]
    note: String,
}

async fn acknowledge_form(
    State(st): State<AppState>,
    user: WebUser,
    Path(raw): Path<String>,
    body: Bytes,
) -> PageResult {
    let id = parse_id(&raw)?;
    if user.key.role < Role::Writer {
        return Err(AppError::Forbidden("acknowledging needs a writer key".into()).into());
    }
    let f: AckForm = form(&body)?;
    acknowledge(&st, &user.key, id, &f.note).await?;
    let mut r = StatusCode::SEE_OTHER.into_response();
    if let Ok(v) = HeaderValue::from_str(&format!("/alerts?done={id}")) {
        r.headers_mut().insert(LOCATION, v);
    }
    r.headers_mut()
        .insert(CONTENT_TYPE, HeaderValue::from_static("text/plain"));
    Ok(r)
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
