//! `Store`'s methods: the callers' checks (a refused value names its field), then the backend
//! the store holds (`dispatch!`); and the mount rule both backends apply.

use super::*;

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

    /// The measured-vs-model curve stored with a fit (`None`: the fit was written without one,
    /// before migration 0006, or had nothing to draw).
    pub async fn fit_curve(&self, fit_id: i64) -> Result<Option<FitCurve>> {
        dispatch!(self, s => s.fit_curve(fit_id).await)
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

    /// Version `version` of `model`'s fleet prior, or (`None`) its newest; `None` when there
    /// is none (fits then use the type file's, version 0).
    pub async fn fleet_prior(
        &self,
        model: &str,
        version: Option<i64>,
    ) -> Result<Option<StoredPrior>> {
        dispatch!(self, s => s.fleet_prior(model, version).await)
    }

    /// Stores `p` as the next fleet prior version and queues, in the same transaction, a refit
    /// at model version `refit_prefix` + version of every `kinds` trace of its type whose
    /// current fit used an older prior (`services::fleet_prior`).
    pub async fn publish_fleet_prior(
        &self,
        p: &NewPrior,
        kinds: &[&str],
        refit_prefix: &str,
    ) -> Result<Published> {
        dispatch!(self, s => s.publish_fleet_prior(p, kinds, refit_prefix).await)
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

    /// The pantograph's traces of `kind`, newest first (recorded time, then id), at most
    /// `limit`: the candidates of a pooled rig fit (issue 36, point 5).
    pub async fn traces_of_kind(
        &self,
        serial: &str,
        kind: &str,
        limit: i64,
    ) -> Result<Vec<TraceMeta>> {
        dispatch!(self, s => s.traces_of_kind(serial, kind, limit).await)
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

    /// Each parameter's latest informing test of each kind, of one serial or (`None`) the fleet
    /// (`param_evidence`: what the evidence and the test plan read).
    pub async fn param_evidence(&self, serial: Option<&str>) -> Result<Vec<EvidenceRow>> {
        dispatch!(self, s => s.param_evidence(serial).await)
    }

    /// The counter every write of `param_evidence` raises (a fit's refresh, its trends).
    pub async fn evidence_version(&self) -> Result<i64> {
        dispatch!(self, s => s.evidence_version().await)
    }

    /// The date of the pantograph's newest test, if it has one.
    pub async fn latest_test_at(&self, serial: &str) -> Result<Option<DateTime<Utc>>> {
        dispatch!(self, s => s.latest_test_at(serial).await)
    }

    /// Writes parameters' trends on their evidence rows (`None` clears one), in one
    /// transaction: (joint, param, trend).
    pub async fn set_param_trends(
        &self,
        serial: &str,
        trends: &[(String, String, Option<StoredTrend>)],
    ) -> Result<()> {
        dispatch!(self, s => s.set_param_trends(serial, trends).await)
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
