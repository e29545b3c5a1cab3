//! Contract suite of the store, run twice: on a fresh SQLite file and on a fresh PostgreSQL
//! database (`PANTOWATCH_TEST_PG_URL`, default local trust auth; unreachable = test failure).

use std::collections::{BTreeMap, HashSet};
use std::sync::Arc;
use std::time::Duration;

use chrono::{DateTime, Utc};
use pantowatch_models::report::{FitResult, JointResult, ParamResult, Quantity, ResidualResult};
use serde_json::json;
use sqlx::{AssertSqlSafe, Connection, Executor};

use super::*;

mod alerts;
mod api_keys;
mod health;
mod jobs;
mod results;
mod traces;
use alerts::*;
use api_keys::*;
use health::*;
use jobs::*;
use traces::*;

const DEFAULT_PG: &str = "postgres://postgres@127.0.0.1:5432/postgres";

/// A store on a throw-away database; the database is removed when this is dropped.
struct TestDb {
    store: Store,
    _dir: Option<tempfile::TempDir>,
    _pg: Option<PgDrop>,
}

struct PgDrop {
    admin_url: String,
    name: String,
}

impl Drop for PgDrop {
    fn drop(&mut self) {
        // Best effort, also after a failed test: a fresh runtime on its own thread, since
        // Drop cannot await and the test's runtime may be shutting down.
        let admin = self.admin_url.clone();
        let sql = format!("DROP DATABASE IF EXISTS {} WITH (FORCE)", self.name);
        let _ = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .ok()?;
            rt.block_on(async {
                let mut c = sqlx::PgConnection::connect(&admin).await.ok()?;
                c.execute(AssertSqlSafe(sql)).await.ok()
            })
        })
        .join();
    }
}

async fn sqlite_db() -> TestDb {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("pantowatch.db");
    let store = Store::connect(path.to_str().expect("utf-8 path"))
        .await
        .expect("open SQLite");
    TestDb {
        store,
        _dir: Some(dir),
        _pg: None,
    }
}

fn pg_admin_url() -> String {
    std::env::var("PANTOWATCH_TEST_PG_URL").unwrap_or_else(|_| DEFAULT_PG.to_owned())
}

/// The admin URL with its database name replaced.
fn with_database(url: &str, name: &str) -> String {
    let (base, query) = match url.split_once('?') {
        Some((b, q)) => (b, format!("?{q}")),
        None => (url, String::new()),
    };
    let scheme_end = base.find("://").map_or(0, |i| i + 3);
    let host_part = match base[scheme_end..].find('/') {
        Some(i) => &base[..scheme_end + i],
        None => base,
    };
    format!("{host_part}/{name}{query}")
}

async fn pg_db() -> TestDb {
    let admin_url = pg_admin_url();
    let name = format!("pw_test_{}", hex::encode(rand_bytes()));
    let mut admin = sqlx::PgConnection::connect(&admin_url)
        .await
        .unwrap_or_else(|e| panic!("PostgreSQL at {admin_url} is required for this test: {e}"));
    admin
        .execute(AssertSqlSafe(format!("CREATE DATABASE {name}")))
        .await
        .expect("CREATE DATABASE");
    admin.close().await.ok();
    let guard = PgDrop {
        admin_url: admin_url.clone(),
        name: name.clone(),
    };
    let store = Store::connect(&with_database(&admin_url, &name))
        .await
        .expect("open PostgreSQL test database");
    assert_eq!(store.kind(), BackendKind::Postgres);
    TestDb {
        store,
        _dir: None,
        _pg: Some(guard),
    }
}

fn rand_bytes() -> [u8; 8] {
    let mut b = [0u8; 8];
    getrandom::fill(&mut b).expect("rng");
    b
}

macro_rules! contract {
    ($($case:ident),+ $(,)?) => {
        mod sqlite {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
                async fn $case() {
                    let db = super::sqlite_db().await;
                    super::$case(&db.store).await;
                    db.store.close().await;
                }
            )+
        }
        mod postgres {
            $(
                #[tokio::test(flavor = "multi_thread", worker_threads = 4)]
                async fn $case() {
                    let db = super::pg_db().await;
                    super::$case(&db.store).await;
                    db.store.close().await;
                }
            )+
        }
    };
}

contract!(
    connect_migrate_ping,
    samples_roundtrip_and_metadata,
    fit_curve_is_stored_with_its_fit,
    corrupt_samples_are_an_error,
    idempotent_insert_and_conflict,
    failed_insert_writes_nothing,
    claim_lease_expiry_and_reclaim,
    fail_retry_and_max_attempts,
    concurrent_workers_complete_exactly_once,
    racing_completes_after_lease_steal,
    requeue_for_new_model_version,
    api_keys_create_verify_revoke,
    history_mounts_and_vehicles,
    fleet_health_filter_and_pagination,
    unknown_status_and_counts,
    alert_lifecycle_dedup_escalate_resolve,
    alert_raises_race_to_one_alert,
    webhook_outbox_claim_retry_finish,
    latest_informed_verdict_wins,
    health_table_agrees_with_window,
);

// ---------------------------------------------------------------- fixtures

fn at(s: &str) -> DateTime<Utc> {
    DateTime::parse_from_rfc3339(s)
        .expect("time")
        .with_timezone(&Utc)
}

fn sha(c: char) -> String {
    std::iter::repeat_n(c, 64).collect()
}

fn channels(n: usize) -> Channels {
    let t = (0..n).map(|i| i as f64 * 0.002).collect();
    let a = (0..n)
        .map(|i| ((i as f64 * 0.05).sin() * 7000.0).round() / 100.0)
        .collect();
    vec![("t_s".into(), t), ("alpha_deg".into(), a)]
}

fn trace(id: &str, vehicle: &str, serial: Option<&str>, recorded: &str) -> NewTrace {
    NewTrace {
        trace_id: Some(id.to_owned()),
        vehicle_id: vehicle.to_owned(),
        serial: serial.map(str::to_owned),
        model: "160EC".into(),
        recorded_at: at(recorded),
        kind: "pendulum".into(),
        joint: Some("J1".into()),
        test_json: r#"{"kind":"pendulum","joint":"J1","rig":{}}"#.into(),
        content_sha256: sha('a'),
        channels: channels(50),
        model_version: "v1".into(),
    }
}

/// A fit result with `joints` at their statuses (each parameter judged as its joint).
fn fit_result(trace_id: &str, joints: &[(&str, Status)]) -> FitResult {
    let param = |value: f64, ci95: [f64; 2], baseline: f64, unit: &str, s: Status| ParamResult {
        value,
        ci95,
        baseline: Some(baseline),
        unit: unit.into(),
        identifiable: s != Status::Unknown,
        status: s,
        combination: None,
    };
    let joints = joints
        .iter()
        .enumerate()
        .map(|(i, (j, s))| JointResult {
            joint: (*j).to_owned(),
            viscous: param(
                0.036 + i as f64 * 1e-3,
                [0.031, 0.041],
                0.034,
                "N·m·s/rad",
                *s,
            ),
            dry: param(0.024, [0.021, 0.027], 0.023, "1", *s),
            identifiable: *s != Status::Unknown,
            status: *s,
        })
        .collect();
    FitResult {
        trace_id: trace_id.to_owned(),
        joints,
        rmse: Quantity {
            value: 0.42,
            unit: "deg".into(),
        },
        residual: ResidualResult {
            rmse_before: 0.42,
            rmse_after: 0.42,
            ..ResidualResult::default()
        },
        ..FitResult::default()
    }
}

fn fit(trace_id: &str, joints: &[(&str, Status)]) -> NewFit {
    NewFit::from_result(fit_result(trace_id, joints))
}

async fn count(store: &Store, table: &str) -> i64 {
    let sql: &'static str = match table {
        "vehicles" => "SELECT count(*) FROM vehicles",
        "pantographs" => "SELECT count(*) FROM pantographs",
        "pantograph_mounts" => "SELECT count(*) FROM pantograph_mounts",
        "traces" => "SELECT count(*) FROM traces",
        "fits" => "SELECT count(*) FROM fits",
        "fit_joints" => "SELECT count(*) FROM fit_joints",
        "fit_curves" => "SELECT count(*) FROM fit_curves",
        "jobs" => "SELECT count(*) FROM jobs",
        other => panic!("no table {other}"),
    };
    match store {
        Store::Sqlite(s) => sqlx::query_scalar(sql).fetch_one(s.pool()).await,
        Store::Postgres(s) => sqlx::query_scalar(sql).fetch_one(s.pool()).await,
    }
    .expect("count")
}

async fn insert_ok(store: &Store, t: NewTrace) -> (String, Option<i64>) {
    match store.insert_trace(t).await.expect("insert") {
        InsertOutcome::Created { trace_id, job_id } => (trace_id, job_id),
        other => panic!("expected Created, got {other:?}"),
    }
}
