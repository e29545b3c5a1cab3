//! Scale-out: two `pantowatch serve --workers 0` and two `pantowatch worker` processes on one
//! PostgreSQL database; 60 uploads alternate between the APIs and every job is processed exactly
//! once (one claim, one fit written, by one of the two workers, both busy); SIGTERM stops all four
//! cleanly.

use std::collections::BTreeMap;
use std::time::{Duration, Instant};

use pantowatch::store::{JobState, Role, Store};
use reqwest::StatusCode;

use crate::harness::{Backend, fresh_db};
use crate::kill::fits_per_trace;
use crate::procs::{self, shared_json, wait_until, with_id};

const TRACES: usize = 60;
const UPLOADERS: usize = 4;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn two_apis_and_two_workers_process_every_job_exactly_once() {
    let db = fresh_db(Backend::Postgres).await;
    // Migrated once here; the four processes find the schema in place.
    let store = Store::connect(&db.url).await.expect("store");
    let (_, writer) = store
        .create_api_key(Role::Writer, "scale-out")
        .await
        .expect("key");
    let api_args = ["serve", "--workers", "0", "--listen", "127.0.0.1:0"];
    let mut api1 = procs::spawn("api-1", &api_args, &db.url, &[]);
    let mut api2 = procs::spawn("api-2", &api_args, &db.url, &[]);
    let wk_args = ["worker", "--workers", "2"];
    let mut wk1 = procs::spawn("worker-1", &wk_args, &db.url, &[]);
    let mut wk2 = procs::spawn("worker-2", &wk_args, &db.url, &[]);
    let apis = [api1.wait_serving(), api2.wait_serving()];
    for w in [&mut wk1, &mut wk2] {
        w.wait_line("pantowatch workers running", Duration::from_secs(30));
    }

    let examples = [
        "J1_baseline",
        "J2_baseline",
        "J3_baseline",
        "J4_baseline",
        "J5_baseline",
        "J6_baseline",
        "J7_baseline",
        "slider_baseline",
    ]
    .map(|n| shared_json(&format!("data/examples/{n}.json")));
    let client = reqwest::Client::builder()
        .timeout(Duration::from_secs(30))
        .no_proxy()
        .build()
        .expect("client");
    // UPLOADERS concurrent clients; upload n goes to API n % 2.
    let t0 = Instant::now();
    let ids: Vec<String> = (0..TRACES).map(|n| format!("scale-{n:03}")).collect();
    let examples = std::sync::Arc::new(examples);
    let mut uploads = tokio::task::JoinSet::new();
    for u in 0..UPLOADERS {
        let (client, writer, examples) = (client.clone(), writer.clone(), examples.clone());
        uploads.spawn(async move {
            for n in (u..TRACES).step_by(UPLOADERS) {
                let id = format!("scale-{n:03}");
                let addr = apis[n % 2];
                let r = client
                    .post(format!("http://{addr}/v1/traces"))
                    .bearer_auth(&writer)
                    .header("content-type", "application/json")
                    .body(with_id(&examples[n % examples.len()], &id))
                    .send()
                    .await
                    .expect("upload");
                assert_eq!(r.status(), StatusCode::ACCEPTED, "upload {id} via {addr}");
            }
        });
    }
    while let Some(r) = uploads.join_next().await {
        r.expect("uploader");
    }
    let uploaded_in = t0.elapsed();
    let counts = wait_until("the queue drained", Duration::from_secs(120), || async {
        let c = store.job_counts().await.expect("job counts");
        (c.queued == 0 && c.running == 0).then_some(c)
    })
    .await;
    let drained_in = t0.elapsed();
    assert_eq!(counts.failed, 0, "{counts:?}");
    assert_eq!(counts.done, TRACES as i64, "{counts:?}");

    // One job per trace, claimed once, done, by a worker of one of the two processes.
    let tags = [("worker-1", wk1.pid()), ("worker-2", wk2.pid())];
    let mut per_process: BTreeMap<&str, usize> = BTreeMap::new();
    for id in &ids {
        let j = store.latest_job(id).await.expect("job").expect("a job");
        assert_eq!((j.state, j.attempts), (JobState::Done, 1), "{j:?}");
        let w = j.worker.clone().expect("worker recorded");
        let (name, _) = tags
            .iter()
            .find(|(_, pid)| w.contains(&format!("-{pid}-")))
            .unwrap_or_else(|| panic!("job {j:?}: worker {w} is neither process"));
        *per_process.entry(name).or_default() += 1;
    }
    let fits = fits_per_trace(&db.url).await;
    assert_eq!(fits.len(), TRACES, "a fit for every trace");
    assert!(fits.iter().all(|(_, n)| *n == 1), "{fits:?}");
    // The processes' own accounts agree: 60 fits written in all, no lease lost, none by the APIs.
    let written: Vec<usize> = [&wk1, &wk2].map(|w| w.count("fit written")).to_vec();
    assert_eq!(written.iter().sum::<usize>(), TRACES, "{written:?}");
    for p in [&wk1, &wk2, &api1, &api2] {
        assert_eq!(p.count("lease lost"), 0, "{}: {:?}", p.name, p.log());
    }
    assert_eq!(api1.count("fit written") + api2.count("fit written"), 0);
    assert!(
        per_process.len() == 2 && per_process.values().all(|n| *n > 0),
        "both worker processes fitted: {per_process:?}"
    );

    // SIGTERM: each process stops cleanly (API: in-flight answered; workers: fits finished).
    let t_stop = Instant::now();
    for p in [&mut api1, &mut api2, &mut wk1, &mut wk2] {
        let st = p.terminate(Duration::from_secs(30));
        assert!(st.success(), "{} exit after SIGTERM: {st}", p.name);
    }
    eprintln!(
        "scale-out: {TRACES} uploads via 2 APIs in {:.1} s, queue drained {:.1} s after the \
         first upload; jobs per worker process {per_process:?}; fits written per log {written:?}; \
         4 processes stopped on SIGTERM in {:.2} s",
        uploaded_in.as_secs_f64(),
        drained_in.as_secs_f64(),
        t_stop.elapsed().as_secs_f64()
    );
    store.close().await;
}
