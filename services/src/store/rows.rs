//! Rows to records, shared by both backends: column accessors (`RowExt`; SQLite keeps
//! timestamps as text) and one mapper per record.

use super::*;

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

pub(crate) fn parse_enum<T: FromStr<Err: std::fmt::Display>>(s: &str) -> Result<T> {
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
    Ok(FitRecord {
        id: r.int("id")?,
        trace_id: r.text("trace_id")?,
        model_version: r.text("model_version")?,
        created_at: r.ts("created_at")?,
        result_json: r.text("result_json")?,
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
        worst_status: r.opt_int("worst")?.map(status_from_rank).transpose()?,
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

/// Rewrites `param_evidence` for the serial `$1` (both dialects; migration 0008 holds the same
/// rule as text): each parameter's latest informing test of each kind. Trends are cleared and
/// written again by the service after the fit (`alerts::after_fit`).
pub(crate) const PARAM_EVIDENCE_REFRESH_SQL: &str = concat!(
    "INSERT INTO param_evidence (serial, joint, param, trace_id, fit_id, kind, recorded_at, value, lo, hi, status)
     SELECT serial, joint, param, trace_id, fit_id, kind, recorded_at, value, lo, hi, status FROM (
        SELECT o.*, ROW_NUMBER() OVER (PARTITION BY joint, param, kind
                                       ORDER BY recorded_at DESC, trace_id DESC) AS rn
        FROM (",
    evidence_select!("viscous"),
    " UNION ALL ",
    evidence_select!("dry"),
    ") o
     ) x WHERE rn = 1"
);

/// The SQL of [`Store::param_evidence`] (both backends); `$1` a serial or NULL for the fleet.
pub(crate) const PARAM_EVIDENCE_SQL: &str = "SELECT e.serial, p.model, e.joint, e.param,
        e.trace_id, e.fit_id, e.kind, e.recorded_at, e.value, e.lo, e.hi, e.status,
        e.slope_per_day, e.slope_lo_per_day, e.slope_hi_per_day, e.slope_significant
    FROM param_evidence e JOIN pantographs p ON p.serial = e.serial
    WHERE e.serial = $1 OR $1 IS NULL";

pub(crate) fn evidence_row_from<R: RowExt>(r: &R) -> Result<EvidenceRow> {
    let trend = match (
        r.opt_real("slope_per_day")?,
        r.opt_real("slope_lo_per_day")?,
        r.opt_real("slope_hi_per_day")?,
        r.opt_flag("slope_significant")?,
    ) {
        (Some(s), Some(lo), Some(hi), Some(sig)) => Some(StoredTrend {
            slope_per_day: s,
            slope_ci95: [lo, hi],
            significant: sig,
        }),
        _ => None,
    };
    Ok(EvidenceRow {
        serial: r.text("serial")?,
        model: r.text("model")?,
        joint: r.text("joint")?,
        param: r.text("param")?,
        trace_id: r.text("trace_id")?,
        fit_id: r.int("fit_id")?,
        kind: r.text("kind")?,
        recorded_at: r.ts("recorded_at")?,
        value: r.opt_real("value")?.unwrap_or(f64::NAN),
        ci95: [
            r.opt_real("lo")?.unwrap_or(f64::NAN),
            r.opt_real("hi")?.unwrap_or(f64::NAN),
        ],
        status: parse_enum(&r.text("status")?)?,
        trend,
    })
}

/// A pantograph mount read back: (vehicle, since).
pub(crate) fn mount_row<R: RowExt>(r: Option<R>) -> Result<Option<(String, DateTime<Utc>)>> {
    r.map(|r| Ok((r.text("vehicle_id")?, r.ts("since")?)))
        .transpose()
}

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

/// One `fleet_prior_params` row.
pub(crate) fn prior_param_from<R: RowExt>(
    r: &R,
) -> Result<pantowatch_models::lift::fleet_prior::ParamPrior> {
    let real = |c: &str| -> Result<f64> { Ok(r.opt_real(c)?.unwrap_or(f64::NAN)) };
    Ok(pantowatch_models::lift::fleet_prior::ParamPrior {
        joint: r.text("joint")?,
        kind: r.text("param")?,
        mean_ratio: real("mean_ratio")?,
        sd_ratio: real("sd_ratio")?,
        spread_ratio: real("spread_ratio")?,
        n_fits: usize::try_from(r.int("n_fits")?).unwrap_or(0),
        learned: r.flag("learned")?,
    })
}
