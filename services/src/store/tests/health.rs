//! Vehicles, joint history and fleet health: mounts, filters, pages, statuses, the informed verdicts.
//! Each case runs on SQLite and on PostgreSQL (`contract!` in `mod.rs`).

use super::*;

pub(super) async fn history_mounts_and_vehicles(store: &Store) {
    // Uploaded out of order; the pantograph moves from V1 to V2 in May.
    let uploads = [
        ("mar", "V1", "2026-03-01T08:00:00Z", Status::Watch),
        ("jan", "V1", "2026-01-01T08:00:00Z", Status::Ok),
        ("may", "V2", "2026-05-01T08:00:00Z", Status::Alarm),
        ("apr", "V1", "2026-04-01T08:00:00Z", Status::Watch),
    ];
    for (id, v, when, status) in uploads {
        insert_ok(store, trace(id, v, Some("S1"), when)).await;
        let f = fit(id, &[("J1", status), ("J2", Status::Ok)]);
        store.insert_fit(id, "v1", &f).await.expect("fit");
    }
    // A trace without serial still links its vehicle; an unfitted later trace changes nothing.
    insert_ok(store, trace("noserial", "V3", None, "2026-06-01T08:00:00Z")).await;
    assert_eq!(
        store
            .get_trace("noserial")
            .await
            .expect("get")
            .expect("exists")
            .serial,
        None
    );
    insert_ok(
        store,
        trace("jun", "V2", Some("S1"), "2026-06-01T08:00:00Z"),
    )
    .await;

    let h = store.joint_history("S1", "J1").await.expect("history");
    let order: Vec<_> = h.iter().map(|p| p.trace_id.as_str()).collect();
    assert_eq!(order, ["jan", "mar", "apr", "may"]);
    assert_eq!(h[3].vehicle_id, "V2");
    assert_eq!(h[0].fit.status, Status::Ok);
    assert_eq!(h[0].fit.viscous_lo, Some(0.031));
    assert!(h.windows(2).all(|w| w[0].recorded_at < w[1].recorded_at));
    // A refit of January with a new model version replaces that point, not adds one.
    store
        .insert_fit("jan", "v2", &fit("jan", &[("J1", Status::Alarm)]))
        .await
        .expect("refit");
    let h = store.joint_history("S1", "J1").await.expect("history");
    assert_eq!(h.len(), 4);
    assert_eq!(
        (h[0].model_version.as_str(), h[0].fit.status),
        ("v2", Status::Alarm)
    );
    assert_eq!(
        store
            .joint_history("S1", "J2")
            .await
            .expect("history")
            .len(),
        3
    );
    assert!(
        store
            .joint_history("S1", "J9")
            .await
            .expect("history")
            .is_empty()
    );
    assert!(
        store
            .joint_history("nope", "J1")
            .await
            .expect("history")
            .is_empty()
    );

    let v1 = store.get_vehicle("V1").await.expect("get").expect("exists");
    assert!(v1.pantographs.is_empty(), "moved away in May");
    let v2 = store.get_vehicle("V2").await.expect("get").expect("exists");
    assert_eq!(v2.pantographs.len(), 1);
    let p = &v2.pantographs[0];
    assert_eq!(p.serial, "S1");
    assert_eq!(p.since, at("2026-05-01T08:00:00Z"));
    assert_eq!(p.last_test, Some(at("2026-06-01T08:00:00Z")));
    let latest: BTreeMap<_, _> = p.joints.iter().map(|j| (j.fit.joint.as_str(), j)).collect();
    assert_eq!(latest["J1"].trace_id, "may");
    assert_eq!(latest["J1"].fit.status, Status::Alarm);
    assert_eq!(latest["J2"].trace_id, "may");
    assert_eq!(p.worst_status, Some(Status::Alarm));
    assert!(store.get_vehicle("V404").await.expect("get").is_none());

    let vs = store.list_vehicles().await.expect("list");
    let summary: Vec<_> = vs
        .iter()
        .map(|v| (v.vehicle_id.as_str(), v.pantographs, v.traces))
        .collect();
    assert_eq!(summary, [("V1", 0, 3), ("V2", 1, 2), ("V3", 0, 1)]);
    assert_eq!(vs[0].last_test, Some(at("2026-04-01T08:00:00Z")));
    assert_eq!(
        count(store, "pantograph_mounts").await,
        2,
        "V1 since Jan, V2 since May"
    );
}

pub(super) async fn fleet_health_filter_and_pagination(store: &Store) {
    // serial, vehicle, [(trace recorded_at, joint statuses)]
    type Plan<'a> = (&'a str, &'a str, &'a [(&'a str, &'a [(&'a str, Status)])]);
    let plan: [Plan<'_>; 7] = [
        (
            "P0",
            "V1",
            &[(
                "2026-02-01",
                &[("J1", Status::Alarm), ("J3", Status::Watch)],
            )],
        ),
        ("P1", "V1", &[("2026-02-02", &[("J1", Status::Watch)])]),
        ("P2", "V2", &[("2026-02-03", &[("J1", Status::Ok)])]),
        ("P3", "V2", &[("2026-02-04", &[("J2", Status::Alarm)])]),
        // Alarm long ago, ok since: latest wins.
        (
            "P4",
            "V3",
            &[
                ("2026-01-01", &[("J1", Status::Alarm)]),
                ("2026-03-01", &[("J1", Status::Ok)]),
            ],
        ),
        ("P5", "V3", &[]),
        (
            "P6",
            "V2",
            &[("2026-02-06", &[("J4", Status::Ok), ("J5", Status::Watch)])],
        ),
    ];
    for (serial, vehicle, tests) in plan {
        if tests.is_empty() {
            insert_ok(
                store,
                trace(
                    &format!("{serial}-x"),
                    vehicle,
                    Some(serial),
                    "2026-02-07T00:00:00Z",
                ),
            )
            .await;
        }
        for (day, joints) in tests {
            let id = format!("{serial}-{day}");
            insert_ok(
                store,
                trace(&id, vehicle, Some(serial), &format!("{day}T10:00:00Z")),
            )
            .await;
            store
                .insert_fit(&id, "v1", &fit(&id, joints))
                .await
                .expect("fit");
        }
    }
    let all = store
        .fleet_health(
            &FleetFilter::default(),
            Page {
                limit: 100,
                offset: 0,
            },
        )
        .await
        .expect("fleet");
    let order: Vec<_> = all.rows.iter().map(|r| r.serial.as_str()).collect();
    assert_eq!(order, ["P0", "P3", "P1", "P6", "P2", "P4", "P5"]);
    assert_eq!(all.total, 7);
    let p0 = &all.rows[0];
    assert_eq!(p0.worst_status, Some(Status::Alarm));
    assert_eq!(p0.vehicle_id.as_deref(), Some("V1"));
    assert_eq!(
        p0.not_ok,
        vec![
            JointStatus {
                joint: "J1".into(),
                status: Status::Alarm
            },
            JointStatus {
                joint: "J3".into(),
                status: Status::Watch
            },
        ]
    );
    assert_eq!(p0.last_test, Some(at("2026-02-01T10:00:00Z")));
    let p4 = all.rows.iter().find(|r| r.serial == "P4").expect("P4");
    assert_eq!((p4.worst_status, p4.not_ok.len()), (Some(Status::Ok), 0));
    let p5 = all.rows.iter().find(|r| r.serial == "P5").expect("P5");
    assert_eq!(p5.worst_status, None);

    let mut paged = Vec::new();
    for offset in [0, 3, 6, 9] {
        let page = store
            .fleet_health(&FleetFilter::default(), Page { limit: 3, offset })
            .await
            .expect("page");
        assert_eq!(page.total, 7);
        paged.extend(page.rows.into_iter().map(|r| r.serial));
    }
    assert_eq!(paged, order);

    let alarms = store
        .fleet_health(
            &FleetFilter {
                status: Some(Status::Alarm),
                vehicle_id: None,
            },
            Page::default(),
        )
        .await
        .expect("alarm");
    assert_eq!(alarms.total, 2);
    let v2 = store
        .fleet_health(
            &FleetFilter {
                status: None,
                vehicle_id: Some("V2".into()),
            },
            Page::default(),
        )
        .await
        .expect("V2");
    let s: Vec<_> = v2.rows.iter().map(|r| r.serial.as_str()).collect();
    assert_eq!(s, ["P3", "P6", "P2"]);
    let both = store
        .fleet_health(
            &FleetFilter {
                status: Some(Status::Watch),
                vehicle_id: Some("V2".into()),
            },
            Page {
                limit: 1,
                offset: 0,
            },
        )
        .await
        .expect("both");
    assert_eq!(both.total, 1);
    assert_eq!(both.rows[0].serial, "P6");
    assert_eq!(
        both.rows[0].not_ok,
        vec![JointStatus {
            joint: "J5".into(),
            status: Status::Watch
        }]
    );
    let none = store
        .fleet_health(
            &FleetFilter {
                status: None,
                vehicle_id: Some("V404".into()),
            },
            Page::default(),
        )
        .await
        .expect("none");
    assert_eq!((none.total, none.rows.len()), (0, 0));
}

pub(super) async fn unknown_status_and_counts(store: &Store) {
    assert_eq!(store.counts().await.expect("counts"), Counts::default());
    // An unidentifiable joint is `unknown`: stored, ranked below `ok`, listed as not ok.
    for (id, serial, joints) in [
        ("u1", "PU", &[("J7", Status::Unknown)][..]),
        (
            "u2",
            "PM",
            &[("J1", Status::Ok), ("J6", Status::Unknown)][..],
        ),
    ] {
        insert_ok(store, trace(id, "VU", Some(serial), "2026-05-01T10:00:00Z")).await;
        let w = store
            .insert_fit(id, "v1", &fit(id, joints))
            .await
            .expect("fit with an unknown joint");
        assert!(w.created);
    }
    let f = store.get_fit("u1").await.expect("get").expect("fit");
    assert_eq!(f.status, Some(Status::Unknown));
    assert!(store.pantograph_exists("PU").await.expect("exists"));
    assert!(!store.pantograph_exists("nope").await.expect("exists"));
    assert_eq!(f.joints[0].status, Status::Unknown);
    let page = store
        .fleet_health(&FleetFilter::default(), Page::default())
        .await
        .expect("fleet");
    let order: Vec<_> = page
        .rows
        .iter()
        .map(|r| (r.serial.as_str(), r.worst_status))
        .collect();
    assert_eq!(
        order,
        [("PM", Some(Status::Ok)), ("PU", Some(Status::Unknown))]
    );
    assert_eq!(
        page.rows[0].not_ok,
        vec![JointStatus {
            joint: "J6".into(),
            status: Status::Unknown
        }]
    );
    let only_unknown = store
        .fleet_health(
            &FleetFilter {
                status: Some(Status::Unknown),
                vehicle_id: None,
            },
            Page::default(),
        )
        .await
        .expect("fleet");
    assert_eq!(only_unknown.total, 1);
    store.create_api_key(Role::Reader, "r").await.expect("key");
    assert_eq!(
        store.counts().await.expect("counts"),
        Counts {
            vehicles: 1,
            pantographs: 2,
            traces: 2,
            fits: 2,
            jobs: 2,
            api_keys: 1,
        }
    );
}

/// A test that cannot identify a joint (a lift for J2) does not hide the last test that could:
/// fleet health and the vehicle view show a joint's latest informed verdict.
pub(super) async fn latest_informed_verdict_wins(store: &Store) {
    for (id, when, status) in [
        ("w1", "2026-04-01T10:00:00Z", Status::Alarm),
        ("w2", "2026-05-01T10:00:00Z", Status::Unknown),
    ] {
        insert_ok(store, trace(id, "VW", Some("PW"), when)).await;
        store
            .insert_fit(id, "v1", &fit(id, &[("J2", status)]))
            .await
            .expect("fit");
    }
    let page = store
        .fleet_health(&FleetFilter::default(), Page::default())
        .await
        .expect("fleet");
    assert_eq!(
        page.rows[0].worst_status,
        Some(Status::Alarm),
        "the uninformed later test hides nothing"
    );
    let v = store
        .get_vehicle("VW")
        .await
        .expect("vehicle")
        .expect("exists");
    assert_eq!(v.pantographs[0].joints[0].fit.status, Status::Alarm);
    // A later informed test decides.
    insert_ok(store, trace("w3", "VW", Some("PW"), "2026-06-01T10:00:00Z")).await;
    store
        .insert_fit("w3", "v1", &fit("w3", &[("J2", Status::Ok)]))
        .await
        .expect("fit");
    let page = store
        .fleet_health(&FleetFilter::default(), Page::default())
        .await
        .expect("fleet");
    assert_eq!(page.rows[0].worst_status, Some(Status::Ok));
    // The history keeps every test, informed or not.
    assert_eq!(
        store
            .joint_history("PW", "J2")
            .await
            .expect("history")
            .len(),
        3
    );
}

/// `joint_latest` / `pantograph_health` (kept at each fit write) against the window over every
/// fit they replace: equal after out-of-order uploads, re-fits by a new model version (which
/// may drop a joint or make it unidentifiable), mount moves, fits written concurrently for one
/// pantograph, and for every filter and page.
pub(super) async fn health_table_agrees_with_window(store: &Store) {
    async fn agree(store: &Store, step: &str) {
        let (window, table) = match store {
            Store::Sqlite(s) => s.latest_both_ways().await,
            Store::Postgres(s) => s.latest_both_ways().await,
        }
        .expect("latest both ways");
        assert!(!window.is_empty(), "{step}: the window found no joint");
        assert_eq!(
            table, window,
            "{step}: joint_latest differs from the window"
        );
        let filters = [
            None,
            Some(Status::Alarm),
            Some(Status::Watch),
            Some(Status::Ok),
            Some(Status::Unknown),
        ]
        .into_iter()
        .flat_map(|s| {
            [None, Some("VA"), Some("VB")].map(move |v| FleetFilter {
                status: s,
                vehicle_id: v.map(str::to_owned),
            })
        });
        for f in filters {
            for page in [
                Page::default(),
                Page {
                    limit: 2,
                    offset: 0,
                },
                Page {
                    limit: 2,
                    offset: 3,
                },
            ] {
                let new = store.fleet_health(&f, page).await.expect("fleet");
                let old = match store {
                    Store::Sqlite(s) => s.fleet_health_by_window(&f, page).await,
                    Store::Postgres(s) => s.fleet_health_by_window(&f, page).await,
                }
                .expect("fleet by window");
                assert_eq!(new, old, "{step}: fleet health differs for {f:?} {page:?}");
            }
        }
    }
    const STATUSES: [Status; 4] = [Status::Ok, Status::Watch, Status::Alarm, Status::Unknown];
    const JOINTS: [&str; 4] = ["J1", "J2", "J3", "J5"];
    // A small deterministic generator: which joints a fit has and their statuses.
    let mut seed: u64 = 0x9E37_79B9_7F4A_7C15;
    let mut next = move || {
        seed = seed.wrapping_mul(6_364_136_223_846_793_005).wrapping_add(1);
        (seed >> 33) as usize
    };
    let mut fitted = Vec::new();
    // Five pantographs, months uploaded out of order (month 3 before month 1).
    for month in [3, 1, 2, 5, 4] {
        for p in 0..5 {
            let id = format!("P{p}-m{month}");
            let vehicle = if p < 3 { "VA" } else { "VB" };
            let when = format!("2026-0{month}-0{}T08:00:00Z", p + 1);
            insert_ok(store, trace(&id, vehicle, Some(&format!("P{p}")), &when)).await;
            let n = 1 + next() % 3;
            let joints: Vec<(&str, Status)> = (0..n)
                .map(|k| (JOINTS[(next() + k) % 4], STATUSES[next() % 4]))
                .collect::<BTreeMap<_, _>>()
                .into_iter()
                .collect();
            store
                .insert_fit(&id, "v1", &fit(&id, &joints))
                .await
                .expect("fit");
            fitted.push(id);
        }
    }
    // A pantograph with a trace but no fit yet, and a trace without a serial.
    insert_ok(
        store,
        trace("P9-m1", "VB", Some("P9"), "2026-01-09T08:00:00Z"),
    )
    .await;
    let (anon, _) = insert_ok(store, trace("anon", "VA", None, "2026-01-09T08:00:00Z")).await;
    store
        .insert_fit(&anon, "v1", &fit(&anon, &[("J1", Status::Alarm)]))
        .await
        .expect("fit");
    agree(store, "after first fits").await;

    // Re-fits by a new model version: the newest fit of a trace replaces its points, even when it
    // drops a joint or can no longer identify it.
    for id in fitted.iter().step_by(3) {
        let joints = [(JOINTS[next() % 4], STATUSES[next() % 4])];
        store
            .insert_fit(id, "v2", &fit(id, &joints))
            .await
            .expect("re-fit");
    }
    // Writing an existing (trace, version) again changes nothing.
    let w = store
        .insert_fit(&fitted[0], "v2", &fit(&fitted[0], &[("J1", Status::Alarm)]))
        .await
        .expect("again");
    assert!(!w.created);
    agree(store, "after re-fits").await;

    // P1 moves to VB; a later month of P0 arrives.
    insert_ok(
        store,
        trace("P1-m6", "VB", Some("P1"), "2026-06-02T08:00:00Z"),
    )
    .await;
    store
        .insert_fit("P1-m6", "v1", &fit("P1-m6", &[("J2", Status::Watch)]))
        .await
        .expect("fit");
    agree(store, "after a move").await;

    // Fits of one pantograph written concurrently (PostgreSQL: the pantograph row lock orders
    // the refreshes; SQLite: BEGIN IMMEDIATE).
    let mut ids = Vec::new();
    for d in 1..=8 {
        let id = format!("P2-c{d}");
        insert_ok(
            store,
            trace(&id, "VA", Some("P2"), &format!("2026-07-0{d}T08:00:00Z")),
        )
        .await;
        ids.push(id);
    }
    let writes = ids.iter().enumerate().map(|(k, id)| {
        let store = store.clone();
        let id = id.clone();
        tokio::spawn(async move {
            let joints = [("J1", STATUSES[k % 4]), ("J3", STATUSES[(k + 1) % 4])];
            store.insert_fit(&id, "v1", &fit(&id, &joints)).await
        })
    });
    for w in writes.collect::<Vec<_>>() {
        w.await.expect("task").expect("concurrent fit");
    }
    agree(store, "after concurrent fits").await;
}
