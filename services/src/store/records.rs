//! The store's records: what callers write (`NewTrace`, `NewFit`) and read (`TraceMeta`,
//! `FitRecord`, jobs, keys, vehicles, joint states, fleet pages), the same on both backends.

use super::*;

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

/// A fit result to store: the typed contract result plus the columns extracted from it. The
/// store serialises the result, here and nowhere else ([`NewFit::result_json`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NewFit {
    /// The contract fit result.
    pub result: FitResult,
    pub rmse: Option<f64>,
    pub joints: Vec<JointFit>,
    /// Measured vs model, stored beside the fit (table `fit_curves`) for pages to draw.
    pub curve: Option<FitCurve>,
}

impl NewFit {
    /// This fit with its curve.
    pub fn with_curve(mut self, curve: Option<FitCurve>) -> Self {
        self.curve = curve;
        self
    }

    /// The fit of `result`, with `rmse.value` and every joint's columns taken from it (a
    /// non-finite number is stored as no value).
    pub fn from_result(result: FitResult) -> Self {
        let joints = result.joints.iter().map(joint_fit).collect();
        NewFit {
            rmse: finite(result.rmse.value),
            result,
            joints,
            curve: None,
        }
    }

    /// Worst joint status (`None` without joints).
    pub fn status(&self) -> Option<Status> {
        self.joints.iter().map(|j| j.status).max()
    }

    /// The result as the store keeps it (`fits.result_json`): the contract JSON with each
    /// object's keys in sorted order (serde_json's map order), as it has always been stored;
    /// a non-finite number is written `null` and reads back as NaN ([`FitRecord::result`]).
    pub(crate) fn result_json(&self) -> Result<String> {
        serde_json::to_value(&self.result)
            .and_then(|v| serde_json::to_string(&v))
            .map_err(|e| StoreError::Invalid(format!("fit result: {e}")))
    }
}

fn finite(v: f64) -> Option<f64> {
    v.is_finite().then_some(v)
}

/// One joint of a result as its `fit_joints` row.
fn joint_fit(j: &JointResult) -> JointFit {
    JointFit {
        joint: j.joint.clone(),
        viscous: finite(j.viscous.value),
        viscous_lo: finite(j.viscous.ci95[0]),
        viscous_hi: finite(j.viscous.ci95[1]),
        dry: finite(j.dry.value),
        dry_lo: finite(j.dry.ci95[0]),
        dry_hi: finite(j.dry.ci95[1]),
        identifiable: j.identifiable,
        status: j.status,
        viscous_informed: Some(j.viscous.identifiable),
        viscous_status: Some(j.viscous.status),
        dry_informed: Some(j.dry.identifiable),
        dry_status: Some(j.dry.status),
    }
}

/// Result of writing a fit: the id of the row for (trace, model version), new or not.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
pub struct FitWrite {
    pub fit_id: i64,
    /// False when a fit for the pair already existed (nothing written).
    pub created: bool,
}

/// A stored fit. Its result is read typed, once, by [`FitRecord::result`].
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct FitRecord {
    pub id: i64,
    pub trace_id: String,
    pub model_version: String,
    pub created_at: DateTime<Utc>,
    /// The stored result text ([`NewFit::result_json`]; PostgreSQL hands back its `jsonb`
    /// rendering of it).
    pub result_json: String,
    pub rmse: Option<f64>,
    pub status: Option<Status>,
    pub joints: Vec<JointFit>,
}

impl FitRecord {
    /// The stored result as the typed contract result. A text that does not read as one is
    /// [`StoreError::Corrupt`] (an internal error to a client), never a panic.
    pub fn result(&self) -> Result<FitResult> {
        serde_json::from_str(&self.result_json)
            .map_err(|e| StoreError::Corrupt(format!("fit {} result_json: {e}", self.id)))
    }
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

/// A parameter's latest informing test of one kind (`param_evidence`, migration 0008).
#[derive(Debug, Clone, PartialEq)]
pub struct EvidenceRow {
    pub serial: String,
    /// The pantograph's type (`160EC`).
    pub model: String,
    pub joint: String,
    /// `viscous` or `dry`.
    pub param: String,
    pub trace_id: String,
    pub fit_id: i64,
    pub kind: String,
    pub recorded_at: DateTime<Utc>,
    pub value: f64,
    pub ci95: [f64; 2],
    pub status: Status,
    /// The parameter's trend over its informing tests, once the service has written it.
    pub trend: Option<StoredTrend>,
}

/// A parameter's trend as `param_evidence` keeps it: slope per day, its 95 % interval, and
/// whether that interval excludes 0.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct StoredTrend {
    pub slope_per_day: f64,
    pub slope_ci95: [f64; 2],
    pub significant: bool,
}

/// A stored fleet prior version (`fleet_priors`, migration 0009; issue 37, point 3).
#[derive(Debug, Clone, PartialEq)]
pub struct StoredPrior {
    pub version: i64,
    /// The pantograph type it is for (`160EC`).
    pub model: String,
    pub learned_at: DateTime<Utc>,
    /// `learned` or `type_file`.
    pub source: String,
    /// Pantographs whose workshop fits it rests on.
    pub n_units: i64,
    /// The type file's floor (Table 4 units) applied where a parameter had few fits.
    pub floor_relative_sd: f64,
    /// The widening of learned sds a fit applies (`[fleet_prior] fit_sd_scale`).
    pub fit_sd_scale: f64,
    /// Per joint and parameter.
    pub params: Vec<pantowatch_models::lift::fleet_prior::ParamPrior>,
}

/// A prior to publish: everything but the version and the time, which the store assigns.
#[derive(Debug, Clone, PartialEq)]
pub struct NewPrior {
    pub model: String,
    pub source: String,
    pub n_units: i64,
    pub floor_relative_sd: f64,
    pub fit_sd_scale: f64,
    pub params: Vec<pantowatch_models::lift::fleet_prior::ParamPrior>,
}

/// What publishing a prior did: the version stored and the fits queued again under it.
#[derive(Debug, Clone, PartialEq)]
pub struct Published {
    pub prior: StoredPrior,
    /// Refit jobs queued (lift and gauge traces whose current fit used an older prior).
    pub queued: u64,
}
