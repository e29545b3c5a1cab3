//! Storage layer: one [`Store`] over SQLite (a file path, the embedded default) or PostgreSQL
//! (a `postgres://` URL) holding traces, fits, the durable fit-job queue and API keys.
//!
//! Both backends implement the same crate-private traits, one per concern (`TraceBackend`,
//! `JobBackend`, `HealthBackend`, `KeyBackend`, `AlertBackend`), so their signatures cannot
//! drift; [`Store`] is an enum that dispatches to them (no `dyn`, no `async_trait`). The SQL and
//! logic of each concern is written once, in `sql/`, and instantiated by each backend with its
//! dialect (issue 19, point 2).
//!
//! # Layout
//! - `mod.rs`: errors, the status/role/job-state words, the concern traits, the joint-state SQL;
//! - `records.rs`: what callers write and read; `facade.rs`: `Store`'s methods (the callers'
//!   checks, then the backend); `rows.rs`: rows to records, for both backends;
//! - `sql/{traces,jobs,health,keys,alerts,priors}.rs`: each concern's statements and steps, once, as a
//!   macro body (`traces_impl!()` …); `sql/mod.rs`: the SQL fragments they share and the
//!   dialect they name (why macros: see there);
//! - `sqlite.rs`, `postgres.rs`: what differs per backend, and nothing else: connection and
//!   migrations, transactions and locking (`BEGIN IMMEDIATE` against row and advisory locks,
//!   each backend's job claim), timestamp types, and the dialect's SQL fragments;
//! - `alerts.rs` (alert and webhook records), `samples.rs` (the packed channels), `keys.rs`
//!   (API-key hashing), `fault.rs`;
//! - `tests/`: the contract suite, one file per concern, run on both backends.
//!
//! Migrations are embedded per backend (`migrations/sqlite`, `migrations/postgres`) and run on
//! connect. Every statement binds its values; the only dynamic SQL is test-database DDL.
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

/// One parameter's informing rows of a serial `$1` for `param_evidence` (both dialects): each
/// trace's current fit that informed `$p` (the rule of [`joint_state_select`]'s `informs`) with
/// a finite interval.
macro_rules! evidence_select {
    ($p:literal) => {
        concat!(
            "SELECT t.serial, j.joint, '", $p, "' AS param, t.trace_id, f.id AS fit_id, t.kind,
                    t.recorded_at, j.", $p, " AS value, j.", $p, "_lo AS lo, j.", $p, "_hi AS hi,
                    COALESCE(j.", $p, "_status, j.status) AS status
             FROM traces t
             JOIN fits f ON f.trace_id = t.trace_id
                        AND f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = t.trace_id)
             JOIN fit_joints j ON j.fit_id = f.id
             WHERE t.serial = $1 AND j.", $p, " IS NOT NULL AND j.", $p, "_lo IS NOT NULL
               AND j.", $p, "_hi IS NOT NULL AND j.", $p, "_hi > j.", $p, "_lo
               AND COALESCE(j.", $p, "_informed, j.identifiable)
               AND COALESCE(j.", $p, "_status, j.status) <> 'unknown'"
        )
    };
}

mod fault;
pub mod keys;
pub mod samples;
#[cfg(test)]
mod tests;

use std::str::FromStr;
use std::time::Duration;

use chrono::{DateTime, Datelike, SubsecRound, Utc};
use pantowatch_models::report::{FitCurve, FitResult, JointResult};
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

/// Health of a joint or parameter: the models' own type (one `Status`, issue 19), stored as its
/// word (`as_str`) and ranked in SQL aggregates (`rank`).
pub use pantowatch_models::drift::Status;

impl From<pantowatch_models::drift::UnknownStatus> for StoreError {
    fn from(e: pantowatch_models::drift::UnknownStatus) -> Self {
        StoreError::Invalid(e.to_string())
    }
}

/// The status of a rank read back from SQL.
fn status_from_rank(r: i64) -> Result<Status> {
    Status::from_rank(r).ok_or_else(|| StoreError::Corrupt(format!("status rank {r}")))
}

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
// The shared SQL and logic (macros) first, then the backends that instantiate it.
#[macro_use]
mod sql;
mod postgres;
mod sqlite;
use alerts::Target;
pub use alerts::{
    Alert, AlertEvent, AlertFilter, AlertState, AttemptResult, Delivery, DeliveryState,
    DueDelivery, NewAlert, RaiseOutcome, Severity, Transition, Webhook,
};

/// The operations each backend implements, one trait per concern; [`Store`] dispatches to them
/// (each concern's implementation, written once: `sql/<concern>.rs`).
pub(crate) trait TraceBackend {
    // traces, fits and their curves, the database itself
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
    fn fit_curve(&self, fit_id: i64) -> impl Future<Output = Result<Option<FitCurve>>> + Send;
    fn counts(&self) -> impl Future<Output = Result<Counts>> + Send;
    fn pantograph_exists(&self, serial: &str) -> impl Future<Output = Result<bool>> + Send;
    fn pantograph_model(&self, serial: &str)
    -> impl Future<Output = Result<Option<String>>> + Send;
    fn latest_trace_of_kind(
        &self,
        serial: &str,
        kind: &str,
    ) -> impl Future<Output = Result<Option<TraceMeta>>> + Send;
    fn traces_of_kind(
        &self,
        serial: &str,
        kind: &str,
        limit: i64,
    ) -> impl Future<Output = Result<Vec<TraceMeta>>> + Send;
    fn close(&self) -> impl Future<Output = ()> + Send;
}

pub(crate) trait JobBackend {
    // the fit queue: enqueue, claim, lease, complete, fail, release
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
}

pub(crate) trait HealthBackend {
    // vehicles, joint history, joint states and fleet health
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
    /// Every joint point of one pantograph (each trace's current fit), by test time.
    fn serial_history(&self, serial: &str) -> impl Future<Output = Result<Vec<JointPoint>>> + Send;
    fn joint_states(&self, serial: &str) -> impl Future<Output = Result<Vec<JointState>>> + Send;
    /// Each parameter's latest informing test of each kind (`param_evidence`), of one serial
    /// or (`None`) of the whole fleet.
    fn param_evidence(
        &self,
        serial: Option<&str>,
    ) -> impl Future<Output = Result<Vec<EvidenceRow>>> + Send;
    /// The counter every write of `param_evidence` raises.
    fn evidence_version(&self) -> impl Future<Output = Result<i64>> + Send;
    /// The date of the pantograph's newest test (any kind, fitted or not).
    fn latest_test_at(
        &self,
        serial: &str,
    ) -> impl Future<Output = Result<Option<DateTime<Utc>>>> + Send;
    /// Writes parameters' trends (or clears them) on their `param_evidence` rows, in one
    /// transaction: (joint, param, trend).
    fn set_param_trends(
        &self,
        serial: &str,
        trends: &[(String, String, Option<StoredTrend>)],
    ) -> impl Future<Output = Result<()>> + Send;
}

pub(crate) trait PriorBackend {
    // fleet priors (issue 37, point 3)
    /// Version `version` of `model`'s prior, or (`None`) its newest.
    fn fleet_prior(
        &self,
        model: &str,
        version: Option<i64>,
    ) -> impl Future<Output = Result<Option<StoredPrior>>> + Send;
    /// Stores `p` as `model`'s next version and, in the same transaction, queues a refit under
    /// the model version `refit_prefix` + the new version of every `kinds` trace of that type
    /// whose current fit used an older prior (or none).
    fn publish_fleet_prior(
        &self,
        p: &NewPrior,
        kinds: &[&str],
        refit_prefix: &str,
    ) -> impl Future<Output = Result<Published>> + Send;
}

pub(crate) trait KeyBackend {
    // API keys
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
}

pub(crate) trait AlertBackend {
    // alerts and the webhook outbox
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

mod records;
pub use records::*;
mod facade;
pub(crate) use facade::{MountAction, mount_action};
mod rows;
pub(crate) use rows::*;

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
    fn fit_columns_from_the_typed_result() {
        use pantowatch_models::report::{ParamResult, Quantity};
        let param = |value: f64, ci95: [f64; 2], status: Status| ParamResult {
            value,
            ci95,
            baseline: None,
            unit: "1".into(),
            identifiable: status != Status::Unknown,
            status,
            combination: None,
        };
        let joint = |name: &str, v: ParamResult, d: ParamResult, status: Status| JointResult {
            joint: name.into(),
            viscous: v,
            dry: d,
            identifiable: status != Status::Unknown,
            status,
        };
        let nan = f64::NAN;
        let r = FitResult {
            trace_id: "x".into(),
            joints: vec![
                joint(
                    "J1",
                    param(0.036, [0.031, 0.041], Status::Watch),
                    param(0.024, [0.021, 0.027], Status::Ok),
                    Status::Watch,
                ),
                // Not estimable: no values stored, only its status.
                joint(
                    "J2",
                    param(nan, [nan; 2], Status::Unknown),
                    param(nan, [nan; 2], Status::Unknown),
                    Status::Unknown,
                ),
            ],
            rmse: Quantity {
                value: 0.42,
                unit: "deg".into(),
            },
            ..FitResult::default()
        };
        let f = NewFit::from_result(r);
        assert_eq!(f.rmse, Some(0.42));
        assert_eq!(f.status(), Some(Status::Watch));
        assert_eq!(f.joints[0].viscous_hi, Some(0.041));
        assert_eq!(f.joints[0].dry_status, Some(Status::Ok));
        assert_eq!(f.joints[1].dry, None);
        assert_eq!(f.joints[1].viscous_lo, None);
        assert!(!f.joints[1].informs("viscous"));
        // Stored as it always was: sorted keys, non-finite numbers `null`; read back typed.
        let text = f.result_json().expect("json");
        assert!(text.starts_with(r#"{"fit":{"#), "{text}");
        assert!(
            text.contains(r#""dry":{"baseline":null,"ci95":[null,null],"identifiable":false,"#)
        );
        let back: FitResult = serde_json::from_str(&text).expect("reads back");
        assert!(back.joints[1].dry.value.is_nan());
        assert_eq!(NewFit::from_result(back).result_json().expect("json"), text);
        // A stored text that is not a fit result is a clear internal error, never a panic.
        let rec = |json: &str| FitRecord {
            id: 7,
            trace_id: "x".into(),
            model_version: "v".into(),
            created_at: t(1),
            result_json: json.into(),
            rmse: None,
            status: None,
            joints: Vec::new(),
        };
        assert_eq!(rec(&text).result().expect("typed").joints.len(), 2);
        for bad in [r#"{"joints": []}"#, "not json", ""] {
            match rec(bad).result() {
                Err(StoreError::Corrupt(m)) => assert!(m.starts_with("fit 7 result_json"), "{m}"),
                other => panic!("{bad:?}: {other:?}"),
            }
        }
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
