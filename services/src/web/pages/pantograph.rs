//! One pantograph: each joint's status badge and, per parameter, its tests over time with their
//! intervals, the Table 4 and alarm bands, the trend and its forecast. A chart draws only the
//! tests that informed its parameter ([`Param::of`]); each point carries its parameter's status
//! in that test as the status class the badges use, so the latest points' colours and the
//! joint's badge (the worst parameter from the latest test that informed it) agree.

use std::collections::BTreeMap;
use std::fmt::Write;

use axum::extract::State;
use chrono::{DateTime, Utc};
use maud::{Markup, html};
use pantowatch_models::drift::DriftThresholds;
use pantowatch_models::plan::PlanItem;

use crate::api::auth::WebUser;
use crate::api::error::AppError;
use crate::api::state::AppState;
use crate::evidence::{EvidenceParam, PantographEvidence, Standing};
use crate::health::{self, Param, ParamTrend};
use crate::ids::Serial;
use crate::store::{AlertFilter, JointPoint, Status};
use crate::web::error::{WebPath, WebQuery};
use crate::web::layout::{age_bar, badge, sev_badge};
use crate::web::svg::{Frame, fmt_num, legend_entry};
use crate::web::{PageResult, day, seg, signed_in_page};

/// A parameter's status in one test: its own verdict, or the joint's when the result has none
/// per parameter — the status fleet health and the alerts read.
fn param_status(p: &JointPoint, param: Param) -> Status {
    match param {
        Param::Viscous => p.fit.viscous_status,
        Param::Dry => p.fit.dry_status,
    }
    .unwrap_or(p.fit.status)
}

fn param_chart(
    serial: &str,
    joint: &str,
    history: &[JointPoint],
    tr: &ParamTrend,
    watch: [f64; 2],
) -> Markup {
    let Some(t0) = history.first().map(|p| p.recorded_at) else {
        return html! {};
    };
    let days = |t: DateTime<Utc>| (t - t0).num_seconds() as f64 / 86_400.0;
    let pts: Vec<(f64, f64, f64, f64, &JointPoint)> = history
        .iter()
        .filter_map(|p| {
            let (v, lo, hi) = tr.param.of(p)?;
            Some((days(p.recorded_at), v, lo, hi, p))
        })
        .collect();
    let param = tr.param.as_str();
    if pts.is_empty() {
        return html! {
            p.chart data-param=(param) { "No test has informed " (param) " of " (joint) " yet." }
        };
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
        let status = param_status(p, tr.param);
        let label = format!(
            "{} {}: {} [{}, {}] {status}",
            day(p.recorded_at),
            p.trace_id,
            fmt_num(*v),
            fmt_num(*lo),
            fmt_num(*hi),
        );
        f.point((*x, *v, *lo, *hi), status, &p.trace_id, &label);
    }
    let x_labels = vec![
        (0.0, day(t0)),
        (last_x, day(pts.last().map_or(t0, |p| p.4.recorded_at))),
    ];
    let title = format!("{serial} {joint} {param} over time");
    let desc = describe(
        joint,
        tr,
        &pts.iter()
            .map(|p| (p.4.recorded_at, p.1))
            .collect::<Vec<_>>(),
    );
    html! {
        figure.chart data-param=(param) {
            (f.finish(&title, &desc, &x_labels, param))
            figcaption { (desc) }
        }
    }
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

/// Class of a raising gauge reading's marker on the static-force chart (one `<g>` per reading).
pub const GAUGE_RAISE_CLASS: &str = "gauge-raise";
/// Class of a lowering gauge reading's marker.
pub const GAUGE_LOWER_CLASS: &str = "gauge-lower";
const RAISE_COLOR: &str = "#1565c0";
const LOWER_COLOR: &str = "#e65100";

/// The predicted static contact force (issue 20): raising and lowering with their 95 % bands,
/// the frictionless curve, and the type's limits (nominal, min, max) over strip height; with
/// the latest force-gauge measurement's readings over it when the pantograph has one (raising:
/// filled blue dots, lowering: hollow orange squares, as stored, not refitted; less the gauge's
/// zero when its fit named one, `sensor_offset`). The drive line is the type's, or its slope ×
/// the `spring_rate` the latest gauge record named (issue 39, point 5).
fn static_force_chart(
    v: &crate::static_force::StaticForceView,
    measured: Option<&crate::static_force::GaugeMeasurement>,
) -> Markup {
    let h = &v.heights_m;
    let (Some(&h0), Some(&h1)) = (h.first(), h.last()) else {
        return html! {};
    };
    let xy =
        |ys: &[f64]| -> Vec<(f64, f64)> { h.iter().copied().zip(ys.iter().copied()).collect() };
    let all = [
        &v.raise_lo_n,
        &v.lower_hi_n,
        &v.limits.min_n,
        &v.limits.max_n,
    ];
    // The gauge reads F + b: its points are drawn as F, the zero it named taken off.
    let zero_n = measured.and_then(|m| m.zero_n).unwrap_or(0.0);
    let gauge_f = measured
        .into_iter()
        .flat_map(|m| m.raise.iter().chain(&m.lower))
        .map(|p| p[1] - zero_n);
    let ylo = all
        .iter()
        .flat_map(|s| s.iter())
        .copied()
        .chain(gauge_f.clone())
        .fold(f64::INFINITY, f64::min);
    let yhi = all
        .iter()
        .flat_map(|s| s.iter())
        .copied()
        .chain(gauge_f)
        .fold(f64::NEG_INFINITY, f64::max);
    let gauge_h = measured
        .into_iter()
        .flat_map(|m| m.raise.iter().chain(&m.lower))
        .map(|p| p[0]);
    let (x0, x1) = gauge_h.fold((h0, h1), |(a, b), h| (a.min(h), b.max(h)));
    let mut f = Frame::new((x0, x1), (ylo, yhi));
    f.band(
        &xy(&v.raise_lo_n),
        &xy(&v.raise_hi_n),
        "#bbdefb",
        "raising, 95 % band",
    );
    f.band(
        &xy(&v.lower_lo_n),
        &xy(&v.lower_hi_n),
        "#ffe0b2",
        "lowering, 95 % band",
    );
    f.polyline(&xy(&v.limits.min_n), "#c62828", 1.5, true);
    f.polyline(&xy(&v.limits.max_n), "#c62828", 1.5, true);
    f.polyline(&xy(&v.limits.nominal_n), "#2e7d32", 1.0, true);
    f.polyline(&xy(&v.frictionless_n), "#9e9e9e", 1.0, true);
    f.polyline(&xy(&v.raise_n), RAISE_COLOR, 2.0, false);
    f.polyline(&xy(&v.lower_n), LOWER_COLOR, 2.0, false);
    let mut legend = vec![
        (
            "band:#bbdefb",
            "raising, predicted with its 95 % band".to_owned(),
        ),
        (
            "band:#ffe0b2",
            "lowering, predicted with its 95 % band".to_owned(),
        ),
        ("dash:#c62828", "the type's limits".to_owned()),
    ];
    if let Some(m) = measured {
        for (pts, class, color, open, branch) in [
            (&m.raise, GAUGE_RAISE_CLASS, RAISE_COLOR, false, "raising"),
            (&m.lower, GAUGE_LOWER_CLASS, LOWER_COLOR, true, "lowering"),
        ] {
            for (i, p) in pts.iter().enumerate() {
                let mut label = format!(
                    "gauge {} {branch} reading {}: H {} m, F {} N",
                    m.trace_id,
                    i + 1,
                    fmt_num(p[0]),
                    fmt_num(p[1] - zero_n)
                );
                if zero_n != 0.0 {
                    let _ = write!(
                        label,
                        " (read {} N, less the gauge's zero {} N)",
                        fmt_num(p[1]),
                        fmt_num(zero_n)
                    );
                }
                f.marker((p[0], p[1] - zero_n), class, color, open, &label);
            }
        }
        legend.push((
            "dot:#1565c0",
            format!("raising, gauge ({} readings)", m.raise.len()),
        ));
        legend.push((
            "square:#e65100",
            format!("lowering, gauge ({} readings)", m.lower.len()),
        ));
    }
    let i0 = 0;
    let i1 = h.len() - 1;
    let mut desc = format!(
        "Predicted static contact force of {} from {} m to {} m: raising {} N to {} N, lowering {} N \
         to {} N (95 % bands shaded); limits {} N to {} N at {} m",
        v.serial,
        fmt_num(h0),
        fmt_num(h1),
        fmt_num(v.raise_n[i0]),
        fmt_num(v.raise_n[i1]),
        fmt_num(v.lower_n[i0]),
        fmt_num(v.lower_n[i1]),
        fmt_num(v.limits.min_n[i0]),
        fmt_num(v.limits.max_n[i0]),
        fmt_num(h0),
    );
    if let Some([lo, hi]) = v.spring.rate_factor_ci95 {
        let _ = write!(
            desc,
            "; drive spring rate × {} [{}, {}] as gauge record {} named it",
            fmt_num(v.spring.rate_factor),
            fmt_num(lo),
            fmt_num(hi),
            v.spring.trace_id.as_deref().unwrap_or("?")
        );
    }
    if v.findings.is_empty() {
        desc.push_str("; every band within the limits.");
    } else {
        let _ = write!(
            desc,
            "; the band leaves the limits at {} point(s), first {} at {} m.",
            v.findings.len(),
            v.findings[0].what,
            fmt_num(v.findings[0].height_m)
        );
    }
    if let Some(m) = measured {
        let _ = write!(
            desc,
            " Measured by force gauge on {} (test {}, resolution {} N): {} raising and {} lowering \
             readings, drawn over the prediction.",
            day(m.recorded_at),
            m.trace_id,
            fmt_num(m.gauge_resolution_n),
            m.raise.len(),
            m.lower.len()
        );
        if let Some(b) = m.zero_n {
            let _ = write!(
                desc,
                " The gauge's zero was off by {} N (its fit named sensor_offset): the readings are \
                 drawn less it.",
                fmt_num(b)
            );
        }
    }
    let x_labels = vec![
        (x0, format!("{} m", fmt_num(x0))),
        (x1, format!("{} m", fmt_num(x1))),
    ];
    html! {
        section id="static-force" {
            h2 { "Static contact force" }
            figure.chart data-param="static_force" {
                (f.finish(&format!("{} static contact force over height", v.serial), &desc, &x_labels, "N"))
                p.legend {
                    @for (swatch, text) in &legend { (legend_entry(swatch, text)) " " }
                }
                figcaption { (desc) }
            }
            p.note {
                "Quasi-static strip force for raising (blue) and lowering (orange) with the drive at \
                 the lift-test line (its slope × the spring rate a force-gauge record named, if \
                 one did), from each joint's dry friction of the latest test that informed it \
                 (others at Table 4); shaded: 95 % bands; red dashed: the type's limits; green \
                 dashed: nominal; grey dashed: without friction."
                @if let Some(m) = measured {
                    " Dots (raising) and hollow squares (lowering): the force gauge's readings of "
                    a href={ "/traces/" (seg(&m.trace_id)) } { (m.trace_id) }
                    @if m.zero_n.is_some() { " less the gauge's zero its fit named." } @else { " as uploaded." }
                }
            }
        }
    }
}

/// A page's `?at=` (RFC 3339): the time evidence ages are read at (default now).
#[derive(Debug, Default, serde::Deserialize)]
#[serde(deny_unknown_fields)]
pub struct AtQuery {
    pub at: Option<String>,
}

pub async fn pantograph_page(
    State(st): State<AppState>,
    user: WebUser,
    WebPath(raw): WebPath<String>,
    WebQuery(q): WebQuery<AtQuery>,
) -> PageResult {
    signed_in_page(&user, &raw, pantograph(&st, &raw, q.at.as_deref()).await)
}

/// What each joint rests on (issue 37): a row per joint with its evidence's age at a glance,
/// each parameter's test, interval then and now; then the ranked workshop tests.
fn evidence_section(ev: &PantographEvidence, plan: &[PlanItem]) -> Markup {
    let param = |p: &EvidenceParam| {
        html! {
            @if let Some(t) = &p.test {
                a href={ "/traces/" (seg(&t.trace_id)) } { (t.kind) } " " (day(t.recorded_at)) ": "
                (fmt_num(t.value)) " [" (fmt_num(t.ci95[0])) ", " (fmt_num(t.ci95[1])) "] → now ["
                (fmt_num(p.now.ci95[0])) ", " (fmt_num(p.now.ci95[1])) "] "
            } @else {
                "never measured "
            }
            (badge(Some(p.status_now)))
            @if p.standing == Standing::Uncertain { " now uncertain" }
        }
    };
    html! {
        section #evidence {
            h2 { "What each joint rests on" }
            p.note {
                "At " (day(ev.at)) ": per parameter the test that last informed it, its 95 % \
                 interval then and now — widened by the time since at the joint's trend or the \
                 fleet's wear rate. The bar: the evidence's age against the age the type allows \
                 before a workshop test is due (red: due)."
            }
            table #evidence-table {
                thead { tr { th { "joint" } th { "age" } th { "viscous" } th { "dry" } th { "test due" } } }
                tbody {
                    @for j in &ev.joints {
                        tr data-joint=(j.joint) {
                            td { (j.joint) }
                            td { (age_bar(j.age_days, j.max_age_days)) }
                            td { (param(&j.viscous)) }
                            td { (param(&j.dry)) }
                            td { @if j.test_due { span.badge.alarm { "due" } } @else { "—" } }
                        }
                    }
                }
            }
            h2 { "Next workshop tests" }
            p.note {
                "Ranked by what each test buys: the probability that a joint it informs has \
                 crossed its watch band unseen, times the share of that uncertainty the test \
                 removes (the information its kind of test gave, from the fits' own intervals)."
            }
            table #plan-table {
                thead { tr { th { "#" } th { "test" } th { "buys" } th { "P(past watch)" } th { "P(past alarm)" } th { "information" } } }
                tbody {
                    @for (i, t) in plan.iter().enumerate() {
                        tr data-kind=(t.kind) data-joint=(t.joint.as_deref().unwrap_or("")) {
                            td { (i + 1) }
                            td {
                                @match t.joint.as_deref() {
                                    Some(j) => { "swing " (j) " (" (t.kind) ")" },
                                    None => { (t.kind) " of the whole pantograph" },
                                }
                            }
                            td { (format!("{:.3}", t.buys)) }
                            td { (format!("{:.0} %", 100.0 * t.p_watch)) }
                            td { (format!("{:.0} %", 100.0 * t.p_alarm)) }
                            td { (format!("{:.1} bits", t.info_bits)) }
                        }
                    }
                }
            }
            @if plan.is_empty() { p { "No test kind has informed these joints yet." } }
        }
    }
}

async fn pantograph(st: &AppState, raw: &str, at: Option<&str>) -> Result<Markup, AppError> {
    let serial = Serial::parse("serial", raw)?;
    if !st.store.pantograph_exists(serial.as_str()).await? {
        return Err(AppError::NotFound(format!("no pantograph `{serial}`")));
    }
    let at = crate::api::plan::parse_at(at)?;
    let evidence = match crate::evidence::load(&st.store, serial.as_str(), at).await {
        Ok((ev, plan)) => evidence_section(&ev, &plan),
        Err(crate::evidence::EvidenceError::Store(e)) => return Err(e.into()),
        Err(_) => html! {},
    };
    let points = st.store.serial_history(serial.as_str()).await?;
    // Each joint's health as fleet health and the alerts see it (issue 15).
    let states = st.store.joint_states(serial.as_str()).await?;
    let mut by_joint: BTreeMap<String, Vec<JointPoint>> = BTreeMap::new();
    for p in points {
        by_joint.entry(p.fit.joint.clone()).or_default().push(p);
    }
    let watch = DriftThresholds::default().watch;
    let live = st
        .store
        .list_alerts(&AlertFilter {
            live: true,
            ..AlertFilter::default()
        })
        .await?;
    // The static force prediction; a type without its model shows none, a model failure says so.
    let measured = crate::static_force::latest_measurement(&st.store, serial.as_str()).await?;
    let static_force = match crate::static_force::predict(&st.store, serial.as_str()).await {
        Ok(v) => static_force_chart(&v, measured.as_ref()),
        Err(crate::static_force::PredictError::Store(e)) => return Err(e.into()),
        Err(crate::static_force::PredictError::Model(e)) => html! {
            section id="static-force" { h2 { "Static contact force" } p { "Not computed: " (e) } }
        },
        Err(_) => html! {},
    };
    let mut joints = Vec::new();
    for (joint, history) in &by_joint {
        let last = history.last();
        let (bv, bd) = match last {
            Some(p) => match st.store.get_fit(&p.trace_id).await? {
                Some(f) => health::baselines(&f.result()?, joint),
                None => (None, None),
            },
            None => (None, None),
        };
        let state = states.iter().find(|s| &s.joint == joint);
        let charts: Vec<Markup> = [(Param::Viscous, bv), (Param::Dry, bd)]
            .into_iter()
            .map(|(param, b)| {
                let tr = health::param_trend(history, param, b, st.alerts.alarm);
                param_chart(serial.as_str(), joint, history, &tr, watch)
            })
            .collect();
        joints.push(html! {
            section id={ "joint-" (joint) } {
                h2 { (joint) " " (badge(state.map(|s| s.status).or(last.map(|p| p.fit.status)))) }
                @match (state, last) {
                    (Some(s), _) if s.informed => p {
                        "Status from the " (s.kind) " test of " (day(s.recorded_at)) " ("
                        a href={ "/traces/" (seg(&s.trace_id)) } { (s.trace_id) }
                        "); tests that could not inform this joint change nothing."
                    },
                    (_, Some(p)) => p {
                        "No test has informed this joint yet; latest test " (day(p.recorded_at)) " ("
                        a href={ "/traces/" (seg(&p.trace_id)) } { (p.trace_id) } ")."
                    },
                    _ => {},
                }
                @for c in &charts { (c) }
            }
        });
    }
    Ok(html! {
        h1 { "Pantograph " (serial.as_str()) }
        @for a in live.iter().filter(|a| a.serial == serial.as_str()) {
            p {
                (sev_badge(a.severity)) " alert on " (a.joint) ": " (a.reason) " — "
                a href="/alerts" { "alerts" }
            }
        }
        p.note {
            "Each point is one test that informed the parameter, with its 95 % interval, in the \
             colour of its status; the green band is Table 4's watch band around the baseline \
             (dashed green), red dashed lines the alarm band, the blue line the robust trend (grey \
             dashed: no trend), the red marker the forecast date of reaching the alarm band."
        }
        (evidence)
        @for j in &joints { (j) }
        @if by_joint.is_empty() { p { "No fitted tests yet." } }
        (static_force)
    })
}
