//! PostgreSQL backend: timestamps are `timestamptz` set by the server clock, fit results JSONB;
//! the job queue claims with `FOR UPDATE SKIP LOCKED` so concurrent workers never wait or collide.
//! Here: the connection, migrations, transactions and locking, the claim, and the dialect the
//! shared SQL (`sql/`, see its module doc) names; the logic itself is instantiated at the end.

use std::time::Duration;

use chrono::{DateTime, Utc};
use sqlx::migrate::{Migrate, Migrator};
use sqlx::postgres::{PgConnectOptions, PgConnection, PgPool, PgPoolOptions, PgRow, PgSslMode};
use sqlx::{Row, query, query_scalar};

use super::alerts::*;
use super::*;

pub(crate) static MIGRATOR: Migrator = sqlx::migrate!("../migrations/postgres");

type Backend = PgStore;
type Conn = PgConnection;
#[cfg(test)]
type DbRow = PgRow;

/// A timestamp as PostgreSQL binds it: `timestamptz`.
fn ts(t: DateTime<Utc>) -> DateTime<Utc> {
    t
}

/// A lease's length in seconds, bound as `lease_until!()`'s `$3` (the server clock adds it).
fn lease_param(lease: Duration) -> f64 {
    lease.as_secs_f64()
}

/// Locks the pantograph's row: uploads and fit refreshes of one serial run one after the other.
async fn lock_serial(c: &mut Conn, serial: &str) -> Result<()> {
    query("SELECT serial FROM pantographs WHERE serial = $1 FOR UPDATE")
        .bind(serial)
        .execute(&mut *c)
        .await?;
    Ok(())
}

/// Serialises raises of one (serial, joint) on a transaction-scoped advisory lock.
async fn lock_alert_pair(c: &mut Conn, serial: &str, joint: &str) -> Result<()> {
    query("SELECT pg_advisory_xact_lock(hashtextextended($1 || '/' || $2, 0))")
        .bind(serial)
        .bind(joint)
        .execute(&mut *c)
        .await?;
    Ok(())
}

/// Current time, from the server clock (the same clock for every worker).
macro_rules! now {
    () => {
        "now()"
    };
}

/// Row locks taken by the reads that precede a write in one transaction.
macro_rules! for_update {
    () => {
        " FOR UPDATE"
    };
}
/// Deliveries due: claimed without waiting for another sender's rows.
macro_rules! claim_lock {
    () => {
        " FOR UPDATE OF d SKIP LOCKED"
    };
}

/// JSON is stored as JSONB; timestamps bound as `Option` need their type named.
macro_rules! jsonb {
    () => {
        "::jsonb"
    };
}
macro_rules! ts_cast {
    () => {
        "::timestamptz"
    };
}

macro_rules! blob_len {
    () => {
        "octet_length(samples)::bigint"
    };
}

/// A pantograph's joints that are not `ok`, as `joint:status` joined by U+001F.
macro_rules! not_ok_agg {
    () => {
        "string_agg(CASE WHEN status <> 'ok' THEN joint || ':' || status END, chr(31))"
    };
}

/// Seconds since the oldest `created_at` of the rows aggregated.
macro_rules! queued_age {
    () => {
        "EXTRACT(EPOCH FROM now() - min(created_at))::float8"
    };
}

/// A renewed lease's end: `$3` seconds from now, by the server clock.
macro_rules! lease_until {
    () => {
        "now() + make_interval(secs => $3)"
    };
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
    /// `pantowatch-tools bench suite --only ingest`). Any other host keeps sqlx's default; production
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

    /// Fails the jobs whose lease ran out at the attempt limit, then leases the oldest queued
    /// (or expired) job; `FOR UPDATE SKIP LOCKED`: concurrent workers never wait or collide.
    async fn claim_job(&self, worker: &str, lease: Duration) -> Result<Option<Job>> {
        let mut tx = self.begin().await?;
        let reaped = query(
            "UPDATE jobs SET state = 'failed', lease_until = NULL, updated_at = now(),
                             last_error = 'lease expired ' || attempts || ' times (worker died?)'
             WHERE id IN (SELECT id FROM jobs
                          WHERE state = 'running' AND lease_until < now() AND attempts >= $1
                          FOR UPDATE SKIP LOCKED)",
        )
        .bind(MAX_ATTEMPTS)
        .execute(&mut *tx)
        .await?
        .rows_affected();
        let row = query(concat!(
            "UPDATE jobs SET state = 'running', attempts = attempts + 1, worker = $1,
                             lease_until = now() + make_interval(secs => $2), updated_at = now()
             WHERE id = (SELECT id FROM jobs
                         WHERE state = 'queued'
                            OR (state = 'running' AND lease_until < now() AND attempts < $3)
                         ORDER BY id LIMIT 1
                         FOR UPDATE SKIP LOCKED)
             RETURNING",
            job_cols!()
        ))
        .bind(worker)
        .bind(lease.as_secs_f64())
        .bind(MAX_ATTEMPTS)
        .fetch_optional(&mut *tx)
        .await?;
        tx.commit().await?;
        super::count_lease_expired(reaped);
        row.map(|r| job_from(&r)).transpose()
    }
}

/// A stored timestamp (`timestamptz`) read back.
fn read_ts(t: DateTime<Utc>) -> Result<DateTime<Utc>> {
    Ok(t)
}
row_ext_impl!(PgRow, DateTime<Utc>);

traces_impl!();
jobs_impl!();
health_impl!();
keys_impl!();
alerts_impl!();
priors_impl!();

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
