//! Graceful shutdown: a job claimed but not started is released (attempt not counted), a fit
//! that outlasts the grace period has its job released (attempt counted, failed at the limit),
//! a fit past its budget fails, a fit within the grace is written, and an HTTP request in
//! flight when the shutdown starts is answered.

use std::sync::Arc;
use std::time::Duration;

use pantowatch::config::Settings;
use pantowatch::ingest::{BodyFormat, Intake};
use pantowatch::store::{Job, JobState, Store};
use pantowatch::worker::{self, JobEvent, WorkerPool};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::sync::{Notify, watch};

use crate::harness::{Backend, Opts, fresh_db, spawn_app_with};
use crate::procs::{runaway_lift, shared_json, slow_lift, wait_until, with_id};

async fn upload(store: &Store, doc: &serde_json::Value, id: &str) -> String {
    Intake::new(store.clone(), Arc::new(Notify::new()))
        .upload(BodyFormat::Json, with_id(doc, id).into())
        .await
        .expect("upload")
        .trace_id
}

async fn job_of(store: &Store, trace_id: &str) -> Job {
    store
        .latest_job(trace_id)
        .await
        .expect("latest_job")
        .expect("a job")
}

fn options(grace: Duration) -> worker::WorkerOptions {
    let mut o = pantowatch::server::worker_options(&Settings::default(), 1);
    o.poll = Duration::from_millis(20);
    o.shutdown_grace = grace;
    o
}

async fn claimed_job_is_released_uncounted(b: Backend) {
    let db = fresh_db(b).await;
    let store = Store::connect(&db.url).await.expect("store");
    let id = upload(
        &store,
        &shared_json("data/examples/J1_baseline.json"),
        "claimed-1",
    )
    .await;
    let opts = options(Duration::from_secs(30));
    let (_tx, stopping) = watch::channel(true);
    let ev = worker::process_next(&store, "w-test", &opts, &stopping)
        .await
        .expect("process_next");
    assert_eq!(
        ev,
        Some(JobEvent::Released {
            trace_id: id.clone()
        })
    );
    let job = job_of(&store, &id).await;
    assert_eq!(
        (
            job.state,
            job.attempts,
            job.worker.as_deref(),
            job.lease_until
        ),
        (JobState::Queued, 0, None, None),
        "{job:?}"
    );
    assert!(store.get_fit(&id).await.expect("fit").is_none());

    // Only the holder may release: another worker's release changes nothing.
    let claimed = store
        .claim("w-a", Duration::from_secs(30))
        .await
        .expect("claim")
        .expect("a job");
    assert!(!store.release(claimed.id, "w-b").await.expect("release"));
    assert_eq!(job_of(&store, &id).await.state, JobState::Running);
    assert!(store.release(claimed.id, "w-a").await.expect("release"));

    // Not stopping: the same job is fitted, its one attempt counted.
    let (_tx, running) = watch::channel(false);
    let ev = worker::process_next(&store, "w-test", &opts, &running)
        .await
        .expect("process_next");
    assert!(matches!(ev, Some(JobEvent::Done { .. })), "{ev:?}");
    let job = job_of(&store, &id).await;
    assert_eq!((job.state, job.attempts), (JobState::Done, 1), "{job:?}");
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn sqlite_claimed_job_is_released_uncounted() {
    claimed_job_is_released_uncounted(Backend::Sqlite).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn postgres_claimed_job_is_released_uncounted() {
    claimed_job_is_released_uncounted(Backend::Postgres).await;
}

/// Starts one worker, uploads a lift whose fit takes seconds (`runaway_lift`: the residual
/// loop tries the vocabulary), waits until its fit runs, stops the pool; returns the trace id
/// and how long the pool took to stop.
///
/// "Its fit runs" is read from the job's first lease renewal, which only the loop around a
/// started fit makes: a job merely `running` may still be between its claim and the worker's
/// shutdown check, and a signal there releases it unstarted (a race seen under load). The lease
/// is short (0.6 s, renewed every 0.2 s) so that the renewal comes well within the fit; one
/// worker holds the only job, so a late renewal cannot hand it to another.
async fn stop_during_fit(store: &Store, grace: Duration, id: &str) -> (String, Duration) {
    let (tx, rx) = watch::channel(false);
    let mut opts = options(grace);
    opts.lease = Duration::from_millis(600);
    let pool = WorkerPool::spawn(store.clone(), opts, Arc::new(Notify::new()), rx, None);
    let id = upload(store, &runaway_lift(), id).await;
    let claimed = wait_until("the job running", Duration::from_secs(30), || async {
        let j = job_of(store, &id).await;
        (j.state == JobState::Running).then_some(j.lease_until)
    })
    .await;
    wait_until(
        "the fit started (its lease renewed)",
        Duration::from_secs(30),
        || async {
            let j = job_of(store, &id).await;
            (j.state != JobState::Running || j.lease_until != claimed).then_some(())
        },
    )
    .await;
    let t0 = std::time::Instant::now();
    tx.send(true).expect("signal");
    tokio::time::timeout(grace + Duration::from_secs(30), pool.join())
        .await
        .expect("the pool stops");
    (id, t0.elapsed())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_outlasting_the_grace_period_has_its_job_released() {
    let db = fresh_db(Backend::Sqlite).await;
    let store = Store::connect(&db.url).await.expect("store");
    let (id, stopped_in) = stop_during_fit(&store, Duration::ZERO, "grace-out").await;
    let job = job_of(&store, &id).await;
    // Its fit had started: the attempt stays counted (issue 18), so it cannot loop for ever.
    assert_eq!(
        (job.state, job.attempts, job.worker.as_deref()),
        (JobState::Queued, 1, None),
        "{job:?}"
    );
    assert!(store.get_fit(&id).await.expect("fit").is_none());
    eprintln!("grace 0: pool stopped {stopped_in:?} after the signal, job released");

    // The next worker fits it: its second attempt, one fit.
    let (_tx, running) = watch::channel(false);
    let ev = worker::process_next(&store, "w-next", &options(Duration::ZERO), &running)
        .await
        .expect("process_next");
    assert!(matches!(ev, Some(JobEvent::Done { .. })), "{ev:?}");
    let job = job_of(&store, &id).await;
    assert_eq!((job.state, job.attempts), (JobState::Done, 2), "{job:?}");
    store.close().await;
}

/// Issue 18: a fit that outlasts every shutdown does not come back for ever — each stop counts
/// its attempt, and at the limit the job fails saying why; the next trace is fitted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_stopped_at_every_shutdown_fails_at_the_attempt_limit() {
    let db = fresh_db(Backend::Sqlite).await;
    let store = Store::connect(&db.url).await.expect("store");
    let (id, _) = stop_during_fit(&store, Duration::ZERO, "grace-loop").await;
    for _ in 1..pantowatch::store::MAX_ATTEMPTS {
        let (tx, rx) = watch::channel(false);
        let pool = WorkerPool::spawn(
            store.clone(),
            options(Duration::ZERO),
            Arc::new(Notify::new()),
            rx,
            None,
        );
        wait_until("the job running again", Duration::from_secs(30), || async {
            let j = job_of(&store, &id).await;
            (j.state == JobState::Running).then_some(())
        })
        .await;
        tx.send(true).expect("signal");
        pool.join().await;
    }
    let job = job_of(&store, &id).await;
    assert_eq!(
        (job.state, job.attempts),
        (JobState::Failed, pantowatch::store::MAX_ATTEMPTS),
        "{job:?}"
    );
    let why = job.last_error.clone().unwrap_or_default();
    assert!(why.contains("shutdown_grace_ms"), "{why}");
    store.close().await;
}

/// Issue 18: a fit past its budget ends `failed` with the reason, and the worker goes on to
/// the next job, which is fitted.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_past_its_budget_fails_and_the_queue_moves_on() {
    let db = fresh_db(Backend::Sqlite).await;
    let store = Store::connect(&db.url).await.expect("store");
    let slow = upload(&store, &slow_lift(), "over-budget").await;
    let (_tx, running) = watch::channel(false);
    let mut tight = options(Duration::from_secs(30));
    tight.fit_budget = Duration::from_millis(1);
    let ev = worker::process_next(&store, "w-budget", &tight, &running)
        .await
        .expect("process_next");
    assert!(matches!(ev, Some(JobEvent::Failed { .. })), "{ev:?}");
    let job = job_of(&store, &slow).await;
    assert_eq!(job.state, JobState::Failed, "{job:?}");
    let why = job.last_error.clone().unwrap_or_default();
    assert!(
        why.contains("budget") && why.contains("fit_budget_secs"),
        "{why}"
    );
    let next = upload(
        &store,
        &shared_json("data/examples/J1_baseline.json"),
        "after-budget",
    )
    .await;
    let ev = worker::process_next(
        &store,
        "w-budget",
        &options(Duration::from_secs(30)),
        &running,
    )
    .await
    .expect("process_next");
    assert!(matches!(ev, Some(JobEvent::Done { .. })), "{ev:?}");
    assert!(store.get_fit(&next).await.expect("fit").is_some());
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_fit_within_the_grace_period_is_written() {
    let db = fresh_db(Backend::Sqlite).await;
    let store = Store::connect(&db.url).await.expect("store");
    let (id, stopped_in) = stop_during_fit(&store, Duration::from_secs(90), "grace-in").await;
    let job = job_of(&store, &id).await;
    assert_eq!((job.state, job.attempts), (JobState::Done, 1), "{job:?}");
    assert!(store.get_fit(&id).await.expect("fit").is_some());
    eprintln!("grace 90 s: pool stopped {stopped_in:?} after the signal, fit written");
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_request_in_flight_at_shutdown_is_answered() {
    let db = fresh_db(Backend::Sqlite).await;
    let app = spawn_app_with(
        db.clone(),
        Opts {
            workers: 0,
            lease_secs: 30,
        },
    )
    .await;
    let addr = app.addr;
    let body = with_id(
        &shared_json("data/examples/J1_baseline.json"),
        "in-flight-1",
    );
    let head = format!(
        "POST /v1/traces HTTP/1.1\r\nHost: {addr}\r\nAuthorization: Bearer {}\r\n\
         Content-Type: application/json\r\nContent-Length: {}\r\nConnection: close\r\n\r\n",
        app.keys.writer,
        body.len()
    );
    let mut s = tokio::net::TcpStream::connect(addr).await.expect("connect");
    let half = body.len() / 2;
    s.write_all(head.as_bytes()).await.expect("head");
    s.write_all(&body[..half]).await.expect("first half");
    s.flush().await.expect("flush");
    // The server is reading the body when the shutdown starts.
    tokio::time::sleep(Duration::from_millis(300)).await;
    let stopping = tokio::spawn(app.stop());
    tokio::time::sleep(Duration::from_millis(300)).await;
    assert!(
        !stopping.is_finished(),
        "the server stopped with a request in flight"
    );
    assert!(
        tokio::net::TcpStream::connect(addr).await.is_err(),
        "a stopping server accepted a new connection"
    );
    s.write_all(&body[half..]).await.expect("second half");
    let mut answer = Vec::new();
    tokio::time::timeout(Duration::from_secs(30), s.read_to_end(&mut answer))
        .await
        .expect("answer within 30 s")
        .expect("read");
    let answer = String::from_utf8_lossy(&answer);
    assert!(answer.starts_with("HTTP/1.1 202"), "{answer}");
    tokio::time::timeout(Duration::from_secs(30), stopping)
        .await
        .expect("server stops")
        .expect("stop task");
    let store = Store::connect(&db.url).await.expect("reopen");
    assert!(
        store
            .get_trace("in-flight-1")
            .await
            .expect("get_trace")
            .is_some()
    );
    store.close().await;
}

#[test]
fn grace_and_acquire_timeout_are_settings_and_zero_timeout_is_refused() {
    let env = |pairs: &[(&str, &str)]| -> Vec<(String, String)> {
        pairs
            .iter()
            .map(|(k, v)| ((*k).to_owned(), (*v).to_owned()))
            .collect()
    };
    let s = Settings::load_from(
        None,
        env(&[
            ("PANTOWATCH__WORKER__SHUTDOWN_GRACE_MS", "250"),
            ("PANTOWATCH__DATABASE__ACQUIRE_TIMEOUT_MS", "400"),
        ]),
    )
    .expect("settings");
    assert_eq!(s.shutdown_grace(), Duration::from_millis(250));
    assert_eq!(s.pool_options().acquire_timeout, Duration::from_millis(400));
    let o = pantowatch::server::worker_options(&s, 1);
    assert_eq!(o.shutdown_grace, Duration::from_millis(250));
    let e = Settings::load_from(
        None,
        env(&[("PANTOWATCH__DATABASE__ACQUIRE_TIMEOUT_MS", "0")]),
    )
    .expect_err("0 ms refused");
    assert!(e.to_string().contains("database.acquire_timeout_ms"), "{e}");
}
