//! The fleet: every pantograph by risk — alarm first, then watch, then the earliest forecast
//! date of reaching the alarm band — with its live alerts.

use std::collections::HashMap;

use axum::extract::State;
use axum::http::HeaderName;
use chrono::{DateTime, Utc};
use maud::{Markup, html};

use crate::alerts::Evidence;
use crate::api::auth::WebUser;
use crate::api::error::AppError;
use crate::api::state::AppState;
use crate::evidence::FleetPlanEntry;
use crate::store::{Alert, AlertFilter, FleetFilter, JobCounts, Page, Status};
use crate::web::error::WebQuery;
use crate::web::layout::{age_bar, badge};
use crate::web::pages::pantograph::AtQuery;
use crate::web::{PageResult, day, seg, signed_in_page};

/// Earliest forecast crossing in a live alert's evidence (typed: `alerts::Evidence`); none
/// when the evidence has no forecast or does not read.
fn alert_forecast(a: &Alert) -> Option<DateTime<Utc>> {
    Evidence::of(a).ok()?.earliest_forecast()
}

pub async fn fleet_page(
    State(st): State<AppState>,
    user: WebUser,
    WebQuery(q): WebQuery<AtQuery>,
) -> PageResult {
    let jobs = st.store.job_counts().await;
    let fitting = matches!(&jobs, Ok(c) if c.queued + c.running > 0);
    let body = match jobs {
        Ok(jobs) => fleet(&st, jobs, q.at.as_deref()).await,
        Err(e) => Err(e.into()),
    };
    let mut page = signed_in_page(&user, "Fleet", body)?;
    if fitting {
        // The browser reloads the page while fits are queued (the demo's fleet filling in).
        page.headers_mut()
            .insert(HeaderName::from_static("refresh"), RELOAD_SECS.into());
    }
    Ok(page)
}

/// How often the fleet page reloads itself while fits are queued or running.
const RELOAD_SECS: u16 = 10;

/// While fits are queued or running (the demo filling its fleet, a re-fit): how many of the
/// queue's jobs are done, read from the store.
fn fits_in_progress(c: JobCounts) -> Markup {
    let total = c.queued + c.running + c.done + c.failed;
    html! {
        @if c.queued + c.running > 0 {
            p.msg #fits-in-progress role="status" {
                "Fitting: " (c.done + c.failed) " of " (total) " fits done ("
                (c.running) " running, " (c.queued) " queued"
                @if c.failed > 0 { ", " (c.failed) " failed" }
                "). The fleet fills in as they complete; this page reloads every "
                (RELOAD_SECS) " s."
            }
        }
    }
}

async fn fleet(st: &AppState, jobs: JobCounts, at: Option<&str>) -> Result<Markup, AppError> {
    let at = crate::api::plan::parse_at(at)?;
    // Each pantograph's oldest evidence and best next test (issue 37), from `param_evidence`
    // (grouped and kept until a fit changes it, as `GET /v1/fleet/plan` reads it).
    let plan = st.plan_cache.fleet_plan(&st.store, at, usize::MAX).await?;
    let plans: HashMap<&str, &FleetPlanEntry> =
        plan.tests.iter().map(|e| (e.serial.as_str(), e)).collect();
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
    let n = |s: Status| rows.iter().filter(|r| r.0.worst_status == Some(s)).count();
    Ok(html! {
        h1 { "Fleet" }
        (fits_in_progress(jobs))
        p {
            (rows.len()) " pantographs: " (n(Status::Alarm)) " alarm, " (n(Status::Watch))
            " watch, " (n(Status::Ok)) " ok, " (n(Status::Unknown)) " unknown. "
            (live.len()) " alerts open or acknowledged."
        }
        table #fleet {
            caption {
                "Pantographs by risk: alarm first, then watch, then the earliest forecast date of \
                 reaching the alarm band. Oldest evidence: the age of the joint evidence that is \
                 oldest, against the age allowed before a workshop test is due; next test: the \
                 one that buys most (the pantograph's page ranks them)."
            }
            thead {
                tr {
                    th { "#" } th { "serial" } th { "vehicle" } th { "worst" }
                    th { "joints not ok" } th { "alerts" } th { "forecast alarm" } th { "last test" }
                    th { "oldest evidence" } th { "next test" }
                }
            }
            tbody {
                @for (i, (r, mine, forecast)) in rows.iter().enumerate() {
                    tr data-serial=(r.serial) {
                        td { (i + 1) }
                        td { a href={ "/pantographs/" (seg(&r.serial)) } { (r.serial) } }
                        td { (r.vehicle_id.as_deref().unwrap_or("—")) }
                        td { (badge(r.worst_status)) }
                        td {
                            @for (k, j) in r.not_ok.iter().enumerate() {
                                @if k > 0 { ", " }
                                (j.joint) " " (badge(Some(j.status)))
                            }
                        }
                        td {
                            @if mine.is_empty() { "—" } @else { a href="/alerts" { (mine.len()) } }
                        }
                        td { (forecast.map_or("—".to_owned(), day)) }
                        td { (r.last_test.map_or("—".to_owned(), day)) }
                        @match plans.get(r.serial.as_str()) {
                            Some(e) => {
                                td.oldest {
                                    (age_bar(e.oldest_evidence_days, e.oldest_allowed_days))
                                    @if !e.tests_due.is_empty() {
                                        " " span.badge.alarm { "due: " (e.tests_due.join(", ")) }
                                    }
                                }
                                td.next {
                                    @match e.test.joint.as_deref() {
                                        Some(j) => { "swing " (j) },
                                        None => { (e.test.kind) },
                                    }
                                    (format!(" (P past watch {:.0} %)", 100.0 * e.test.p_watch))
                                }
                            },
                            None => { td { "—" } td { "—" } },
                        }
                    }
                }
            }
        }
    })
}
