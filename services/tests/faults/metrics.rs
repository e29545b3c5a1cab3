//! Worker observability (issue 18, point 6): a `pantowatch worker` process serves `/metrics`
//! with its fits' duration by test kind, outcomes, the queue gauges (jobs per state, the oldest
//! queued job's age) and the webhook outbox backlog, read from the shared database.

use std::sync::Arc;
use std::time::Duration;

use pantowatch::ingest::{BodyFormat, Intake};
use pantowatch::store::{JobState, Store};
use tokio::sync::Notify;

use crate::harness::{Backend, fresh_db};
use crate::procs::{self, shared_json, wait_until, with_id};

/// The value of the first sample line starting with `name` (labels included in `name`).
pub(crate) fn sample(text: &str, name: &str) -> Option<f64> {
    text.lines()
        .find(|l| l.starts_with(name))
        .and_then(|l| l.rsplit(' ').next())
        .and_then(|v| v.parse().ok())
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_worker_process_serves_its_metrics() {
    let db = fresh_db(Backend::Postgres).await;
    let store = Store::connect(&db.url).await.expect("store");
    let intake = Intake::new(store.clone(), Arc::new(Notify::new()));
    // Queued before any worker runs: the oldest-job age has something to measure.
    let mut ids = Vec::new();
    for (n, name) in ["J1_baseline", "slider_baseline"].iter().enumerate() {
        let doc = with_id(
            &shared_json(&format!("data/examples/{name}.json")),
            &format!("m-{n}"),
        );
        ids.push(
            intake
                .upload(BodyFormat::Json, doc.into())
                .await
                .expect("upload")
                .trace_id,
        );
    }
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let q = store.queue_stats().await.expect("queue stats");
    let age = q.oldest_queued_age_s.expect("a queued job");
    assert!((1.1..60.0).contains(&age), "oldest queued job {age} s old");
    assert_eq!(q.outbox_backlog, 0);
    let mut w = procs::spawn(
        "worker",
        &[
            "worker",
            "--workers",
            "1",
            "--metrics-listen",
            "127.0.0.1:0",
        ],
        &db.url,
        &[],
    );
    let line = w.wait_line(
        "pantowatch worker metrics on http://",
        Duration::from_secs(30),
    );
    let addr = line
        .rsplit("http://")
        .next()
        .expect("address")
        .trim()
        .to_owned();
    wait_until("both fits done", Duration::from_secs(60), || async {
        let mut done = 0;
        for id in &ids {
            let j = store.latest_job(id).await.expect("job").expect("a job");
            done += usize::from(j.state == JobState::Done);
        }
        (done == ids.len()).then_some(())
    })
    .await;
    let client = reqwest::Client::builder()
        .timeout(Duration::from_secs(10))
        .no_proxy()
        .build()
        .expect("client");
    let text = client
        .get(format!("http://{addr}/metrics"))
        .send()
        .await
        .expect("GET /metrics")
        .text()
        .await
        .expect("body");
    for (name, want) in [
        (
            "pantowatch_fit_duration_seconds_count{kind=\"pendulum\"}",
            1.0,
        ),
        (
            "pantowatch_fit_duration_seconds_count{kind=\"slider\"}",
            1.0,
        ),
        ("pantowatch_jobs_processed_total{outcome=\"done\"}", 2.0),
        ("pantowatch_job_attempts_total{attempt=\"1\"}", 2.0),
        ("pantowatch_fit_evaluations_count{kind=\"pendulum\"}", 1.0),
        ("pantowatch_jobs{state=\"done\"}", 2.0),
        ("pantowatch_jobs{state=\"queued\"}", 0.0),
        ("pantowatch_queue_oldest_job_age_seconds", 0.0),
        ("pantowatch_webhook_outbox_backlog", 0.0),
    ] {
        assert_eq!(sample(&text, name), Some(want), "{name} in:\n{text}");
    }
    let health = client
        .get(format!("http://{addr}/healthz"))
        .send()
        .await
        .expect("healthz");
    assert!(health.status().is_success());
    let st = w.terminate(Duration::from_secs(30));
    assert!(st.success(), "exit after SIGTERM: {st}");
    store.close().await;
}

/// The queue gauges on SQLite too (the age is computed in each backend's SQL dialect).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn queue_stats_on_sqlite() {
    let db = fresh_db(Backend::Sqlite).await;
    let store = Store::connect(&db.url).await.expect("store");
    assert_eq!(
        store
            .queue_stats()
            .await
            .expect("stats")
            .oldest_queued_age_s,
        None
    );
    let intake = Intake::new(store.clone(), Arc::new(Notify::new()));
    let doc = with_id(&shared_json("data/examples/J1_baseline.json"), "q-0");
    intake
        .upload(BodyFormat::Json, doc.into())
        .await
        .expect("upload");
    tokio::time::sleep(Duration::from_millis(1200)).await;
    let age = store
        .queue_stats()
        .await
        .expect("stats")
        .oldest_queued_age_s
        .expect("queued");
    assert!((1.1..60.0).contains(&age), "oldest queued job {age} s old");
    store.close().await;
}
