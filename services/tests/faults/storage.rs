//! A full or read-only database: uploads are answered at once with a problem naming the cause
//! (507 "database is full", 503 "database is read-only"), nothing is half-written, and reads
//! keep being answered. SQLite: `max_page_count` at the current size (SQLITE_FULL) and a file
//! opened read-only; PostgreSQL: `default_transaction_read_only` on the database.

use std::time::{Duration, Instant};

use pantowatch::config::{SecretString, Settings};
use pantowatch::store::{Role, Store};
use reqwest::StatusCode;
use serde_json::Value;
use sqlx::{AssertSqlSafe, Connection, Executor};

use crate::harness::{Backend, Opts, TestApp, fresh_db, spawn_app_with};
use crate::procs::{shared_json, with_id};

/// Connections in the SQLite pool (`SqliteStore::connect`).
const SQLITE_POOL: usize = 8;

fn j1(id: &str) -> Vec<u8> {
    with_id(&shared_json("data/examples/J1_baseline.json"), id)
}

async fn upload(
    client: &reqwest::Client,
    base: &str,
    key: &str,
    body: Vec<u8>,
) -> (reqwest::Response, Duration) {
    let t0 = Instant::now();
    let r = client
        .post(format!("{base}/v1/traces"))
        .bearer_auth(key)
        .header("content-type", "application/json")
        .body(body)
        .send()
        .await
        .expect("POST /v1/traces");
    (r, t0.elapsed())
}

/// Asserts the problem answer of a refused write: status, type, detail, `Retry-After`, fast.
async fn assert_refused(
    r: reqwest::Response,
    took: Duration,
    status: StatusCode,
    kind: &str,
    says: &str,
) -> Value {
    assert_eq!(r.status(), status);
    assert!(
        r.headers()
            .get("content-type")
            .and_then(|v| v.to_str().ok())
            .is_some_and(|c| c.starts_with("application/problem+json"))
    );
    assert!(r.headers().get("retry-after").is_some(), "no Retry-After");
    let body: Value = r.json().await.expect("problem json");
    assert_eq!(body["type"], kind, "{body}");
    assert!(
        body["detail"].as_str().is_some_and(|d| d.contains(says)),
        "{body}"
    );
    assert!(took < Duration::from_secs(2), "answered in {took:?}");
    body
}

fn no_proxy_client() -> reqwest::Client {
    reqwest::Client::builder()
        .timeout(Duration::from_secs(30))
        .no_proxy()
        .build()
        .expect("client")
}

async fn reads_still_work(app_get: impl AsyncFn(&str) -> StatusCode, trace_id: &str) {
    assert_eq!(
        app_get(&format!("/v1/traces/{trace_id}")).await,
        StatusCode::OK
    );
    assert_eq!(app_get("/v1/vehicles").await, StatusCode::OK);
}

async fn app_reads(app: &TestApp, trace_id: &str) {
    reads_still_work(
        async |p: &str| app.get(p, &app.keys.reader).await.status(),
        trace_id,
    )
    .await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_full_answers_507_and_writes_nothing() {
    let app = spawn_app_with(
        fresh_db(Backend::Sqlite).await,
        Opts {
            workers: 0,
            lease_secs: 30,
        },
    )
    .await;
    let r = app.upload_json(&j1("full-0")).await;
    assert_eq!(r.status(), StatusCode::ACCEPTED);
    // The file may not grow past its current pages: set on every pooled connection (the
    // limit is per connection), all held at once so each is a different one.
    let Store::Sqlite(s) = &app.store else {
        panic!("sqlite store")
    };
    let mut held = Vec::new();
    for _ in 0..SQLITE_POOL {
        held.push(s.pool().acquire().await.expect("acquire"));
    }
    for c in &mut held {
        let pages: i64 = sqlx::query_scalar("PRAGMA page_count")
            .fetch_one(&mut **c)
            .await
            .expect("page_count");
        c.execute(AssertSqlSafe(format!("PRAGMA max_page_count = {pages}")))
            .await
            .expect("max_page_count");
    }
    drop(held);
    let before = app.counts().await;
    let base = app.url("");
    let (r, took) = upload(&app.client, &base, &app.keys.writer, j1("full-1")).await;
    assert_refused(
        r,
        took,
        StatusCode::INSUFFICIENT_STORAGE,
        "/problems/database-full",
        "database is full",
    )
    .await;
    assert_eq!(app.counts().await, before, "nothing half-written");
    app_reads(&app, "full-0").await;
    app.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_read_only_file_answers_503_and_keeps_reading() {
    let db = fresh_db(Backend::Sqlite).await;
    let writer;
    {
        let app = spawn_app_with(
            db.clone(),
            Opts {
                workers: 0,
                lease_secs: 30,
            },
        )
        .await;
        assert_eq!(
            app.upload_json(&j1("ro-0")).await.status(),
            StatusCode::ACCEPTED
        );
        writer = app.keys.writer.clone();
        app.stop().await;
    }
    let setup = Store::connect(&db.url).await.expect("store");
    let (_, reader) = setup.create_api_key(Role::Reader, "ro").await.expect("key");
    setup.close().await;
    // The same file opened read-only (what a read-only mount or file mode gives).
    let ro_url = format!("sqlite://{}?mode=ro", db.url);
    let store = Store::connect(&ro_url).await.expect("open read-only");
    let before = store.counts().await.expect("counts");
    let mut settings = Settings::default();
    settings.database.url = SecretString::new(ro_url);
    settings.workers = 0;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let base = format!("http://{}", listener.local_addr().expect("addr"));
    let (tx, rx) = tokio::sync::oneshot::channel::<()>();
    let run_store = store.clone();
    let server = tokio::spawn(async move {
        pantowatch::server::run(listener, run_store, &settings, async {
            let _ = rx.await;
        })
        .await
    });
    let client = no_proxy_client();
    let (r, took) = upload(&client, &base, &writer, j1("ro-1")).await;
    assert_refused(
        r,
        took,
        StatusCode::SERVICE_UNAVAILABLE,
        "/problems/database-read-only",
        "database is read-only",
    )
    .await;
    assert_eq!(store.counts().await.expect("counts"), before);
    reads_still_work(
        async |p: &str| {
            client
                .get(format!("{base}{p}"))
                .bearer_auth(&reader)
                .send()
                .await
                .expect("GET")
                .status()
        },
        "ro-0",
    )
    .await;
    let _ = tx.send(());
    server.await.expect("server").expect("run");
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_read_only_answers_503_and_keeps_reading() {
    let db = fresh_db(Backend::Postgres).await;
    let app = spawn_app_with(
        db.clone(),
        Opts {
            workers: 0,
            lease_secs: 30,
        },
    )
    .await;
    assert_eq!(
        app.upload_json(&j1("pg-ro-0")).await.status(),
        StatusCode::ACCEPTED
    );
    let name = db.url.rsplit('/').next().expect("database name").to_owned();
    let mut admin = sqlx::PgConnection::connect(&db.url).await.expect("admin");
    admin
        .execute(AssertSqlSafe(format!(
            "ALTER DATABASE {name} SET default_transaction_read_only = on"
        )))
        .await
        .expect("read-only");
    // Sessions keep the setting they started with: end the service's, its pool reconnects.
    sqlx::query(
        "SELECT pg_terminate_backend(pid) FROM pg_stat_activity
         WHERE datname = $1 AND pid <> pg_backend_pid()",
    )
    .bind(&name)
    .execute(&mut admin)
    .await
    .expect("terminate sessions");
    admin.close().await.ok();
    let before = app.counts().await;
    let base = app.url("");
    let (r, took) = upload(&app.client, &base, &app.keys.writer, j1("pg-ro-1")).await;
    assert_refused(
        r,
        took,
        StatusCode::SERVICE_UNAVAILABLE,
        "/problems/database-read-only",
        "database is read-only",
    )
    .await;
    assert_eq!(app.counts().await, before, "nothing half-written");
    app_reads(&app, "pg-ro-0").await;
    app.stop().await;
}
