//! Traces: connection and migrations, lossless samples, idempotent and atomic inserts, fit curves, upgrades.
//! Each case runs on SQLite and on PostgreSQL (`contract!` in `mod.rs`).

use super::*;

pub(super) async fn connect_migrate_ping(store: &Store) {
    store.ping().await.expect("ping");
    assert!(store.migrations_applied().await.expect("migrations"));
    // Connecting again to the same database re-runs nothing and keeps data.
    insert_ok(store, trace("t1", "V1", Some("S1"), "2026-03-02T07:00:00Z")).await;
    let url = match store {
        Store::Sqlite(s) => {
            let opts = s.pool().connect_options();
            opts.get_filename().to_string_lossy().into_owned()
        }
        Store::Postgres(s) => {
            let name: String = sqlx::query_scalar("SELECT current_database()")
                .fetch_one(s.pool())
                .await
                .expect("db name");
            with_database(&pg_admin_url(), &name)
        }
    };
    let again = Store::connect(&url).await.expect("reconnect");
    assert!(again.migrations_applied().await.expect("migrations"));
    assert!(again.get_trace("t1").await.expect("get").is_some());
    again.close().await;
}

pub(super) async fn samples_roundtrip_and_metadata(store: &Store) {
    let mut ch = channels(15001);
    ch[1].1[3] = -0.0;
    ch[1].1[4] = 0.1 + 0.2;
    ch.push((
        "F_N".into(),
        (0..15001).map(|i| f64::from(i % 7) * 9.81).collect(),
    ));
    let mut t = trace(
        "rt",
        "EN57-1021",
        Some("160EC-0042"),
        "2026-03-02T09:15:00.1234567+02:00",
    );
    t.test_json = "{ \"kind\" : \"pendulum\",  \"rig\": {\"z\": 1, \"a\": 2.50} }".into();
    t.channels = ch.clone();
    t.content_sha256 = sha('B');
    let (id, job) = insert_ok(store, t.clone()).await;
    assert!(job.is_some());
    let meta = store.get_trace(&id).await.expect("get").expect("exists");
    assert_eq!(meta.recorded_at, at("2026-03-02T07:15:00.123456Z"));
    assert_eq!(meta.test_json, t.test_json, "test object kept verbatim");
    assert_eq!(
        meta.content_sha256,
        sha('b'),
        "hash normalised to lowercase"
    );
    assert_eq!(meta.channel_names, vec!["t_s", "alpha_deg", "F_N"]);
    assert_eq!(meta.sample_count, 15001);
    assert_eq!(meta.serial.as_deref(), Some("160EC-0042"));
    assert_eq!(meta.joint.as_deref(), Some("J1"));
    assert!(
        (meta.samples_bytes as f64) < 4.0 * 3.0 * 15001.0,
        "{} bytes",
        meta.samples_bytes
    );
    let back = store
        .get_samples(&id)
        .await
        .expect("samples")
        .expect("exists");
    assert_eq!(back.len(), ch.len());
    for ((na, va), (nb, vb)) in ch.iter().zip(&back) {
        assert_eq!(na, nb);
        assert!(
            va.iter().zip(vb).all(|(x, y)| x.to_bits() == y.to_bits()),
            "{na}"
        );
        assert_eq!(va.len(), vb.len());
    }
    assert!(store.get_trace("nope").await.expect("get").is_none());
    assert!(store.get_samples("nope").await.expect("get").is_none());
}

pub(super) async fn corrupt_samples_are_an_error(store: &Store) {
    let (id, _) = insert_ok(store, trace("c1", "V1", None, "2026-03-02T07:00:00Z")).await;
    let good = samples::encode(&channels(50)).expect("encode");
    let mut bad = good.clone();
    let last = bad.len() - 1;
    bad[last] ^= 0x55;
    let sql = "UPDATE traces SET samples = $1 WHERE trace_id = $2";
    match store {
        Store::Sqlite(s) => sqlx::query(sql)
            .bind(bad)
            .bind(&id)
            .execute(s.pool())
            .await
            .map(|r| r.rows_affected()),
        Store::Postgres(s) => sqlx::query(sql)
            .bind(bad)
            .bind(&id)
            .execute(s.pool())
            .await
            .map(|r| r.rows_affected()),
    }
    .expect("corrupt it");
    let err = store
        .get_samples(&id)
        .await
        .expect_err("corruption detected");
    assert!(
        matches!(err, StoreError::Codec(CodecError::Corrupt(_))),
        "{err}"
    );
}

pub(super) async fn idempotent_insert_and_conflict(store: &Store) {
    let t = trace("same", "V1", Some("S1"), "2026-03-02T07:00:00Z");
    let (_, job) = insert_ok(store, t.clone()).await;
    assert!(job.is_some());
    assert_eq!(
        store.insert_trace(t.clone()).await.expect("again"),
        InsertOutcome::Existing {
            trace_id: "same".into()
        }
    );
    let mut other = t.clone();
    other.content_sha256 = sha('c');
    other.vehicle_id = "V2".into();
    assert_eq!(
        store.insert_trace(other).await.expect("conflict"),
        InsertOutcome::Conflict {
            trace_id: "same".into()
        }
    );
    assert_eq!(count(store, "traces").await, 1);
    assert_eq!(count(store, "jobs").await, 1);
    assert_eq!(
        count(store, "vehicles").await,
        1,
        "conflicting upload wrote no vehicle"
    );
    // Generated ids are fresh UUIDs.
    let mut anon = t.clone();
    anon.trace_id = None;
    let (a, _) = insert_ok(store, anon.clone()).await;
    let (b, _) = insert_ok(store, anon).await;
    assert_ne!(a, b);
    assert_eq!(a.len(), 36);
    // Concurrent uploads of one new id: exactly one is Created.
    let store2 = Arc::new(store.clone());
    let mut handles = Vec::new();
    for _ in 0..6 {
        let s = store2.clone();
        let t = trace("race", "V9", Some("S9"), "2026-03-03T07:00:00Z");
        handles.push(tokio::spawn(async move { s.insert_trace(t).await }));
    }
    let mut created = 0;
    for h in handles {
        match h.await.expect("join").expect("insert") {
            InsertOutcome::Created { .. } => created += 1,
            InsertOutcome::Existing { .. } => {}
            c @ InsertOutcome::Conflict { .. } => panic!("{c:?}"),
        }
    }
    assert_eq!(created, 1);
    assert_eq!(count(store, "pantograph_mounts").await, 2);
}

/// The measured-vs-model curve is written with its fit, in the same transaction, read back
/// bit for bit, kept once per fit (a repeated write keeps the first) and deleted with it.
pub(super) async fn fit_curve_is_stored_with_its_fit(store: &Store) {
    let (id, _) = insert_ok(
        store,
        trace("curve", "V-1", Some("S-1"), "2026-03-02T07:00:00Z"),
    )
    .await;
    let t: Vec<f64> = (0..1000).map(|k| f64::from(k) * 0.002).collect();
    let y: Vec<f64> = t.iter().map(|t| (3.0 * t).sin() + 0.1 + 0.2).collect();
    let m: Vec<f64> = y.iter().map(|v| v - 1e-17).collect();
    let curve = pantowatch_models::report::FitCurve::thinned("alpha_deg", "deg", &t, &y, &m)
        .expect("a curve");
    let f = fit(&id, &[("J1", Status::Ok)]).with_curve(Some(curve.clone()));
    let w = store.insert_fit(&id, "v1", &f).await.expect("fit");
    assert_eq!(
        store.fit_curve(w.fit_id).await.expect("read"),
        Some(curve.clone())
    );
    // The first write wins, curve included.
    let other = fit(&id, &[("J1", Status::Ok)]);
    assert!(
        !store
            .insert_fit(&id, "v1", &other)
            .await
            .expect("again")
            .created
    );
    assert_eq!(store.fit_curve(w.fit_id).await.expect("read"), Some(curve));
    // A fit without a curve has none; the curve goes with its fit.
    let w2 = store.insert_fit(&id, "v2", &other).await.expect("v2");
    assert_eq!(store.fit_curve(w2.fit_id).await.expect("read"), None);
    assert_eq!(count(store, "fit_curves").await, 1);
    let del = "DELETE FROM fits WHERE id = $1";
    let deleted = match store {
        Store::Sqlite(s) => sqlx::query(del)
            .bind(w.fit_id)
            .execute(s.pool())
            .await
            .map(|r| r.rows_affected()),
        Store::Postgres(s) => sqlx::query(del)
            .bind(w.fit_id)
            .execute(s.pool())
            .await
            .map(|r| r.rows_affected()),
    };
    assert_eq!(deleted.expect("delete the fit"), 1);
    assert_eq!(count(store, "fit_curves").await, 0);
}

pub(super) async fn failed_insert_writes_nothing(store: &Store) {
    // The last step (job enqueue) violates a CHECK: vehicle, pantograph, mount and trace
    // written before it in the same transaction must all disappear.
    let mut t = trace("half", "V-new", Some("S-new"), "2026-03-02T07:00:00Z");
    t.model_version = String::new();
    let err = store.insert_trace(t).await.expect_err("must fail");
    assert!(matches!(err, StoreError::Db(_)), "{err}");
    for table in [
        "vehicles",
        "pantographs",
        "pantograph_mounts",
        "traces",
        "jobs",
    ] {
        assert_eq!(count(store, table).await, 0, "{table}");
    }
    // Rejected before any SQL.
    // Each refusal names the caller's field (the API answers 422 naming it).
    let refused = |r: Result<InsertOutcome>| match r {
        Err(StoreError::InvalidField { field, .. }) => field,
        other => panic!("not a named refusal: {other:?}"),
    };
    let mut t = trace("bad", " ", None, "2026-03-02T07:00:00Z");
    assert_eq!(refused(store.insert_trace(t.clone()).await), "vehicle_id");
    t.vehicle_id = "V".into();
    t.content_sha256 = "xyz".into();
    assert_eq!(
        refused(store.insert_trace(t.clone()).await),
        "content_sha256"
    );
    t.content_sha256 = sha('a');
    // A year the backends cannot read back (issue 18: year 10000 made its vehicle answer 500).
    for year in [10_000, 0] {
        let mut y = t.clone();
        y.recorded_at = chrono::NaiveDate::from_ymd_opt(year, 1, 1)
            .and_then(|d| d.and_hms_opt(0, 30, 0))
            .expect("a date")
            .and_utc();
        assert_eq!(
            refused(store.insert_trace(y).await),
            "recorded_at",
            "year {year}"
        );
    }
    t.channels[1].1.pop();
    assert_eq!(refused(store.insert_trace(t).await), "channels");
    // A failure on an existing vehicle leaves the vehicle as it was and adds nothing else.
    insert_ok(store, trace("ok", "V1", Some("S1"), "2026-03-02T07:00:00Z")).await;
    let mut t = trace("half2", "V1", Some("S2"), "2026-03-05T07:00:00Z");
    t.model_version = String::new();
    assert!(store.insert_trace(t).await.is_err());
    assert_eq!(count(store, "pantographs").await, 1);
    assert_eq!(count(store, "traces").await, 1);
    assert!(store.get_trace("half2").await.expect("get").is_none());
    let f = store
        .fleet_health(&FleetFilter::default(), Page::default())
        .await
        .expect("fleet");
    assert_eq!(f.total, 1);
}

#[tokio::test]
async fn sqlite_url_forms() {
    let mem = Store::connect("sqlite::memory:").await.expect("memory");
    insert_ok(&mem, trace("m", "V1", Some("S1"), "2026-03-02T07:00:00Z")).await;
    assert!(mem.get_trace("m").await.expect("get").is_some());
    assert_eq!(mem.kind(), BackendKind::Sqlite);
    let dir = tempfile::tempdir().expect("dir");
    let url = format!("sqlite://{}", dir.path().join("nested.db").display());
    let file = Store::connect(&url)
        .await
        .expect("sqlite:// URL, created if missing");
    assert!(file.migrations_applied().await.expect("migrations"));
    file.close().await;
    assert!(dir.path().join("nested.db").exists());
}

/// A database migrated to 0001 with a fit in it upgrades to `unknown`-capable fit tables
/// without losing or orphaning rows.
async fn upgrade_from_0001(store_url: &str, blob: &str) {
    let rows: &[&str] = &[
        "INSERT INTO vehicles (id) VALUES ('V1')",
        "INSERT INTO pantographs (serial, model) VALUES ('S1', '160EC')",
        "INSERT INTO pantograph_mounts (serial, vehicle_id, since)
             VALUES ('S1', 'V1', '2026-01-01T00:00:00.000000Z')",
        // $BLOB is replaced by the backend's empty-blob literal.
        "INSERT INTO traces (trace_id, vehicle_id, serial, model, recorded_at, kind, joint,
                                 test_json, content_sha256, samples, sample_count, channel_names)
             VALUES ('t1', 'V1', 'S1', '160EC', '2026-01-01T00:00:00.000000Z', 'pendulum', 'J1',
                     '{}', 'aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa',
                     $BLOB, 0, '[]')",
        "INSERT INTO fits (trace_id, model_version, result_json, rmse, status)
             VALUES ('t1', 'v1', '{\"joints\": []}', 0.5, 'watch')",
        "INSERT INTO fit_joints (fit_id, joint, viscous, identifiable, status)
             SELECT id, 'J1', 0.1, true, 'watch' FROM fits",
    ];
    if store_url.starts_with("postgres") {
        let pool = sqlx::PgPool::connect(store_url).await.expect("pool");
        crate::store::postgres::MIGRATOR
            .run_to(1, &pool)
            .await
            .expect("0001");
        for r in rows {
            pool.execute(AssertSqlSafe(r.replace("$BLOB", blob)))
                .await
                .expect(r);
        }
        pool.close().await;
    } else {
        let opts = sqlx::sqlite::SqliteConnectOptions::new()
            .filename(store_url)
            .create_if_missing(true)
            .foreign_keys(true);
        let pool = sqlx::SqlitePool::connect_with(opts).await.expect("pool");
        crate::store::sqlite::MIGRATOR
            .run_to(1, &pool)
            .await
            .expect("0001");
        for r in rows {
            pool.execute(AssertSqlSafe(r.replace("$BLOB", blob)))
                .await
                .expect(r);
        }
        pool.close().await;
    }
    let store = Store::connect(store_url).await.expect("upgrade");
    assert!(store.migrations_applied().await.expect("applied"));
    let f = store.get_fit("t1").await.expect("get").expect("fit kept");
    assert_eq!(f.status, Some(Status::Watch));
    assert_eq!(f.joints.len(), 1);
    // The rebuilt tables keep their keys: a second fit of the pair is refused, a new one with
    // an unknown joint is accepted, and ids continue.
    let again = store
        .insert_fit("t1", "v1", &fit("t1", &[("J1", Status::Ok)]))
        .await
        .expect("again");
    assert!(!again.created);
    let w = store
        .insert_fit("t1", "v2", &fit("t1", &[("J1", Status::Unknown)]))
        .await
        .expect("unknown after upgrade");
    assert!(w.created && w.fit_id > f.id);
    assert_eq!(count(&store, "fit_joints").await, 2);
    if let Store::Sqlite(s) = &store {
        let bad: Vec<sqlx::sqlite::SqliteRow> = sqlx::query("PRAGMA foreign_key_check")
            .fetch_all(s.pool())
            .await
            .expect("fk check");
        assert!(bad.is_empty(), "foreign keys intact");
        let fk: i64 = sqlx::query_scalar("PRAGMA foreign_keys")
            .fetch_one(s.pool())
            .await
            .expect("pragma");
        assert_eq!(fk, 1);
    }
    store.close().await;
}

#[tokio::test]
async fn sqlite_upgrade_from_0001() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = dir.path().join("old.db");
    upgrade_from_0001(path.to_str().expect("utf-8"), "x''").await;
}

#[tokio::test]
async fn postgres_upgrade_from_0001() {
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
    let _guard = PgDrop {
        admin_url: admin_url.clone(),
        name: name.clone(),
    };
    upgrade_from_0001(&with_database(&admin_url, &name), "'\\x'::bytea").await;
}
