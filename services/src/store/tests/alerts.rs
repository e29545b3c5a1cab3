//! Alerts and the webhook outbox.
//! Each case runs on SQLite and on PostgreSQL (`contract!` in `mod.rs`).

use super::*;

fn new_alert(serial: &str, joint: &str, sev: Severity, trace_id: &str) -> NewAlert {
    NewAlert {
        serial: serial.into(),
        joint: joint.into(),
        vehicle_id: Some("V-1".into()),
        severity: sev,
        reason: format!("status {sev}"),
        evidence: json!({"model_version": "v1", "trace_id": trace_id}),
        trace_id: trace_id.into(),
    }
}

pub(super) async fn alert_lifecycle_dedup_escalate_resolve(store: &Store) {
    insert_ok(
        store,
        trace("t1", "V-1", Some("S-1"), "2026-01-01T00:00:00Z"),
    )
    .await;
    let (_, secret) = store
        .create_webhook("http://127.0.0.1:9/hook", &[Severity::Alarm])
        .await
        .expect("webhook");
    assert!(secret.starts_with("whsec_") && secret.len() > 40);
    store
        .create_webhook(
            "http://127.0.0.1:9/all",
            &[Severity::Watch, Severity::Alarm],
        )
        .await
        .expect("webhook");
    assert!(store.create_webhook("http://x", &[]).await.is_err());

    let a = match store
        .raise_alert(&new_alert("S-1", "J1", Severity::Watch, "t1"))
        .await
        .expect("raise")
    {
        RaiseOutcome::Opened(a) => a,
        o => panic!("expected Opened, got {o:?}"),
    };
    assert_eq!((a.state, a.severity), (AlertState::Open, Severity::Watch));
    assert_eq!(a.evidence["trace_id"], "t1");
    // Same joint again at watch: the same alert, refreshed.
    let o = store
        .raise_alert(&new_alert("S-1", "J1", Severity::Watch, "t2"))
        .await
        .expect("raise");
    assert!(
        matches!(&o, RaiseOutcome::Updated(b) if b.id == a.id && b.trace_id == "t2"),
        "{o:?}"
    );
    // Acknowledged, then escalated: back to open at alarm, in place.
    let t = store
        .acknowledge_alert(a.id, "ann", "looking")
        .await
        .expect("ack");
    assert!(
        matches!(&t, Transition::Done(b) if b.state == AlertState::Acknowledged
        && b.acknowledged_by.as_deref() == Some("ann")),
        "{t:?}"
    );
    let t = store
        .acknowledge_alert(a.id, "bob", "again")
        .await
        .expect("ack");
    assert!(matches!(t, Transition::Refused(_)));
    let o = store
        .raise_alert(&new_alert("S-1", "J1", Severity::Alarm, "t3"))
        .await
        .expect("raise");
    assert!(
        matches!(&o, RaiseOutcome::Escalated(b) if b.id == a.id
        && b.severity == Severity::Alarm && b.state == AlertState::Open),
        "{o:?}"
    );
    // A lower severity never downgrades.
    let o = store
        .raise_alert(&new_alert("S-1", "J1", Severity::Watch, "t4"))
        .await
        .expect("raise");
    assert_eq!(o.alert().severity, Severity::Alarm);
    // Another joint: its own alert.
    let other = store
        .raise_alert(&new_alert("S-1", "J2", Severity::Watch, "t4"))
        .await
        .expect("raise");
    assert!(matches!(other, RaiseOutcome::Opened(_)));

    let live = store
        .list_alerts(&AlertFilter {
            live: true,
            ..AlertFilter::default()
        })
        .await
        .expect("list");
    assert_eq!(live.len(), 2);
    let alarms = store
        .list_alerts(&AlertFilter {
            severity: Some(Severity::Alarm),
            ..AlertFilter::default()
        })
        .await
        .expect("list");
    assert_eq!(alarms.iter().map(|a| a.id).collect::<Vec<_>>(), vec![a.id]);
    let none = store
        .list_alerts(&AlertFilter {
            vehicle_id: Some("V-9".into()),
            ..AlertFilter::default()
        })
        .await
        .expect("list");
    assert!(none.is_empty());

    // Back in band: resolved automatically; resolving again is refused; a new raise opens anew.
    let r = store
        .resolve_joint_alert("S-1", "J1", "t5", "back in band")
        .await
        .expect("resolve");
    assert_eq!(
        r.map(|a| (a.id, a.state)),
        Some((a.id, AlertState::Resolved))
    );
    assert!(
        store
            .resolve_joint_alert("S-1", "J1", "t5", "x")
            .await
            .expect("r")
            .is_none()
    );
    assert!(matches!(
        store.resolve_alert(a.id, "ann", "x").await.expect("r"),
        Transition::Refused(_)
    ));
    assert!(matches!(
        store.resolve_alert(999_999, "ann", "x").await.expect("r"),
        Transition::NotFound
    ));
    let again = store
        .raise_alert(&new_alert("S-1", "J1", Severity::Watch, "t6"))
        .await
        .expect("raise");
    assert!(matches!(&again, RaiseOutcome::Opened(b) if b.id != a.id));

    let kinds: Vec<String> = store
        .alert_events(a.id)
        .await
        .expect("events")
        .into_iter()
        .map(|e| format!("{}:{}:{}", e.kind, e.severity, e.actor))
        .collect();
    assert_eq!(
        kinds,
        [
            "opened:watch:system",
            "updated:watch:system",
            "acknowledged:watch:ann",
            "escalated:alarm:system",
            "updated:alarm:system",
            "resolved:alarm:system"
        ]
    );
    // Outbox: alarm-only hook got escalated + resolved of J1; the all-hook also the openings.
    let hooks = store.list_webhooks().await.expect("hooks");
    let events = |v: Vec<Delivery>| {
        let mut e: Vec<String> = v
            .into_iter()
            .map(|d| format!("{}#{}", d.event, d.alert_id))
            .collect();
        e.sort();
        e
    };
    let alarm_only = events(store.list_deliveries(hooks[0].id, 100).await.expect("d"));
    assert_eq!(
        alarm_only,
        [
            format!("alert.escalated#{}", a.id),
            format!("alert.resolved#{}", a.id)
        ]
    );
    let all = store.list_deliveries(hooks[1].id, 100).await.expect("d");
    assert_eq!(all.len(), 5, "{:?}", events(all));
}

pub(super) async fn alert_raises_race_to_one_alert(store: &Store) {
    insert_ok(
        store,
        trace("t1", "V-1", Some("S-1"), "2026-01-01T00:00:00Z"),
    )
    .await;
    let mut set = tokio::task::JoinSet::new();
    for i in 0..8 {
        let s = store.clone();
        set.spawn(async move {
            let sev = if i % 2 == 0 {
                Severity::Watch
            } else {
                Severity::Alarm
            };
            s.raise_alert(&new_alert("S-1", "J3", sev, &format!("t{i}")))
                .await
        });
    }
    let mut opened = 0;
    while let Some(r) = set.join_next().await {
        opened += usize::from(matches!(
            r.expect("task").expect("raise"),
            RaiseOutcome::Opened(_)
        ));
    }
    assert_eq!(opened, 1);
    let live = store
        .list_alerts(&AlertFilter {
            live: true,
            ..AlertFilter::default()
        })
        .await
        .expect("list");
    assert_eq!(live.len(), 1);
    assert_eq!(live[0].severity, Severity::Alarm);
}

pub(super) async fn webhook_outbox_claim_retry_finish(store: &Store) {
    insert_ok(
        store,
        trace("t1", "V-1", Some("S-1"), "2026-01-01T00:00:00Z"),
    )
    .await;
    let (hook, secret) = store
        .create_webhook(
            "http://127.0.0.1:9/hook",
            &[Severity::Watch, Severity::Alarm],
        )
        .await
        .expect("webhook");
    let a = store
        .raise_alert(&new_alert("S-1", "J1", Severity::Watch, "t1"))
        .await
        .expect("raise");
    let lease = Duration::from_secs(60);
    let due = store.claim_deliveries(10, lease).await.expect("claim");
    assert_eq!(due.len(), 1);
    let d = &due[0];
    assert_eq!(
        (d.attempts, d.secret.as_str(), d.url.as_str()),
        (1, secret.as_str(), "http://127.0.0.1:9/hook")
    );
    let body: serde_json::Value = serde_json::from_str(&d.payload).expect("payload json");
    assert_eq!(body["event"], "alert.opened");
    assert_eq!(body["alert"]["id"], a.alert().id);
    // Leased: not due again.
    assert!(
        store
            .claim_deliveries(10, lease)
            .await
            .expect("claim")
            .is_empty()
    );
    // Failed attempt, retry due now.
    let retry = AttemptResult::Retry {
        status: Some(500),
        error: "HTTP 500".into(),
        next_at: Utc::now() - chrono::TimeDelta::seconds(1),
    };
    assert!(
        store
            .finish_delivery(d.id, 1, &retry)
            .await
            .expect("finish")
    );
    let due = store.claim_deliveries(10, lease).await.expect("claim");
    assert_eq!(due.iter().map(|d| d.attempts).collect::<Vec<_>>(), vec![2]);
    // The first attempt's late finisher changes nothing: attempt 2 holds the delivery.
    assert!(
        !store
            .finish_delivery(d.id, 1, &AttemptResult::Delivered { status: 200 })
            .await
            .expect("finish")
    );
    assert!(
        store
            .finish_delivery(d.id, 2, &AttemptResult::Delivered { status: 204 })
            .await
            .expect("finish")
    );
    let log = store.list_deliveries(hook.id, 10).await.expect("log");
    assert_eq!(log.len(), 1);
    assert_eq!(
        (log[0].state, log[0].attempts, log[0].last_status),
        (DeliveryState::Delivered, 2, Some(204))
    );
    assert!(log[0].delivered_at.is_some());

    // A lease that runs out makes the delivery due again (at least once).
    store
        .resolve_alert(a.alert().id, "ann", "fixed")
        .await
        .expect("resolve");
    let due = store
        .claim_deliveries(10, Duration::from_millis(1))
        .await
        .expect("claim");
    assert_eq!(due.len(), 1);
    tokio::time::sleep(Duration::from_millis(20)).await;
    let again = store.claim_deliveries(10, lease).await.expect("claim");
    assert_eq!((again.len(), again[0].attempts), (1, 2));
    assert!(
        store
            .finish_delivery(
                again[0].id,
                2,
                &AttemptResult::Failed {
                    status: None,
                    error: "timeout".into()
                }
            )
            .await
            .expect("finish")
    );
    // Deleting the subscription fails what is pending and stops claims.
    store
        .raise_alert(&new_alert("S-1", "J2", Severity::Alarm, "t2"))
        .await
        .expect("raise");
    assert!(store.delete_webhook(hook.id).await.expect("delete"));
    assert!(!store.delete_webhook(hook.id).await.expect("delete"));
    assert!(
        store
            .claim_deliveries(10, lease)
            .await
            .expect("claim")
            .is_empty()
    );
    let log = store.list_deliveries(hook.id, 10).await.expect("log");
    let states: Vec<_> = log.iter().map(|d| d.state).collect();
    assert_eq!(
        states,
        [
            DeliveryState::Failed,
            DeliveryState::Failed,
            DeliveryState::Delivered
        ]
    );
    assert_eq!(log[0].last_error.as_deref(), Some("subscription deleted"));
}
