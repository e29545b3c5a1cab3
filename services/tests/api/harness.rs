//! `spawn_app()`: the service on an ephemeral port over a throw-away database, with a key of
//! each role and an HTTP client with timeouts.

use std::net::SocketAddr;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::{Duration, Instant};

use pantowatch::config::{SecretString, Settings};
use pantowatch::store::{Counts, Role, Store};
use reqwest::{Method, RequestBuilder, Response, StatusCode};
use serde_json::Value;
use sqlx::{AssertSqlSafe, Connection, Executor};
use tokio::sync::oneshot;
use tokio::task::JoinHandle;

const DEFAULT_PG: &str = "postgres://postgres@127.0.0.1:5432/postgres";

#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Backend {
    Sqlite,
    Postgres,
}

/// A fresh database, removed when the last holder drops it.
pub struct TestDb {
    pub url: String,
    _dir: Option<tempfile::TempDir>,
    pg: Option<(String, String)>,
}

impl Drop for TestDb {
    fn drop(&mut self) {
        let Some((admin, name)) = self.pg.take() else {
            return;
        };
        // Drop cannot await and the test's runtime may be gone: a runtime on its own thread.
        let _ = std::thread::spawn(move || {
            let rt = tokio::runtime::Builder::new_current_thread()
                .enable_all()
                .build()
                .ok()?;
            rt.block_on(async {
                let mut c = sqlx::PgConnection::connect(&admin).await.ok()?;
                c.execute(AssertSqlSafe(format!(
                    "DROP DATABASE IF EXISTS {name} WITH (FORCE)"
                )))
                .await
                .ok()
            })
        })
        .join();
    }
}

fn with_database(url: &str, name: &str) -> String {
    let (base, query) = match url.split_once('?') {
        Some((b, q)) => (b, format!("?{q}")),
        None => (url, String::new()),
    };
    let scheme_end = base.find("://").map_or(0, |i| i + 3);
    let host = match base[scheme_end..].find('/') {
        Some(i) => &base[..scheme_end + i],
        None => base,
    };
    format!("{host}/{name}{query}")
}

pub async fn fresh_db(backend: Backend) -> Arc<TestDb> {
    match backend {
        Backend::Sqlite => {
            let dir = tempfile::tempdir().expect("temp dir");
            let url = dir
                .path()
                .join("pantowatch.db")
                .to_str()
                .expect("utf-8 path")
                .to_owned();
            Arc::new(TestDb {
                url,
                _dir: Some(dir),
                pg: None,
            })
        }
        Backend::Postgres => {
            let admin =
                std::env::var("PANTOWATCH_TEST_PG_URL").unwrap_or_else(|_| DEFAULT_PG.into());
            let mut b = [0u8; 8];
            getrandom::fill(&mut b).expect("rng");
            let name = format!("pw_test_{}", hex::encode(b));
            let mut c = sqlx::PgConnection::connect(&admin).await.unwrap_or_else(|e| {
                panic!("PostgreSQL at {admin} is required for these tests (set PANTOWATCH_TEST_PG_URL): {e}")
            });
            c.execute(AssertSqlSafe(format!("CREATE DATABASE {name}")))
                .await
                .expect("CREATE DATABASE");
            c.close().await.ok();
            Arc::new(TestDb {
                url: with_database(&admin, &name),
                _dir: None,
                pg: Some((admin, name)),
            })
        }
    }
}

/// How to start the app.
#[derive(Debug, Clone, Copy)]
pub struct Opts {
    pub workers: usize,
    pub lease_secs: u64,
}

impl Default for Opts {
    fn default() -> Self {
        Opts {
            workers: 2,
            lease_secs: 30,
        }
    }
}

/// Body limit of the test apps.
pub const BODY_LIMIT_MIB: u64 = 1;

pub struct Keys {
    pub reader: String,
    pub writer: String,
    pub admin: String,
}

impl Keys {
    pub fn of(&self, role: Role) -> &str {
        match role {
            Role::Reader => &self.reader,
            Role::Writer => &self.writer,
            Role::Admin => &self.admin,
        }
    }
}

pub struct TestApp {
    pub addr: SocketAddr,
    pub client: reqwest::Client,
    /// The app's database, for checks the API does not expose (row counts, job leases).
    pub store: Store,
    pub keys: Keys,
    /// Keeps the database alive (dropped: removed) while the app runs.
    _db: Arc<TestDb>,
    stop: Option<oneshot::Sender<()>>,
    handle: Option<JoinHandle<anyhow::Result<()>>>,
}

pub async fn spawn_app(backend: Backend) -> TestApp {
    spawn_app_with(fresh_db(backend).await, Opts::default()).await
}

/// Starts the service on `db` (which may hold a previous run's data).
pub async fn spawn_app_with(db: Arc<TestDb>, opts: Opts) -> TestApp {
    let store = Store::connect(&db.url)
        .await
        .expect("open the test database");
    let keys = Keys {
        reader: store
            .create_api_key(Role::Reader, "test")
            .await
            .expect("key")
            .1,
        writer: store
            .create_api_key(Role::Writer, "test")
            .await
            .expect("key")
            .1,
        admin: store
            .create_api_key(Role::Admin, "test")
            .await
            .expect("key")
            .1,
    };
    let mut settings = Settings::default();
    settings.database.url = SecretString::new(db.url.clone());
    settings.workers = opts.workers;
    settings.worker.lease_secs = opts.lease_secs;
    settings.worker.poll_ms = 50;
    settings.http.body_limit_mib = BODY_LIMIT_MIB;
    // The limiter stays on (every request still goes through key identification) but far
    // above what a test sends; security.rs tests the limit itself.
    settings.http.rate_limit_per_s = 10_000.0;
    settings.http.rate_limit_burst = 100_000;
    // Webhook deliveries on a test's time scale: retries after 100 ms, 200 ms; 500 ms timeout.
    settings.webhooks.backoff_base_ms = 100;
    settings.webhooks.max_attempts = 3;
    settings.webhooks.timeout_ms = 500;
    settings.webhooks.poll_ms = 50;
    settings.web.session_secret = SecretString::new("test session secret");
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind 127.0.0.1:0");
    let addr = listener.local_addr().expect("addr");
    let (tx, rx) = oneshot::channel::<()>();
    let run_store = store.clone();
    let handle = tokio::spawn(async move {
        pantowatch::server::run(listener, run_store, &settings, async {
            let _ = rx.await;
        })
        .await
    });
    let client = reqwest::Client::builder()
        .timeout(Duration::from_secs(30))
        .connect_timeout(Duration::from_secs(5))
        .no_proxy()
        .build()
        .expect("client");
    TestApp {
        addr,
        client,
        store,
        keys,
        _db: db,
        stop: Some(tx),
        handle: Some(handle),
    }
}

impl TestApp {
    pub fn url(&self, path: &str) -> String {
        format!("http://{}{path}", self.addr)
    }

    pub fn req(&self, method: Method, path: &str, key: Option<&str>) -> RequestBuilder {
        let r = self.client.request(method, self.url(path));
        match key {
            Some(k) => r.bearer_auth(k),
            None => r,
        }
    }

    pub async fn get(&self, path: &str, key: &str) -> Response {
        self.req(Method::GET, path, Some(key))
            .send()
            .await
            .expect("GET")
    }

    pub async fn get_json(&self, path: &str) -> (StatusCode, Value) {
        let r = self.get(path, &self.keys.reader).await;
        let s = r.status();
        (s, r.json().await.unwrap_or(Value::Null))
    }

    pub async fn upload_json(&self, body: &[u8]) -> Response {
        self.req(Method::POST, "/v1/traces", Some(&self.keys.writer))
            .header("content-type", "application/json")
            .body(body.to_vec())
            .send()
            .await
            .expect("POST /v1/traces")
    }

    /// Polls `GET /v1/traces/{trace_id}/fit` until it answers 200.
    pub async fn wait_for_fit(&self, trace_id: &str) -> Value {
        let t0 = Instant::now();
        loop {
            let (s, v) = self.get_json(&format!("/v1/traces/{trace_id}/fit")).await;
            if s == StatusCode::OK {
                return v;
            }
            assert_eq!(s, StatusCode::NOT_FOUND, "{v}");
            assert!(v["job"]["state"] != "failed", "fit failed: {v}");
            assert!(
                t0.elapsed() < Duration::from_secs(30),
                "no fit after 30 s: {v}"
            );
            tokio::time::sleep(Duration::from_millis(50)).await;
        }
    }

    /// `GET /v1/traces/{id}/fit` (`fit`) serves the stored result's JSON unchanged (issue 19,
    /// point 1: the API re-serialises the typed result it reads back): every part of it equals
    /// the stored text's, absent parts absent.
    pub async fn assert_fit_serves_the_stored_json(&self, fit: &Value) {
        let id = fit["trace_id"].as_str().expect("trace_id");
        let rec = self.store.get_fit(id).await.expect("get").expect("fit");
        assert_eq!(fit["fit_id"], rec.id, "{fit}");
        let stored: Value = serde_json::from_str(&rec.result_json).expect("stored json");
        for k in [
            "joints",
            "rmse",
            "residual",
            "fit",
            "pooled",
            "combinations",
            "pooled_rig",
        ] {
            assert_eq!(fit.get(k), stored.get(k), "{id}: `{k}`");
        }
    }

    /// A web page's HTML as a reader signed in through `/login` sees it.
    pub async fn web_page(&self, path: &str) -> String {
        let client = reqwest::Client::builder()
            .redirect(reqwest::redirect::Policy::none())
            .build()
            .expect("client");
        let r = client
            .post(self.url("/login"))
            .header("content-type", "application/x-www-form-urlencoded")
            .body(format!("key={}", self.keys.reader))
            .send()
            .await
            .expect("POST /login");
        let cookie = r
            .headers()
            .get("set-cookie")
            .and_then(|v| v.to_str().ok())
            .and_then(|v| v.split(';').next())
            .expect("session cookie")
            .to_owned();
        let r = client
            .get(self.url(path))
            .header("cookie", cookie)
            .send()
            .await
            .expect("GET page");
        assert_eq!(r.status(), StatusCode::OK, "{path}");
        r.text().await.expect("html")
    }

    pub async fn counts(&self) -> Counts {
        self.store.counts().await.expect("counts")
    }

    /// The rows an upload writes — vehicles, pantographs, traces, jobs — and not the fits,
    /// which the workers write on their own time: the same before and after a refusal.
    pub async fn stored(&self) -> [i64; 4] {
        let c = self.counts().await;
        [c.vehicles, c.pantographs, c.traces, c.jobs]
    }

    /// Graceful stop: waits for the server and its workers.
    pub async fn stop(mut self) {
        if let Some(tx) = self.stop.take() {
            let _ = tx.send(());
        }
        if let Some(h) = self.handle.take() {
            h.await.expect("server task").expect("server result");
        }
        self.store.close().await;
    }
}

/// The shared example traces (`../shared/data/examples` beside the repository).
pub fn example(name: &str) -> Vec<u8> {
    let p: PathBuf = [
        env!("CARGO_MANIFEST_DIR"),
        "..",
        "..",
        "shared",
        "data",
        "examples",
        name,
    ]
    .iter()
    .collect();
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

pub fn shared(rel: &str) -> Vec<u8> {
    let p: PathBuf = [env!("CARGO_MANIFEST_DIR"), "..", "..", "shared", rel]
        .iter()
        .collect();
    std::fs::read(&p).unwrap_or_else(|e| panic!("{}: {e}", p.display()))
}

/// Asserts a problem answer: status, media type, and the named field. Every 4xx names what to
/// change (issue 18): a `field`, or a `parameter` of the address.
pub async fn assert_problem(
    r: Response,
    status: StatusCode,
    field: Option<&str>,
    what: &str,
) -> Value {
    let got = r.status();
    let ct = r
        .headers()
        .get("content-type")
        .and_then(|v| v.to_str().ok())
        .unwrap_or("")
        .to_owned();
    let body: Value = r.json().await.unwrap_or(Value::Null);
    assert_eq!(got, status, "{what}: {body}");
    assert!(
        ct.starts_with("application/problem+json"),
        "{what}: content type {ct}"
    );
    for k in ["type", "title", "status", "detail"] {
        assert!(!body[k].is_null(), "{what}: problem without `{k}`: {body}");
    }
    assert_eq!(body["status"], status.as_u16(), "{what}");
    if status.is_client_error() {
        assert!(
            body["field"].is_string() || body["parameter"].is_string(),
            "{what}: a 4xx naming neither a field nor a parameter: {body}"
        );
    }
    if let Some(f) = field {
        assert_eq!(body["field"], f, "{what}: {body}");
    }
    body
}

/// Asserts a problem answer about the request's address: status, media type, `parameter`
/// naming the path segment or query key, and no `field`.
pub async fn assert_problem_param(
    r: Response,
    status: StatusCode,
    parameter: &str,
    what: &str,
) -> Value {
    let body = assert_problem(r, status, None, what).await;
    assert_eq!(body["parameter"], parameter, "{what}: {body}");
    assert!(body["field"].is_null(), "{what}: a field as well: {body}");
    body
}
