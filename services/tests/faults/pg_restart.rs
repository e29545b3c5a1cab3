//! PostgreSQL restarted under load, on a private throw-away cluster (initdb in a temp dir, a
//! free port; as the `postgres` user when the test runs as root): uploads during the outage are
//! answered 503 quickly, the service recovers by itself, and every upload answered 202 is stored
//! and fitted. The cluster is stopped and removed even when the test fails (Drop).

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::{Duration, Instant};

use pantowatch::config::{SecretString, Settings};
use pantowatch::store::{Role, Store};
use tokio::sync::Mutex;

use crate::procs::{shared_json, wait_until, with_id};

/// How long PostgreSQL stays down: long enough that each of the loops has at least one request
/// wholly inside it even when a 503 takes 2 s on a loaded CI machine (at 4 s, CI once saw 2).
const OUTAGE: Duration = Duration::from_secs(6);
/// Concurrent upload loops (each: upload, wait 50 ms, again).
const LOOPS: usize = 3;
/// Longest acceptable answer while it is down: the 1 s pool acquire timeout plus slack for a
/// 2-core CI machine running this binary's other tests at once (1.83 s seen at load 17); a
/// request that waited on the database would take the old 10–30 s.
const FAST: Duration = Duration::from_secs(3);

/// A private PostgreSQL cluster.
pub struct Cluster {
    dir: tempfile::TempDir,
    bin: PathBuf,
    as_postgres: bool,
    pub port: u16,
}

fn output(cmd: &str, args: &[&str]) -> Option<String> {
    let o = Command::new(cmd).args(args).output().ok()?;
    o.status
        .success()
        .then(|| String::from_utf8_lossy(&o.stdout).trim().to_owned())
}

/// The PostgreSQL server binaries: `PANTOWATCH_PG_BIN`, `pg_config --bindir`, or the newest
/// `/usr/lib/postgresql/*/bin`.
fn pg_bin() -> PathBuf {
    let mut candidates: Vec<PathBuf> = Vec::new();
    if let Ok(b) = std::env::var("PANTOWATCH_PG_BIN") {
        candidates.push(b.into());
    }
    if let Some(b) = output("pg_config", &["--bindir"]) {
        candidates.push(b.into());
    }
    if let Ok(rd) = std::fs::read_dir("/usr/lib/postgresql") {
        let mut v: Vec<PathBuf> = rd.flatten().map(|e| e.path().join("bin")).collect();
        v.sort();
        candidates.extend(v.into_iter().rev());
    }
    candidates
        .into_iter()
        .find(|b| b.join("initdb").is_file() && b.join("pg_ctl").is_file())
        .expect(
            "PostgreSQL server binaries (initdb, pg_ctl) are required for the restart drill: \
             set PANTOWATCH_PG_BIN",
        )
}

fn free_port() -> u16 {
    std::net::TcpListener::bind("127.0.0.1:0")
        .and_then(|l| l.local_addr())
        .expect("free port")
        .port()
}

impl Cluster {
    /// initdb in a temp dir (owned by `postgres` when running as root: initdb refuses root).
    pub fn init() -> Cluster {
        let bin = pg_bin();
        let as_postgres = output("id", &["-u"]).as_deref() == Some("0");
        let dir = tempfile::Builder::new()
            .prefix("pw-pg-drill-")
            .tempdir()
            .expect("temp dir");
        if as_postgres {
            let st = Command::new("chown")
                .args(["postgres:postgres", dir.path().to_str().expect("utf-8")])
                .status()
                .expect("chown");
            assert!(st.success(), "chown the cluster dir to postgres");
        }
        let c = Cluster {
            dir,
            bin,
            as_postgres,
            port: free_port(),
        };
        let data = c.data();
        c.run(
            "initdb",
            &[
                "-D", &data, "-U", "postgres", "-A", "trust", "-N", "-E", "UTF8",
            ],
        );
        c
    }

    fn data(&self) -> String {
        self.dir.path().join("data").display().to_string()
    }

    fn run(&self, tool: &str, args: &[&str]) {
        let exe = self.bin.join(tool);
        let mut cmd = if self.as_postgres {
            let mut c = Command::new("runuser");
            c.args(["-u", "postgres", "--"]).arg(&exe);
            c
        } else {
            Command::new(&exe)
        };
        let out = cmd
            .args(args)
            .current_dir(self.dir.path())
            .stdin(Stdio::null())
            .output()
            .unwrap_or_else(|e| panic!("{tool}: {e}"));
        assert!(
            out.status.success(),
            "{tool} {args:?}: {}\n{}\n{}",
            out.status,
            String::from_utf8_lossy(&out.stdout),
            String::from_utf8_lossy(&out.stderr)
        );
    }

    pub fn start(&self) {
        let opts = format!(
            "-p {} -k {} -c listen_addresses=127.0.0.1",
            self.port,
            self.dir.path().display()
        );
        let log = self.dir.path().join("server.log").display().to_string();
        self.run(
            "pg_ctl",
            &[
                "-D",
                &self.data(),
                "-l",
                &log,
                "-o",
                &opts,
                "-w",
                "-t",
                "60",
                "start",
            ],
        );
    }

    /// `pg_ctl stop -m fast`: sessions are terminated, the server shuts down cleanly.
    pub fn stop(&self) {
        self.run(
            "pg_ctl",
            &["-D", &self.data(), "-m", "fast", "-w", "-t", "60", "stop"],
        );
    }

    pub fn url(&self) -> String {
        format!("postgres://postgres@127.0.0.1:{}/postgres", self.port)
    }
}

impl Drop for Cluster {
    fn drop(&mut self) {
        // Whatever state the test left it in: stop it (immediate), then the TempDir goes.
        let exe = self.bin.join("pg_ctl");
        let data = self.data();
        let args = ["-D", data.as_str(), "-m", "immediate", "-w", "stop"];
        let _ = if self.as_postgres {
            Command::new("runuser")
                .args(["-u", "postgres", "--"])
                .arg(&exe)
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
        } else {
            Command::new(&exe)
                .args(args)
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .status()
        };
    }
}

/// One upload of the load loop.
#[derive(Debug, Clone)]
struct Shot {
    id: String,
    start: Instant,
    took: Duration,
    /// HTTP status, or 0 for a transport error.
    status: u16,
    retry_after: Option<String>,
    problem_type: Option<String>,
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_restart_under_load_answers_503_fast_and_recovers() {
    let cluster = Cluster::init();
    cluster.start();
    let url = cluster.url();
    let store = Store::connect(&url).await.expect("store");
    let (_, writer) = store
        .create_api_key(Role::Writer, "drill")
        .await
        .expect("key");
    let mut settings = Settings::default();
    settings.database.url = SecretString::new(url.clone());
    settings.workers = 1;
    settings.worker.lease_secs = 3;
    settings.worker.poll_ms = 50;
    let listener = tokio::net::TcpListener::bind("127.0.0.1:0")
        .await
        .expect("bind");
    let addr = listener.local_addr().expect("addr");
    let (stop_tx, stop_rx) = tokio::sync::oneshot::channel::<()>();
    let server_store = store.clone();
    let server = tokio::spawn(async move {
        pantowatch::server::run(listener, server_store, &settings, async {
            let _ = stop_rx.await;
        })
        .await
    });

    // The load: LOOPS loops of upload-then-50 ms, each answer recorded.
    let shots = Arc::new(Mutex::new(Vec::<Shot>::new()));
    let running = Arc::new(AtomicBool::new(true));
    let mut load = tokio::task::JoinSet::new();
    for k in 0..LOOPS {
        let (shots, running) = (shots.clone(), running.clone());
        let writer = writer.clone();
        let doc = shared_json("data/examples/J1_baseline.json");
        let client = reqwest::Client::builder()
            .timeout(Duration::from_secs(30))
            .no_proxy()
            .build()
            .expect("client");
        load.spawn(async move {
            let mut n = 0;
            while running.load(Ordering::SeqCst) {
                let id = format!("drill-{k}-{n:04}");
                n += 1;
                let start = Instant::now();
                let r = client
                    .post(format!("http://{addr}/v1/traces"))
                    .bearer_auth(&writer)
                    .header("content-type", "application/json")
                    .body(with_id(&doc, &id))
                    .send()
                    .await;
                let took = start.elapsed();
                let shot = match r {
                    Ok(r) => {
                        let status = r.status().as_u16();
                        let retry_after = r
                            .headers()
                            .get("retry-after")
                            .and_then(|v| v.to_str().ok())
                            .map(str::to_owned);
                        let body: serde_json::Value =
                            r.json().await.unwrap_or(serde_json::Value::Null);
                        Shot {
                            id,
                            start,
                            took,
                            status,
                            retry_after,
                            problem_type: body["type"].as_str().map(str::to_owned),
                        }
                    }
                    Err(_) => Shot {
                        id,
                        start,
                        took,
                        status: 0,
                        retry_after: None,
                        problem_type: None,
                    },
                };
                shots.lock().await.push(shot);
                tokio::time::sleep(Duration::from_millis(50)).await;
            }
        });
    }
    let ok_count = |from: Instant| {
        let shots = shots.clone();
        async move {
            shots
                .lock()
                .await
                .iter()
                .filter(|s| s.start >= from && s.status == 202)
                .count()
        }
    };
    let t_begin = Instant::now();
    wait_until(
        "uploads before the outage",
        Duration::from_secs(30),
        || async { (ok_count(t_begin).await >= 10).then_some(()) },
    )
    .await;

    let t_stop = Instant::now();
    tokio::task::block_in_place(|| cluster.stop());
    let t_down = Instant::now();
    tokio::time::sleep(OUTAGE).await;
    let t_restart = Instant::now();
    tokio::task::block_in_place(|| cluster.start());
    let t_up = Instant::now();
    wait_until(
        "uploads after the restart",
        Duration::from_secs(30),
        || async { (ok_count(t_up).await >= 10).then_some(()) },
    )
    .await;
    running.store(false, Ordering::SeqCst);
    while let Some(r) = load.join_next().await {
        r.expect("load task");
    }
    let shots = shots.lock().await.clone();
    let n503 = shots.iter().filter(|s| s.status == 503).count();
    let n202 = shots.iter().filter(|s| s.status == 202).count();
    let during: Vec<&Shot> = shots
        .iter()
        .filter(|s| s.start >= t_down && s.start + s.took <= t_restart)
        .collect();
    let max_503 = during.iter().map(|s| s.took).max().unwrap_or_default();
    let first_ok = shots
        .iter()
        .filter(|s| s.start >= t_restart && s.status == 202)
        .map(|s| s.start + s.took)
        .min();
    let recovery = first_ok.map(|t| t.saturating_duration_since(t_up));
    eprintln!(
        "PostgreSQL restart drill: stop took {:.2} s, down {:.1} s, start took {:.2} s; \
         {} uploads from {LOOPS} loops: {n202} × 202, {n503} × 503, {} other; {} requests \
         inside the outage, slowest {:.3} s; first 202 {:?} after PostgreSQL was up",
        (t_down - t_stop).as_secs_f64(),
        (t_restart - t_down).as_secs_f64(),
        (t_up - t_restart).as_secs_f64(),
        shots.len(),
        shots.len() - n202 - n503,
        during.len(),
        max_503.as_secs_f64(),
        recovery,
    );

    // Every answer is 202 or a 503 problem with Retry-After: never a 500, never a hang.
    for s in &shots {
        assert!(
            s.status == 202
                || (s.status == 503
                    && s.retry_after.is_some()
                    && s.problem_type.as_deref() == Some("/problems/unavailable")),
            "{s:?}"
        );
    }
    // While it is down (started after the stop returned, ended before the restart began):
    // all 503, each fast.
    assert!(
        during.len() >= 3,
        "too few requests in the outage: {}",
        during.len()
    );
    for s in &during {
        assert_eq!(s.status, 503, "{s:?}");
        assert!(s.took < FAST, "slow 503: {s:?}");
    }
    // Recovery without restarting the service: the first 202 after PostgreSQL is back.
    let recovery = recovery.expect("a 202 after the restart");
    assert!(
        recovery < Duration::from_secs(10),
        "recovery took {recovery:?}"
    );

    // No accepted upload is lost, and every one is fitted (the worker recovered too).
    let accepted: Vec<&Shot> = shots.iter().filter(|s| s.status == 202).collect();
    for s in &accepted {
        assert!(
            store.get_trace(&s.id).await.expect("get_trace").is_some(),
            "accepted upload {} lost",
            s.id
        );
    }
    let counts = wait_until("every job done", Duration::from_secs(60), || async {
        let c = store.job_counts().await.ok()?;
        (c.queued == 0 && c.running == 0).then_some(c)
    })
    .await;
    assert_eq!(counts.failed, 0, "{counts:?}");
    let stored = store.counts().await.expect("counts");
    assert!(stored.traces >= accepted.len() as i64);
    assert_eq!(stored.fits, stored.traces, "{stored:?}");

    let _ = stop_tx.send(());
    tokio::time::timeout(Duration::from_secs(30), server)
        .await
        .expect("server stops")
        .expect("server task")
        .expect("server result");
    store.close().await;
    eprintln!(
        "PostgreSQL restart drill: afterwards {} traces stored ({} accepted), {} fits, \
         0 jobs failed",
        stored.traces,
        accepted.len(),
        stored.fits,
    );
}
