//! Alerts, their event history, webhook subscriptions and the delivery outbox: the types both
//! backends share, the row mappers and the webhook payload written with each alert change.
//!
//! Contract (both backends): one live (not resolved) alert per (serial, joint); a raise opens,
//! escalates (watch → alarm, back to `open`) or updates it; opened/escalated/resolved changes
//! write their webhook deliveries in the same transaction as the alert row and its event.

use chrono::{DateTime, Utc};
use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::{Result, RowExt, StoreError, parse_enum};

text_enum!(
    /// How bad an alert is.
    Severity {
        /// Drifting, or forecast to reach the alarm band within the horizon.
        Watch = "watch",
        /// Out of tolerance.
        Alarm = "alarm",
    }
);
text_enum!(
    /// Life cycle of an alert.
    AlertState {
        /// Raised, nobody has taken it yet.
        Open = "open",
        /// Someone has it (who, note).
        Acknowledged = "acknowledged",
        /// Back in band (automatic) or closed by hand.
        Resolved = "resolved",
    }
);
text_enum!(
    /// Life cycle of a webhook delivery.
    DeliveryState {
        /// Waiting for its (next) attempt.
        Pending = "pending",
        /// A 2xx answer was received.
        Delivered = "delivered",
        /// Attempts exhausted or the subscription was deleted.
        Failed = "failed",
    }
);

/// An alert to raise for a joint (from the worker after a fit).
#[derive(Debug, Clone, PartialEq)]
pub struct NewAlert {
    pub serial: String,
    pub joint: String,
    pub vehicle_id: Option<String>,
    pub severity: Severity,
    /// One line: why (`status alarm`, `forecast crosses the alarm band on …`).
    pub reason: String,
    /// Model version, parameters with intervals, residual finding, trends, trace id.
    pub evidence: serde_json::Value,
    pub trace_id: String,
}

/// A stored alert.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct Alert {
    pub id: i64,
    pub serial: String,
    pub joint: String,
    pub vehicle_id: Option<String>,
    pub severity: Severity,
    pub state: AlertState,
    pub reason: String,
    /// Model version, fit id, parameters with intervals and baseline, residual finding, trends
    /// and forecast, trace id of the test that raised or last updated the alert.
    #[schema(value_type = Object)]
    pub evidence: serde_json::Value,
    /// The test that raised or last updated the alert.
    pub trace_id: String,
    pub opened_at: DateTime<Utc>,
    pub updated_at: DateTime<Utc>,
    pub acknowledged_by: Option<String>,
    pub acknowledged_at: Option<DateTime<Utc>>,
    pub resolved_by: Option<String>,
    pub resolved_at: Option<DateTime<Utc>>,
}

/// One entry of an alert's history.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct AlertEvent {
    pub id: i64,
    pub alert_id: i64,
    pub at: DateTime<Utc>,
    /// `opened`, `escalated`, `updated`, `acknowledged`, `resolved`.
    pub kind: String,
    /// Severity after the event.
    pub severity: Severity,
    /// `system` (the worker) or the API key that acted.
    pub actor: String,
    pub note: String,
    pub trace_id: Option<String>,
}

/// What a raise did.
#[derive(Debug, Clone, PartialEq)]
pub enum RaiseOutcome {
    Opened(Alert),
    /// Severity went up (watch → alarm): back to `open`, webhooks told.
    Escalated(Alert),
    /// Same or lower severity: evidence refreshed, severity kept.
    Updated(Alert),
}

impl RaiseOutcome {
    pub fn alert(&self) -> &Alert {
        match self {
            RaiseOutcome::Opened(a) | RaiseOutcome::Escalated(a) | RaiseOutcome::Updated(a) => a,
        }
    }
}

/// What acknowledge/resolve did.
#[derive(Debug, Clone, PartialEq)]
pub enum Transition {
    Done(Alert),
    NotFound,
    /// Not allowed from the alert's state (resolved, or acknowledged twice).
    Refused(Alert),
}

/// Filter of [`super::Store::list_alerts`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct AlertFilter {
    pub state: Option<AlertState>,
    pub severity: Option<Severity>,
    pub vehicle_id: Option<String>,
    /// Only alerts that are not resolved (ignored when `state` is given).
    pub live: bool,
}

/// A webhook subscription (never its secret).
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct Webhook {
    pub id: i64,
    pub url: String,
    pub severities: Vec<Severity>,
    pub created_at: DateTime<Utc>,
    pub deleted_at: Option<DateTime<Utc>>,
}

/// One delivery of one alert change to one subscription (the outbox row and its log).
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct Delivery {
    /// Also the `Idempotency-Key` header of every attempt.
    pub id: i64,
    pub webhook_id: i64,
    pub alert_id: i64,
    /// `alert.opened`, `alert.escalated`, `alert.resolved`.
    pub event: String,
    pub state: DeliveryState,
    pub attempts: i64,
    pub next_attempt_at: DateTime<Utc>,
    /// HTTP status of the last attempt, if it got an answer.
    pub last_status: Option<i64>,
    pub last_error: Option<String>,
    pub created_at: DateTime<Utc>,
    pub updated_at: DateTime<Utc>,
    pub delivered_at: Option<DateTime<Utc>>,
}

/// A delivery claimed for an attempt: what to send where, and the secret to sign with.
#[derive(Debug, Clone, PartialEq)]
pub struct DueDelivery {
    pub id: i64,
    pub url: String,
    pub secret: String,
    /// The body, byte for byte what is signed and sent.
    pub payload: String,
    /// Attempts including this one.
    pub attempts: i64,
}

/// How an attempt ended.
#[derive(Debug, Clone, PartialEq)]
pub enum AttemptResult {
    Delivered {
        status: i64,
    },
    /// Try again at `next_at`.
    Retry {
        status: Option<i64>,
        error: String,
        next_at: DateTime<Utc>,
    },
    /// Give up.
    Failed {
        status: Option<i64>,
        error: String,
    },
}

/// Webhook event names.
pub const EVENT_OPENED: &str = "alert.opened";
pub const EVENT_ESCALATED: &str = "alert.escalated";
pub const EVENT_RESOLVED: &str = "alert.resolved";

/// The JSON body of a webhook delivery.
pub(crate) fn payload(event: &str, alert: &Alert) -> Result<String> {
    serde_json::to_string(&serde_json::json!({
        "event": event,
        "occurred_at": alert.updated_at,
        "alert": alert,
    }))
    .map_err(|e| StoreError::Invalid(format!("webhook payload: {e}")))
}

/// `watch,alarm` ↔ severities.
pub(crate) fn severities_text(s: &[Severity]) -> String {
    s.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(",")
}

pub(crate) fn parse_severities(s: &str) -> Result<Vec<Severity>> {
    s.split(',')
        .filter(|p| !p.is_empty())
        .map(parse_enum)
        .collect()
}

pub(crate) fn alert_from<R: RowExt>(r: &R) -> Result<Alert> {
    let ev = r.text("evidence_json")?;
    Ok(Alert {
        id: r.int("id")?,
        serial: r.text("serial")?,
        joint: r.text("joint")?,
        vehicle_id: r.opt_text("vehicle_id")?,
        severity: parse_enum(&r.text("severity")?)?,
        state: parse_enum(&r.text("state")?)?,
        reason: r.text("reason")?,
        evidence: serde_json::from_str(&ev)
            .map_err(|e| StoreError::Corrupt(format!("evidence_json: {e}")))?,
        trace_id: r.text("trace_id")?,
        opened_at: r.ts("opened_at")?,
        updated_at: r.ts("updated_at")?,
        acknowledged_by: r.opt_text("acknowledged_by")?,
        acknowledged_at: r.opt_ts("acknowledged_at")?,
        resolved_by: r.opt_text("resolved_by")?,
        resolved_at: r.opt_ts("resolved_at")?,
    })
}

pub(crate) fn event_from<R: RowExt>(r: &R) -> Result<AlertEvent> {
    Ok(AlertEvent {
        id: r.int("id")?,
        alert_id: r.int("alert_id")?,
        at: r.ts("at")?,
        kind: r.text("kind")?,
        severity: parse_enum(&r.text("severity")?)?,
        actor: r.text("actor")?,
        note: r.text("note")?,
        trace_id: r.opt_text("trace_id")?,
    })
}

pub(crate) fn webhook_from<R: RowExt>(r: &R) -> Result<Webhook> {
    Ok(Webhook {
        id: r.int("id")?,
        url: r.text("url")?,
        severities: parse_severities(&r.text("severities")?)?,
        created_at: r.ts("created_at")?,
        deleted_at: r.opt_ts("deleted_at")?,
    })
}

pub(crate) fn delivery_from<R: RowExt>(r: &R) -> Result<Delivery> {
    Ok(Delivery {
        id: r.int("id")?,
        webhook_id: r.int("webhook_id")?,
        alert_id: r.int("alert_id")?,
        event: r.text("event")?,
        state: parse_enum(&r.text("state")?)?,
        attempts: r.int("attempts")?,
        next_attempt_at: r.ts("next_attempt_at")?,
        last_status: r.opt_int("last_status")?,
        last_error: r.opt_text("last_error")?,
        created_at: r.ts("created_at")?,
        updated_at: r.ts("updated_at")?,
        delivered_at: r.opt_ts("delivered_at")?,
    })
}

/// Which live alert a resolve targets.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Target<'a> {
    Id(i64),
    /// The live alert of (serial, joint), if any.
    Pair(&'a str, &'a str),
}

/// Accepts the severities a subscription asks for (at least one, no repeats).
pub fn check_severities(s: &[Severity]) -> Result<()> {
    if s.is_empty() {
        return Err(StoreError::InvalidField {
            field: "severities".into(),
            message: "is empty".into(),
        });
    }
    let mut v = s.to_vec();
    v.sort();
    v.dedup();
    if v.len() != s.len() {
        return Err(StoreError::InvalidField {
            field: "severities".into(),
            message: "repeat".into(),
        });
    }
    Ok(())
}
