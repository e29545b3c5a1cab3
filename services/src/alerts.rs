//! Alerts raised after each fit: a joint at `watch`/`alarm`, or forecast to reach its alarm band
//! within the horizon, opens or escalates its one live alert; a later test back in band resolves it.
//! A lift that names a fault of its H channel opens a sensor finding instead (`H sensor`).
//!
//! A joint's state is the one fleet health shows (`Store::joint_states`: each parameter from the
//! latest test that informed it, the joint at the worst of them); only the test that decides it
//! acts, so a test that cannot inform a joint, or an older test fitted late, changes nothing.
//! The horizon is counted from the deciding test's date. The store writes alert, event and webhook outbox rows
//! in one transaction.

use chrono::{DateTime, Utc};
use pantowatch_models::report::{EffectResult, FitResult};

use crate::health::{self, Param, ParamTrend};
use crate::store::{NewAlert, RaiseOutcome, Severity, Status, Store, StoreError};

mod evidence;
pub use evidence::{EffectEvidence, Evidence, JointEvidence, StaticForceEvidence, TestDueEvidence};

/// What the alert rules need.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AlertOptions {
    /// Forecast horizon after the latest test, days.
    pub horizon_days: f64,
    /// Drift alarm band (× baseline).
    pub alarm: [f64; 2],
}

impl Default for AlertOptions {
    fn default() -> Self {
        AlertOptions {
            horizon_days: 90.0,
            alarm: [0.5, 2.0],
        }
    }
}

/// What the hook did for one joint.
#[derive(Debug, Clone, PartialEq)]
pub enum AlertAction {
    Raised(Box<RaiseOutcome>),
    Resolved { alert_id: i64 },
}

/// The earliest forecast crossing within `horizon_days` of `last_test`, if any.
pub fn crossing_within(
    trends: &[ParamTrend],
    last_test: DateTime<Utc>,
    horizon_days: f64,
) -> Option<(Param, DateTime<Utc>)> {
    trends
        .iter()
        .filter_map(|t| Some((t.param, t.forecast.as_ref()?.date)))
        .filter(|(_, d)| ((*d - last_test).num_seconds() as f64) / 86_400.0 <= horizon_days)
        .min_by_key(|(_, d)| *d)
}

/// Runs the alert rules for every joint of a fit just written for `trace_id`.
pub async fn after_fit(
    store: &Store,
    trace_id: &str,
    fit_id: i64,
    result: &FitResult,
    opts: &AlertOptions,
) -> Result<Vec<AlertAction>, StoreError> {
    let Some(meta) = store.get_trace(trace_id).await? else {
        return Ok(Vec::new());
    };
    let Some(serial) = meta.serial.as_deref() else {
        return Ok(Vec::new());
    };
    // The joints' health as fleet health shows it (`joint_latest`, written in the fit's
    // transaction): the rules act on the same state, so alerts and fleet health agree.
    let states = store.joint_states(serial).await?;
    let mut actions = Vec::new();
    for j in &result.joints {
        let joint = j.joint.as_str();
        let Some(state) = states.iter().find(|s| s.joint == joint) else {
            continue;
        };
        if state.trace_id != trace_id {
            // This test does not decide the joint: it did not inform the parameter that sets
            // its status (a lift for J5's viscous damping), or it is an older test fitted late.
            // It changes nothing — no raise, no resolve (issue 15).
            continue;
        }
        let history = store.joint_history(serial, joint).await?;
        let Some(last) = history.iter().find(|p| p.trace_id == trace_id) else {
            continue;
        };
        let (bv, bd) = health::baselines(result, joint);
        let trends: Vec<ParamTrend> = Param::BOTH
            .iter()
            .map(|&p| {
                let b = if p == Param::Viscous { bv } else { bd };
                health::param_trend(&history, p, b, opts.alarm)
            })
            .collect();
        let status = state.status;
        let crossing = crossing_within(&trends, last.recorded_at, opts.horizon_days);
        let (severity, reason) = match (status, crossing) {
            (Status::Alarm, _) => (Some(Severity::Alarm), "status alarm".to_owned()),
            (Status::Watch, _) => (Some(Severity::Watch), "status watch".to_owned()),
            (_, Some((p, d))) => (
                Some(Severity::Watch),
                format!(
                    "{} forecast to reach its alarm band on {} (within {} days)",
                    p.as_str(),
                    d.format("%Y-%m-%d"),
                    opts.horizon_days
                ),
            ),
            _ => (None, String::new()),
        };
        if let Some(severity) = severity {
            let reason = match (severity, crossing) {
                (_, Some((p, d))) if status != Status::Ok && status != Status::Unknown => format!(
                    "{reason}; {} forecast to reach the alarm band on {}",
                    p.as_str(),
                    d.format("%Y-%m-%d")
                ),
                _ => reason,
            };
            let evidence = Evidence::Joint(Box::new(JointEvidence {
                model_version: last.model_version.clone(),
                fit_id,
                trace_id: trace_id.to_owned(),
                recorded_at: last.recorded_at,
                status,
                viscous: j.viscous.clone(),
                dry: j.dry.clone(),
                residual: result.residual.clone(),
                rmse: result.rmse.clone(),
                trends,
                horizon_days: opts.horizon_days,
                tests: history.len(),
            }))
            .to_json();
            let new = NewAlert {
                serial: serial.to_owned(),
                joint: joint.to_owned(),
                vehicle_id: Some(meta.vehicle_id.clone()),
                severity,
                reason,
                evidence,
                trace_id: trace_id.to_owned(),
            };
            actions.push(raise_logged(store, &new).await?);
        } else if status == Status::Ok {
            let note = format!("back in band: test {trace_id}");
            if let Some(a) = store
                .resolve_joint_alert(serial, joint, trace_id, &note)
                .await?
            {
                tracing::info!(alert = a.id, serial, joint, "alert resolved");
                actions.push(AlertAction::Resolved { alert_id: a.id });
            }
        }
    }
    if meta.kind == "lift" {
        actions.extend(lift_sensor_finding(store, &meta, serial, trace_id, fit_id, result).await?);
    }
    if meta.kind == crate::trace::STATIC_FORCE {
        actions.extend(gauge_findings(store, &meta, serial, trace_id, fit_id, result).await?);
    }
    actions.extend(static_force_finding(store, &meta, serial, trace_id, fit_id).await?);
    crate::evidence::refresh_trends(store, serial).await?;
    actions.extend(tests_due(store, &meta, serial, trace_id).await?);
    Ok(actions)
}

/// A workshop test due (issue 37, point 2): after every fit of the pantograph, each joint whose
/// evidence (its older parameter's latest informing test) is older than the type's
/// `[test_plan] max_evidence_age_days` at the pantograph's newest test opens (or updates) one
/// `watch` alert named `<joint> test due` (a pseudo-joint, as `static force`: the same alert
/// table, lifecycle and webhooks); a later fit that leaves it young enough resolves it. Judged
/// at the newest test's date, not the wall clock: a lift that could not see J5 is the moment
/// J5's old evidence matters, and a pantograph no test touches raises nothing new.
async fn tests_due(
    store: &Store,
    meta: &crate::store::TraceMeta,
    serial: &str,
    trace_id: &str,
) -> Result<Vec<AlertAction>, StoreError> {
    let Some(ev) = crate::evidence::at_newest_test(store, serial).await? else {
        return Ok(Vec::new());
    };
    let mut actions = Vec::new();
    for j in &ev.joints {
        let name = crate::evidence::test_due_alert(&j.joint);
        match (j.test_due, j.age_days, j.max_age_days) {
            (true, Some(age), Some(max)) => {
                let reason = format!(
                    "test due: {}'s evidence is {age:.0} days old (allowed {max:.0}); viscous {}, dry {}",
                    j.joint, j.viscous.summary, j.dry.summary
                );
                let evidence = Evidence::TestDue(Box::new(TestDueEvidence {
                    trace_id: trace_id.to_owned(),
                    at: ev.at,
                    due: j.clone(),
                }))
                .to_json();
                let new = finding_alert(serial, &name, meta, trace_id, reason, evidence);
                actions.push(raise_logged(store, &new).await?);
            }
            _ => {
                let note = format!("evidence young enough after test {trace_id}");
                if let Some(a) = store
                    .resolve_joint_alert(serial, &name, trace_id, &note)
                    .await?
                {
                    tracing::info!(alert = a.id, serial, joint = %j.joint, "test due resolved");
                    actions.push(AlertAction::Resolved { alert_id: a.id });
                }
            }
        }
    }
    Ok(actions)
}

/// The predicted static contact force against the type's limits (issue 20, point 2): a 95 %
/// band that leaves them opens (or updates) one `watch` alert named
/// [`STATIC_FORCE_ALERT`](crate::static_force::STATIC_FORCE_ALERT) — a pseudo-joint, as the
/// lift's `H sensor` finding is, so the alert table, its events and webhooks need no change; a
/// later fit whose prediction is back within the limits resolves it. Recomputed after every fit of
/// the pantograph (any test can change a parameter it uses). A type without a static-force model
/// has none; a prediction the models cannot compute is logged and raises nothing.
async fn static_force_finding(
    store: &Store,
    meta: &crate::store::TraceMeta,
    serial: &str,
    trace_id: &str,
    fit_id: i64,
) -> Result<Vec<AlertAction>, StoreError> {
    use crate::static_force::{PredictError, STATIC_FORCE_ALERT, predict};
    let v = match predict(store, serial).await {
        Ok(v) => v,
        Err(PredictError::Store(e)) => return Err(e),
        Err(PredictError::NoModel(_) | PredictError::NoPantograph(_)) => return Ok(Vec::new()),
        Err(e) => {
            tracing::warn!(serial, error = %e, "static force not predicted");
            return Ok(Vec::new());
        }
    };
    if let Some(first) = v.findings.first() {
        let reason = format!(
            "static force: predicted band leaves the limits at {} height(s); first {} at H = {:.2} m \
             ({:.1} N against {:.1} N)",
            v.findings.len(),
            first.what,
            first.height_m,
            first.value_n,
            first.limit_n
        );
        let evidence = Evidence::StaticForce(Box::new(StaticForceEvidence {
            fit_id,
            trace_id: trace_id.to_owned(),
            recorded_at: meta.recorded_at,
            findings: v.findings,
            parameters: v.parameters,
            spring: Some(v.spring),
            limits: v.limits,
        }))
        .to_json();
        let new = finding_alert(serial, STATIC_FORCE_ALERT, meta, trace_id, reason, evidence);
        return Ok(vec![raise_logged(store, &new).await?]);
    }
    let note = format!("static force within the limits after test {trace_id}");
    if let Some(a) = store
        .resolve_joint_alert(serial, STATIC_FORCE_ALERT, trace_id, &note)
        .await?
    {
        tracing::info!(alert = a.id, serial, "static force finding resolved");
        return Ok(vec![AlertAction::Resolved { alert_id: a.id }]);
    }
    Ok(Vec::new())
}

/// Raise (or update) `new`, logging a newly opened or escalated alert.
/// A `watch` alert on a pantograph-level finding (a pseudo-joint such as `H sensor` or
/// `static force`) raised from test `trace_id`.
fn finding_alert(
    serial: &str,
    finding: &str,
    meta: &crate::store::TraceMeta,
    trace_id: &str,
    reason: String,
    evidence: serde_json::Value,
) -> NewAlert {
    NewAlert {
        serial: serial.to_owned(),
        joint: finding.to_owned(),
        vehicle_id: Some(meta.vehicle_id.clone()),
        severity: Severity::Watch,
        reason,
        evidence,
        trace_id: trace_id.to_owned(),
    }
}

/// The evidence of a finding named by `result`'s residual loop (effect `e`).
fn effect_evidence(
    result: &FitResult,
    fit_id: i64,
    trace_id: &str,
    meta: &crate::store::TraceMeta,
    e: &EffectResult,
) -> serde_json::Value {
    Evidence::Effect(Box::new(EffectEvidence {
        model_version: result.fit.model_version.clone(),
        fit_id,
        trace_id: trace_id.to_owned(),
        recorded_at: meta.recorded_at,
        effect: e.clone(),
        residual: result.residual.clone(),
    }))
    .to_json()
}

async fn raise_logged(store: &Store, new: &NewAlert) -> Result<AlertAction, StoreError> {
    let out = store.raise_alert(new).await?;
    if !matches!(out, RaiseOutcome::Updated(_)) {
        let a = out.alert();
        tracing::info!(alert = a.id, serial = %new.serial, joint = %new.joint, severity = %a.severity, "alert raised");
    }
    Ok(AlertAction::Raised(Box::new(out)))
}

/// The alert name of a force gauge's zero found off (`sensor_offset` named by a `static_force`
/// fit; one live alert per pantograph).
pub const GAUGE_ZERO: &str = "force gauge";
/// The alert name of a drive spring whose rate differs from the type's (`spring_rate` named by a
/// `static_force` fit; one live alert per pantograph).
pub const SPRING_RATE: &str = "spring rate";

/// What a `static_force` fit's residual loop names (issue 20) is a finding on the pantograph, not
/// on a joint: `sensor_offset` (the gauge's zero, N) opens (or updates) one `watch` alert named
/// [`GAUGE_ZERO`] — the measuring chain; `spring_rate` (the drive characteristic's slope × the
/// type's) one named [`SPRING_RATE`] — the pantograph's spring. A later gauge test of the
/// pantograph that does not name one, with a residual the model explains, resolves its alert.
async fn gauge_findings(
    store: &Store,
    meta: &crate::store::TraceMeta,
    serial: &str,
    trace_id: &str,
    fit_id: i64,
    result: &FitResult,
) -> Result<Vec<AlertAction>, StoreError> {
    let residual = &result.residual;
    let explained = residual.verdict.is_none();
    let mut actions = Vec::new();
    for (finding, effect, key, unit) in [
        (GAUGE_ZERO, "sensor_offset", "offset_n", "N"),
        (SPRING_RATE, "spring_rate", "rate_factor", "× the type's"),
    ] {
        match residual.effects.iter().find(|e| e.name == effect) {
            Some(e) => {
                let value = match (e.param(key), e.ci95(key)) {
                    (Some(v), Some([lo, hi])) => format!(" {v:.3} {unit} [{lo:.3}, {hi:.3}]"),
                    (Some(v), _) => format!(" {v:.3} {unit}"),
                    _ => String::new(),
                };
                let what = if finding == GAUGE_ZERO {
                    "the force gauge's zero is off — check the gauge; not a joint finding"
                } else {
                    "the drive spring's rate differs from the type's — check the spring; not a \
                     joint finding"
                };
                let reason = format!("{effect}{value}: {what}");
                let evidence = effect_evidence(result, fit_id, trace_id, meta, e);
                let new = finding_alert(serial, finding, meta, trace_id, reason, evidence);
                actions.push(raise_logged(store, &new).await?);
            }
            None if explained => {
                let note = format!("no {effect} in gauge test {trace_id}");
                if let Some(a) = store
                    .resolve_joint_alert(serial, finding, trace_id, &note)
                    .await?
                {
                    tracing::info!(alert = a.id, serial, finding, "gauge finding resolved");
                    actions.push(AlertAction::Resolved { alert_id: a.id });
                }
            }
            None => {}
        }
    }
    Ok(actions)
}

/// The alert name of a lift's height-channel finding (one live alert per pantograph).
pub const LIFT_H_SENSOR: &str = "H sensor";

/// A named fault of a lift's H channel (issue 16, point 4: `sensor_delay`, `sensor_offset`) is a
/// finding about
/// the measuring chain, not about a joint: it opens (or updates) one `watch` alert named
/// [`LIFT_H_SENSOR`], which joint health does not show; the joints of that fit come from the
/// fit with the delay taken out. The next lift of the pantograph that names no sensor fault,
/// with a residual the model explains, resolves it. Only lifts: a single-joint test's fitted
/// zero is routine (the contract reports a significant one as `sensor_offset`), and its channel
/// is another sensor.
async fn lift_sensor_finding(
    store: &Store,
    meta: &crate::store::TraceMeta,
    serial: &str,
    trace_id: &str,
    fit_id: i64,
    result: &FitResult,
) -> Result<Vec<AlertAction>, StoreError> {
    let residual = &result.residual;
    let named: Option<&EffectResult> = residual
        .effects
        .iter()
        .find(|e| matches!(e.name.as_str(), "sensor_delay" | "sensor_offset"));
    if let Some(e) = named {
        let is_offset = e.name == "sensor_offset";
        let ci = e.ci95(if is_offset { "offset_m" } else { "delay_s" });
        let reason = match (e.param("delay_s"), e.param("offset_m"), ci) {
            (_, Some(b), Some([lo, hi])) if is_offset => format!(
                "sensor_offset: H reads {:+.1} mm [{:+.1}, {:+.1}] from the static start — check the \
                 height sensor's zero; not a joint finding",
                b * 1e3,
                lo * 1e3,
                hi * 1e3
            ),
            _ if is_offset => "sensor_offset: H's zero is off — check the height sensor's zero; \
                               not a joint finding"
                .to_owned(),
            (Some(d), _, Some([lo, hi])) => format!(
                "sensor_delay: H lags the drive inputs by {:.1} ms [{:.1}, {:.1}] — check the height \
                 sensor and logger; not a joint finding",
                d * 1e3,
                lo * 1e3,
                hi * 1e3
            ),
            _ => "sensor_delay: H lags the drive inputs — check the height sensor and logger; \
                  not a joint finding"
                .to_owned(),
        };
        let evidence = effect_evidence(result, fit_id, trace_id, meta, e);
        let new = finding_alert(serial, LIFT_H_SENSOR, meta, trace_id, reason, evidence);
        return Ok(vec![raise_logged(store, &new).await?]);
    }
    if residual.verdict.is_none() {
        let note = format!("no sensor fault in lift {trace_id}");
        if let Some(a) = store
            .resolve_joint_alert(serial, LIFT_H_SENSOR, trace_id, &note)
            .await?
        {
            tracing::info!(alert = a.id, serial, "H sensor finding resolved");
            return Ok(vec![AlertAction::Resolved { alert_id: a.id }]);
        }
    }
    Ok(Vec::new())
}
