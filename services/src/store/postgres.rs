//! PostgreSQL backend: timestamps are `timestamptz` set by the server clock, fit results JSONB;
//! the job queue claims with `FOR UPDATE SKIP LOCKED` so concurrent workers never wait or collide.

use std::time::Duration;

use chrono::{DateTime, Utc};
use sqlx::migrate::{Migrate, Migrator};
use sqlx::postgres::{PgConnectOptions, PgConnection, PgPool, PgPoolOptions, PgRow, PgSslMode};
use sqlx::{Row, query, query_scalar};

use super::*;

pub(crate) static MIGRATOR: Migrator = sqlx::migrate!("../migrations/postgres");

/// Current time, from the server clock (the same clock for every worker).
macro_rules! now {
    () => {
        "now()"
    };
}

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
                       max(CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2 WHEN 'ok' THEN 1 ELSE 0 END)::bigint
                           AS worst,
                       string_agg(CASE WHEN status <> 'ok' THEN joint || ':' || status END,
                                  chr(31)) AS not_ok
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
                WHERE ($1::bigint IS NULL OR agg.worst = $1::bigint)
                  AND ($2::text IS NULL OR mount.vehicle_id = $2::text)
            ) "
        )
    };
}

macro_rules! job_cols {
    () => {
        " id, trace_id, model_version, state, attempts, lease_until, worker, last_error,
          created_at, updated_at "
    };
}

/// `localhost`, a loopback address, or a Unix socket directory.
fn is_loopback(host: &str) -> bool {
    host == "localhost"
        || host.starts_with('/')
        || host
            .trim_matches(|c| c == '[' || c == ']')
            .parse::<std::net::IpAddr>()
            .is_ok_and(|ip| ip.is_loopback())
}

/// PostgreSQL implementation of the store.
#[derive(Debug, Clone)]
pub struct PgStore {
    pool: PgPool,
    /// API-key lookups sent to the database (`Store::key_lookups`).
    key_lookups: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl PgStore {
    /// API-key lookups this store has sent to the database since it was opened.
    pub fn key_lookups(&self) -> u64 {
        self.key_lookups.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Connects to the `postgres://` URL and migrates (concurrent migrators take a lock).
    /// While the server is down every operation fails after `opts.acquire_timeout`; pooled
    /// connections are tested before use, so the pool heals by itself when it is back.
    ///
    /// TLS follows the URL's `sslmode`. A URL without one to a loopback host gets
    /// `sslmode=disable`: sqlx's default (`prefer`) negotiates TLS wherever the server offers it,
    /// which protects nothing on loopback and cost the ingest path 3.6× (57 against 205 traces/s,
    /// `pantowatch bench suite --only ingest`). Any other host keeps sqlx's default; production
    /// sets `sslmode=verify-full` (SECURITY.md).
    pub async fn connect(url: &str, opts: PoolOptions) -> Result<Self> {
        let mut connect: PgConnectOptions = url.parse()?;
        if !url.contains("sslmode=") && is_loopback(connect.get_host()) {
            connect = connect.ssl_mode(PgSslMode::Disable);
        }
        let pool = PgPoolOptions::new()
            .max_connections(10)
            .acquire_timeout(opts.acquire_timeout)
            .connect_with(connect)
            .await?;
        MIGRATOR.run(&pool).await?;
        Ok(PgStore {
            pool,
            key_lookups: Default::default(),
        })
    }

    /// The underlying pool.
    pub fn pool(&self) -> &PgPool {
        &self.pool
    }

    async fn begin(&self) -> Result<sqlx::Transaction<'static, sqlx::Postgres>> {
        Ok(self.pool.begin().await?)
    }
}

impl RowExt for PgRow {
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
        Ok(self.try_get(c)?)
    }
    fn opt_ts(&self, c: &str) -> Result<Option<DateTime<Utc>>> {
        Ok(self.try_get(c)?)
    }
}

fn mount_row(r: Option<PgRow>) -> Result<Option<(String, DateTime<Utc>)>> {
    r.map(|r| Ok((r.text("vehicle_id")?, r.ts("since")?)))
        .transpose()
}

/// Fleet rows from `pantograph_health` with the filters `$1` (worst rank) and `$2` (current
/// vehicle); the current mount by `DISTINCT ON`, one index scan.
macro_rules! fleet_sql {
    () => {
        concat!(
            "WITH mount AS (
                SELECT DISTINCT ON (serial) serial, vehicle_id FROM pantograph_mounts
                ORDER BY serial, since DESC
            ),
            fleet AS (
                SELECT p.serial, p.model, m.vehicle_id, h.worst, h.not_ok
                FROM pantographs p
                LEFT JOIN mount m ON m.serial = p.serial
                LEFT JOIN pantograph_health h ON h.serial = p.serial
                WHERE ($1::bigint IS NULL OR h.worst = $1::bigint)
                  AND ($2::text IS NULL OR m.vehicle_id = $2::text)
            ) "
        )
    };
}

/// Rewrites the health rows (`joint_latest`, `pantograph_health`) of the trace's pantograph
/// inside the caller's transaction, which has just written a fit of the trace. The pantograph
/// row is locked first, so fits of one serial written concurrently refresh one after the other
/// and the later one (READ COMMITTED: a fresh snapshot per statement) sees the earlier fit.
async fn refresh_health(conn: &mut PgConnection, trace_id: &str) -> Result<()> {
    let serial: Option<Option<String>> =
        query_scalar("SELECT serial FROM traces WHERE trace_id = $1")
            .bind(trace_id)
            .fetch_optional(&mut *conn)
            .await?;
    let Some(serial) = serial.flatten() else {
        return Ok(());
    };
    query("SELECT serial FROM pantographs WHERE serial = $1 FOR UPDATE")
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query("DELETE FROM joint_latest WHERE serial = $1")
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query(JOINT_LATEST_REFRESH_SQL)
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query("DELETE FROM pantograph_health WHERE serial = $1")
        .bind(&serial)
        .execute(&mut *conn)
        .await?;
    query(
        "INSERT INTO pantograph_health (serial, worst, not_ok)
         SELECT serial,
                max(CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2 WHEN 'ok' THEN 1 ELSE 0 END),
                string_agg(CASE WHEN status <> 'ok' THEN joint || ':' || status END, chr(31))
         FROM joint_latest WHERE serial = $1 GROUP BY serial",
    )
    .bind(&serial)
    .execute(&mut *conn)
    .await?;
    Ok(())
}

#[cfg(test)]
impl PgStore {
    /// The fleet health by the window over every fit (the pre-0004 query), for the tests.
    pub(crate) async fn fleet_health_by_window(
        &self,
        filter: &FleetFilter,
        page: Page,
    ) -> Result<FleetPage> {
        let rank = filter.status.map(Status::rank);
        let total: i64 = query_scalar(concat!(fleet_cte!(), "SELECT count(*) FROM fleet"))
            .bind(rank)
            .bind(&filter.vehicle_id)
            .fetch_one(&self.pool)
            .await?;
        let rows = query(concat!(
            fleet_cte!(),
            "SELECT * FROM fleet ORDER BY worst DESC NULLS LAST, serial LIMIT $3 OFFSET $4"
        ))
        .bind(rank)
        .bind(&filter.vehicle_id)
        .bind(i64::from(page.limit))
        .bind(i64::try_from(page.offset).unwrap_or(i64::MAX))
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(fleet_row_from)
        .collect::<Result<Vec<_>>>()?;
        Ok(FleetPage {
            total: u64::try_from(total).unwrap_or(0),
            rows,
        })
    }

    /// Each joint's latest state by the window (left) and from `joint_latest` (right), sorted.
    pub(crate) async fn latest_both_ways(&self) -> Result<(Vec<LatestRow>, Vec<LatestRow>)> {
        let window = query(concat!(
            "SELECT serial, joint, trace_id, fit_id, status FROM (",
            joint_state_select!("t.serial IS NOT NULL"),
            ") s ORDER BY serial, joint"
        ))
        .fetch_all(&self.pool)
        .await?;
        let table = query(
            "SELECT serial, joint, trace_id, fit_id, status FROM joint_latest ORDER BY serial, joint",
        )
        .fetch_all(&self.pool)
        .await?;
        let rows = |v: Vec<PgRow>| -> Result<Vec<LatestRow>> {
            v.iter()
                .map(|r| {
                    Ok((
                        r.text("serial")?,
                        r.text("joint")?,
                        r.text("trace_id")?,
                        r.int("fit_id")?,
                        r.text("status")?,
                    ))
                })
                .collect()
        };
        Ok((rows(window)?, rows(table)?))
    }
}

/// Writes the fit for (trace, model version) once, inside the caller's transaction.
async fn insert_fit_tx(
    conn: &mut PgConnection,
    trace_id: &str,
    model_version: &str,
    fit: &NewFit,
) -> Result<FitWrite> {
    let result = serde_json::to_string(&fit.result)
        .map_err(|e| StoreError::Invalid(format!("fit result: {e}")))?;
    let id: Option<i64> = query_scalar(
        "INSERT INTO fits (trace_id, model_version, result_json, rmse, status)
         VALUES ($1, $2, $3::jsonb, $4, $5)
         ON CONFLICT (trace_id, model_version) DO NOTHING
         RETURNING id",
    )
    .bind(trace_id)
    .bind(model_version)
    .bind(result)
    .bind(fit.rmse)
    .bind(fit.status().map(Status::as_str))
    .fetch_optional(&mut *conn)
    .await?;
    let Some(fit_id) = id else {
        let fit_id: i64 =
            query_scalar("SELECT id FROM fits WHERE trace_id = $1 AND model_version = $2")
                .bind(trace_id)
                .bind(model_version)
                .fetch_one(&mut *conn)
                .await?;
        return Ok(FitWrite {
            fit_id,
            created: false,
        });
    };
    for j in &fit.joints {
        query(
            "INSERT INTO fit_joints (fit_id, joint, viscous, viscous_lo, viscous_hi,
                                     dry, dry_lo, dry_hi, identifiable, status,
                                     viscous_informed, viscous_status, dry_informed, dry_status)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12, $13, $14)",
        )
        .bind(fit_id)
        .bind(&j.joint)
        .bind(j.viscous)
        .bind(j.viscous_lo)
        .bind(j.viscous_hi)
        .bind(j.dry)
        .bind(j.dry_lo)
        .bind(j.dry_hi)
        .bind(j.identifiable)
        .bind(j.status.as_str())
        .bind(j.viscous_informed)
        .bind(j.viscous_status.map(Status::as_str))
        .bind(j.dry_informed)
        .bind(j.dry_status.map(Status::as_str))
        .execute(&mut *conn)
        .await?;
    }
    if let Some(curve) = &fit.curve {
        let json = serde_json::to_string(curve)
            .map_err(|e| StoreError::Invalid(format!("fit curve: {e}")))?;
        query("INSERT INTO fit_curves (fit_id, curve_json) VALUES ($1, $2::jsonb)")
            .bind(fit_id)
            .bind(json)
            .execute(&mut *conn)
            .await?;
    }
    refresh_health(conn, trace_id).await?;
    Ok(FitWrite {
        fit_id,
        created: true,
    })
}

mod alerts;
mod health;
mod jobs;
mod keys;
mod traces;

#[cfg(test)]
mod loopback_tests {
    use super::is_loopback;

    #[test]
    fn only_local_hosts_are_loopback() {
        for h in [
            "localhost",
            "127.0.0.1",
            "127.0.0.2",
            "::1",
            "[::1]",
            "/var/run/postgresql",
        ] {
            assert!(is_loopback(h), "{h}");
        }
        for h in ["db", "10.0.0.5", "db.example.org", "::2", ""] {
            assert!(!is_loopback(h), "{h}");
        }
    }
}
