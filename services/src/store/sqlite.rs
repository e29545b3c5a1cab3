//! SQLite backend: one file, WAL, foreign keys on, `synchronous=FULL`; every write transaction
//! is `BEGIN IMMEDIATE`, which serialises writers and gives the job queue its claim contract.
//! Here: the connection, migrations, transactions and locking, the claim, and the dialect the
//! shared SQL (`sql/`, see its module doc) names; the logic itself is instantiated at the end.

use std::str::FromStr;
use std::time::Duration;

use chrono::{DateTime, Utc};
use sqlx::migrate::{Migrate, Migrator};
use sqlx::sqlite::{
    SqliteConnectOptions, SqliteConnection, SqliteJournalMode, SqlitePool, SqlitePoolOptions,
    SqliteRow, SqliteSynchronous,
};
use sqlx::{Row, query, query_scalar};

use super::alerts::*;
use super::*;

pub(crate) static MIGRATOR: Migrator = sqlx::migrate!("../migrations/sqlite");

type Backend = SqliteStore;
type Conn = SqliteConnection;
#[cfg(test)]
type DbRow = SqliteRow;

/// A timestamp as SQLite stores it: fixed-width UTC text (text order = time order).
fn ts(t: DateTime<Utc>) -> String {
    ts_text(t)
}

/// The end of a lease from now, bound as `lease_until!()`'s `$3`.
fn lease_param(lease: Duration) -> String {
    ts_text(Utc::now() + lease_delta(lease))
}

/// `BEGIN IMMEDIATE` already serialises every writer: no row lock to take.
async fn lock_serial(_: &mut Conn, _: &str) -> Result<()> {
    Ok(())
}

/// `BEGIN IMMEDIATE` already serialises every raise.
async fn lock_alert_pair(_: &mut Conn, _: &str, _: &str) -> Result<()> {
    Ok(())
}

/// Current time in the stored text format, computed by SQLite.
macro_rules! now {
    () => {
        "strftime('%Y-%m-%dT%H:%M:%f000Z', 'now')"
    };
}

/// Row locks (none: the transaction holds the write lock).
macro_rules! for_update {
    () => {
        ""
    };
}
macro_rules! claim_lock {
    () => {
        ""
    };
}

/// JSON is stored as text: no cast.
macro_rules! jsonb {
    () => {
        ""
    };
}
macro_rules! ts_cast {
    () => {
        ""
    };
}

macro_rules! blob_len {
    () => {
        "length(samples)"
    };
}

/// A pantograph's joints that are not `ok`, as `joint:status` joined by U+001F.
macro_rules! not_ok_agg {
    () => {
        "group_concat(CASE WHEN status <> 'ok' THEN joint || ':' || status END, char(31))"
    };
}

/// Seconds since the oldest `created_at` of the rows aggregated.
macro_rules! queued_age {
    () => {
        "(julianday('now') - julianday(min(created_at))) * 86400.0"
    };
}

/// A renewed lease's end: `$3`, computed by [`lease_param`].
macro_rules! lease_until {
    () => {
        "$3"
    };
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

    /// Fails the jobs whose lease ran out at the attempt limit, then leases the oldest queued
    /// (or expired) job: one `BEGIN IMMEDIATE` transaction, so two workers never share a job.
    async fn claim_job(&self, worker: &str, lease: Duration) -> Result<Option<Job>> {
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
}

/// A stored timestamp (text) read back.
fn read_ts(s: String) -> Result<DateTime<Utc>> {
    parse_ts_text(&s)
}
row_ext_impl!(SqliteRow, String);

traces_impl!();
jobs_impl!();
health_impl!();
keys_impl!();
alerts_impl!();
priors_impl!();
