//! Storage layer: one [`Store`] over SQLite (a file path, the embedded default) or PostgreSQL
//! (a `postgres://` URL) holding traces, fits, the durable fit-job queue and API keys.
//!
//! Both backends implement the same crate-private `Backend` trait, so their signatures cannot
//! drift; [`Store`] is an enum that dispatches to them (no `dyn`, no `async_trait`). Migrations
//! are embedded per backend (`migrations/sqlite`, `migrations/postgres`) and run on connect.
//! Every statement binds its values; the only dynamic SQL is test-database DDL.
//!
//! Semantics shared by both backends:
//! - An upload ([`Store::insert_trace`]) writes vehicle, pantograph, mount, trace and fit job in
//!   one transaction: all or nothing. Idempotent on `trace_id` + `content_sha256`.
//! - The *current fit* of a trace is its most recently written fit (any model version); a
//!   joint's *latest status* is the current fit of the latest-recorded trace that fitted it.
//! - A worker *holds* a job while the job is `running` under its worker id: once another worker
//!   has reclaimed an expired lease, the first worker's `complete`/`fail` are no-ops.

/// Each joint's health as `joint_latest` keeps it (issue 15): for each parameter (viscous,
/// dry), the latest fit that *informed* it ([`JointFit::informs`]: a value, identified, a
/// verdict other than `unknown`); the joint's status is the worst of those, its row the fit that
/// decides it; a joint no fit has informed is its latest fit's (`unknown`). A test that cannot
/// inform a parameter — a lift for J5's viscous damping — never changes that parameter's status.
/// `$where` narrows the traces (`t.serial = $1` for the per-fit refresh,
/// [`JOINT_LATEST_REFRESH_SQL`]; `t.serial IS NOT NULL` for the tests' window over every
/// pantograph); migration 0005 holds the same rule as text.
macro_rules! joint_state_select {
    ($where:literal) => {
        concat!("SELECT serial, joint, trace_id, fit_id, recorded_at, (informs = 1) AS identifiable, status FROM (
        SELECT p.*, ROW_NUMBER() OVER (PARTITION BY serial, joint
                        ORDER BY informs DESC,
                                 CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2
                                             WHEN 'ok' THEN 1 ELSE 0 END DESC,
                                 recorded_at DESC, trace_id DESC) AS rn2
        FROM (
            SELECT o.*, ROW_NUMBER() OVER (PARTITION BY serial, joint, param
                            ORDER BY informs DESC, recorded_at DESC, trace_id DESC) AS rn
            FROM (
            SELECT t.serial, j.joint, 'viscous' AS param, t.trace_id, f.id AS fit_id, t.recorded_at,
                   CASE WHEN j.viscous IS NOT NULL AND COALESCE(j.viscous_informed, j.identifiable)
                             AND COALESCE(j.viscous_status, j.status) <> 'unknown' THEN 1 ELSE 0 END AS informs,
                   CASE WHEN j.viscous IS NOT NULL THEN COALESCE(j.viscous_status, j.status)
                        ELSE 'unknown' END AS status
            FROM traces t
            JOIN fits f ON f.trace_id = t.trace_id
                       AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
            JOIN fit_joints j ON j.fit_id = f.id
            WHERE ", $where, "
            UNION ALL
            SELECT t.serial, j.joint, 'dry' AS param, t.trace_id, f.id AS fit_id, t.recorded_at,
                   CASE WHEN j.dry IS NOT NULL AND COALESCE(j.dry_informed, j.identifiable)
                             AND COALESCE(j.dry_status, j.status) <> 'unknown' THEN 1 ELSE 0 END AS informs,
                   CASE WHEN j.dry IS NOT NULL THEN COALESCE(j.dry_status, j.status)
                        ELSE 'unknown' END AS status
            FROM traces t
            JOIN fits f ON f.trace_id = t.trace_id
                       AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
            JOIN fit_joints j ON j.fit_id = f.id
            WHERE ", $where, "
            ) o
        ) p WHERE rn = 1
    ) x WHERE rn2 = 1")
    };
}

mod fault;
pub mod keys;
mod postgres;
pub mod samples;
mod sqlite;
#[cfg(test)]
mod tests;

use std::str::FromStr;
use std::time::Duration;

use chrono::{DateTime, Datelike, SubsecRound, Utc};
use serde::{Deserialize, Serialize};

pub use fault::DbFault;
pub use postgres::PgStore;
pub use samples::{Channels, CodecError};
pub use sqlite::SqliteStore;

/// Result type of the storage layer.
pub type Result<T, E = StoreError> = std::result::Result<T, E>;

/// Everything that can go wrong in the storage layer.
#[derive(Debug, thiserror::Error)]
pub enum StoreError {
    /// The database refused or failed (connection, constraint, I/O).
    #[error("database error: {0}")]
    Db(#[from] sqlx::Error),
    /// Embedded migrations could not be applied.
    #[error("migration error: {0}")]
    Migrate(#[from] sqlx::migrate::MigrateError),
    /// A samples blob could not be encoded or decoded.
    #[error(transparent)]
    Codec(#[from] CodecError),
    /// A caller's value the store cannot accept, named as the caller spelled it
    /// (`vehicle_id`, `channels`): the API answers 422 naming `field`.
    #[error("invalid input: `{field}`: {message}")]
    InvalidField { field: String, message: String },
    /// A value this code built (a fit result, an alert's evidence, a generated key) that the
    /// store cannot accept: a server fault, never the caller's.
    #[error("invalid input: {0}")]
    Invalid(String),
    /// A row holds a value this code does not understand.
    #[error("unexpected data in the database: {0}")]
    Corrupt(String),
    /// The OS random number generator failed.
    #[error("random number generator: {0}")]
    Rng(String),
    /// A blocking task (codec) panicked or was cancelled.
    #[error("background task failed: {0}")]
    Task(String),
}

impl From<getrandom::Error> for StoreError {
    fn from(e: getrandom::Error) -> Self {
        StoreError::Rng(e.to_string())
    }
}

/// How the connection pool waits.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PoolOptions {
    /// Longest wait for a connection (a free one, or a new one while the server refuses):
    /// past it the operation fails with [`DbFault::Unavailable`] instead of hanging.
    pub acquire_timeout: Duration,
}

impl Default for PoolOptions {
    fn default() -> Self {
        PoolOptions {
            acquire_timeout: Duration::from_secs(1),
        }
    }
}

/// Attempts after which a job is failed for good (by `fail` or by lease expiry).
pub const MAX_ATTEMPTS: i64 = 3;

/// Counts jobs a claim failed because their lease ran out at the attempt limit (their workers
/// died mid-fit), in `pantowatch_jobs_failed_total{reason="lease_expired"}`.
fn count_lease_expired(jobs: u64) {
    if jobs > 0 {
        metrics::counter!("pantowatch_jobs_failed_total", "reason" => "lease_expired")
            .increment(jobs);
    }
}

macro_rules! text_enum {
    ($(#[$m:meta])* $name:ident { $($(#[$vm:meta])* $v:ident = $s:literal),+ $(,)? }) => {
        $(#[$m])*
        #[derive(
            Debug, Clone, Copy, PartialEq, Eq, PartialOrd, Ord, Hash, Serialize, Deserialize,
            utoipa::ToSchema,
        )]
        #[serde(rename_all = "lowercase")]
        pub enum $name { $($(#[$vm])* $v),+ }

        impl $name {
            /// The text stored in the database and used on the wire.
            pub fn as_str(self) -> &'static str {
                match self { $($name::$v => $s),+ }
            }
        }

        impl FromStr for $name {
            type Err = StoreError;
            fn from_str(s: &str) -> Result<Self> {
                match s {
                    $($s => Ok($name::$v),)+
                    other => Err(StoreError::Invalid(format!(
                        concat!("unknown ", stringify!($name), " {:?}"), other))),
                }
            }
        }

        impl std::fmt::Display for $name {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.pad(self.as_str())
            }
        }
    };
}

text_enum!(
    /// Health of a joint; ordered `Unknown < Ok < Watch < Alarm` so `max` is the worst
    /// (the models' order: `unknown` says nothing is known to be wrong).
    Status {
        /// Not judged: the trace cannot pin the joint down, or it has no baseline.
        Unknown = "unknown",
        /// Within its baseline.
        Ok = "ok",
        /// Drifting: look at it at the next service.
        Watch = "watch",
        /// Out of tolerance.
        Alarm = "alarm",
    }
);
text_enum!(
    /// Access level of an API key; ordered so `role >= Role::Writer` means "may upload".
    Role {
        /// Reads everything.
        Reader = "reader",
        /// Also uploads traces.
        Writer = "writer",
        /// Also manages keys and re-fits.
        Admin = "admin",
    }
);
text_enum!(
    /// Life cycle of a fit job.
    JobState {
        /// Waiting for a worker.
        Queued = "queued",
        /// Leased by a worker until `lease_until`.
        Running = "running",
        /// Fit written.
        Done = "done",
        /// Gave up after an error or `MAX_ATTEMPTS`.
        Failed = "failed",
    }
);

/// Columns of `alerts` every query selects (PostgreSQL reads the JSONB evidence as text).
macro_rules! alert_cols {
    () => {
        " id, serial, joint, vehicle_id, severity, state, reason, CAST(evidence_json AS TEXT) AS evidence_json,
          trace_id, opened_at, updated_at, acknowledged_by, acknowledged_at, resolved_by,
          resolved_at "
    };
}

macro_rules! delivery_cols {
    () => {
        " id, webhook_id, alert_id, event, state, attempts, next_attempt_at, last_status,
          last_error, created_at, updated_at, delivered_at "
    };
}

pub mod alerts;
mod pg_alerts;
mod sqlite_alerts;
use alerts::Target;
pub use alerts::{
    Alert, AlertEvent, AlertFilter, AlertState, AttemptResult, Delivery, DeliveryState,
    DueDelivery, NewAlert, RaiseOutcome, Severity, Transition, Webhook,
};

impl Status {
    /// Rank used in SQL aggregates (`unknown` 0, `ok` 1, `watch` 2, `alarm` 3).
    pub fn rank(self) -> i64 {
        self as i64
    }
    fn from_rank(r: i64) -> Result<Self> {
        match r {
            0 => Ok(Status::Unknown),
            1 => Ok(Status::Ok),
            2 => Ok(Status::Watch),
            3 => Ok(Status::Alarm),
            _ => Err(StoreError::Corrupt(format!("status rank {r}"))),
        }
    }
}

/// Which database a [`Store`] talks to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum BackendKind {
    /// Embedded SQLite file.
    Sqlite,
    /// PostgreSQL server.
    Postgres,
}

/// One uploaded trace document, parsed and validated by the caller.
#[derive(Debug, Clone)]
pub struct NewTrace {
    /// Client-chosen id; a UUID is generated when `None`.
    pub trace_id: Option<String>,
    pub vehicle_id: String,
    /// `pantograph.serial`; optional in the contract (then no pantograph row is linked).
    pub serial: Option<String>,
    pub model: String,
    /// Normalised to UTC and truncated to microseconds when stored.
    pub recorded_at: DateTime<Utc>,
    pub kind: String,
    pub joint: Option<String>,
    /// The document's `test` object, verbatim JSON text.
    pub test_json: String,
    /// Lowercase hex SHA-256 of the canonical document bytes (idempotency key with `trace_id`).
    pub content_sha256: String,
    /// Channel name → values, `t_s` first.
    pub channels: Channels,
    /// Model version of the fit job enqueued with the upload.
    pub model_version: String,
}

/// What [`Store::insert_trace`] did.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
#[serde(tag = "outcome", rename_all = "snake_case")]
pub enum InsertOutcome {
    /// Stored now, with its fit job (None if a live job for the pair already existed).
    Created {
        trace_id: String,
        job_id: Option<i64>,
    },
    /// Already stored with the same content: nothing written.
    Existing { trace_id: String },
    /// Already stored with other content: nothing written.
    Conflict { trace_id: String },
}

impl InsertOutcome {
    /// The trace id the outcome is about.
    pub fn trace_id(&self) -> &str {
        match self {
            InsertOutcome::Created { trace_id, .. }
            | InsertOutcome::Existing { trace_id }
            | InsertOutcome::Conflict { trace_id } => trace_id,
        }
    }
}

/// Stored metadata of a trace (everything but the samples).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TraceMeta {
    pub trace_id: String,
    pub vehicle_id: String,
    pub serial: Option<String>,
    pub model: String,
    pub recorded_at: DateTime<Utc>,
    pub kind: String,
    pub joint: Option<String>,
    pub test_json: String,
    pub content_sha256: String,
    /// Values per channel.
    pub sample_count: i64,
    pub channel_names: Vec<String>,
    /// Size of the stored samples blob.
    pub samples_bytes: i64,
    pub created_at: DateTime<Utc>,
}

/// One joint of a fit, flattened for queries.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize, utoipa::ToSchema)]
pub struct JointFit {
    pub joint: String,
    pub viscous: Option<f64>,
    pub viscous_lo: Option<f64>,
    pub viscous_hi: Option<f64>,
    pub dry: Option<f64>,
    pub dry_lo: Option<f64>,
    pub dry_hi: Option<f64>,
    pub identifiable: bool,
    pub status: Status,
    /// Whether the fit informed each parameter (its `identifiable`) and the parameter's own
    /// status; `None` for a result without them (read as the joint's).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub viscous_informed: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub viscous_status: Option<Status>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dry_informed: Option<bool>,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dry_status: Option<Status>,
}

impl JointFit {
    /// Whether this fit informed `param` ("viscous" or "dry"): it has a value, the fit says it
    /// identified it, and its status is a verdict (not `unknown`). A fit that did not inform a
    /// parameter never changes that parameter's status (issue 15).
    pub fn informs(&self, param: &str) -> bool {
        let (value, informed, status) = match param {
            "viscous" => (self.viscous, self.viscous_informed, self.viscous_status),
            _ => (self.dry, self.dry_informed, self.dry_status),
        };
        value.is_some()
            && informed.unwrap_or(self.identifiable)
            && status.unwrap_or(self.status) != Status::Unknown
    }
}

/// A fit result to store: the contract JSON plus the columns extracted from it.
#[derive(Debug, Clone, PartialEq)]
pub struct NewFit {
    /// The contract fit result, stored as is.
    pub result: serde_json::Value,
    pub rmse: Option<f64>,
    pub joints: Vec<JointFit>,
}

impl NewFit {
    /// Extracts `rmse.value` and every `joints[]` entry from a contract fit result.
    pub fn from_result(result: serde_json::Value) -> Result<Self> {
        let bad = |m: String| StoreError::Invalid(format!("fit result: {m}"));
        let rmse = result
            .pointer("/rmse/value")
            .and_then(serde_json::Value::as_f64);
        let mut joints = Vec::new();
        let list = result
            .get("joints")
            .and_then(serde_json::Value::as_array)
            .ok_or_else(|| bad("no `joints` array".into()))?;
        for (i, j) in list.iter().enumerate() {
            let name = j
                .get("joint")
                .and_then(serde_json::Value::as_str)
                .ok_or_else(|| bad(format!("joints[{i}].joint missing")))?;
            let status = j
                .get("status")
                .and_then(serde_json::Value::as_str)
                .ok_or_else(|| bad(format!("joints[{i}].status missing")))?
                .parse::<Status>()?;
            let num = |p: &str| j.pointer(p).and_then(serde_json::Value::as_f64);
            joints.push(JointFit {
                joint: name.to_owned(),
                viscous: num("/viscous/value"),
                viscous_lo: num("/viscous/ci95/0"),
                viscous_hi: num("/viscous/ci95/1"),
                dry: num("/dry/value"),
                dry_lo: num("/dry/ci95/0"),
                dry_hi: num("/dry/ci95/1"),
                identifiable: j
                    .get("identifiable")
                    .and_then(serde_json::Value::as_bool)
                    .unwrap_or(true),
                status,
                viscous_informed: j
                    .pointer("/viscous/identifiable")
                    .and_then(serde_json::Value::as_bool),
                viscous_status: j
                    .pointer("/viscous/status")
                    .and_then(serde_json::Value::as_str)
                    .and_then(|s| s.parse().ok()),
                dry_informed: j
                    .pointer("/dry/identifiable")
                    .and_then(serde_json::Value::as_bool),
                dry_status: j
                    .pointer("/dry/status")
                    .and_then(serde_json::Value::as_str)
                    .and_then(|s| s.parse().ok()),
            });
        }
        Ok(NewFit {
            result,
            rmse,
            joints,
        })
    }

    /// Worst joint status (`None` without joints).
    pub fn status(&self) -> Option<Status> {
        self.joints.iter().map(|j| j.status).max()
    }
}

/// Result of writing a fit: the id of the row for (trace, model version), new or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct FitWrite {
    pub fit_id: i64,
    /// False when a fit for the pair already existed (nothing written).
    pub created: bool,
}

/// A stored fit.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitRecord {
    pub id: i64,
    pub trace_id: String,
    pub model_version: String,
    pub created_at: DateTime<Utc>,
    pub result: serde_json::Value,
    pub rmse: Option<f64>,
    pub status: Option<Status>,
    pub joints: Vec<JointFit>,
}

/// A fit job.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct Job {
    pub id: i64,
    pub trace_id: String,
    pub model_version: String,
    pub state: JobState,
    pub attempts: i64,
    pub lease_until: Option<DateTime<Utc>>,
    pub worker: Option<String>,
    pub last_error: Option<String>,
    pub created_at: DateTime<Utc>,
    pub updated_at: DateTime<Utc>,
}

/// What [`Store::complete`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CompleteOutcome {
    /// Fit stored (or already there) and job marked done, atomically.
    Completed(FitWrite),
    /// This worker no longer holds the job: nothing written.
    LeaseLost,
}

/// What [`Store::fail`] did.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FailOutcome {
    /// Back in the queue for another attempt.
    Requeued,
    /// Failed for good (no retry asked, or `MAX_ATTEMPTS` reached).
    Failed,
    /// This worker no longer holds the job: nothing written.
    LeaseLost,
}

/// Number of jobs per state.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct JobCounts {
    pub queued: i64,
    pub running: i64,
    pub done: i64,
    pub failed: i64,
}

/// What an operator watches on the queues (issue 18): the age of the oldest queued fit job and
/// the webhook deliveries still pending.
#[derive(Debug, Clone, Copy, Default, PartialEq)]
pub struct QueueStats {
    /// Seconds since the oldest queued job was queued; `None` when none is queued.
    pub oldest_queued_age_s: Option<f64>,
    /// Webhook deliveries not yet delivered or given up.
    pub outbox_backlog: i64,
}

/// Rows per table (readiness detail, metrics, and the tests' "nothing was stored" checks).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct Counts {
    pub vehicles: i64,
    pub pantographs: i64,
    pub traces: i64,
    pub fits: i64,
    pub jobs: i64,
    pub api_keys: i64,
}

/// Stored API key (never the key itself).
#[derive(Debug, Clone, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct ApiKey {
    pub id: i64,
    pub prefix: String,
    pub role: Role,
    pub label: String,
    pub created_at: DateTime<Utc>,
    pub revoked_at: Option<DateTime<Utc>>,
}

/// A vehicle in the list.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct VehicleSummary {
    pub vehicle_id: String,
    pub created_at: DateTime<Utc>,
    /// Pantographs currently mounted.
    pub pantographs: i64,
    pub traces: i64,
    pub last_test: Option<DateTime<Utc>>,
}

/// A vehicle with its current pantographs.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct VehicleDetail {
    pub vehicle_id: String,
    pub created_at: DateTime<Utc>,
    pub pantographs: Vec<PantographState>,
}

/// A pantograph as mounted now, with each joint's latest status.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct PantographState {
    pub serial: String,
    pub model: String,
    /// Mounted on this vehicle since.
    pub since: DateTime<Utc>,
    pub worst_status: Option<Status>,
    pub last_test: Option<DateTime<Utc>>,
    /// Each joint's point from the fit that decides its health.
    pub joints: Vec<JointPoint>,
    /// Each joint's health with the test that decides it: its date and test kind (issue 15).
    pub joint_states: Vec<JointState>,
}

/// One joint's fit from one trace (a history point, or the latest state).
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct JointPoint {
    pub trace_id: String,
    pub vehicle_id: String,
    pub recorded_at: DateTime<Utc>,
    pub model_version: String,
    pub fit_id: i64,
    pub fitted_at: DateTime<Utc>,
    #[serde(flatten)]
    pub fit: JointFit,
}

/// A joint's health now (`joint_latest`, [`joint_state_select`]): the fit that decides its
/// status, and that status. Fleet health and the alert rules both read it.
#[derive(Debug, Clone, PartialEq, Serialize, utoipa::ToSchema)]
pub struct JointState {
    pub joint: String,
    /// The test whose fit decides the joint's status (the latest that informed its worst
    /// parameter), its date and kind.
    pub trace_id: String,
    pub fit_id: i64,
    pub recorded_at: DateTime<Utc>,
    pub kind: String,
    /// False when no test has informed the joint yet (status `unknown`).
    pub informed: bool,
    pub status: Status,
}

/// Filter of [`Store::fleet_health`].
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct FleetFilter {
    /// Only pantographs whose worst latest status is this.
    pub status: Option<Status>,
    /// Only pantographs currently mounted on this vehicle.
    pub vehicle_id: Option<String>,
}

/// Offset pagination.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Page {
    pub limit: u32,
    pub offset: u64,
}

impl Default for Page {
    fn default() -> Self {
        Page {
            limit: 50,
            offset: 0,
        }
    }
}

/// A joint that is not `ok`.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct JointStatus {
    pub joint: String,
    pub status: Status,
}

/// One pantograph's health.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, utoipa::ToSchema)]
pub struct FleetRow {
    pub serial: String,
    pub model: String,
    /// Current vehicle.
    pub vehicle_id: Option<String>,
    /// Worst latest joint status; `None` until a fit exists.
    pub worst_status: Option<Status>,
    /// Joints whose latest status is not `ok`, worst first.
    pub not_ok: Vec<JointStatus>,
    pub last_test: Option<DateTime<Utc>>,
}

/// A page of fleet health, worst first (`alarm`, `watch`, `ok`, `unknown`, not yet fitted), then
/// serial.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct FleetPage {
    /// Rows matching the filter, over all pages.
    pub total: u64,
    pub rows: Vec<FleetRow>,
}

/// A trace ready for the backend: validated, id chosen, samples encoded.
#[derive(Debug, Clone)]
pub(crate) struct PreparedTrace {
    pub trace_id: String,
    pub vehicle_id: String,
    pub serial: Option<String>,
    pub model: String,
    pub recorded_at: DateTime<Utc>,
    pub kind: String,
    pub joint: Option<String>,
    pub test_json: String,
    pub content_sha256: String,
    pub samples: Vec<u8>,
    pub sample_count: i64,
    pub channel_names: String,
    pub model_version: String,
}

/// The operations each backend implements; [`Store`] dispatches to them.
pub(crate) trait Backend {
    fn ping(&self) -> impl Future<Output = Result<()>> + Send;
    fn migrations_applied(&self) -> impl Future<Output = Result<bool>> + Send;
    fn insert_trace(&self, t: PreparedTrace) -> impl Future<Output = Result<InsertOutcome>> + Send;
    fn get_trace(&self, id: &str) -> impl Future<Output = Result<Option<TraceMeta>>> + Send;
    fn samples_blob(&self, id: &str) -> impl Future<Output = Result<Option<Vec<u8>>>> + Send;
    fn insert_fit(
        &self,
        trace_id: &str,
        model_version: &str,
        fit: &NewFit,
    ) -> impl Future<Output = Result<FitWrite>> + Send;
    fn get_fit(&self, trace_id: &str) -> impl Future<Output = Result<Option<FitRecord>>> + Send;
    fn list_vehicles(&self) -> impl Future<Output = Result<Vec<VehicleSummary>>> + Send;
    fn get_vehicle(&self, id: &str) -> impl Future<Output = Result<Option<VehicleDetail>>> + Send;
    fn joint_history(
        &self,
        serial: &str,
        joint: &str,
    ) -> impl Future<Output = Result<Vec<JointPoint>>> + Send;
    fn fleet_health(
        &self,
        filter: &FleetFilter,
        page: Page,
    ) -> impl Future<Output = Result<FleetPage>> + Send;
    fn enqueue(
        &self,
        trace_id: &str,
        model_version: &str,
    ) -> impl Future<Output = Result<Option<i64>>> + Send;
    fn claim(
        &self,
        worker: &str,
        lease: Duration,
    ) -> impl Future<Output = Result<Option<Job>>> + Send;
    fn complete(
        &self,
        job_id: i64,
        worker: &str,
        fit: &NewFit,
    ) -> impl Future<Output = Result<CompleteOutcome>> + Send;
    fn fail(
        &self,
        job_id: i64,
        worker: &str,
        error: &str,
        retry: bool,
    ) -> impl Future<Output = Result<FailOutcome>> + Send;
    fn release(&self, job_id: i64, worker: &str) -> impl Future<Output = Result<bool>> + Send;
    fn release_counted(
        &self,
        job_id: i64,
        worker: &str,
    ) -> impl Future<Output = Result<Option<JobState>>> + Send;
    fn renew_lease(
        &self,
        job_id: i64,
        worker: &str,
        lease: Duration,
    ) -> impl Future<Output = Result<bool>> + Send;
    fn requeue(
        &self,
        vehicle_id: Option<&str>,
        model_version: &str,
    ) -> impl Future<Output = Result<u64>> + Send;
    fn get_job(&self, id: i64) -> impl Future<Output = Result<Option<Job>>> + Send;
    fn latest_job(&self, trace_id: &str) -> impl Future<Output = Result<Option<Job>>> + Send;
    fn job_counts(&self) -> impl Future<Output = Result<JobCounts>> + Send;
    fn queue_stats(&self) -> impl Future<Output = Result<QueueStats>> + Send;
    fn counts(&self) -> impl Future<Output = Result<Counts>> + Send;
    fn pantograph_exists(&self, serial: &str) -> impl Future<Output = Result<bool>> + Send;
    fn pantograph_model(&self, serial: &str)
    -> impl Future<Output = Result<Option<String>>> + Send;
    fn latest_trace_of_kind(
        &self,
        serial: &str,
        kind: &str,
    ) -> impl Future<Output = Result<Option<TraceMeta>>> + Send;
    fn insert_api_key(
        &self,
        prefix: &str,
        hash: &str,
        role: Role,
        label: &str,
    ) -> impl Future<Output = Result<ApiKey>> + Send;
    /// Unrevoked keys with this prefix, with their hashes.
    fn keys_by_prefix(
        &self,
        prefix: &str,
    ) -> impl Future<Output = Result<Vec<(ApiKey, String)>>> + Send;
    fn revoke_api_key(&self, id: i64) -> impl Future<Output = Result<bool>> + Send;
    fn list_api_keys(&self) -> impl Future<Output = Result<Vec<ApiKey>>> + Send;
    /// Every joint point of one pantograph (each trace's current fit), by test time.
    fn serial_history(&self, serial: &str) -> impl Future<Output = Result<Vec<JointPoint>>> + Send;
    fn joint_states(&self, serial: &str) -> impl Future<Output = Result<Vec<JointState>>> + Send;
    fn raise_alert(&self, a: &NewAlert) -> impl Future<Output = Result<RaiseOutcome>> + Send;
    fn acknowledge_alert(
        &self,
        id: i64,
        actor: &str,
        note: &str,
    ) -> impl Future<Output = Result<Transition>> + Send;
    fn resolve_alert(
        &self,
        target: Target<'_>,
        actor: &str,
        note: &str,
        trace_id: Option<&str>,
    ) -> impl Future<Output = Result<Transition>> + Send;
    fn list_alerts(&self, f: &AlertFilter) -> impl Future<Output = Result<Vec<Alert>>> + Send;
    fn get_alert(&self, id: i64) -> impl Future<Output = Result<Option<Alert>>> + Send;
    fn alert_events(&self, id: i64) -> impl Future<Output = Result<Vec<AlertEvent>>> + Send;
    fn insert_webhook(
        &self,
        url: &str,
        severities: &str,
        secret: &str,
    ) -> impl Future<Output = Result<Webhook>> + Send;
    fn list_webhooks(&self) -> impl Future<Output = Result<Vec<Webhook>>> + Send;
    fn delete_webhook(&self, id: i64) -> impl Future<Output = Result<bool>> + Send;
    fn claim_deliveries(
        &self,
        limit: i64,
        lease: Duration,
    ) -> impl Future<Output = Result<Vec<DueDelivery>>> + Send;
    fn finish_delivery(
        &self,
        id: i64,
        attempts: i64,
        r: &AttemptResult,
    ) -> impl Future<Output = Result<bool>> + Send;
    fn list_deliveries(
        &self,
        webhook_id: i64,
        limit: i64,
    ) -> impl Future<Output = Result<Vec<Delivery>>> + Send;
    fn close(&self) -> impl Future<Output = ()> + Send;
}

/// The store: SQLite or PostgreSQL behind the same methods.
#[derive(Debug, Clone)]
pub enum Store {
    Sqlite(SqliteStore),
    Postgres(PgStore),
}

macro_rules! dispatch {
    ($self:ident, $s:ident => $e:expr) => {
        match $self {
            Store::Sqlite($s) => $e,
            Store::Postgres($s) => $e,
        }
    };
}

impl Store {
    /// Opens the database named by `url` and applies pending migrations.
    ///
    /// `postgres://…` / `postgresql://…` → PostgreSQL; anything else is a SQLite file path or
    /// `sqlite:` URL, created if missing (WAL, foreign keys on, `synchronous=FULL` so that an
    /// accepted upload survives a power cut).
    pub async fn connect(url: &str) -> Result<Store> {
        Self::connect_with(url, PoolOptions::default()).await
    }

    /// As [`Store::connect`] with explicit pool options.
    pub async fn connect_with(url: &str, pool: PoolOptions) -> Result<Store> {
        if url.starts_with("postgres://") || url.starts_with("postgresql://") {
            Ok(Store::Postgres(PgStore::connect(url, pool).await?))
        } else {
            Ok(Store::Sqlite(SqliteStore::connect(url, pool).await?))
        }
    }

    /// Which backend this is.
    pub fn kind(&self) -> BackendKind {
        match self {
            Store::Sqlite(_) => BackendKind::Sqlite,
            Store::Postgres(_) => BackendKind::Postgres,
        }
    }

    /// A round trip to the database.
    pub async fn ping(&self) -> Result<()> {
        dispatch!(self, s => s.ping().await)
    }

    /// True when every embedded migration is applied (for `/readyz`).
    pub async fn migrations_applied(&self) -> Result<bool> {
        dispatch!(self, s => s.migrations_applied().await)
    }

    /// Stores a trace and enqueues its fit job, atomically. Same id and hash → `Existing`;
    /// same id, other hash → `Conflict`; neither writes anything.
    pub async fn insert_trace(&self, trace: NewTrace) -> Result<InsertOutcome> {
        let prepared = prepare_trace(trace).await?;
        dispatch!(self, s => s.insert_trace(prepared).await)
    }

    /// Metadata of a trace.
    pub async fn get_trace(&self, trace_id: &str) -> Result<Option<TraceMeta>> {
        dispatch!(self, s => s.get_trace(trace_id).await)
    }

    /// Decoded, checksum-verified channels of a trace (decoded off the async runtime).
    pub async fn get_samples(&self, trace_id: &str) -> Result<Option<Channels>> {
        let Some(blob) = dispatch!(self, s => s.samples_blob(trace_id).await)? else {
            return Ok(None);
        };
        let channels = tokio::task::spawn_blocking(move || samples::decode(&blob))
            .await
            .map_err(|e| StoreError::Task(e.to_string()))??;
        Ok(Some(channels))
    }

    /// Writes the fit of (trace, model version) once; later calls return the existing id.
    pub async fn insert_fit(
        &self,
        trace_id: &str,
        model_version: &str,
        fit: &NewFit,
    ) -> Result<FitWrite> {
        dispatch!(self, s => s.insert_fit(trace_id, model_version, fit).await)
    }

    /// The trace's current fit (the most recently written, whatever the model version).
    pub async fn get_fit(&self, trace_id: &str) -> Result<Option<FitRecord>> {
        dispatch!(self, s => s.get_fit(trace_id).await)
    }

    /// All vehicles, by id.
    pub async fn list_vehicles(&self) -> Result<Vec<VehicleSummary>> {
        dispatch!(self, s => s.list_vehicles().await)
    }

    /// A vehicle, its current pantographs and each joint's latest status.
    pub async fn get_vehicle(&self, vehicle_id: &str) -> Result<Option<VehicleDetail>> {
        dispatch!(self, s => s.get_vehicle(vehicle_id).await)
    }

    /// The joint's fit in every trace of this pantograph (each trace's current fit),
    /// ordered by `recorded_at` then trace id.
    pub async fn joint_history(&self, serial: &str, joint: &str) -> Result<Vec<JointPoint>> {
        dispatch!(self, s => s.joint_history(serial, joint).await)
    }

    /// A row per pantograph: worst latest status, joints not ok, last test; filtered, paged.
    pub async fn fleet_health(&self, filter: &FleetFilter, page: Page) -> Result<FleetPage> {
        dispatch!(self, s => s.fleet_health(filter, page).await)
    }

    /// Queues a fit of (trace, model version). `None` when a live (queued or running) job for
    /// the pair exists or the fit is already written.
    pub async fn enqueue(&self, trace_id: &str, model_version: &str) -> Result<Option<i64>> {
        dispatch!(self, s => s.enqueue(trace_id, model_version).await)
    }

    /// Leases the oldest claimable job (queued, or running with an expired lease) to `worker`.
    /// Jobs whose lease expired `MAX_ATTEMPTS` times are failed instead.
    pub async fn claim(&self, worker: &str, lease: Duration) -> Result<Option<Job>> {
        dispatch!(self, s => s.claim(worker, lease).await)
    }

    /// Writes the fit and marks the job done in one transaction, if `worker` still holds it.
    pub async fn complete(
        &self,
        job_id: i64,
        worker: &str,
        fit: &NewFit,
    ) -> Result<CompleteOutcome> {
        dispatch!(self, s => s.complete(job_id, worker, fit).await)
    }

    /// Records an error; requeues if `retry` and attempts remain, else fails the job.
    pub async fn fail(
        &self,
        job_id: i64,
        worker: &str,
        error: &str,
        retry: bool,
    ) -> Result<FailOutcome> {
        dispatch!(self, s => s.fail(job_id, worker, error, retry).await)
    }

    /// Gives a job this worker holds back to the queue without counting the attempt (shutdown
    /// before its fit started). False when `worker` no longer holds it (nothing written).
    pub async fn release(&self, job_id: i64, worker: &str) -> Result<bool> {
        dispatch!(self, s => s.release(job_id, worker).await)
    }

    /// Gives back a job whose fit had started (the grace period ran out mid-fit): the attempt
    /// stays counted, and at `MAX_ATTEMPTS` the job fails with the reason, so no job can be
    /// released at every shutdown for ever. The job's new state (`Queued`, or `Failed` at the
    /// limit); `None` when `worker` no longer holds it.
    pub async fn release_counted(&self, job_id: i64, worker: &str) -> Result<Option<JobState>> {
        dispatch!(self, s => s.release_counted(job_id, worker).await)
    }

    /// Extends a running job's lease to `lease` from now, while its worker still fits it (so a
    /// fit may outlast one lease, and a dead worker's job is still taken over within one).
    /// False when `worker` no longer holds it.
    pub async fn renew_lease(&self, job_id: i64, worker: &str, lease: Duration) -> Result<bool> {
        dispatch!(self, s => s.renew_lease(job_id, worker, lease).await)
    }

    /// Queues a fit at `model_version` for every trace without one; returns jobs created.
    pub async fn requeue_all(&self, model_version: &str) -> Result<u64> {
        dispatch!(self, s => s.requeue(None, model_version).await)
    }

    /// As [`Store::requeue_all`], for the traces of one vehicle.
    pub async fn requeue_vehicle(&self, vehicle_id: &str, model_version: &str) -> Result<u64> {
        dispatch!(self, s => s.requeue(Some(vehicle_id), model_version).await)
    }

    /// A job by id.
    pub async fn get_job(&self, job_id: i64) -> Result<Option<Job>> {
        dispatch!(self, s => s.get_job(job_id).await)
    }

    /// The trace's most recent job (for "fit pending / failed" answers).
    pub async fn latest_job(&self, trace_id: &str) -> Result<Option<Job>> {
        dispatch!(self, s => s.latest_job(trace_id).await)
    }

    /// Jobs per state (metrics, progress).
    pub async fn job_counts(&self) -> Result<JobCounts> {
        dispatch!(self, s => s.job_counts().await)
    }

    /// The oldest queued job's age and the webhook outbox backlog (metrics).
    pub async fn queue_stats(&self) -> Result<QueueStats> {
        dispatch!(self, s => s.queue_stats().await)
    }

    /// True when a pantograph with this serial is stored.
    pub async fn pantograph_exists(&self, serial: &str) -> Result<bool> {
        dispatch!(self, s => s.pantograph_exists(serial).await)
    }

    /// The pantograph's type (`160EC`), `None` when no such pantograph is stored.
    pub async fn pantograph_model(&self, serial: &str) -> Result<Option<String>> {
        dispatch!(self, s => s.pantograph_model(serial).await)
    }

    /// The pantograph's latest stored trace of test kind `kind` (by `recorded_at`, then
    /// `trace_id`), fitted or not; `None` when it has none.
    pub async fn latest_trace_of_kind(
        &self,
        serial: &str,
        kind: &str,
    ) -> Result<Option<TraceMeta>> {
        dispatch!(self, s => s.latest_trace_of_kind(serial, kind).await)
    }

    /// Rows per table.
    pub async fn counts(&self) -> Result<Counts> {
        dispatch!(self, s => s.counts().await)
    }

    /// Creates a key; returns its record and the key itself, which is not stored.
    pub async fn create_api_key(&self, role: Role, label: &str) -> Result<(ApiKey, String)> {
        let secret = keys::generate()?;
        let prefix = keys::prefix(&secret)
            .ok_or_else(|| StoreError::Invalid("generated key too short".into()))?;
        let hash = keys::hash(&secret);
        let key = dispatch!(self, s => s.insert_api_key(prefix, &hash, role, label).await)?;
        Ok((key, secret))
    }

    /// API-key lookups this store (and its clones) has sent to the database since it was
    /// opened: one per [`Store::verify_api_key`] of a key-shaped secret. The rate limiter's
    /// test counts them (an over-quota request must cost none).
    pub fn key_lookups(&self) -> u64 {
        dispatch!(self, s => s.key_lookups())
    }

    /// The unrevoked key matching `secret` (hash compared in constant time), if any.
    pub async fn verify_api_key(&self, secret: &str) -> Result<Option<ApiKey>> {
        let Some(prefix) = keys::prefix(secret) else {
            return Ok(None);
        };
        let hash = keys::hash(secret);
        let candidates = dispatch!(self, s => s.keys_by_prefix(prefix).await)?;
        let mut found = None;
        for (key, stored) in candidates {
            if keys::hashes_equal(&stored, &hash) {
                found = Some(key);
            }
        }
        Ok(found)
    }

    /// Revokes a key; false if it does not exist or was already revoked.
    pub async fn revoke_api_key(&self, key_id: i64) -> Result<bool> {
        dispatch!(self, s => s.revoke_api_key(key_id).await)
    }

    /// All keys, revoked included, by id.
    pub async fn list_api_keys(&self) -> Result<Vec<ApiKey>> {
        dispatch!(self, s => s.list_api_keys().await)
    }

    /// Every joint point of one pantograph (each trace's current fit), by test time then joint.
    pub async fn serial_history(&self, serial: &str) -> Result<Vec<JointPoint>> {
        dispatch!(self, s => s.serial_history(serial).await)
    }

    /// Each joint's health now, by joint: what fleet health shows and the alert rules act on.
    pub async fn joint_states(&self, serial: &str) -> Result<Vec<JointState>> {
        dispatch!(self, s => s.joint_states(serial).await)
    }

    /// Opens, escalates or updates the live alert of (serial, joint), with its event and, when
    /// opened or escalated, its webhook deliveries, in one transaction.
    pub async fn raise_alert(&self, a: &NewAlert) -> Result<RaiseOutcome> {
        non_empty("serial", &a.serial)?;
        non_empty("joint", &a.joint)?;
        dispatch!(self, s => s.raise_alert(a).await)
    }

    /// `open` → `acknowledged` by `actor` with a note.
    pub async fn acknowledge_alert(&self, id: i64, actor: &str, note: &str) -> Result<Transition> {
        dispatch!(self, s => s.acknowledge_alert(id, actor, note).await)
    }

    /// Resolves an alert by hand (`open` or `acknowledged` → `resolved`), with its deliveries.
    pub async fn resolve_alert(&self, id: i64, actor: &str, note: &str) -> Result<Transition> {
        dispatch!(self, s => s.resolve_alert(Target::Id(id), actor, note, None).await)
    }

    /// Resolves the live alert of (serial, joint), if any: a later test is back in band.
    pub async fn resolve_joint_alert(
        &self,
        serial: &str,
        joint: &str,
        trace_id: &str,
        note: &str,
    ) -> Result<Option<Alert>> {
        let t = dispatch!(self, s => s.resolve_alert(Target::Pair(serial, joint), "system", note, Some(trace_id)).await)?;
        Ok(match t {
            Transition::Done(a) => Some(a),
            _ => None,
        })
    }

    /// Alerts matching the filter, newest first.
    pub async fn list_alerts(&self, f: &AlertFilter) -> Result<Vec<Alert>> {
        dispatch!(self, s => s.list_alerts(f).await)
    }

    pub async fn get_alert(&self, id: i64) -> Result<Option<Alert>> {
        dispatch!(self, s => s.get_alert(id).await)
    }

    /// An alert's history, oldest first.
    pub async fn alert_events(&self, id: i64) -> Result<Vec<AlertEvent>> {
        dispatch!(self, s => s.alert_events(id).await)
    }

    /// Creates a subscription; returns it and its signing secret (shown once).
    pub async fn create_webhook(
        &self,
        url: &str,
        severities: &[Severity],
    ) -> Result<(Webhook, String)> {
        non_empty("url", url)?;
        alerts::check_severities(severities)?;
        let mut b = [0u8; 32];
        getrandom::fill(&mut b)?;
        let secret = format!("whsec_{}", hex::encode(b));
        let w = dispatch!(self, s => s.insert_webhook(url, &alerts::severities_text(severities), &secret).await)?;
        Ok((w, secret))
    }

    /// Every subscription, deleted ones included.
    pub async fn list_webhooks(&self) -> Result<Vec<Webhook>> {
        dispatch!(self, s => s.list_webhooks().await)
    }

    /// Deletes a subscription (its pending deliveries fail); false if unknown or deleted.
    pub async fn delete_webhook(&self, id: i64) -> Result<bool> {
        dispatch!(self, s => s.delete_webhook(id).await)
    }

    /// Leases up to `limit` due deliveries for one attempt each; a delivery whose attempt is
    /// not finished within `lease` is due again (at least once).
    pub async fn claim_deliveries(&self, limit: i64, lease: Duration) -> Result<Vec<DueDelivery>> {
        dispatch!(self, s => s.claim_deliveries(limit, lease).await)
    }

    /// Records an attempt's end; false when the delivery was claimed again meanwhile.
    pub async fn finish_delivery(&self, id: i64, attempts: i64, r: &AttemptResult) -> Result<bool> {
        dispatch!(self, s => s.finish_delivery(id, attempts, r).await)
    }

    /// A subscription's deliveries, newest first.
    pub async fn list_deliveries(&self, webhook_id: i64, limit: i64) -> Result<Vec<Delivery>> {
        dispatch!(self, s => s.list_deliveries(webhook_id, limit).await)
    }

    /// Closes the connection pool (waits for connections in use).
    pub async fn close(&self) {
        dispatch!(self, s => s.close().await)
    }
}

/// A refusal of the caller's value `field`.
fn refused(field: &str, message: impl Into<String>) -> StoreError {
    StoreError::InvalidField {
        field: field.to_owned(),
        message: message.into(),
    }
}

fn non_empty(what: &str, v: &str) -> Result<()> {
    if v.trim().is_empty() {
        return Err(refused(what, "is empty"));
    }
    Ok(())
}

/// Validates, chooses the id, normalises the time and encodes samples (off the runtime).
async fn prepare_trace(t: NewTrace) -> Result<PreparedTrace> {
    non_empty("vehicle_id", &t.vehicle_id)?;
    non_empty("pantograph.model", &t.model)?;
    non_empty("test.kind", &t.kind)?;
    if let Some(s) = &t.serial {
        non_empty("pantograph.serial", s)?;
    }
    // Every backend stores years 1–9999 (SQLite as RFC 3339 text, PostgreSQL as timestamptz);
    // a year outside would be written and then unreadable, making its vehicle answer 500
    // (issue 18). The upload refuses it first; this keeps any other writer from storing one.
    if !(1..=9999).contains(&t.recorded_at.year()) {
        return Err(refused("recorded_at", "is outside the years 1 to 9999"));
    }
    let sha = t.content_sha256.to_ascii_lowercase();
    if sha.len() != 64 || !sha.bytes().all(|b| b.is_ascii_hexdigit()) {
        return Err(refused("content_sha256", "is not 64 hex digits"));
    }
    if serde_json::from_str::<serde_json::Value>(&t.test_json).is_err() {
        return Err(refused("test", "is not JSON"));
    }
    let trace_id = match t.trace_id {
        Some(id) => {
            non_empty("trace_id", &id)?;
            id
        }
        None => keys::new_uuid()?,
    };
    let sample_count = t.channels.first().map_or(0, |(_, v)| v.len());
    if t.channels.iter().any(|(_, v)| v.len() != sample_count) {
        return Err(refused("channels", "differ in length"));
    }
    let names: Vec<&str> = t.channels.iter().map(|(n, _)| n.as_str()).collect();
    let channel_names =
        serde_json::to_string(&names).map_err(|e| refused("channels", e.to_string()))?;
    let channels = t.channels;
    let samples = tokio::task::spawn_blocking(move || samples::encode(&channels))
        .await
        .map_err(|e| StoreError::Task(e.to_string()))??;
    Ok(PreparedTrace {
        trace_id,
        vehicle_id: t.vehicle_id,
        serial: t.serial,
        model: t.model,
        recorded_at: t.recorded_at.trunc_subsecs(6),
        kind: t.kind,
        joint: t.joint,
        test_json: t.test_json,
        content_sha256: sha,
        samples,
        sample_count: i64::try_from(sample_count)
            .map_err(|_| refused("channels.t_s", "too many samples"))?,
        channel_names,
        model_version: t.model_version,
    })
}

/// What to do with the mount history when a trace says `serial` was on `vehicle` at `at`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub(crate) enum MountAction {
    /// History already agrees.
    Keep,
    /// Open a mount at `at`.
    Insert,
    /// The next mount is on the same vehicle: move its start back to `at`.
    MoveNext { since: DateTime<Utc> },
}

/// `in_effect`: the latest mount with `since <= at`; `next`: the earliest with `since > at`.
pub(crate) fn mount_action(
    vehicle: &str,
    at: DateTime<Utc>,
    in_effect: Option<(&str, DateTime<Utc>)>,
    next: Option<(&str, DateTime<Utc>)>,
) -> MountAction {
    match in_effect {
        Some((v, _)) if v == vehicle => MountAction::Keep,
        // Two vehicles claim the serial at the same instant: the first upload wins.
        Some((_, since)) if since == at => MountAction::Keep,
        _ => match next {
            Some((v, since)) if v == vehicle => MountAction::MoveNext { since },
            _ => MountAction::Insert,
        },
    }
}

/// Column accessors shared by the row mappers; SQLite stores timestamps as text.
pub(crate) trait RowExt {
    fn text(&self, c: &str) -> Result<String>;
    fn opt_text(&self, c: &str) -> Result<Option<String>>;
    fn int(&self, c: &str) -> Result<i64>;
    fn opt_int(&self, c: &str) -> Result<Option<i64>>;
    fn opt_real(&self, c: &str) -> Result<Option<f64>>;
    fn flag(&self, c: &str) -> Result<bool>;
    fn opt_flag(&self, c: &str) -> Result<Option<bool>>;
    fn ts(&self, c: &str) -> Result<DateTime<Utc>>;
    fn opt_ts(&self, c: &str) -> Result<Option<DateTime<Utc>>>;
}

fn parse_enum<T: FromStr<Err = StoreError>>(s: &str) -> Result<T> {
    s.parse::<T>()
        .map_err(|e| StoreError::Corrupt(e.to_string()))
}

pub(crate) fn trace_from<R: RowExt>(r: &R) -> Result<TraceMeta> {
    let names = r.text("channel_names")?;
    Ok(TraceMeta {
        trace_id: r.text("trace_id")?,
        vehicle_id: r.text("vehicle_id")?,
        serial: r.opt_text("serial")?,
        model: r.text("model")?,
        recorded_at: r.ts("recorded_at")?,
        kind: r.text("kind")?,
        joint: r.opt_text("joint")?,
        test_json: r.text("test_json")?,
        content_sha256: r.text("content_sha256")?,
        sample_count: r.int("sample_count")?,
        channel_names: serde_json::from_str(&names)
            .map_err(|e| StoreError::Corrupt(format!("channel_names: {e}")))?,
        samples_bytes: r.int("samples_bytes")?,
        created_at: r.ts("created_at")?,
    })
}

pub(crate) fn joint_fit_from<R: RowExt>(r: &R) -> Result<JointFit> {
    Ok(JointFit {
        joint: r.text("joint")?,
        viscous: r.opt_real("viscous")?,
        viscous_lo: r.opt_real("viscous_lo")?,
        viscous_hi: r.opt_real("viscous_hi")?,
        dry: r.opt_real("dry")?,
        dry_lo: r.opt_real("dry_lo")?,
        dry_hi: r.opt_real("dry_hi")?,
        identifiable: r.flag("identifiable")?,
        status: parse_enum(&r.text("status")?)?,
        viscous_informed: r.opt_flag("viscous_informed")?,
        viscous_status: r
            .opt_text("viscous_status")?
            .map(|s| parse_enum(&s))
            .transpose()?,
        dry_informed: r.opt_flag("dry_informed")?,
        dry_status: r
            .opt_text("dry_status")?
            .map(|s| parse_enum(&s))
            .transpose()?,
    })
}

/// The SQL of [`Store::joint_states`] (both backends).
pub(crate) const JOINT_STATES_SQL: &str = "SELECT l.joint, l.trace_id, l.fit_id, l.recorded_at,
        l.identifiable, l.status, t.kind
    FROM joint_latest l JOIN traces t ON t.trace_id = l.trace_id
    WHERE l.serial = $1 ORDER BY l.joint";

pub(crate) fn joint_state_from<R: RowExt>(r: &R) -> Result<JointState> {
    Ok(JointState {
        joint: r.text("joint")?,
        trace_id: r.text("trace_id")?,
        fit_id: r.int("fit_id")?,
        recorded_at: r.ts("recorded_at")?,
        kind: r.text("kind")?,
        informed: r.flag("identifiable")?,
        status: parse_enum(&r.text("status")?)?,
    })
}

pub(crate) fn joint_point_from<R: RowExt>(r: &R) -> Result<JointPoint> {
    Ok(JointPoint {
        trace_id: r.text("trace_id")?,
        vehicle_id: r.text("vehicle_id")?,
        recorded_at: r.ts("recorded_at")?,
        model_version: r.text("model_version")?,
        fit_id: r.int("fit_id")?,
        fitted_at: r.ts("fitted_at")?,
        fit: joint_fit_from(r)?,
    })
}

pub(crate) fn fit_from<R: RowExt>(r: &R, joints: Vec<JointFit>) -> Result<FitRecord> {
    let text = r.text("result_json")?;
    Ok(FitRecord {
        id: r.int("id")?,
        trace_id: r.text("trace_id")?,
        model_version: r.text("model_version")?,
        created_at: r.ts("created_at")?,
        result: serde_json::from_str(&text)
            .map_err(|e| StoreError::Corrupt(format!("result_json: {e}")))?,
        rmse: r.opt_real("rmse")?,
        status: r.opt_text("status")?.map(|s| parse_enum(&s)).transpose()?,
        joints,
    })
}

pub(crate) fn job_from<R: RowExt>(r: &R) -> Result<Job> {
    Ok(Job {
        id: r.int("id")?,
        trace_id: r.text("trace_id")?,
        model_version: r.text("model_version")?,
        state: parse_enum(&r.text("state")?)?,
        attempts: r.int("attempts")?,
        lease_until: r.opt_ts("lease_until")?,
        worker: r.opt_text("worker")?,
        last_error: r.opt_text("last_error")?,
        created_at: r.ts("created_at")?,
        updated_at: r.ts("updated_at")?,
    })
}

pub(crate) fn api_key_from<R: RowExt>(r: &R) -> Result<ApiKey> {
    Ok(ApiKey {
        id: r.int("id")?,
        prefix: r.text("prefix")?,
        role: parse_enum(&r.text("role")?)?,
        label: r.text("label")?,
        created_at: r.ts("created_at")?,
        revoked_at: r.opt_ts("revoked_at")?,
    })
}

pub(crate) fn counts_from<R: RowExt>(r: &R) -> Result<Counts> {
    Ok(Counts {
        vehicles: r.int("vehicles")?,
        pantographs: r.int("pantographs")?,
        traces: r.int("traces")?,
        fits: r.int("fits")?,
        jobs: r.int("jobs")?,
        api_keys: r.int("api_keys")?,
    })
}

/// Counts every table in one statement (both dialects).
pub(crate) const COUNTS_SQL: &str = "SELECT
    (SELECT count(*) FROM vehicles) AS vehicles,
    (SELECT count(*) FROM pantographs) AS pantographs,
    (SELECT count(*) FROM traces) AS traces,
    (SELECT count(*) FROM fits) AS fits,
    (SELECT count(*) FROM jobs) AS jobs,
    (SELECT count(*) FROM api_keys) AS api_keys";

pub(crate) fn vehicle_from<R: RowExt>(r: &R) -> Result<VehicleSummary> {
    Ok(VehicleSummary {
        vehicle_id: r.text("id")?,
        created_at: r.ts("created_at")?,
        pantographs: r.int("pantographs")?,
        traces: r.int("traces")?,
        last_test: r.opt_ts("last_test")?,
    })
}

/// `not_ok` is `joint:status` pairs joined by U+001F (unit separator); split on the last `:`.
pub(crate) fn fleet_row_from<R: RowExt>(r: &R) -> Result<FleetRow> {
    let mut not_ok = Vec::new();
    if let Some(list) = r.opt_text("not_ok")? {
        for pair in list.split('\u{1f}').filter(|p| !p.is_empty()) {
            let (joint, status) = pair
                .rsplit_once(':')
                .ok_or_else(|| StoreError::Corrupt(format!("not_ok entry {pair:?}")))?;
            not_ok.push(JointStatus {
                joint: joint.to_owned(),
                status: parse_enum(status)?,
            });
        }
    }
    not_ok.sort_by(|a, b| b.status.cmp(&a.status).then_with(|| a.joint.cmp(&b.joint)));
    Ok(FleetRow {
        serial: r.text("serial")?,
        model: r.text("model")?,
        vehicle_id: r.opt_text("vehicle_id")?,
        worst_status: r.opt_int("worst")?.map(Status::from_rank).transpose()?,
        not_ok,
        last_test: r.opt_ts("last_test")?,
    })
}

/// Builds a [`PantographState`] from its mount row and its latest joint points.
pub(crate) fn pantograph_state(
    serial: String,
    model: String,
    since: DateTime<Utc>,
    last_test: Option<DateTime<Utc>>,
    joints: Vec<JointPoint>,
    joint_states: Vec<JointState>,
) -> PantographState {
    PantographState {
        worst_status: joint_states.iter().map(|j| j.status).max(),
        serial,
        model,
        since,
        last_test,
        joints,
        joint_states,
    }
}

/// Rewrites `joint_latest` for the serial `$1` (both dialects) by [`joint_state_select`]: each
/// parameter from the latest current fit that informed it, the joint at the worst of them.
pub(crate) const JOINT_LATEST_REFRESH_SQL: &str = concat!(
    "INSERT INTO joint_latest (serial, joint, trace_id, fit_id, recorded_at, identifiable, status)
     SELECT serial, joint, trace_id, fit_id, recorded_at, identifiable, status FROM (",
    joint_state_select!("t.serial = $1"),
    ") s"
);

/// A joint's latest state as `joint_latest` holds it: (serial, joint, trace, fit, status).
#[cfg(test)]
pub(crate) type LatestRow = (String, String, String, i64, String);

/// Fixed-width UTC text used for SQLite timestamps (text order = time order).
pub(crate) fn ts_text(t: DateTime<Utc>) -> String {
    t.format("%Y-%m-%dT%H:%M:%S%.6fZ").to_string()
}

pub(crate) fn parse_ts_text(s: &str) -> Result<DateTime<Utc>> {
    DateTime::parse_from_rfc3339(s)
        .map(|t| t.with_timezone(&Utc))
        .map_err(|e| StoreError::Corrupt(format!("timestamp {s:?}: {e}")))
}

/// A lease length as a chrono duration (saturating).
pub(crate) fn lease_delta(lease: Duration) -> chrono::TimeDelta {
    chrono::TimeDelta::from_std(lease).unwrap_or(chrono::TimeDelta::MAX)
}

#[cfg(test)]
mod unit {
    use super::*;
    use chrono::TimeZone;

    fn t(h: u32) -> DateTime<Utc> {
        Utc.with_ymd_and_hms(2026, 1, 1, h, 0, 0)
            .single()
            .expect("time")
    }

    #[test]
    fn mount_decisions() {
        use MountAction::*;
        assert_eq!(mount_action("A", t(5), None, None), Insert);
        assert_eq!(mount_action("A", t(5), Some(("A", t(1))), None), Keep);
        assert_eq!(mount_action("B", t(5), Some(("A", t(1))), None), Insert);
        assert_eq!(mount_action("B", t(1), Some(("A", t(1))), None), Keep);
        assert_eq!(
            mount_action("A", t(0), None, Some(("A", t(1)))),
            MoveNext { since: t(1) }
        );
        assert_eq!(mount_action("B", t(0), None, Some(("A", t(1)))), Insert);
        assert_eq!(
            mount_action("B", t(3), Some(("A", t(1))), Some(("B", t(4)))),
            MoveNext { since: t(4) }
        );
    }

    #[test]
    fn fit_from_contract_json() {
        let v = serde_json::json!({
            "trace_id": "x",
            "joints": [
                { "joint": "J1",
                  "viscous": { "value": 0.036, "ci95": [0.031, 0.041] },
                  "dry": { "value": 0.024, "ci95": [0.021, 0.027] },
                  "identifiable": true, "status": "watch" },
                { "joint": "J2", "identifiable": false, "status": "ok" }
            ],
            "rmse": { "value": 0.42, "unit": "deg" }
        });
        let f = NewFit::from_result(v).expect("fit");
        assert_eq!(f.rmse, Some(0.42));
        assert_eq!(f.status(), Some(Status::Watch));
        assert_eq!(f.joints[0].viscous_hi, Some(0.041));
        assert_eq!(f.joints[1].dry, None);
        assert!(NewFit::from_result(serde_json::json!({})).is_err());
        let bad = serde_json::json!({"joints": [{"joint": "J1", "status": "bad"}]});
        assert!(NewFit::from_result(bad).is_err());
    }

    #[test]
    fn timestamps_sort_as_text() {
        let a = ts_text(t(1));
        let b = ts_text(t(1) + chrono::TimeDelta::microseconds(1));
        assert!(a < b);
        assert_eq!(parse_ts_text(&a).expect("parse"), t(1));
        assert_eq!(a, "2026-01-01T01:00:00.000000Z");
    }
}
