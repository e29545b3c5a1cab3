//! The store's SQL and logic, written once for both backends (issue 19, point 2): one file per
//! concern, each a `macro_rules!` body that `sqlite.rs` and `postgres.rs` instantiate
//! (`traces_impl!();` …; `row_ext_impl!` for the row type). The body names the backend's
//! dialect, defined in the instantiating file: the types `Backend`, `Conn`, `DbRow` (tests
//! only); `ts` (a timestamp as the backend binds it), `read_ts` and `lease_param`;
//! `lock_serial`, `lock_alert_pair` (PostgreSQL row and advisory locks; no-ops under SQLite's
//! `BEGIN IMMEDIATE`); `Backend::claim_job`; and SQL fragments as macros, so every statement
//! stays a `concat!` of literals: `now!`, `for_update!`, `claim_lock!`, `jsonb!`, `ts_cast!`,
//! `blob_len!`, `not_ok_agg!`, `queued_age!`, `lease_until!`, `fleet_sql!`.
//!
//! Why macros and not a generic `impl<DB: sqlx::Database>`: the two backends bind different
//! timestamp types and need SQL fragments spliced into constant statements (sqlx 0.9 accepts
//! only `&'static str` without `AssertSqlSafe`), which `concat!` can do and associated consts
//! cannot; the macro body is the single copy of each statement and each step.

/// Every joint point from each trace's current fit; `$extra` narrows the trace/joint set.
/// `rn = 1` is a joint's latest *informed* verdict (a test that could not identify the joint — a
/// lift for J2, say — does not hide the last test that could), else its latest.
macro_rules! points_cte {
    ($extra:literal) => {
        concat!(
            "WITH cur AS (
                SELECT f.id, f.trace_id, f.model_version, f.created_at
                FROM fits f
                WHERE f.id = (SELECT max(f2.id) FROM fits f2 WHERE f2.trace_id = f.trace_id)
            ),
            pts AS (
                SELECT t.serial, t.vehicle_id, t.trace_id, t.recorded_at, cur.model_version,
                       cur.id AS fit_id, cur.created_at AS fitted_at,
                       j.joint, j.viscous, j.viscous_lo, j.viscous_hi, j.dry, j.dry_lo, j.dry_hi,
                       j.identifiable, j.status, j.viscous_informed, j.viscous_status,
                       j.dry_informed, j.dry_status,
                       ROW_NUMBER() OVER (PARTITION BY t.serial, j.joint
                                          ORDER BY j.identifiable DESC, t.recorded_at DESC, t.trace_id DESC) AS rn
                FROM cur
                JOIN traces t ON t.trace_id = cur.trace_id
                JOIN fit_joints j ON j.fit_id = cur.id
                WHERE t.serial IS NOT NULL ",
            $extra,
            ") "
        )
    };
}

/// The mount in effect now for each serial.
macro_rules! current_mount {
    () => {
        "m.since = (SELECT max(m2.since) FROM pantograph_mounts m2 WHERE m2.serial = m.serial)"
    };
}

/// Fleet rows with the filters `$1` (worst rank) and `$2` (current vehicle), by a window over
/// every fit: the definition `pantograph_health` is kept equal to (tests compare the two).
#[cfg(test)]
macro_rules! fleet_cte {
    () => {
        concat!(
            points_cte!(""),
            ", latest AS (SELECT serial, joint, status FROM (",
            joint_state_select!("t.serial IS NOT NULL"),
            ") s),
            agg AS (
                SELECT serial,
                       CAST(max(CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2 WHEN 'ok' THEN 1 ELSE 0 END)
                            AS BIGINT) AS worst, ",
            not_ok_agg!(),
            " AS not_ok
                FROM latest GROUP BY serial
            ),
            mount AS (SELECT m.serial, m.vehicle_id FROM pantograph_mounts m WHERE ",
            current_mount!(),
            "),
            lt AS (SELECT serial, max(recorded_at) AS last_test FROM traces
                   WHERE serial IS NOT NULL GROUP BY serial),
            fleet AS (
                SELECT p.serial, p.model, mount.vehicle_id, agg.worst, agg.not_ok, lt.last_test
                FROM pantographs p
                LEFT JOIN mount ON mount.serial = p.serial
                LEFT JOIN agg ON agg.serial = p.serial
                LEFT JOIN lt ON lt.serial = p.serial
                WHERE (CAST($1 AS BIGINT) IS NULL OR agg.worst = CAST($1 AS BIGINT))
                  AND (CAST($2 AS TEXT) IS NULL OR mount.vehicle_id = CAST($2 AS TEXT))
            ) "
        )
    };
}

/// `RowExt` for the backend's row type `$row`: each column by `try_get`; a timestamp read as
/// the backend stores it (`$ts`), then by the backend's `read_ts`.
macro_rules! row_ext_impl {
    ($row:ty, $ts:ty) => {
        impl RowExt for $row {
            fn text(&self, c: &str) -> Result<String> {
                Ok(self.try_get(c)?)
            }
            fn opt_text(&self, c: &str) -> Result<Option<String>> {
                Ok(self.try_get(c)?)
            }
            fn int(&self, c: &str) -> Result<i64> {
                Ok(self.try_get(c)?)
            }
            fn opt_int(&self, c: &str) -> Result<Option<i64>> {
                Ok(self.try_get(c)?)
            }
            fn opt_real(&self, c: &str) -> Result<Option<f64>> {
                Ok(self.try_get(c)?)
            }
            fn flag(&self, c: &str) -> Result<bool> {
                Ok(self.try_get(c)?)
            }
            fn opt_flag(&self, c: &str) -> Result<Option<bool>> {
                Ok(self.try_get(c)?)
            }
            fn ts(&self, c: &str) -> Result<DateTime<Utc>> {
                read_ts(self.try_get::<$ts, _>(c)?)
            }
            fn opt_ts(&self, c: &str) -> Result<Option<DateTime<Utc>>> {
                self.try_get::<Option<$ts>, _>(c)?.map(read_ts).transpose()
            }
        }
    };
}

macro_rules! job_cols {
    () => {
        " id, trace_id, model_version, state, attempts, lease_until, worker, last_error,
          created_at, updated_at "
    };
}

#[macro_use]
mod alerts;
#[macro_use]
mod health;
#[macro_use]
mod jobs;
#[macro_use]
mod keys;
#[macro_use]
mod priors;
#[macro_use]
mod traces;
