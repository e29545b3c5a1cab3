//! Every job ends (issue 18): an absurd rig value is refused at upload; the same document
//! stored as if before that rule, an unfittable trace and a fit past its evaluation budget end
//! `failed` with their reasons while the valid trace queued behind them is fitted; then a fit
//! stopped by SIGTERM at every attempt fails at the attempt limit and nothing loops. Real
//! `pantowatch worker` processes on both backends.

use std::sync::Arc;
use std::time::Duration;

use chrono::Utc;
use pantowatch::ingest::{BodyFormat, IngestError, Intake};
use pantowatch::store::{Job, JobState, MAX_ATTEMPTS, NewTrace, Store};
use serde_json::{Value, json};
use tokio::sync::Notify;

use crate::harness::{Backend, fresh_db};
use crate::procs::{self, runaway_lift, shared_json, wait_until, with_id};

/// Stores `doc` straight into the store, past the upload's validation (a trace stored before
/// a rule existed, or by a bug): the worker must still end its job.
async fn store_unchecked(store: &Store, doc: &Value, id: &str) {
    let obj = doc["channels"].as_object().expect("channels");
    let mut channels: Vec<(String, Vec<f64>)> = vec![(
        "t_s".to_owned(),
        serde_json::from_value(obj["t_s"].clone()).expect("t_s"),
    )];
    for (k, v) in obj.iter().filter(|(k, _)| *k != "t_s") {
        channels.push((
            k.clone(),
            serde_json::from_value(v.clone()).expect("channel"),
        ));
    }
    store
        .insert_trace(NewTrace {
            trace_id: Some(id.to_owned()),
            vehicle_id: doc["vehicle_id"].as_str().expect("vehicle").to_owned(),
            serial: doc["pantograph"]["serial"].as_str().map(str::to_owned),
            model: "160EC".to_owned(),
            recorded_at: Utc::now(),
            kind: doc["test"]["kind"].as_str().expect("kind").to_owned(),
            joint: doc["test"]["joint"].as_str().map(str::to_owned),
            test_json: doc["test"].to_string(),
            content_sha256: format!("{:064x}", id.len()),
            channels,
            model_version: pantowatch_models::report::MODEL_VERSION.to_owned(),
        })
        .await
        .expect("insert unchecked");
}

async fn job(store: &Store, id: &str) -> Job {
    store
        .latest_job(id)
        .await
        .expect("latest_job")
        .expect("a job")
}

async fn every_job_ends(b: Backend) {
    let db = fresh_db(b).await;
    let store = Store::connect(&db.url).await.expect("store");
    let intake = Intake::new(store.clone(), Arc::new(Notify::new()));

    // A pin radius of 1e308 m is refused at upload, naming the field; nothing is stored.
    let pendulum = shared_json("data/examples/J1_baseline.json");
    let mut absurd = pendulum.clone();
    absurd["test"]["rig"]["pin_radius_m"] = json!(1e308);
    match intake
        .upload(BodyFormat::Json, with_id(&absurd, "absurd").into())
        .await
    {
        Err(IngestError::Invalid(e)) => assert_eq!(e.field, "test.rig.pin_radius_m", "{e}"),
        other => panic!("a pin radius of 1e308 m: {other:?}"),
    }
    assert!(store.get_trace("absurd").await.expect("get").is_none());

    // Queued ahead of a valid trace: that document stored unchecked, an unfittable lift (two
    // samples) and a fit that needs ~840 evaluations under a budget of 100.
    store_unchecked(&store, &absurd, "absurd-stored").await;
    let two_samples = json!({"format": "pantograph-trace/1", "vehicle_id": "V-1",
        "pantograph": {"model": "160EC", "serial": "160EC-9"},
        "recorded_at": "2026-03-02T07:15:00Z", "test": {"kind": "lift", "rig": {}},
        "channels": {"t_s": [0.0, 0.1], "H_m": [1.0, 1.0], "T_Nm": [0.0, 0.0], "Fs_N": [0.0, 0.0]}});
    store_unchecked(&store, &two_samples, "unfittable").await;
    let lift = runaway_lift();
    for (doc, id) in [(&lift, "runaway"), (&pendulum, "valid")] {
        intake
            .upload(BodyFormat::Json, with_id(doc, id).into())
            .await
            .expect("upload");
    }
    let env = [("PANTOWATCH__WORKER__FIT_MAX_EVALUATIONS", "100")];
    let mut w = procs::spawn(
        "worker-budget",
        &[
            "worker",
            "--workers",
            "1",
            "--metrics-listen",
            "127.0.0.1:0",
        ],
        &db.url,
        &env,
    );
    let line = w.wait_line(
        "pantowatch worker metrics on http://",
        Duration::from_secs(30),
    );
    let metrics_url = format!(
        "{}/metrics",
        line.rsplit(' ').next().expect("address").trim()
    );
    let ids = ["absurd-stored", "unfittable", "runaway", "valid"];
    let ended = wait_until("every job ended", Duration::from_secs(120), || async {
        let mut js = Vec::new();
        for id in ids {
            js.push(job(&store, id).await);
        }
        js.iter()
            .all(|j| matches!(j.state, JobState::Done | JobState::Failed))
            .then_some(js)
    })
    .await;
    let why = |j: &Job| j.last_error.clone().unwrap_or_default();
    assert_eq!(ended[0].state, JobState::Failed, "{:?}", ended[0]);
    assert!(why(&ended[0]).contains("pin_radius_m"), "{:?}", ended[0]);
    assert_eq!(ended[1].state, JobState::Failed, "{:?}", ended[1]);
    assert!(!why(&ended[1]).is_empty(), "{:?}", ended[1]);
    assert_eq!(ended[2].state, JobState::Failed, "{:?}", ended[2]);
    assert!(
        why(&ended[2]).contains("100 model evaluations")
            && why(&ended[2]).contains("worker.fit_max_evaluations"),
        "{:?}",
        ended[2]
    );
    assert_eq!(ended[3].state, JobState::Done, "{:?}", ended[3]);
    assert!(store.get_fit("valid").await.expect("fit").is_some());
    for j in &ended {
        assert_eq!(j.attempts, 1, "each job ran once: {j:?}");
    }
    // The worker's metrics count each failure under its reason.
    let text = reqwest::get(&metrics_url)
        .await
        .expect("GET /metrics")
        .text()
        .await
        .expect("body");
    let failed = |reason: &str| {
        crate::metrics::sample(
            &text,
            &format!("pantowatch_jobs_failed_total{{reason=\"{reason}\"}}"),
        )
        .unwrap_or(0.0)
    };
    assert_eq!(failed("evaluations"), 1.0, "{text}");
    assert!(failed("invalid") >= 1.0, "{text}");
    assert_eq!(
        failed("invalid") + failed("model"),
        2.0,
        "the stored absurd pin and the two-sample lift: {text}"
    );
    assert!(w.terminate(Duration::from_secs(30)).success());

    // A fit stopped by SIGTERM (grace 0) at every attempt: its attempts are counted when
    // claimed, so at the limit the job fails instead of blocking the queue after each restart.
    intake
        .upload(BodyFormat::Json, with_id(&lift, "stopped").into())
        .await
        .expect("upload");
    let env = [("PANTOWATCH__WORKER__SHUTDOWN_GRACE_MS", "0")];
    for attempt in 1..=MAX_ATTEMPTS {
        let mut w = procs::spawn("worker-term", &["worker", "--workers", "1"], &db.url, &env);
        wait_until("the fit running", Duration::from_secs(60), || async {
            let j = job(&store, "stopped").await;
            (j.state == JobState::Running && j.attempts == attempt).then_some(())
        })
        .await;
        // Past the claim and into the fit (which takes seconds) before the signal.
        tokio::time::sleep(Duration::from_millis(300)).await;
        assert!(
            w.terminate(Duration::from_secs(30)).success(),
            "{:?}",
            w.log()
        );
        let j = job(&store, "stopped").await;
        assert_eq!(j.attempts, attempt, "{j:?}");
        if attempt < MAX_ATTEMPTS {
            assert_eq!(j.state, JobState::Queued, "{j:?}");
        } else {
            assert_eq!(j.state, JobState::Failed, "{j:?}");
            assert!(why(&j).contains("shutdown"), "{j:?}");
        }
    }
    // A restarted worker fits new work and leaves the failed job alone.
    intake
        .upload(BodyFormat::Json, with_id(&pendulum, "after").into())
        .await
        .expect("upload");
    let mut w = procs::spawn("worker-after", &["worker", "--workers", "1"], &db.url, &[]);
    wait_until("the next trace fitted", Duration::from_secs(60), || async {
        (job(&store, "after").await.state == JobState::Done).then_some(())
    })
    .await;
    let j = job(&store, "stopped").await;
    assert_eq!(
        (j.state, j.attempts),
        (JobState::Failed, MAX_ATTEMPTS),
        "{j:?}"
    );
    let counts = store.job_counts().await.expect("counts");
    assert_eq!((counts.queued, counts.running), (0, 0), "{counts:?}");
    assert!(w.terminate(Duration::from_secs(30)).success());
    store.close().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_job_ends_on_sqlite() {
    every_job_ends(Backend::Sqlite).await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_job_ends_on_postgres() {
    every_job_ends(Backend::Postgres).await;
}
