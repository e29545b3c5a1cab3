//! SQLite backend: one file, WAL, foreign keys on, `synchronous=FULL`; every write transaction
//! is `BEGIN IMMEDIATE`, which serialises writers and gives the job queue its claim contract.

use std::str::FromStr;
use std::time::Duration;

use chrono::{DateTime, Utc};
use sqlx::migrate::{Migrate, Migrator};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteConnection, SqliteJournalMode, SqlitePool, SqlitePoolOptions,
    SqliteRow, SqliteSynchronous,
};
use sqlx::{Row, query, query_scalar};

use super::*;

pub(crate) static MIGRATOR: Migrator = sqlx::migrate!("../migrations/sqlite");

/// Current time in the stored text format, computed by SQLite.
macro_rules! now {
    () => {
        "strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')"
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
                       max(CASE status WHEN 'alarm' THEN 3 WHEN 'watch' THEN 2 WHEN 'ok' THEN 1 ELSE 0 END) AS worst,
                       group_concat(CASE WHEN status <> 'ok' THEN joint || ':' || status END,
                                    char(31)) AS not_ok
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
                WHERE ($1 IS NULL OR agg.worst = $1) AND ($2 IS NULL OR mount.vehicle_id = $2)
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

/// SQLite implementation of the store.
#[derive(Debug, Clone)]
pub struct SqliteStore {
    pool: SqlitePool,
    /// API-key lookups sent to the database (`Store::key_lookups`).
    key_lookups: std::sync::Arc<std::sync::atomic::AtomicU64>,
}

impl SqliteStore {
    /// API-key lookups this store has sent to the database since it was opened.
    pub fn key_lookups(&self) -> u64 {
        self.key_lookups.load(std::sync::atomic::Ordering::Relaxed)
    }

    /// Opens (creating if missing) the file at `url` (a path or `sqlite:` URL) and migrates.
    /// Pool waits on a file are bounded by `pool_opts.acquire_timeout`, lock waits by the 30 s
    /// busy timeout. An in-memory database (one connection, no outage possible) keeps sqlx's
    /// 30 s acquire wait: its callers queue on the one connection by design.
    pub async fn connect(url: &str, pool_opts: PoolOptions) -> Result<Self> {
        let opts = if url.starts_with("sqlite:") {
            SqliteConnectOptions::from_str(url)?
        } else {
            SqliteConnectOptions::new().filename(url)
        };
        let opts = opts
            .create_if_missing(true)
            .journal_mode(SqliteJournalMode::Wal)
            .synchronous(SqliteSynchronous::Full)
            .foreign_keys(true)
            .busy_timeout(Duration::from_secs(30));
        let memory = url.contains(":memory:") || url.contains("mode=memory");
        let pool = if memory {
            // One connection holds the whole in-memory database: never let it go.
            SqlitePoolOptions::new()
                .max_connections(1)
                .min_connections(1)
                .idle_timeout(None)
                .max_lifetime(None)
        } else {
            SqlitePoolOptions::new()
                .max_connections(8)
                .acquire_timeout(pool_opts.acquire_timeout)
        }
        .connect_with(opts)
        .await?;
        MIGRATOR.run(&pool).await?;
        Ok(SqliteStore {
            pool,
            key_lookups: Default::default(),
        })
    }

    /// The underlying pool.
    pub fn pool(&self) -> &SqlitePool {
        &self.pool
    }

    async fn begin(&self) -> Result<sqlx::Transaction<'static, sqlx::Sqlite>> {
        Ok(self.pool.begin_with("BEGIN IMMEDIATE").await?)
    }
}

impl RowExt for SqliteRow {
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
        parse_ts_text(&self.text(c)?)
    }
    fn opt_ts(&self, c: &str) -> Result<Option<DateTime<Utc>>> {
        self.opt_text(c)?.map(|s| parse_ts_text(&s)).transpose()
    }
}

fn mount_row(r: Option<SqliteRow>) -> Result<Option<(String, DateTime<Utc>)>> {
    r.map(|r| Ok((r.text("vehicle_id")?, r.ts("since")?)))
        .transpose()
}

/// Fleet rows from `pantograph_health` with the filters `$1` (worst rank) and `$2` (current
/// vehicle); `last_test` is looked up only for the page's rows (index `traces_serial`).
macro_rules! fleet_sql {
    () => {
        concat!(
            "WITH fleet AS (
                SELECT p.serial, p.model, m.vehicle_id, h.worst, h.not_ok
                FROM pantographs p
                LEFT JOIN pantograph_mounts m ON m.serial = p.serial AND ",
            current_mount!(),
            " LEFT JOIN pantograph_health h ON h.serial = p.serial
                WHERE ($1 IS NULL OR h.worst = $1) AND ($2 IS NULL OR m.vehicle_id = $2)
            ) "
        )
    };
}

/// Rewrites the health rows (`joint_latest`, `pantograph_health`) of the trace's pantograph
/// inside the caller's transaction, which has just written a fit of the trace. `BEGIN
/// IMMEDIATE` serialises writers, so no other fit of the serial can interleave.
async fn refresh_health(conn: &mut SqliteConnection, trace_id: &str) -> Result<()> {
    let serial: Option<Option<String>> =
        query_scalar("SELECT serial FROM traces WHERE trace_id = $1")
            .bind(trace_id)
            .fetch_optional(&mut *conn)
            .await?;
    let Some(serial) = serial.flatten() else {
        return Ok(());
    };
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
                group_concat(CASE WHEN status <> 'ok' THEN joint || ':' || status END, char(31))
         FROM joint_latest WHERE serial = $1 GROUP BY serial",
    )
    .bind(&serial)
    .execute(&mut *conn)
    .await?;
    Ok(())
}

#[cfg(test)]
impl SqliteStore {
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
        let rows = |v: Vec<SqliteRow>| -> Result<Vec<LatestRow>> {
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
    conn: &mut SqliteConnection,
    trace_id: &str,
    model_version: &str,
    fit: &NewFit,
) -> Result<FitWrite> {
    let result = serde_json::to_string(&fit.result)
        .map_err(|e| StoreError::Invalid(format!("fit result: {e}")))?;
    let id: Option<i64> = query_scalar(
        "INSERT INTO fits (trace_id, model_version, result_json, rmse, status)
         VALUES ($1, $2, $3, $4, $5)
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
    refresh_health(conn, trace_id).await?;
    Ok(FitWrite {
        fit_id,
        created: true,
    })
}

impl Backend for SqliteStore {
    async fn ping(&self) -> Result<()> {
        query("SELECT 1").execute(&self.pool).await?;
        Ok(())
    }

    async fn migrations_applied(&self) -> Result<bool> {
        let mut conn = self.pool.acquire().await?;
        let table = &MIGRATOR.table_name;
        if conn.dirty_version(table).await?.is_some() {
            return Ok(false);
        }
        let applied = conn.list_applied_migrations(table).await?;
        Ok(MIGRATOR
            .iter()
            .filter(|m| m.migration_type.is_up_migration())
            .all(|m| {
                applied
                    .iter()
                    .any(|a| a.version == m.version && a.checksum == m.checksum)
            }))
    }

    async fn insert_trace(&self, t: PreparedTrace) -> Result<InsertOutcome> {
        let mut tx = self.begin().await?;
        let existing: Option<String> =
            query_scalar("SELECT content_sha256 FROM traces WHERE trace_id = $1")
                .bind(&t.trace_id)
                .fetch_optional(&mut *tx)
                .await?;
        if let Some(sha) = existing {
            tx.rollback().await?;
            return Ok(if sha == t.content_sha256 {
                InsertOutcome::Existing {
                    trace_id: t.trace_id,
                }
            } else {
                InsertOutcome::Conflict {
                    trace_id: t.trace_id,
                }
            });
        }
        query("INSERT INTO vehicles (id) VALUES ($1) ON CONFLICT (id) DO NOTHING")
            .bind(&t.vehicle_id)
            .execute(&mut *tx)
            .await?;
        let recorded = ts_text(t.recorded_at);
        if let Some(serial) = &t.serial {
            query("INSERT INTO pantographs (serial, model) VALUES ($1, $2) ON CONFLICT (serial) DO NOTHING")
                .bind(serial)
                .bind(&t.model)
                .execute(&mut *tx)
                .await?;
            let in_effect = mount_row(
                query(
                    "SELECT vehicle_id, since FROM pantograph_mounts
                     WHERE serial = $1 AND since <= $2 ORDER BY since DESC LIMIT 1",
                )
                .bind(serial)
                .bind(&recorded)
                .fetch_optional(&mut *tx)
                .await?,
            )?;
            let next = mount_row(
                query(
                    "SELECT vehicle_id, since FROM pantograph_mounts
                     WHERE serial = $1 AND since > $2 ORDER BY since ASC LIMIT 1",
                )
                .bind(serial)
                .bind(&recorded)
                .fetch_optional(&mut *tx)
                .await?,
            )?;
            let action = mount_action(
                &t.vehicle_id,
                t.recorded_at,
                in_effect.as_ref().map(|(v, s)| (v.as_str(), *s)),
                next.as_ref().map(|(v, s)| (v.as_str(), *s)),
            );
            match action {
                MountAction::Keep => {}
                MountAction::Insert => {
                    query(
                        "INSERT INTO pantograph_mounts (serial, vehicle_id, since) VALUES ($1, $2, $3)",
                    )
                    .bind(serial)
                    .bind(&t.vehicle_id)
                    .bind(&recorded)
                    .execute(&mut *tx)
                    .await?;
                }
                MountAction::MoveNext { since } => {
                    query(
                        "UPDATE pantograph_mounts SET since = $1 WHERE serial = $2 AND since = $3",
                    )
                    .bind(&recorded)
                    .bind(serial)
                    .bind(ts_text(since))
                    .execute(&mut *tx)
                    .await?;
                }
            }
        }
        query(
            "INSERT INTO traces (trace_id, vehicle_id, serial, model, recorded_at, kind, joint,
                                 test_json, content_sha256, samples, sample_count, channel_names)
             VALUES ($1, $2, $3, $4, $5, $6, $7, $8, $9, $10, $11, $12)",
        )
        .bind(&t.trace_id)
        .bind(&t.vehicle_id)
        .bind(&t.serial)
        .bind(&t.model)
        .bind(&recorded)
        .bind(&t.kind)
        .bind(&t.joint)
        .bind(&t.test_json)
        .bind(&t.content_sha256)
        .bind(&t.samples)
        .bind(t.sample_count)
        .bind(&t.channel_names)
        .execute(&mut *tx)
        .await?;
        let job_id: Option<i64> = query_scalar(
            "INSERT INTO jobs (trace_id, model_version) VALUES ($1, $2)
             ON CONFLICT DO NOTHING RETURNING id",
        )
        .bind(&t.trace_id)
        .bind(&t.model_version)
        .fetch_optional(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(InsertOutcome::Created {
            trace_id: t.trace_id,
            job_id,
        })
    }

    async fn get_trace(&self, id: &str) -> Result<Option<TraceMeta>> {
        query(
            "SELECT trace_id, vehicle_id, serial, model, recorded_at, kind, joint, test_json,
                    content_sha256, sample_count, channel_names,
                    length(samples) AS samples_bytes, created_at
             FROM traces WHERE trace_id = $1",
        )
        .bind(id)
        .fetch_optional(&self.pool)
        .await?
        .map(|r| trace_from(&r))
        .transpose()
    }

    async fn samples_blob(&self, id: &str) -> Result<Option<Vec<u8>>> {
        Ok(
            query_scalar("SELECT samples FROM traces WHERE trace_id = $1")
                .bind(id)
                .fetch_optional(&self.pool)
                .await?,
        )
    }

    async fn insert_fit(
        &self,
        trace_id: &str,
        model_version: &str,
        fit: &NewFit,
    ) -> Result<FitWrite> {
        let mut tx = self.begin().await?;
        let w = insert_fit_tx(&mut tx, trace_id, model_version, fit).await?;
        tx.commit().await?;
        Ok(w)
    }

    async fn get_fit(&self, trace_id: &str) -> Result<Option<FitRecord>> {
        let Some(row) = query(
            "SELECT id, trace_id, model_version, created_at, result_json, rmse, status
             FROM fits WHERE trace_id = $1 ORDER BY id DESC LIMIT 1",
        )
        .bind(trace_id)
        .fetch_optional(&self.pool)
        .await?
        else {
            return Ok(None);
        };
        let joints = query(
            "SELECT joint, viscous, viscous_lo, viscous_hi, dry, dry_lo, dry_hi, identifiable, status,
                    viscous_informed, viscous_status, dry_informed, dry_status
             FROM fit_joints WHERE fit_id = $1 ORDER BY joint",
        )
        .bind(row.int("id")?)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(joint_fit_from)
        .collect::<Result<Vec<_>>>()?;
        fit_from(&row, joints).map(Some)
    }

    async fn list_vehicles(&self) -> Result<Vec<VehicleSummary>> {
        query(concat!(
            "SELECT v.id, v.created_at,
                    (SELECT count(*) FROM pantograph_mounts m
                     WHERE m.vehicle_id = v.id AND ",
            current_mount!(),
            ") AS pantographs,
                    (SELECT count(*) FROM traces t WHERE t.vehicle_id = v.id) AS traces,
                    (SELECT max(t.recorded_at) FROM traces t WHERE t.vehicle_id = v.id) AS last_test
             FROM vehicles v ORDER BY v.id"
        ))
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(vehicle_from)
        .collect()
    }

    async fn get_vehicle(&self, id: &str) -> Result<Option<VehicleDetail>> {
        let Some(v) = query("SELECT id, created_at FROM vehicles WHERE id = $1")
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
        else {
            return Ok(None);
        };
        let mounted = query(concat!(
            "SELECT p.serial, p.model, m.since,
                    (SELECT max(t.recorded_at) FROM traces t WHERE t.serial = p.serial) AS last_test
             FROM pantograph_mounts m JOIN pantographs p ON p.serial = m.serial
             WHERE m.vehicle_id = $1 AND ",
            current_mount!(),
            " ORDER BY p.serial"
        ))
        .bind(id)
        .fetch_all(&self.pool)
        .await?;
        let mut points = query(concat!(
            points_cte!(
                "AND t.serial IN (SELECT m.serial FROM pantograph_mounts m
                                  WHERE m.vehicle_id = $1 AND
                                  m.since = (SELECT max(m2.since) FROM pantograph_mounts m2
                                             WHERE m2.serial = m.serial))"
            ),
            // Each joint's point is the fit that decides its health (`joint_latest`), with the
            // joint's state as fleet health and the alerts see it.
            "SELECT pts.serial, pts.vehicle_id, pts.trace_id, pts.recorded_at, pts.model_version,
                    pts.fit_id, pts.fitted_at, pts.joint, pts.viscous, pts.viscous_lo,
                    pts.viscous_hi, pts.dry, pts.dry_lo, pts.dry_hi, l.identifiable, l.status,
                    pts.viscous_informed, pts.viscous_status, pts.dry_informed, pts.dry_status
             FROM pts JOIN joint_latest l
               ON l.serial = pts.serial AND l.joint = pts.joint AND l.trace_id = pts.trace_id
             ORDER BY pts.serial, pts.joint"
        ))
        .bind(id)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(|r| Ok((r.text("serial")?, joint_point_from(r)?)))
        .collect::<Result<Vec<_>>>()?;
        let mut pantographs = Vec::with_capacity(mounted.len());
        for m in &mounted {
            let serial = m.text("serial")?;
            let joints = points
                .extract_if(.., |(s, _)| *s == serial)
                .map(|(_, p)| p)
                .collect();
            let states = self.joint_states(&serial).await?;
            pantographs.push(pantograph_state(
                serial,
                m.text("model")?,
                m.ts("since")?,
                m.opt_ts("last_test")?,
                joints,
                states,
            ));
        }
        Ok(Some(VehicleDetail {
            vehicle_id: v.text("id")?,
            created_at: v.ts("created_at")?,
            pantographs,
        }))
    }

    async fn joint_history(&self, serial: &str, joint: &str) -> Result<Vec<JointPoint>> {
        query(concat!(
            points_cte!("AND t.serial = $1 AND j.joint = $2"),
            "SELECT * FROM pts ORDER BY recorded_at, trace_id"
        ))
        .bind(serial)
        .bind(joint)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(joint_point_from)
        .collect()
    }

    async fn fleet_health(&self, filter: &FleetFilter, page: Page) -> Result<FleetPage> {
        let rank = filter.status.map(Status::rank);
        // One statement: the page, the total over all pages (a window count before the limit),
        // and `last_test` looked up for the page's rows only.
        let found = query(concat!(
            fleet_sql!(),
            ", page AS (
                SELECT fleet.*, count(*) OVER () AS total FROM fleet
                ORDER BY worst DESC NULLS LAST, serial LIMIT $3 OFFSET $4
            )
            SELECT page.*,
                   (SELECT max(t.recorded_at) FROM traces t WHERE t.serial = page.serial)
                       AS last_test
            FROM page ORDER BY worst DESC NULLS LAST, serial"
        ))
        .bind(rank)
        .bind(&filter.vehicle_id)
        .bind(i64::from(page.limit))
        .bind(i64::try_from(page.offset).unwrap_or(i64::MAX))
        .fetch_all(&self.pool)
        .await?;
        let total: i64 = match found.first() {
            Some(r) => r.int("total")?,
            // Past the last page (or nothing matches): the total needs its own count.
            None => {
                query_scalar(concat!(fleet_sql!(), "SELECT count(*) FROM fleet"))
                    .bind(rank)
                    .bind(&filter.vehicle_id)
                    .fetch_one(&self.pool)
                    .await?
            }
        };
        let rows = found
            .iter()
            .map(fleet_row_from)
            .collect::<Result<Vec<_>>>()?;
        Ok(FleetPage {
            total: u64::try_from(total).unwrap_or(0),
            rows,
        })
    }

    async fn enqueue(&self, trace_id: &str, model_version: &str) -> Result<Option<i64>> {
        let mut tx = self.begin().await?;
        let id: Option<i64> = query_scalar(
            "INSERT INTO jobs (trace_id, model_version)
             SELECT $1, $2 WHERE NOT EXISTS
                (SELECT 1 FROM fits WHERE trace_id = $1 AND model_version = $2)
             ON CONFLICT DO NOTHING RETURNING id",
        )
        .bind(trace_id)
        .bind(model_version)
        .fetch_optional(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(id)
    }

    async fn claim(&self, worker: &str, lease: Duration) -> Result<Option<Job>> {
        let now = Utc::now();
        let now_s = ts_text(now);
        let until = ts_text(now + lease_delta(lease));
        let mut tx = self.begin().await?;
        let reaped = query(concat!(
            "UPDATE jobs SET state = 'failed', lease_until = NULL, updated_at = ",
            now!(),
            ", last_error = 'lease expired ' || attempts || ' times (worker died?)'
             WHERE state = 'running' AND lease_until < $1 AND attempts >= $2"
        ))
        .bind(&now_s)
        .bind(MAX_ATTEMPTS)
        .execute(&mut *tx)
        .await?
        .rows_affected();
        let row = query(concat!(
            "UPDATE jobs SET state = 'running', attempts = attempts + 1, worker = $1,
                             lease_until = $2, updated_at = $3
             WHERE id = (SELECT id FROM jobs
                         WHERE state = 'queued' OR (state = 'running' AND lease_until < $3)
                         ORDER BY id LIMIT 1)
             RETURNING",
            job_cols!()
        ))
        .bind(worker)
        .bind(&until)
        .bind(&now_s)
        .fetch_optional(&mut *tx)
        .await?;
        tx.commit().await?;
        super::count_lease_expired(reaped);
        row.map(|r| job_from(&r)).transpose()
    }

    async fn complete(&self, job_id: i64, worker: &str, fit: &NewFit) -> Result<CompleteOutcome> {
        let mut tx = self.begin().await?;
        let Some(job) = query(
            "SELECT trace_id, model_version FROM jobs
             WHERE id = $1 AND state = 'running' AND worker = $2",
        )
        .bind(job_id)
        .bind(worker)
        .fetch_optional(&mut *tx)
        .await?
        else {
            tx.rollback().await?;
            return Ok(CompleteOutcome::LeaseLost);
        };
        let w = insert_fit_tx(
            &mut tx,
            &job.text("trace_id")?,
            &job.text("model_version")?,
            fit,
        )
        .await?;
        query(concat!(
            "UPDATE jobs SET state = 'done', lease_until = NULL, last_error = NULL, updated_at = ",
            now!(),
            " WHERE id = $1"
        ))
        .bind(job_id)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(CompleteOutcome::Completed(w))
    }

    async fn fail(
        &self,
        job_id: i64,
        worker: &str,
        error: &str,
        retry: bool,
    ) -> Result<FailOutcome> {
        let mut tx = self.begin().await?;
        let Some(attempts): Option<i64> = query_scalar(
            "SELECT attempts FROM jobs WHERE id = $1 AND state = 'running' AND worker = $2",
        )
        .bind(job_id)
        .bind(worker)
        .fetch_optional(&mut *tx)
        .await?
        else {
            tx.rollback().await?;
            return Ok(FailOutcome::LeaseLost);
        };
        let outcome = if retry && attempts < MAX_ATTEMPTS {
            FailOutcome::Requeued
        } else {
            FailOutcome::Failed
        };
        let state = match outcome {
            FailOutcome::Requeued => JobState::Queued,
            _ => JobState::Failed,
        };
        query(concat!(
            "UPDATE jobs SET state = $2, lease_until = NULL, last_error = $3, updated_at = ",
            now!(),
            " WHERE id = $1"
        ))
        .bind(job_id)
        .bind(state.as_str())
        .bind(error)
        .execute(&mut *tx)
        .await?;
        tx.commit().await?;
        Ok(outcome)
    }

    async fn release(&self, job_id: i64, worker: &str) -> Result<bool> {
        // The claim counted an attempt; a release is not a failure, so it is given back.
        let n = query(concat!(
            "UPDATE jobs SET state = 'queued', attempts = MAX(attempts - 1, 0), worker = NULL,
                             lease_until = NULL, updated_at = ",
            now!(),
            " WHERE id = $1 AND state = 'running' AND worker = $2"
        ))
        .bind(job_id)
        .bind(worker)
        .execute(&self.pool)
        .await?
        .rows_affected();
        Ok(n == 1)
    }

    async fn release_counted(&self, job_id: i64, worker: &str) -> Result<Option<JobState>> {
        // Its fit had started: the attempt the claim counted stays counted, so a fit that
        // outlasts every shutdown cannot loop for ever; at the limit the job fails (issue 18).
        let state: Option<String> = query_scalar(concat!(
            "UPDATE jobs SET state = CASE WHEN attempts >= $3 THEN 'failed' ELSE 'queued' END,
                             last_error = CASE WHEN attempts >= $3
                                 THEN 'stopped by a shutdown during each of its ' || attempts
                                      || ' attempts: its fit outlasts worker.shutdown_grace_ms'
                                 ELSE last_error END,
                             worker = NULL, lease_until = NULL, updated_at = ",
            now!(),
            " WHERE id = $1 AND state = 'running' AND worker = $2 RETURNING state"
        ))
        .bind(job_id)
        .bind(worker)
        .bind(MAX_ATTEMPTS)
        .fetch_optional(&self.pool)
        .await?;
        state.map(|s| s.parse()).transpose()
    }

    async fn renew_lease(&self, job_id: i64, worker: &str, lease: Duration) -> Result<bool> {
        let until = ts_text(Utc::now() + lease_delta(lease));
        let n = query(concat!(
            "UPDATE jobs SET lease_until = $3, updated_at = ",
            now!(),
            " WHERE id = $1 AND state = 'running' AND worker = $2"
        ))
        .bind(job_id)
        .bind(worker)
        .bind(&until)
        .execute(&self.pool)
        .await?
        .rows_affected();
        Ok(n == 1)
    }

    async fn requeue(&self, vehicle_id: Option<&str>, model_version: &str) -> Result<u64> {
        let mut tx = self.begin().await?;
        let n = query(
            "INSERT INTO jobs (trace_id, model_version)
             SELECT t.trace_id, $1 FROM traces t
             WHERE ($2 IS NULL OR t.vehicle_id = $2)
               AND NOT EXISTS (SELECT 1 FROM fits f
                               WHERE f.trace_id = t.trace_id AND f.model_version = $1)
             ORDER BY t.recorded_at, t.trace_id
             ON CONFLICT DO NOTHING",
        )
        .bind(model_version)
        .bind(vehicle_id)
        .execute(&mut *tx)
        .await?
        .rows_affected();
        tx.commit().await?;
        Ok(n)
    }

    async fn get_job(&self, id: i64) -> Result<Option<Job>> {
        query(concat!("SELECT", job_cols!(), "FROM jobs WHERE id = $1"))
            .bind(id)
            .fetch_optional(&self.pool)
            .await?
            .map(|r| job_from(&r))
            .transpose()
    }

    async fn latest_job(&self, trace_id: &str) -> Result<Option<Job>> {
        query(concat!(
            "SELECT",
            job_cols!(),
            "FROM jobs WHERE trace_id = $1 ORDER BY id DESC LIMIT 1"
        ))
        .bind(trace_id)
        .fetch_optional(&self.pool)
        .await?
        .map(|r| job_from(&r))
        .transpose()
    }

    async fn job_counts(&self) -> Result<JobCounts> {
        let mut c = JobCounts::default();
        for r in query("SELECT state, count(*) AS n FROM jobs GROUP BY state")
            .fetch_all(&self.pool)
            .await?
        {
            let n = r.int("n")?;
            match parse_enum::<JobState>(&r.text("state")?)? {
                JobState::Queued => c.queued = n,
                JobState::Running => c.running = n,
                JobState::Done => c.done = n,
                JobState::Failed => c.failed = n,
            }
        }
        Ok(c)
    }

    async fn queue_stats(&self) -> Result<QueueStats> {
        let r = query(
            "SELECT (SELECT (julianday('now') - julianday(min(created_at))) * 86400.0 FROM jobs WHERE state = 'queued') AS age,
                    (SELECT count(*) FROM webhook_deliveries WHERE state = 'pending') AS backlog",
        )
        .fetch_one(&self.pool)
        .await?;
        Ok(QueueStats {
            oldest_queued_age_s: r.try_get::<Option<f64>, _>("age")?,
            outbox_backlog: r.try_get::<i64, _>("backlog")?,
        })
    }

    async fn counts(&self) -> Result<Counts> {
        let r = query(COUNTS_SQL).fetch_one(&self.pool).await?;
        counts_from(&r)
    }

    async fn latest_trace_of_kind(&self, serial: &str, kind: &str) -> Result<Option<TraceMeta>> {
        query(
            "SELECT trace_id, vehicle_id, serial, model, recorded_at, kind, joint, test_json,
                    content_sha256, sample_count, channel_names,
                    length(samples) AS samples_bytes, created_at
             FROM traces WHERE serial = $1 AND kind = $2
             ORDER BY recorded_at DESC, trace_id DESC LIMIT 1",
        )
        .bind(serial)
        .bind(kind)
        .fetch_optional(&self.pool)
        .await?
        .map(|r| trace_from(&r))
        .transpose()
    }

    async fn pantograph_model(&self, serial: &str) -> Result<Option<String>> {
        Ok(
            query_scalar::<_, String>("SELECT model FROM pantographs WHERE serial = $1")
                .bind(serial)
                .fetch_optional(&self.pool)
                .await?,
        )
    }

    async fn pantograph_exists(&self, serial: &str) -> Result<bool> {
        let n: i64 = query_scalar("SELECT count(*) FROM pantographs WHERE serial = $1")
            .bind(serial)
            .fetch_one(&self.pool)
            .await?;
        Ok(n > 0)
    }

    async fn insert_api_key(
        &self,
        prefix: &str,
        hash: &str,
        role: Role,
        label: &str,
    ) -> Result<ApiKey> {
        let r = query(
            "INSERT INTO api_keys (prefix, key_sha256, role, label) VALUES ($1, $2, $3, $4)
             RETURNING id, prefix, role, label, created_at, revoked_at",
        )
        .bind(prefix)
        .bind(hash)
        .bind(role.as_str())
        .bind(label)
        .fetch_one(&self.pool)
        .await?;
        api_key_from(&r)
    }

    async fn keys_by_prefix(&self, prefix: &str) -> Result<Vec<(ApiKey, String)>> {
        self.key_lookups
            .fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        query(
            "SELECT id, prefix, role, label, created_at, revoked_at, key_sha256 FROM api_keys
             WHERE prefix = $1 AND revoked_at IS NULL",
        )
        .bind(prefix)
        .fetch_all(&self.pool)
        .await?
        .iter()
        .map(|r| Ok((api_key_from(r)?, r.text("key_sha256")?)))
        .collect()
    }

    async fn revoke_api_key(&self, id: i64) -> Result<bool> {
        let n = query(concat!(
            "UPDATE api_keys SET revoked_at = ",
            now!(),
            " WHERE id = $1 AND revoked_at IS NULL"
        ))
        .bind(id)
        .execute(&self.pool)
        .await?
        .rows_affected();
        Ok(n > 0)
    }

    async fn list_api_keys(&self) -> Result<Vec<ApiKey>> {
        query("SELECT id, prefix, role, label, created_at, revoked_at FROM api_keys ORDER BY id")
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(api_key_from)
            .collect()
    }

    async fn joint_states(&self, serial: &str) -> Result<Vec<JointState>> {
        query(JOINT_STATES_SQL)
            .bind(serial)
            .fetch_all(&self.pool)
            .await?
            .iter()
            .map(joint_state_from)
            .collect()
    }

    async fn serial_history(&self, serial: &str) -> Result<Vec<JointPoint>> {
        self.a_serial_history(serial).await
    }

    async fn raise_alert(&self, a: &NewAlert) -> Result<RaiseOutcome> {
        self.a_raise(a).await
    }

    async fn acknowledge_alert(&self, id: i64, actor: &str, note: &str) -> Result<Transition> {
        self.a_acknowledge(id, actor, note).await
    }

    async fn resolve_alert(
        &self,
        target: Target<'_>,
        actor: &str,
        note: &str,
        trace_id: Option<&str>,
    ) -> Result<Transition> {
        self.a_resolve(target, actor, note, trace_id).await
    }

    async fn list_alerts(&self, f: &AlertFilter) -> Result<Vec<Alert>> {
        self.a_list(f).await
    }

    async fn get_alert(&self, id: i64) -> Result<Option<Alert>> {
        self.a_get(id).await
    }

    async fn alert_events(&self, id: i64) -> Result<Vec<AlertEvent>> {
        self.a_events(id).await
    }

    async fn insert_webhook(&self, url: &str, severities: &str, secret: &str) -> Result<Webhook> {
        self.w_insert(url, severities, secret).await
    }

    async fn list_webhooks(&self) -> Result<Vec<Webhook>> {
        self.w_list().await
    }

    async fn delete_webhook(&self, id: i64) -> Result<bool> {
        self.w_delete(id).await
    }

    async fn claim_deliveries(&self, limit: i64, lease: Duration) -> Result<Vec<DueDelivery>> {
        self.w_claim(limit, lease).await
    }

    async fn finish_delivery(&self, id: i64, attempts: i64, r: &AttemptResult) -> Result<bool> {
        self.w_finish(id, attempts, r).await
    }

    async fn list_deliveries(&self, webhook_id: i64, limit: i64) -> Result<Vec<Delivery>> {
        self.w_deliveries(webhook_id, limit).await
    }

    async fn close(&self) {
        self.pool.close().await;
    }
}
