//! Fit jobs: claims, leases, retries, concurrent workers, re-queues for a new model version.
//! Each case runs on SQLite and on PostgreSQL (`contract!` in `mod.rs`).

use super::*;

pub(super) async fn claim_lease_expiry_and_reclaim(store: &Store) {
    let (id, Some(job_id)) =
        insert_ok(store, trace("j1", "V1", Some("S1"), "2026-03-02T07:00:00Z")).await
    else {
        panic!("no job")
    };
    let lease = Duration::from_millis(1000);
    let a = store
        .claim("A", lease)
        .await
        .expect("claim")
        .expect("a job");
    assert_eq!((a.id, a.attempts, a.state), (job_id, 1, JobState::Running));
    assert_eq!(a.worker.as_deref(), Some("A"));
    assert!(a.lease_until.is_some());
    assert!(
        store.claim("B", lease).await.expect("claim").is_none(),
        "leased"
    );
    tokio::time::sleep(Duration::from_millis(1300)).await;
    let b = store
        .claim("B", lease * 60)
        .await
        .expect("claim")
        .expect("reclaimed");
    assert_eq!((b.id, b.attempts), (job_id, 2));
    let f = fit(&id, &[("J1", Status::Ok)]);
    assert_eq!(
        store.complete(job_id, "A", &f).await.expect("complete"),
        CompleteOutcome::LeaseLost
    );
    assert_eq!(
        store.fail(job_id, "A", "late", true).await.expect("fail"),
        FailOutcome::LeaseLost
    );
    assert_eq!(count(store, "fits").await, 0);
    let CompleteOutcome::Completed(w) = store.complete(job_id, "B", &f).await.expect("complete")
    else {
        panic!("B holds the lease")
    };
    assert!(w.created);
    let job = store.get_job(job_id).await.expect("job").expect("exists");
    assert_eq!(job.state, JobState::Done);
    assert_eq!(job.lease_until, None);
    assert_eq!(
        store.latest_job(&id).await.expect("job").map(|j| j.id),
        Some(job_id)
    );
    assert!(store.claim("C", lease).await.expect("claim").is_none());
    assert_eq!(
        store.complete(job_id, "B", &f).await.expect("again"),
        CompleteOutcome::LeaseLost
    );
    // Direct writes are idempotent too, and enqueue refuses a pair that is already fitted.
    let again = store
        .insert_fit(&id, "v1", &fit(&id, &[("J1", Status::Alarm)]))
        .await;
    assert_eq!(
        again.expect("insert_fit"),
        FitWrite {
            fit_id: w.fit_id,
            created: false
        }
    );
    assert_eq!(store.enqueue(&id, "v1").await.expect("enqueue"), None);
    let stored = store.get_fit(&id).await.expect("fit").expect("exists");
    assert_eq!(stored.id, w.fit_id);
    assert_eq!(stored.status, Some(Status::Ok), "first write wins");
    assert_eq!(
        stored.result().expect("typed"),
        f.result,
        "result round-trips"
    );
    assert_eq!(stored.joints, f.joints);
    assert_eq!(stored.rmse, Some(0.42));
    assert_eq!(count(store, "fits").await, 1);
    assert_eq!(count(store, "fit_joints").await, 1);
    let c = store.job_counts().await.expect("counts");
    assert_eq!(
        c,
        JobCounts {
            queued: 0,
            running: 0,
            done: 1,
            failed: 0
        }
    );
}

pub(super) async fn fail_retry_and_max_attempts(store: &Store) {
    let (_, Some(job_id)) =
        insert_ok(store, trace("f1", "V1", Some("S1"), "2026-03-02T07:00:00Z")).await
    else {
        panic!("no job")
    };
    let lease = Duration::from_secs(60);
    for attempt in 1..=MAX_ATTEMPTS {
        let j = store.claim("W", lease).await.expect("claim").expect("job");
        assert_eq!((j.id, j.attempts), (job_id, attempt));
        let expected = if attempt < MAX_ATTEMPTS {
            FailOutcome::Requeued
        } else {
            FailOutcome::Failed
        };
        assert_eq!(
            store.fail(job_id, "W", "boom", true).await.expect("fail"),
            expected
        );
    }
    let j = store.get_job(job_id).await.expect("job").expect("exists");
    assert_eq!(j.state, JobState::Failed);
    assert_eq!(j.last_error.as_deref(), Some("boom"));
    assert!(store.claim("W", lease).await.expect("claim").is_none());
    // No retry asked: failed at once.
    let (_, Some(j2)) =
        insert_ok(store, trace("f2", "V1", Some("S1"), "2026-03-03T07:00:00Z")).await
    else {
        panic!("no job")
    };
    store.claim("W", lease).await.expect("claim").expect("job");
    assert_eq!(
        store.fail(j2, "W", "bad trace", false).await.expect("fail"),
        FailOutcome::Failed
    );
    // Workers that die every time: after MAX_ATTEMPTS expired leases the job is failed.
    let (_, Some(j3)) =
        insert_ok(store, trace("f3", "V1", Some("S1"), "2026-03-04T07:00:00Z")).await
    else {
        panic!("no job")
    };
    let short = Duration::from_millis(150);
    for attempt in 1..=MAX_ATTEMPTS {
        let j = store
            .claim("dies", short)
            .await
            .expect("claim")
            .expect("job");
        assert_eq!((j.id, j.attempts), (j3, attempt));
        tokio::time::sleep(Duration::from_millis(300)).await;
    }
    assert!(store.claim("W", lease).await.expect("claim").is_none());
    let j = store.get_job(j3).await.expect("job").expect("exists");
    assert_eq!(j.state, JobState::Failed);
    assert!(j.last_error.unwrap_or_default().contains("lease expired"));
    assert_eq!(store.job_counts().await.expect("counts").failed, 3);
}

pub(super) async fn concurrent_workers_complete_exactly_once(store: &Store) {
    const N: usize = 24;
    for i in 0..N {
        let t = trace(
            &format!("c{i:02}"),
            "V1",
            Some("S1"),
            "2026-03-02T07:00:00Z",
        );
        insert_ok(store, t).await;
    }
    let store = Arc::new(store.clone());
    let mut handles = Vec::new();
    for w in 0..6 {
        let s = store.clone();
        handles.push(tokio::spawn(async move {
            let worker = format!("w{w}");
            let mut done = Vec::new();
            while let Some(job) = s
                .claim(&worker, Duration::from_secs(60))
                .await
                .expect("claim")
            {
                let f = fit(&job.trace_id, &[("J1", Status::Ok)]);
                match s.complete(job.id, &worker, &f).await.expect("complete") {
                    CompleteOutcome::Completed(w) => {
                        assert!(w.created);
                        done.push(job.id);
                    }
                    CompleteOutcome::LeaseLost => panic!("lease lost with a 60 s lease"),
                }
            }
            done
        }));
    }
    let mut all = Vec::new();
    for h in handles {
        all.extend(h.await.expect("join"));
    }
    let unique: HashSet<_> = all.iter().collect();
    assert_eq!(all.len(), N, "every job completed once");
    assert_eq!(unique.len(), N);
    assert_eq!(count(&store, "fits").await, N as i64);
    assert_eq!(store.job_counts().await.expect("counts").done, N as i64);
    // Many claimers, one job: exactly one wins.
    insert_ok(
        &store,
        trace("solo", "V1", Some("S1"), "2026-03-03T07:00:00Z"),
    )
    .await;
    let mut handles = Vec::new();
    for w in 0..8 {
        let s = store.clone();
        handles.push(tokio::spawn(async move {
            s.claim(&format!("c{w}"), Duration::from_secs(60)).await
        }));
    }
    let mut winners = 0;
    for h in handles {
        if h.await.expect("join").expect("claim").is_some() {
            winners += 1;
        }
    }
    assert_eq!(winners, 1);
}

pub(super) async fn racing_completes_after_lease_steal(store: &Store) {
    let store = Arc::new(store.clone());
    for round in 0..4 {
        let id = format!("steal{round}");
        let (_, Some(job_id)) =
            insert_ok(&store, trace(&id, "V1", Some("S1"), "2026-03-02T07:00:00Z")).await
        else {
            panic!("no job")
        };
        store
            .claim("A", Duration::from_millis(150))
            .await
            .expect("claim")
            .expect("A");
        tokio::time::sleep(Duration::from_millis(300)).await;
        let b = store
            .claim("B", Duration::from_secs(60))
            .await
            .expect("claim")
            .expect("B");
        assert_eq!(b.id, job_id);
        let f = Arc::new(fit(&id, &[("J1", Status::Watch)]));
        let (sa, sb, fa, fb) = (store.clone(), store.clone(), f.clone(), f.clone());
        let ha = tokio::spawn(async move { sa.complete(job_id, "A", &fa).await });
        let hb = tokio::spawn(async move { sb.complete(job_id, "B", &fb).await });
        let ra = ha.await.expect("join").expect("complete A");
        let rb = hb.await.expect("join").expect("complete B");
        assert_eq!(ra, CompleteOutcome::LeaseLost);
        assert!(matches!(rb, CompleteOutcome::Completed(w) if w.created));
    }
    assert_eq!(count(&store, "fits").await, 4);
}

pub(super) async fn requeue_for_new_model_version(store: &Store) {
    for (i, v) in ["V1", "V1", "V2"].iter().enumerate() {
        let t = trace(&format!("r{i}"), v, None, "2026-03-02T07:00:00Z");
        insert_ok(store, t).await;
    }
    // Drain v1.
    while let Some(j) = store
        .claim("w", Duration::from_secs(60))
        .await
        .expect("claim")
    {
        let f = fit(&j.trace_id, &[("J1", Status::Ok)]);
        store.complete(j.id, "w", &f).await.expect("complete");
    }
    assert_eq!(store.requeue_vehicle("V2", "v2").await.expect("requeue"), 1);
    assert_eq!(
        store.requeue_all("v2").await.expect("requeue"),
        2,
        "V2's job is live"
    );
    assert_eq!(store.requeue_all("v2").await.expect("requeue"), 0);
    assert_eq!(
        store.requeue_all("v1").await.expect("requeue"),
        0,
        "v1 fits exist"
    );
    assert_eq!(
        store.enqueue("r0", "v2").await.expect("enqueue"),
        None,
        "live job"
    );
    let mut versions = Vec::new();
    while let Some(j) = store
        .claim("w", Duration::from_secs(60))
        .await
        .expect("claim")
    {
        versions.push(j.model_version.clone());
        let f = fit(&j.trace_id, &[("J1", Status::Alarm)]);
        store.complete(j.id, "w", &f).await.expect("complete");
    }
    assert_eq!(versions, vec!["v2"; 3]);
    let cur = store.get_fit("r0").await.expect("fit").expect("exists");
    assert_eq!(
        cur.model_version, "v2",
        "latest model version is the current fit"
    );
    assert_eq!(cur.status, Some(Status::Alarm));
    assert!(store.enqueue("r0", "v3").await.expect("enqueue").is_some());
    assert!(
        store.enqueue("missing", "v3").await.is_err(),
        "unknown trace"
    );
}
