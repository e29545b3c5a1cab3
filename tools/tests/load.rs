//! `pantowatch-tools load` (the binary) against the real server on a fresh PostgreSQL database:
//! a small run loses and duplicates nothing, even sent twice; the verifier catches a deleted
//! trace, a duplicate row and swapped samples.

// The service's own test harness (a server on a fresh database), shared rather than copied.
#[allow(dead_code)]
#[path = "../../services/tests/api/harness.rs"]
mod harness;

use harness::{Backend, Opts, fresh_db, spawn_app_with};
use serde_json::Value;
use sqlx::{Connection, Executor};

const WORKERS: usize = 4;
const PER_WORKER: usize = 10;

/// Runs `pantowatch-tools load --json` with `extra` flags; (exit success, summary).
async fn load(url: &str, key: &str, run: &str, extra: &[&str]) -> (bool, Value) {
    let out = tokio::process::Command::new(env!("CARGO_BIN_EXE_pantowatch-tools"))
        .args(["load", "--json", "--url", url, "--run-id", run])
        .args(["--concurrency", &WORKERS.to_string()])
        .args(["--traces-per-worker", &PER_WORKER.to_string()])
        .args(["--duration-s", "1", "--fs-hz", "100"])
        .args(extra)
        .env("PANTOWATCH_KEY", key)
        .output()
        .await
        .expect("run pantowatch-tools load");
    let summary: Value = serde_json::from_slice(&out.stdout).unwrap_or_else(|e| {
        panic!(
            "no JSON summary ({e}): stdout {} stderr {}",
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        )
    });
    (out.status.success(), summary)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn load_run_loses_nothing_and_verifier_catches_tampering() {
    let db = fresh_db(Backend::Postgres).await;
    let app = spawn_app_with(
        db.clone(),
        Opts {
            workers: 0,
            ..Opts::default()
        },
    )
    .await;
    let url = app.url("");
    let n = (WORKERS * PER_WORKER) as i64;

    // A clean run: every document accepted, stored once, read back identical.
    let (ok, s) = load(&url, &app.keys.writer, "lt1", &[]).await;
    assert!(ok, "{s:#}");
    assert_eq!(s["accepted"], n, "{s:#}");
    for k in [
        "failed",
        "lost",
        "duplicated",
        "mismatched",
        "unreadable",
        "stored_unacknowledged",
    ] {
        assert_eq!(s[k], 0, "{k}: {s:#}");
    }
    assert_eq!(s["server_count"], n, "{s:#}");
    assert!(s["latency"]["p50_ms"].as_f64().unwrap() > 0.0, "{s:#}");
    assert!(
        s["latency"]["p99_ms"].as_f64() >= s["latency"]["p50_ms"].as_f64(),
        "{s:#}"
    );
    assert!(s["traces_per_s"].as_f64().unwrap() > 0.0, "{s:#}");
    assert_eq!(app.counts().await.traces, n);

    // The same run again: idempotent uploads, still one row per trace.
    let (ok, s) = load(&url, &app.keys.writer, "lt1", &[]).await;
    assert!(ok, "{s:#}");
    assert_eq!(s["server_count"], n, "{s:#}");
    assert_eq!(app.counts().await.traces, n);

    // A reader key cannot upload: every upload fails, and the run says so.
    let (ok, s) = load(&url, &app.keys.reader, "lt2", &["--max-retries", "0"]).await;
    assert!(!ok, "{s:#}");
    assert_eq!(s["failed"], n, "{s:#}");
    assert_eq!(s["accepted"], 0, "{s:#}");

    // Tamper with the database behind the service's back; the verifier must notice each.
    let mut c = sqlx::PgConnection::connect(&db.url).await.expect("connect");
    c.execute("DELETE FROM traces WHERE trace_id = 'lt1-w001-000003'")
        .await
        .expect("delete");
    let (ok, s) = load(&url, &app.keys.writer, "lt1", &["--verify-only"]).await;
    assert!(!ok, "a deleted trace passed: {s:#}");
    assert_eq!(s["lost"], 1, "{s:#}");
    assert_eq!(s["server_count"], n - 1, "{s:#}");
    assert_eq!(s["mismatched"], 0, "{s:#}");

    c.execute(
        "INSERT INTO traces (trace_id, vehicle_id, serial, model, recorded_at, kind, joint,
             test_json, content_sha256, samples, sample_count, channel_names)
         SELECT 'lt1-copy', vehicle_id, serial, model, recorded_at, kind, joint,
             test_json, content_sha256, samples, sample_count, channel_names
         FROM traces WHERE trace_id = 'lt1-w002-000004'",
    )
    .await
    .expect("insert a duplicate");
    c.execute(
        "UPDATE traces SET samples = (SELECT samples FROM traces WHERE trace_id = 'lt1-w000-000001')
         WHERE trace_id = 'lt1-w000-000002'",
    )
    .await
    .expect("swap samples");
    let (ok, s) = load(&url, &app.keys.writer, "lt1", &["--verify-only"]).await;
    assert!(!ok, "{s:#}");
    assert_eq!(s["lost"], 1, "{s:#}");
    assert_eq!(s["duplicated"], 1, "{s:#}");
    assert_eq!(s["mismatched"], 1, "{s:#}");
    let errors = s["errors"].to_string();
    assert!(
        errors.contains("lt1-w000-000002") && errors.contains("samples SHA-256"),
        "{errors}"
    );
    c.close().await.ok();
    app.stop().await;
}
